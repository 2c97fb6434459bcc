"""Output size and wall time of runs, estimated before they start, and the disk check."""

import os
import shutil
import sys
from pathlib import Path

from .scenario import Scenario

RECORDED_COLUMNS = 40  # time + 15 plant, 12 trajectory and 12 controller outputs (the FMUs' model descriptions)
BYTES_PER_VALUE = {"csv": 21, "mat": 8}  # csv: shortest round-trip text and a comma (measured: 20.5 on a 11 s run)
SECONDS_PER_STEP = 1.3e-5  # CPU time of one 0.1 ms step of the native FMUs (measured: 1.37 s for 111112 steps)
# CPU time of recording one row, with its share of the run's set-up (measured: `tapmp compare
# scenarios/paper_simulation.toml --no-figures`, 20 runs of 25000 steps and rows, 14.4 s of CPU)
SECONDS_PER_ROW = 1.1e-5
SHOW_BYTES = 100e6  # print the estimate above this size [bytes]
WARN_BYTES = 1e9  # and a warning line above this one


class DiskSpaceError(OSError):
    """The runs would write more than the free space of the output folder's disk."""


def recorded_rows(scenario: Scenario) -> int:
    """Rows a run of ``scenario`` writes: step 0, every ``record_every``-th step and the last."""
    n, every = scenario.n_steps, scenario.record_every
    return n // every + 1 + (1 if n % every else 0)


def output_estimate(scenarios) -> tuple[int, float]:
    """(bytes, seconds): the result files of the runs of ``scenarios`` (rows x
    RECORDED_COLUMNS x BYTES_PER_VALUE of each one's format) and their summed CPU time
    (SECONDS_PER_STEP a step, SECONDS_PER_ROW a recorded row)."""
    size = sum(recorded_rows(s) * RECORDED_COLUMNS * BYTES_PER_VALUE[getattr(s, "format", "csv")]
               for s in scenarios)
    return size, sum(s.n_steps * SECONDS_PER_STEP + recorded_rows(s) * SECONDS_PER_ROW for s in scenarios)


def wall_estimate(cpu_s: float, processes: int) -> tuple[float, str]:
    """(seconds, how): the wall time [s] of ``cpu_s`` seconds of CPU on ``processes`` processes on
    this machine, each getting a whole CPU unless the CPUs are shared: with the machine's load (the
    1-minute load average of the processes already running) each gets cpus / (load + processes) of
    one; ``how`` says so in a few words."""
    cpus = os.cpu_count() or 1
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else 0.0
    throughput = processes * min(1.0, cpus / (load + processes))  # CPUs' worth this command gets
    return cpu_s / throughput, (f"{processes} process(es) on {cpus} CPU(s) at a load of {load:.1f}, "
                                f"{cpu_s:.0f} s of CPU")


def human_bytes(n: float) -> str:
    """``n`` bytes as kB, MB, GB or TB (powers of 1000), three significant digits."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{int(n)} B"


def _existing_parent(path: Path) -> Path:
    path = Path(path).absolute()
    while not path.exists():
        path = path.parent
    return path


def check_output_size(scenarios, out: Path, label: str, processes: int = 1, stream=None) -> int:
    """Before runs start: their estimated output size [bytes] (returned). Above SHOW_BYTES one
    line with the size and the wall time on ``stream`` (stderr), above WARN_BYTES a
    ``warning:`` line too; DiskSpaceError if the disk of ``out`` (its nearest existing
    folder) has less free space than the runs need (a MAT run holds its rows twice while it
    writes results.mat)."""
    scenarios = list(scenarios)
    stream = stream or sys.stderr
    size, seconds = output_estimate(scenarios)
    need = sum(output_estimate([s])[0] * (2 if getattr(s, "format", "csv") == "mat" else 1) for s in scenarios)
    free = shutil.disk_usage(_existing_parent(out)).free
    # TAPMP_NO_DISK_CHECK=1: run anyway (a disk whose free space is misreported; the tests of a
    # disk that fills up while a run writes)
    if need > free and os.environ.get("TAPMP_NO_DISK_CHECK") != "1":
        raise DiskSpaceError(f"{label}: the runs would write about {human_bytes(need)} into {out} but its disk has "
                             f"{human_bytes(free)} free: shorten stop_time, record fewer rows (--record-every N) or "
                             "write MAT (--format mat)")
    if size > SHOW_BYTES:
        rows = sum(recorded_rows(s) for s in scenarios)
        fmts = "/".join(sorted({getattr(s, "format", "csv") for s in scenarios}))
        wall, how = wall_estimate(seconds, max(1, min(processes, len(scenarios))))
        print(f"{label}: about {human_bytes(size)} of results ({rows} rows x {RECORDED_COLUMNS} columns, {fmts}) "
              f"and about {wall:.0f} s of runs ({how})", file=stream, flush=True)
    if size > WARN_BYTES:
        print(f"warning: {label}: the results will take about {human_bytes(size)} of {human_bytes(free)} free; "
              "--record-every N keeps every N-th step, --format mat writes about 40 % of it", file=stream, flush=True)
    return size
