"""The tapmp master against its peers on the same FMUs, in one process, interleaved. Run from
the repository root after `bash build_fmus.sh`:

    .venv/bin/python benchmarks/bench_peers.py [--ssp build/native/fmi2/TAPMP.ssp] [--stop-time 1.0] [--repeat 3]

Microseconds per macro step (0.1 ms steps of the paper scenario, the stepping loop only:
loading and initialization not timed) of
  * tapmp (Python loop): CoSimulation.advance with stepper = "python", the reference loop;
  * tapmp (compiled core): the same with the compiled core (orchestrator/engine/stepper.c);
  * Ecos (ecospy, C++): EcosSimulation.step(n) on the same SSP;
  * libcosim (libcosimpy): CosimExecution.step(n) on the same SSP;
  * C loop: benchmarks/c_master.c, the native FMI 2.0 loop stepped from C without Python
    (only for a native FMI 2.0 SSP): the limit; it reads the 18 outputs the connections need;
  * C loop, all outputs: the same reading all 39 outputs after each step, the work of a master
    that records every output (as tapmp does).
Each row gets the fastest of --repeat runs (the machine may be shared: the minimum is the
least disturbed run). tapmp and the C loop step Gauss-Seidel (the default); Ecos and
libcosim step Jacobi, their only fixed-step algorithm (the same number of FMI calls).
"""

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from orchestrator.engine.master import CoSimulation, RunOptions  # noqa: E402
from orchestrator.tool.roles import ROLES
from orchestrator.tool.envelope import envelope  # noqa: E402
from orchestrator.tool.scenario import load  # noqa: E402

INTEGER_PARAMETERS = {"law", "velocity_source", "substeps"}


def time_tapmp(ssp: Path, scenario, stepper: str) -> float:
    """Wall seconds of the tapmp master's stepping (rows stored, as tapmp run does)."""
    with CoSimulation(ssp, scenario.parameters(), RunOptions(start_time=scenario.start_time, step_size=scenario.step,
                                                             ordering=scenario.ordering, check=envelope(scenario),
                                                             stepper=stepper, roles=ROLES)) as sim:
        block = np.empty((1000, len(sim.columns)))
        start = time.perf_counter()
        left = scenario.n_steps
        while left:
            left -= sim.advance(block[:min(left, 1000)])
        return time.perf_counter() - start


def time_ecos(ssp: Path, scenario) -> float:
    from ecospy import EcosSimulation
    sim = EcosSimulation(ssp_path=str(ssp), step_size=scenario.step)
    try:
        for element, params in scenario.parameters().items():
            for name, value in params.items():
                if name in INTEGER_PARAMETERS:
                    sim.set_integer(f"{element}::{name}", int(value))
                else:
                    sim.set_real(f"{element}::{name}", float(value))
        sim.init(scenario.start_time)
        start = time.perf_counter()
        sim.step(scenario.n_steps)
        wall = time.perf_counter() - start
        sim.terminate()
    finally:
        sim.free()
    return wall


def time_libcosim(ssp: Path, scenario) -> float:
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    log_output_level(CosimLogLevel.WARNING)
    execution = CosimExecution.from_ssp_file(str(ssp), step_size=round(scenario.step * 1e9))
    index = {s.name.decode(): s.index for s in execution.slave_infos()}
    variables = {e: {v.name.decode(): v for v in execution.slave_variables(i)} for e, i in index.items()}
    for element, params in scenario.parameters().items():
        for name, value in params.items():
            var = variables[element][name]
            if var.type == CosimVariableType.INTEGER.value:
                execution.integer_initial_value(index[element], var.reference, int(value))
            else:
                execution.real_initial_value(index[element], var.reference, float(value))
    execution.step(1)  # initialization happens in the first step: not timed
    start = time.perf_counter()
    execution.step(scenario.n_steps - 1)
    return (time.perf_counter() - start) * scenario.n_steps / (scenario.n_steps - 1)


def time_c_loop(ssp: Path, scenario, tmp: Path, every_output: bool = False) -> float:
    from bench_cosim import time_c_master
    return time_c_master(ssp, scenario, tmp, every_output)


def is_native_fmi2(ssp: Path) -> bool:
    """Whether the SSP holds the native FMI 2.0 TAPMP FMUs (C sources inside, FMI 2.0), which
    benchmarks/c_master.c steps."""
    import io
    import zipfile
    with zipfile.ZipFile(ssp) as z:
        if "resources/TAPMP_Plant.fmu" not in z.namelist():
            return False
        with zipfile.ZipFile(io.BytesIO(z.read("resources/TAPMP_Plant.fmu"))) as fmu:
            names = fmu.namelist()
            return "sources/tapmp_model.c" in names and 'fmiVersion="2.0"' in fmu.read("modelDescription.xml").decode()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ssp", default=str(ROOT / "build" / "native" / "fmi2" / "TAPMP.ssp"))
    ap.add_argument("--stop-time", type=float, default=1.0, help="simulated seconds (default 1.0)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per master (default 3)")
    args = ap.parse_args(argv)
    ssp = Path(args.ssp)
    if not ssp.is_file():
        print(f"error: {ssp} does not exist: run bash build_fmus.sh first", file=sys.stderr)
        return 2
    sc = load(ROOT / "scenarios" / "paper_simulation.toml", [f"stop_time={args.stop_time}"])
    native_fmi2 = is_native_fmi2(ssp)
    with tempfile.TemporaryDirectory(prefix="tapmp_peers_") as tmp:
        masters = [("tapmp (Python loop)", lambda: time_tapmp(ssp, sc, "python")),
                   ("tapmp (compiled core)", lambda: time_tapmp(ssp, sc, "compiled")),
                   ("Ecos (ecospy)", lambda: time_ecos(ssp, sc)),
                   ("libcosim (libcosimpy)", lambda: time_libcosim(ssp, sc))]
        if native_fmi2:
            masters.append(("C loop, all outputs", lambda: time_c_loop(ssp, sc, Path(tmp), True)))
            masters.append(("C loop (c_master.c)", lambda: time_c_loop(ssp, sc, Path(tmp))))
        best = {}
        for r in range(args.repeat):
            for name, fn in masters:
                wall = fn()
                best[name] = min(best.get(name, wall), wall)
                print(f"run {r + 1}/{args.repeat} {name:24s} {wall:8.4f} s", file=sys.stderr)
    n = sc.n_steps
    limit = best.get("C loop (c_master.c)")
    print(f"{ssp}, {args.stop_time:g} s = {n} macro steps of {sc.step:g} s; fastest of {args.repeat}")
    print(f"{'master':24s} {'us/step':>9s} {'x C loop':>9s}")
    for name, wall in best.items():
        ratio = f"{wall / limit:9.2f}" if limit else f"{'-':>9s}"
        print(f"{name:24s}  {wall / n * 1e6:9.2f}  {ratio}")
    compiled, ecos = best["tapmp (compiled core)"], best["Ecos (ecospy)"]
    print(f"tapmp compiled core / Ecos: {compiled / ecos:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
