"""Lateness of paced runs (`tapmp run --real-time`) on this machine: factors 1 and 10, idle and loaded.

Each case is the real command in a child process, the paper scenario on the native FMI 2.0 FMUs
(build/native/fmi2/TAPMP.ssp; `tapmp build` first), and reads run.json's "real_time". Loaded: the
script starts --load busy processes (`python -c 'while 1: pass'`, as many as the machine has CPUs by
default) for the case and ends them after it. With --rt-priority N the cases run again with the
stepping thread at SCHED_FIFO priority N.

Usage (from the repository root):

    .venv/bin/python benchmarks/bench_real_time.py [--ssp FILE] [--seconds 2] [--factors 1,10]
                                                   [--load N] [--rt-priority N] [--format csv|mat] [--out DIR]

Prints a table: per case the lateness percentiles and maximum [us] (completion minus deadline;
negative: early), the execution time p99 [us], the overruns, the longest run of them, the achieved
real-time factor, whether SCHED_FIFO was applied and how often the stepping waited for the recording
thread (ring waits); with the load average before the cases. Then what recording a block of 1,000 rows
takes (the CSV text and the metrics), which a paced run does on another thread.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SSP = ROOT / "build" / "native" / "fmi2" / "TAPMP.ssp"
PAPER = ROOT / "scenarios" / "paper_simulation.toml"
BUSY = "while 1: pass"


def case(ssp: Path, out: Path, factor: float, seconds: float, priority: int | None, fmt: str) -> dict:
    """run.json's real_time of one paced run lasting about ``seconds`` of wall time, results in ``fmt``."""
    args = [sys.executable, "-m", "orchestrator", "run", str(PAPER), "--ssp", str(ssp), "--out", str(out),
            "--overwrite", "--no-progress", "--set", f"stop_time={seconds * factor:g}", "--real-time", f"{factor:g}",
            "--format", fmt]
    if priority is not None:
        args += ["--rt-priority", str(priority)]
    res = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    if res.returncode != 0:
        raise SystemExit(f"tapmp run failed: {res.stderr.strip()}")
    return json.loads((out / "run.json").read_text())["real_time"]


def recording_ms(ssp: Path, blocks: int = 10) -> list[float]:
    """Milliseconds the recording takes per block of results.BLOCK rows (the CSV text and the streaming
    metrics, as tapmp run does them between blocks), for ``blocks`` blocks of a run's rows."""
    import numpy as np

    from orchestrator.engine.master import CoSimulation
    from orchestrator.tool import metrics
    from orchestrator.tool.results import BLOCK, run_options
    from orchestrator.tool.scenario import load
    from orchestrator.tool.writers import CsvBlocks
    scenario = load(PAPER, [f"stop_time={blocks * BLOCK * 1e-4:g}"])
    with CoSimulation(ssp, scenario.parameters(), run_options(scenario)) as sim:
        rows = np.empty((blocks * BLOCK, len(sim.columns)))
        sim.advance(rows)
        stats = metrics.ErrorStatistics(sim.columns, metrics.saturation_limit(sim.parameters),
                                        metrics.force_step(sim.parameters, 0.0, scenario.stop_time),
                                        metrics.move_spec(sim.parameters, scenario.settling_bands))
    times = []
    with tempfile.TemporaryDirectory() as tmp:
        writer = CsvBlocks(Path(tmp), sim.columns)
        try:
            for i in range(blocks):
                block = rows[i * BLOCK:(i + 1) * BLOCK]
                start = time.perf_counter()
                writer.write(block)
                stats.add(block)
                times.append((time.perf_counter() - start) * 1e3)
            writer.finish()
        finally:
            writer.close()
    return times


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ssp", type=Path, default=SSP)
    ap.add_argument("--seconds", type=float, default=2.0, help="wall time of each case [s] (default 2)")
    ap.add_argument("--factors", default="1,10", help="real-time factors (default 1,10)")
    ap.add_argument("--load", type=int, default=os.cpu_count() or 1, help="busy processes of a loaded case "
                    "(default: one per CPU)")
    ap.add_argument("--rt-priority", type=int, help="also run every case at SCHED_FIFO priority N")
    ap.add_argument("--format", default="csv", choices=("csv", "mat"), help="result files of the runs (default csv)")
    ap.add_argument("--out", type=Path, help="folder of the runs (default: a temporary folder, removed)")
    a = ap.parse_args()
    factors = [float(f) for f in a.factors.split(",")]
    priorities = [None] + ([a.rt_priority] if a.rt_priority is not None else [])
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = a.out or Path(tmp)
        print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}; {os.cpu_count()} CPUs; "
              f"{a.seconds:g} s of wall time per case, results as {a.format}; loaded = {a.load} x python -c '{BUSY}'")
        for loaded in (False, True):
            busy = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(a.load if loaded else 0)]
            try:
                time.sleep(0.5 if busy else 0)  # the load running before the case starts
                for factor in factors:
                    for priority in priorities:
                        name = f"{'loaded' if loaded else 'idle'}-{factor:g}-{priority or 'other'}"
                        rows.append((loaded, factor, priority, case(a.ssp, base / name, factor, a.seconds, priority, a.format)))
            finally:
                for p in busy:
                    p.kill()
                    p.wait()

    def us(v):
        return f"{v * 1e6:.1f}"
    print(f"{'machine':<7}  {'factor':>6}  {'sched':>8}  {'steps':>6}  {'late p50 [us]':>13}  {'p99':>8}  "
          f"{'p99.9':>8}  {'max':>8}  {'exec p99 [us]':>13}  {'overruns':>8}  {'longest':>7}  {'achieved':>8}  "
          f"{'ring waits':>10}")
    for loaded, factor, priority, rt in rows:
        late = rt["lateness_s"]
        fifo = rt["measures"]["sched_fifo"]
        sched = f"fifo {priority}" if fifo["applied"] else ("other" if priority is None else "refused")
        print(f"{'loaded' if loaded else 'idle':<7}  {factor:>6g}  {sched:>8}  {rt['steps']:>6}  {us(late['p50']):>13}  "
              f"{us(late['p99']):>8}  {us(late['p999']):>8}  {us(late['max']):>8}  {us(rt['execution_s']['p99']):>13}  "
              f"{rt['overruns']:>8}  {rt['longest_overrun_run']:>7}  {rt['achieved_factor']:>8.4f}  {rt['ring_waits']:>10}")
    ms = sorted(recording_ms(a.ssp))
    print(f"\nrecording a block of 1000 rows (CSV text and metrics, as between the blocks of an unpaced run): "
          f"min {ms[0]:.2f} ms, median {ms[len(ms) // 2]:.2f} ms, max {ms[-1]:.2f} ms of {len(ms)} blocks")
    return 0


if __name__ == "__main__":
    sys.exit(main())
