"""Co-simulation speed on the paper scenario, in one process so the ratios hold on a noisy
machine. Run from the repository root:

    .venv/bin/python benchmarks/bench_cosim.py [--stop-time 2.5] [--repeat 3] [--json PATH]

Measures, per ordering, microseconds per macro step and the real-time factor (wall time /
simulated time) of
  * full:           the three TAPMP FMUs through the orchestrator's master, Python loop
                    (CoSimulation stepper "python", the reference);
  * floor:          the same loop, the same FMI calls and values, against pass-through
                    FMUs with the same interfaces whose doStep does nothing, built with
                    this project's FMU binary;
  * floor-pythonfmu the same pass-through FMUs on pythonfmu 0.7's own binary (the floor
                    this project started from);
  * plain:          the FMI-free closed loop (tapmp.closed_loop) with the same models;
  * full-native, floor-native, full-fmi3, floor-fmi3: the same for the native C FMUs
                    (FMI 2.0 and 3.0; the floor is benchmarks/floor_model.c in place of
                    each model file);
  * full compiled, full-native compiled, full-fmi3 compiled: the same FMUs stepped by the
                    master's compiled core (orchestrator/engine/stepper.c), as tapmp run does;
  * c-master:       the native FMI 2.0 closed loop stepped from C (benchmarks/c_master.c),
                    no Python in the process: the cost without a Python master;
plus `tapmp run` end to end (results.csv written every step) and the peak memory.
Each configuration runs --repeat times, interleaved; the table shows the fastest run.
"""

import argparse
import json
import platform
import resource
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from orchestrator.builder import build  # noqa: E402
from orchestrator.engine.master import CoSimulation, RunOptions  # noqa: E402
from orchestrator.tool.roles import ROLES
from orchestrator.tool.results import run_scenario  # noqa: E402
from orchestrator.tool.scenario import load  # noqa: E402
from orchestrator.builder.ssp import write_ssp  # noqa: E402
from tapmp.closed_loop import simulate  # noqa: E402
from tapmp.interface import FMU_NAMES  # noqa: E402

OWN_FLOOR = '''
from fmu_common.slave import TapmpSlave
from tapmp.interface import VARIABLES


class {name}(TapmpSlave):
    """Pass-through floor: the interface of {model}, a doStep that does nothing."""
    VARIABLES = VARIABLES["{model}"]

    def setup_model(self):
        pass

    def step(self, t, h):
        pass
'''

PYTHONFMU_FLOOR = '''

class {name}(Fmi2Slave):
    """Pass-through floor on pythonfmu's binary: the interface of {model}, an empty doStep."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        register_interface(self, "{model}")

    def do_step(self, current_time, step_size):
        return True
'''


def build_native_systems(tmp: Path, log) -> dict[str, Path]:
    """SSP files of the native families and their pass-through floors."""
    from orchestrator.builder.build_native import build_native, build_native_fmu

    systems = {}
    for family, paths in build_native(tmp / "native", log=lambda *_: None, windows=False).items():
        name = "native" if family == "fmi2" else family
        systems[f"full-{name}"] = paths["ssp"]
        out = tmp / f"floor-{name}"
        out.mkdir()
        # the floor model is no TAPMP model: its FMUs carry no reference experiment
        fmus = {m: build_native_fmu(m, family, out, windows=False, model_source=ROOT / "benchmarks" / "floor_model.c",
                                    extras=False) for m in FMU_NAMES}
        systems[f"floor-{name}"] = write_ssp(out / "TAPMP.ssp", fmus)
        log(f"built the native {family} systems")
    return systems


