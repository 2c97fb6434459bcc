"""Write tests/data/reference_run.csv: motor positions of short paper-scenario runs through
the FMUs, kept as the reference that optimizations must reproduce to 1e-12 m
(tests/engine/test_reference_run.py). Regenerate only when results are meant to change:

    .venv/bin/python benchmarks/reference_run.py
"""

import csv
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from orchestrator.builder.build import build_all  # noqa: E402
from orchestrator.engine.master import CoSimulation, RunOptions  # noqa: E402
from orchestrator.tool.roles import ROLES
from orchestrator.tool.scenario import load  # noqa: E402

REFERENCE = ROOT / "tests" / "data" / "reference_run.csv"
CASES = (("sc-dc", "gauss-seidel"), ("apd-dc", "gauss-seidel"), ("sc-dc", "jacobi"))
STOP = 0.2          # s of the paper scenario
EVERY = 10          # store every 10th step
SIGNALS = ("plant.q1_true", "plant.q2_true", "plant.q3_true", "plant.B")


def run_case(ssp: Path, law: str, ordering: str):
    """Rows (time, SIGNALS...) of one case, every EVERY-th step from t = 0 to STOP."""
    scenario = load(ROOT / "scenarios" / "paper_simulation.toml",
                    [f"law={law!r}", f"ordering={ordering!r}", f"stop_time={STOP}"])
    rows = []
    with CoSimulation(ssp, scenario.parameters(), RunOptions(start_time=scenario.start_time, step_size=scenario.step,
                                                             ordering=scenario.ordering, roles=ROLES)) as sim:
        index = [sim.columns.index(s) for s in ("time", *SIGNALS)]
        for k in range(scenario.n_steps + 1):
            if k:
                sim.step()
            if k % EVERY == 0:
                row = sim.row()
                rows.append([row[i] for i in index])
    return rows


def main():
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=str(REFERENCE), help=f"file to write (default {REFERENCE})")
    out = Path(ap.parse_args().out)
    with tempfile.TemporaryDirectory() as tmp:
        ssp = build_all(Path(tmp), log=lambda *_: None)["ssp"]
        with open(out, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["law", "ordering", "time", *SIGNALS])
            for law, ordering in CASES:
                for row in run_case(ssp, law, ordering):
                    w.writerow([law, ordering, *(repr(v) for v in row)])
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
