"""The tapmp command line as typed: main(argv) parses and records the argv it is given, the
shared FMU options are one definition, check refuses --fmus, and only user errors are one line."""

import shlex
import sys
from pathlib import Path

import pytest

from orchestrator import cli
from orchestrator.cli import main

ROOT = Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")


def _produced_by(folder: Path) -> str:
    line = next(x for x in (folder / "comparison.md").read_text().splitlines() if x.startswith("Produced by"))
    return line.removeprefix("Produced by `").removesuffix("`.")


@pytest.mark.slow  # a whole comparison: every baseline, its robustness analysis and figures (15-30 s)
def test_main_from_code_records_its_argv_with_the_top_level_options(built, tmp_path, monkeypatch, capsys):
    # sys.argv is not what main parses here: the old record "tapmp compare " + sys.argv[2:] was wrong twice
    monkeypatch.setattr(sys, "argv", ["pytest", "-q", "tests/test_cli_command_line.py"])
    out = tmp_path / "cmp dir"  # a space: the record quotes it as a shell would need
    argv = ["--debug", "compare", PAPER, "--ssp", str(built["ssp"]), "--out", str(out), "--set", "stop_time=0.001",
            "--set", 'law="sc-dc"', "--jobs", "1", "--no-progress"]
    assert main(argv) == 0
    assert _produced_by(out) == "tapmp " + shlex.join(argv)
    assert _produced_by(out).startswith(f"tapmp --debug compare {PAPER} --ssp ")
    assert shlex.split(_produced_by(out))[1:] == argv  # typed again, it is the same command


def test_the_shared_fmu_options_are_one_definition_on_every_command(tmp_path, capsys):
    # reproduce and study once listed the families as plain choices: now every command names the closest one
    for argv in (["run", PAPER], ["compare", PAPER], ["export", PAPER, "--out", "x.ssp"], ["reproduce"],
                 ["study", "studies/robustness.toml"]):
        with pytest.raises(SystemExit) as exit_:
            main([*argv, "--fmus", "nativ"])
        assert exit_.value.code == 2
        err = capsys.readouterr().err
        assert err == (f"error: tapmp {argv[0]}: argument --fmus: fmus = 'nativ' is invalid: allowed are python, "
                       f"native, fmi3; did you mean native? (see tapmp {argv[0]} --help)\n"), (argv, err)
    helps = {}
    for name, sub in cli.parser()._subparsers._group_actions[0].choices.items():
        for action in sub._actions:
            if action.dest in ("fmus", "ssp", "fmus_dir"):
                helps.setdefault(action.dest, set()).add(action.help)
    assert {k: len(v) for k, v in helps.items()} == {"ssp": 1, "fmus": 2, "fmus_dir": 1}  # check's is hidden


def test_check_refuses_fmus_with_one_line_saying_why(capsys):
    assert main(["check", PAPER, "--fmus", "python"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --fmus = 'python' is not an option of check: the check linearizes the FMI-free "
                          "model") and len(err.strip().splitlines()) == 1
    assert main(["check", PAPER]) == 0


@pytest.mark.parametrize("error", [TypeError("unsupported operand type(s) for *: 'NoneType' and 'float'"),
                                   ValueError("math domain error")])
def test_a_programming_error_keeps_its_traceback(error, monkeypatch, capsys):
    # a bug inside the stability check (a plain ValueError or a TypeError) is not a user error
    def broken(scenario):
        raise error
    monkeypatch.setattr("orchestrator.tool.stability.check", broken)
    with pytest.raises(type(error), match=str(error).split("(")[0]):
        main(["check", PAPER])
    assert "error:" not in capsys.readouterr().err


def test_a_user_error_is_still_one_line_and_debug_shows_its_traceback(tmp_path, capsys):
    assert main(["plot", str(tmp_path), "--window", "2:1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --window = '2:1' is invalid") and len(err.strip().splitlines()) == 1
    assert main(["--debug", "plot", str(tmp_path), "--window", "2:1"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" in err and err.strip().splitlines()[-1].startswith("error: --window = '2:1' is invalid")


def test_a_worker_keeps_bad_input_one_line_and_a_plain_value_error_a_programming_error():
    # a run in a worker process comes back to the parent by its message: the project's own
    # ValueErrors (bad input) as UsageError, a plain ValueError as ValueError (not one line)
    from orchestrator.errors import UsageError
    from orchestrator.tool import pool
    from orchestrator.tool.scenario import ScenarioError

    for err, expected in ((ScenarioError("step = -1.0 is invalid: allowed is a number > 0"), UsageError),
                          (ValueError("math domain error"), ValueError)):
        with pytest.raises(ValueError) as raised:
            pool._raise(pool._error_record(err))
        assert type(raised.value) is expected and str(raised.value) == str(err)
        assert isinstance(raised.value, cli.USER_ERRORS) == (expected is UsageError)