def time_c_master(fmi2_ssp: Path, scenario, tmp: Path, every_output: bool = False) -> float:
    """Wall seconds of the native FMI 2.0 loop stepped by benchmarks/c_master.c (reading every
    output after each step if ``every_output``, else those the connections need)."""
    import subprocess
    import zipfile

    from orchestrator.builder.build_native import fmi_headers_dir
    from ctoolchain import compile_c
    exe = tmp / "c_master"
    if not exe.exists():
        compile_c([ROOT / "benchmarks" / "c_master.c"], exe, shared=False, flags=["-O2"],
                  includes=[fmi_headers_dir()], libs=["dl"])
        with zipfile.ZipFile(fmi2_ssp) as z:
            for model in FMU_NAMES:
                z.extract(f"resources/{model}.fmu", tmp / "cm")
                with zipfile.ZipFile(tmp / "cm" / "resources" / f"{model}.fmu") as f:
                    f.extractall(tmp / "cm" / model)
    dirs = [str(tmp / "cm" / m) for m in ("TAPMP_Trajectory", "TAPMP_Controller", "TAPMP_Plant")]
    order = "gs" if scenario.ordering == "gauss-seidel" else "jacobi"
    out = subprocess.run([str(exe), *dirs, str(scenario.n_steps), order, *(["all"] if every_output else [])],
                         check=True, capture_output=True, text=True)
    return float(out.stdout.split()[0])


def build_systems(tmp: Path, log) -> dict[str, Path]:
    """SSP files of the real system and of the two pass-through floors."""
    systems = {"full": build.build_all(tmp / "full", log=lambda *_: None)["ssp"]}
    binaries = build.compile_binaries(tmp)
    # Own class names: pythonfmu's binary imports the adapter module by name, so a
    # floor FMU named TAPMP_Plant would run the real plant already imported.
    for kind, template, prefix in (("floor", OWN_FLOOR, "Floor_"), ("floor-pythonfmu", PYTHONFMU_FLOOR, "PyFloor_")):
        out = tmp / kind
        out.mkdir()
        fmus = {}
        for model in FMU_NAMES:
            script = tmp / f"{kind}-src" / model / f"{prefix}{model}.py"
            code = template.format(model=model, name=prefix + model)
            if kind == "floor":
                script.parent.mkdir(parents=True)
                script.write_text(code)
                fmus[model] = build.build_fmu(model, out, binaries, script)
            else:
                fmus[model] = build.build_interface_fmu(script, code, out)
        systems[kind] = write_ssp(out / "TAPMP.ssp", fmus)
        log(f"built the {kind} system")
    return systems


def time_loop(ssp: Path, scenario, stepper: str = "python") -> float:
    """Wall seconds of the master loop (steps and rows stored in blocks, no file output) with
    the Python loop or the compiled core (``stepper``)."""
    with CoSimulation(ssp, scenario.parameters(), RunOptions(start_time=scenario.start_time, step_size=scenario.step,
                                                             ordering=scenario.ordering, stepper=stepper,
                                                             roles=ROLES)) as sim:
        block = np.empty((1000, len(sim.columns)))
        left = scenario.n_steps
        start = time.perf_counter()
        while left:
            left -= sim.advance(block[:min(left, 1000)])
        return time.perf_counter() - start


def time_plain(scenario) -> float:
    plant, ctrl, traj = scenario.plain_models()
    start = time.perf_counter()
    simulate(plant, ctrl, traj, scenario.start_time, scenario.n_steps, scenario.step, scenario.ordering)
    return time.perf_counter() - start


