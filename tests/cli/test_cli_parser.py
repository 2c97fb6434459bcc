"""What a new user meets first: `tapmp --help` answers before any numerical library is loaded, an
argparse error is one line saying where the help is, and a shipped scenario or study is found by
name (a misspelled one gets the shipped names and the closest ones). Every case runs the real
command (`python -m orchestrator`) in a child process from a folder that is not the checkout."""

import subprocess
import sys

import pytest

from orchestrator.builder.families import data_dir
from orchestrator.tool.scenario import RESULT_FORMATS

pytestmark = pytest.mark.slow  # child processes

HEAVY = ("numpy", "scipy", "matplotlib", "fmpy", "dask", "pydantic")


def _tapmp(*args, cwd):
    return subprocess.run([sys.executable, "-m", "orchestrator", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=600)


def _modules_loaded_by(argv, cwd) -> set[str]:
    """The top-level modules `tapmp ARGV` has loaded when it exits (here: through --help or an error)."""
    code = ("import sys\nfrom orchestrator.cli import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit:\n"
            "    pass\nprint(' '.join(sorted({m.split('.')[0] for m in sys.modules})), file=sys.stderr)\n")
    res = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, cwd=cwd, timeout=600)
    return set(res.stderr.strip().splitlines()[-1].split())


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["study", "--help"], ["run", "--fmus", "natve", "x"]])
def test_help_and_a_refused_option_load_no_numerical_library(tmp_path, argv):
    loaded = _modules_loaded_by(argv, tmp_path)
    assert "orchestrator" in loaded and "argparse" in loaded
    assert not loaded & set(HEAVY), sorted(loaded & set(HEAVY))


def test_a_run_loads_no_dask(tmp_path):
    # the error types the CLI reports as one line include the studies' (StudyError): naming them
    # must not import the study runner and Dask (about 0.6 s of every `tapmp run`)
    loaded = _modules_loaded_by(["run", str(tmp_path / "missing.toml")], tmp_path)
    assert "orchestrator" in loaded and not loaded & {"dask", "distributed"}, sorted(loaded & {"dask", "distributed"})


def test_the_help_lists_every_subcommand_and_the_shipped_names(tmp_path):
    res = _tapmp("--help", cwd=tmp_path)
    assert res.returncode == 0 and res.stderr == ""
    for command in ("build", "run", "check", "compare", "reproduce", "study", "export", "plot"):
        assert command in res.stdout
    run = _tapmp("run", "--help", cwd=tmp_path).stdout
    assert "paper_simulation" in run and "point_to_point" in run
    study = _tapmp("study", "--help", cwd=tmp_path).stdout
    assert "gain_sweep" in study and "robustness" in study


@pytest.mark.parametrize("argv, expected", [
    (["run", "x.toml", "--fmus", "natve"],
     "error: tapmp run: argument --fmus: fmus = 'natve' is invalid: allowed are python, native, fmi3; did you mean "
     "native? (see tapmp run --help)"),
    (["run"], "error: tapmp run: the following arguments are required: scenario (see tapmp run --help)"),
    (["compare", "x.toml", "--format", "cvs"],
     "error: tapmp compare: argument --format: format = 'cvs' is invalid: allowed are csv, mat; did you mean csv? "
     "(see tapmp compare --help)"),
    (["rnu"], "error: tapmp: argument command: 'rnu' is invalid: allowed are build, run, check, analyze, frf, compare, "
              "reproduce, study, export, plot, paper-gains, calibrate, null-models, theorem1, modal; did you mean run? "
              "(see tapmp --help)"),
    (["run", "x.toml", "--no-such-option"], "error: tapmp: unrecognized arguments: --no-such-option "
                                            "(see tapmp --help)"),
    (["reproduce", "--workers", "two"], "error: tapmp reproduce: argument --workers: invalid int value: 'two' "
                                        "(see tapmp reproduce --help)"),
])
def test_an_argparse_error_is_one_line_naming_the_help_exit_2(tmp_path, argv, expected):
    res = _tapmp(*argv, cwd=tmp_path)
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr == expected + "\n"


def test_the_format_option_offers_the_scenario_formats(tmp_path):
    # the option's metavar and its refusal list what a scenario's `format` accepts
    assert "--format {" + ",".join(RESULT_FORMATS) + "}" in _tapmp("run", "--help", cwd=tmp_path).stdout
    res = _tapmp("run", "--format", "hdf5", cwd=tmp_path)
    assert res.returncode == 2 and "format = 'hdf5' is invalid: allowed are " + ", ".join(RESULT_FORMATS) in res.stderr


