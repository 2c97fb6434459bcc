"""Measure how far each third-party tool running an exported scenario is from `tapmp run`.

    .venv/bin/python tests/interop/measure_export.py [--fmus python|native] [--stop-time 0.2]

Exports scenarios/paper_simulation.toml with the real `tapmp export` from the built SSP of
the family (bash build_fmus.sh first), runs libcosim, Ecos (ecospy and the `ecos`
executable), FMPy's simulate_ssp and `fmpy simulate` on build/TAPMP_ClosedLoop.fmu with
only what the export wrote (tests/interop/test_export.py's runners), and prints, per tool, the
largest difference on the true motor positions [m], the encoder positions [m] and the
commands [N] against the orchestrator (the engine of `tapmp run`): on the tool's own
conventions, with `--set ordering='"jacobi"'`, with the defaults (gauss-seidel), and with
the plant at rest (the start transient a tool saw before the FMUs' defaults became the
reference's start).
"""

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent.parent)]  # the repository root: the tests package
from tests.support.runs import COMMANDS, MOTOR_POSITIONS, orchestrator_rows, paper_scenario  # noqa: E402
from tests.support.shared import ROOT  # noqa: E402
from tests.interop.test_export import (run_container, run_ecos_executable, run_ecos_exported,  # noqa: E402
                                       run_fmpy_ssp_exported, run_libcosim_exported)

from orchestrator.builder.families import family_ssp, fmus_dir  # noqa: E402

NAMES = MOTOR_POSITIONS + COMMANDS


def gaps(rows, ref, cols):
    """Largest |difference| over time on true positions, encoder positions, commands (in ``cols``)."""
    d = np.abs(rows - ref).max(axis=0)
    groups = ([i for i, n in enumerate(cols) if n.endswith("_true")],
              [i for i, n in enumerate(cols) if n.startswith("plant.q") and not n.endswith("_true")],
              [i for i, n in enumerate(cols) if n.startswith("controller.F")])
    return tuple(float(d[g].max()) if g else None for g in groups)


def fmt(g):
    return " / ".join("-" if x is None else ("0" if x == 0.0 else f"{x:.2g}") for x in g)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fmus", choices=["python", "native"], default="python")
    ap.add_argument("--stop-time", type=float, default=0.2)
    args = ap.parse_args()
    source = family_ssp(args.fmus)
    scenario = paper_scenario(args.stop_time)
    with tempfile.TemporaryDirectory(prefix="tapmp_measure_") as tmp:
        ssp = Path(tmp) / "paper.ssp"
        subprocess.run([str(Path(sys.executable).with_name("tapmp")), "export", str(ROOT / "scenarios" /
                        "paper_simulation.toml"), "--out", str(ssp), "--fmus", args.fmus, "--set",
                        f"stop_time={args.stop_time!r}"], check=True, capture_output=True)
        values = ssp.with_suffix(".start-values.txt")

        def ours(sc=scenario, names=NAMES, ordering="jacobi", **conv):
            return orchestrator_rows(source, sc, names, ordering, **conv)
        # the plant at rest at the home pose, given explicitly: its defaults are the reference's start
        rest = scenario.with_changes(start_on_trajectory=False, plant={
            **scenario.plant, **dict.fromkeys(("X0", "Z0", "B0", "dX0", "dZ0", "dB0"), 0.0)})
        longer = scenario.with_changes(stop_time=scenario.stop_time + scenario.step)
        # (tool, conventions text, its rows, first orchestrator row it matches, names, conventions)
        runs = [("libcosim", "clock nanoseconds", run_libcosim_exported(ssp, NAMES), 1, NAMES,
                 {"clock": "nanoseconds"}, scenario),
                ("Ecos (ecospy)", "clock accumulated", run_ecos_exported(ssp, NAMES, scenario.name), 0, NAMES,
                 {"clock": "accumulated"}, scenario),
                ("ecos executable (CSV, 6 decimals)", "clock accumulated",
                 run_ecos_executable(ssp, scenario.name, Path(tmp) / "ecos", COMMANDS), 0, COMMANDS,
                 {"clock": "accumulated"}, scenario),
                ("FMPy simulate_ssp", "clock accumulated, connection_start zero",
                 run_fmpy_ssp_exported(ssp, NAMES), 1, NAMES, {"clock": "accumulated", "connection_start": "zero"},
                 longer),
                ("fmpy simulate, container", "clock exact",
                 run_container(fmus_dir() / "TAPMP_ClosedLoop.fmu", ssp, values, NAMES, Path(tmp) / "c.csv"),
                 0, NAMES, {}, scenario)]
        print(f"paper_simulation, {scenario.n_steps} steps of {scenario.step:g} s, {args.fmus} FMUs; "
              "max |difference|: true positions [m] / encoder positions [m] / commands [N]")
        print("| tool | vs tapmp run, jacobi + its conventions | vs tapmp run, jacobi | vs tapmp run (gauss-seidel) "
              "| vs a run without the initial state |")
        print("|---|---|---|---|---|")
        for tool, conv_text, rows, first, names, conv, sc in runs:
            n = len(rows)
            same = ours(sc, names, **conv)[first:first + n]
            cols = [ours(scenario, names, "jacobi"), ours(scenario, names, "gauss-seidel"),
                    ours(rest, names, "jacobi", **conv)]
            m = min(n, len(cols[0]) - first)
            print(f"| {tool} | {fmt(gaps(rows, same, names))} ({conv_text}) | "
                  + " | ".join(fmt(gaps(rows[:m], c[first:first + m], names)) for c in cols) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