def time_run(ssp: Path, scenario, out: Path) -> float:
    start = time.perf_counter()
    run_scenario(scenario, ssp, out, overwrite=True)
    return time.perf_counter() - start


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stop-time", type=float, default=2.5, help="simulated seconds (default 2.5)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per configuration (default 3)")
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "cosim.json"))
    args = ap.parse_args(argv)
    base = load(ROOT / "scenarios" / "paper_simulation.toml", [f"stop_time={args.stop_time}"])
    sim_time = base.stop_time - base.start_time
    with tempfile.TemporaryDirectory(prefix="tapmp_bench_") as tmp:
        tmp = Path(tmp)
        systems = build_systems(tmp, log=lambda m: print(m, file=sys.stderr))
        systems.update(build_native_systems(tmp, log=lambda m: print(m, file=sys.stderr)))
        configs = []
        for ordering in ("gauss-seidel", "jacobi"):
            sc = base.with_changes(ordering=ordering)
            for kind in ("full", "floor", "floor-pythonfmu", "full-native", "floor-native", "full-fmi3",
                         "floor-fmi3"):
                configs.append((kind, ordering, lambda s=systems[kind], sc=sc: time_loop(s, sc)))
            for kind in ("full", "full-native", "full-fmi3"):
                configs.append((f"{kind} compiled", ordering,
                                lambda s=systems[kind], sc=sc: time_loop(s, sc, "compiled")))
            configs.append(("plain", ordering, lambda sc=sc: time_plain(sc)))
            configs.append(("c-master", ordering, lambda sc=sc: time_c_master(systems["full-native"], sc, tmp)))
        configs.append(("tapmp run (csv)", "gauss-seidel",
                        lambda: time_run(systems["full"], base, tmp / "run")))
        best = {}
        for r in range(args.repeat):
            for kind, ordering, fn in configs:
                wall = fn()
                key = (kind, ordering)
                best[key] = min(best.get(key, wall), wall)
                print(f"run {r + 1}/{args.repeat} {kind:16s} {ordering:12s} {wall:7.3f} s", file=sys.stderr)
    n = base.n_steps
    rows = [{"config": k, "ordering": o, "wall_s": w, "us_per_step": w / n * 1e6,
             "real_time_factor": w / sim_time} for (k, o), w in best.items()]
    ratios = {o: best[("full", o)] / best[("floor", o)] for o in ("gauss-seidel", "jacobi")}
    native = {o: {"full_native_over_floor_native": best[("full-native", o)] / best[("floor-native", o)],
                  "full_fmi3_over_floor_fmi3": best[("full-fmi3", o)] / best[("floor-fmi3", o)],
                  "speedup_native_over_pythonfmu": best[("full", o)] / best[("full-native", o)],
                  "speedup_fmi3_over_pythonfmu": best[("full", o)] / best[("full-fmi3", o)],
                  "python_master_over_c_master": best[("full-native", o)] / best[("c-master", o)],
                  "compiled_core_over_c_master": best[("full-native compiled", o)] / best[("c-master", o)]}
              for o in ("gauss-seidel", "jacobi")}
    ratios_pythonfmu = {o: best[("full", o)] / best[("floor-pythonfmu", o)] for o in ("gauss-seidel", "jacobi")}
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    report = {
        "machine": {"cpus": __import__("os").cpu_count(), "python": platform.python_version(),
                    "platform": platform.platform(), "processor": platform.processor()},
        "scenario": "paper_simulation", "simulated_s": sim_time, "steps": n, "repeat": args.repeat,
        "rows": rows, "full_over_floor": ratios, "full_over_floor_pythonfmu": ratios_pythonfmu,
        "native": native,
        "peak_rss_mib": peak_mib,
    }
    print(f"\npaper scenario, {sim_time:g} s simulated = {n} macro steps of {base.step:g} s; "
          f"best of {args.repeat}")
    print(f"{'configuration':22s} {'ordering':13s} {'us/step':>9s} {'wall s':>8s} {'RTF':>8s}")
    for row in rows:  # columns at least two spaces apart, however large a value
        print(f"{row['config']:22s} {row['ordering']:13s} {row['us_per_step']:9.1f}  "
              f"{row['wall_s']:8.3f}  {row['real_time_factor']:7.3f}")
    for o in ratios:
        print(f"full / floor ({o}): {ratios[o]:.2f}   full / pythonfmu floor: {ratios_pythonfmu[o]:.2f}")
        print("  " + ", ".join(f"{k} {v:.2f}" for k, v in native[o].items()))
    print(f"peak memory (max RSS of this process): {peak_mib:.0f} MiB")
    path = Path(args.json)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(report, indent=2) + "\n")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