@pytest.mark.parametrize("kind, argv, close", [
    ("scenario", ["run", "paper_simulaton"], "paper_simulation"),
    ("scenario", ["check", "point_to_pont.toml"], "point_to_point"),
    ("study", ["study", "gain_swep"], "gain_sweep"),
])
def test_a_missing_scenario_or_study_gets_the_shipped_names_and_the_closest(tmp_path, kind, argv, close):
    res = _tapmp(*argv, cwd=tmp_path)
    names = sorted(f.stem for f in data_dir("scenarios" if kind == "scenario" else "studies").glob("*.toml"))
    assert res.returncode == 2 and len(res.stderr.splitlines()) == 1, res.stderr
    assert res.stderr.startswith(f"error: {kind} '{argv[1]}' is neither a file nor a shipped {kind}: shipped are "
                                 f"{', '.join(names)}; did you mean {close}"), res.stderr


def test_a_shipped_study_is_found_by_name_like_a_shipped_scenario(tmp_path):
    # from a folder without studies/: the name finds the shipped file, which then reaches the next check
    res = _tapmp("study", "gain_sweep", "--ssp", "none.ssp", cwd=tmp_path)
    assert res.returncode == 2
    assert res.stderr == ("error: SSP file none.ssp does not exist: build the FMUs first (bash build_fmus.sh, or "
                          "tapmp build) or pass --ssp\n")
    res = _tapmp("check", "paper_simulation", "--set", "stop_time=0.01", cwd=tmp_path)
    assert res.returncode == 0 and res.stdout.startswith("paper_simulation: "), res.stderr


@pytest.mark.parametrize("command", ["check", "run", "analyze"])
def test_a_study_file_given_as_a_scenario_says_to_run_it_with_tapmp_study(tmp_path, command):
    study = data_dir("studies") / "gain_sweep.toml"
    res = _tapmp(command, str(study), cwd=tmp_path)
    assert (res.returncode, res.stdout) == (2, "")
    assert res.stderr == (f"error: {study} is a study file (it has a [study] table), not a scenario: run it with "
                          f"tapmp study {study}\n")


def test_check_prints_a_growth_factor_just_above_1_with_the_digits_that_show_it(tmp_path):
    # Theorem 1's counterexample at a 1 us step: the worst mode grows by about 2e-5 per step
    from tests.paper.test_theorem1 import COUNTER
    from orchestrator.tool.scenario import load
    from orchestrator.tool.stability import check
    scenario = tmp_path / "theorem1.toml"
    scenario.write_text('name = "theorem1"\nstop_time = 0.01\nstep = 1e-6\n[gain_overrides]\n'
                        + "".join(f"{k} = {v[0]!r}\n" for k, v in COUNTER.items()))
    rho = check(load(str(scenario))).spectral_radius
    assert 1.0 < rho < 1.001
    res = _tapmp("check", str(scenario), cwd=tmp_path)
    assert res.returncode == 1, res.stderr
    printed = res.stdout.split("spectral radius ")[1].split()[0]
    factor = res.stdout.split("worst mode grows x")[1].split()[0]
    assert factor == printed
    assert abs((float(factor) - 1.0) - (rho - 1.0)) <= 0.05 * (rho - 1.0), (factor, rho)  # the growth is there


def _blas_threads_after_check(cwd, env_value):
    """(OPENBLAS_NUM_THREADS, the process's thread count) after `tapmp check` of the paper scenario
    in a child process whose environment sets OPENBLAS_NUM_THREADS to ``env_value`` (None: unset)."""
    import os
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if env_value is not None:
        env["OPENBLAS_NUM_THREADS"] = env_value
    code = ("import os, sys\nfrom orchestrator.cli import main\nmain(sys.argv[1:])\n"
            "threads = next(l.split()[1] for l in open('/proc/self/status') if l.startswith('Threads:'))\n"
            "print(os.environ['OPENBLAS_NUM_THREADS'], threads, file=sys.stderr)\n")
    res = subprocess.run([sys.executable, "-c", code, "check", "paper_simulation", "--set", "stop_time=0.01"],
                         capture_output=True, text=True, cwd=cwd, env=env, timeout=600)
    value, threads = res.stderr.strip().splitlines()[-1].split()
    return value, int(threads)


def test_a_command_runs_blas_on_one_thread_unless_the_environment_says_otherwise(tmp_path):
    # the matrices are tiny: OpenBLAS's threads only wait on each other (docs/performance.md)
    assert _blas_threads_after_check(tmp_path, None) == ("1", 1)  # numpy and scipy loaded, no BLAS thread
    value, threads = _blas_threads_after_check(tmp_path, "2")
    assert value == "2" and threads > 1  # the user's setting is kept: OpenBLAS started its threads
