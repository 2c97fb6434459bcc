"""Cases in batches: how many cases one Dask task runs, and how many tasks are in flight.

A study's cases travel to the workers in batches (one Dask task per batch) through a
bounded window of batches in flight (window), so that the client's cost per case (submitting,
collecting, Dask's bookkeeping) is paid once per batch, and the scheduler never holds more than a
few tasks per worker. The task itself is orchestrator.studies.study.run_batch.

The batch size rule (batch_size): about TARGET_BATCH_S of work per task, from the case's expected
cost (case_seconds: CASE_S + its macro steps x STEP_S, measured with the native FMUs), but at
least BATCHES_PER_THREAD batches per worker thread so that the work balances across workers (a
slow worker does not hold the last large batch while the others idle), and at most MAX_BATCH
cases. A lost worker reruns at most the batches it held: about TARGET_BATCH_S each.
"""

import os

TARGET_BATCH_S = 1.0  # work per task [s]: Dask's per-task cost (a few ms of client and scheduler) is < 1 %
BATCHES_PER_THREAD = 4  # at least this many batches per worker thread: the last ones balance the workers
MAX_BATCH = 200  # cases per batch at most: the rows of one batch are what a killed worker loses
# A case's expected cost in a worker [s]: a fixed part (validating its scenario, the stability check,
# run.json and metrics.json) and a part per macro step. Rounded up from the workers' CPU per case that
# benchmarks/bench_study_scale.py measured with the native FMUs (about 20 ms + 4-6 us per step), so
# that a batch stays near TARGET_BATCH_S where cases run slower (a loaded machine, the pythonfmu FMUs).
CASE_S = 0.03
STEP_S = 6e-6
BATCH_FILES_BYTES = 64 * 2**20  # kept result files sent back per batch at most (estimated) [bytes]
WINDOW_PER_THREAD = 2  # batches in flight per worker thread: one running, one queued on the worker


def case_seconds(n_steps: int) -> float:
    """Expected worker time of one case of ``n_steps`` macro steps [s] (CASE_S + n_steps x STEP_S)."""
    return CASE_S + max(int(n_steps), 0) * STEP_S


def batch_size(n_cases: int, seconds_per_case: float, threads: int) -> int:
    """Cases per batch by the module's rule, for ``n_cases`` cases of ``seconds_per_case`` [s]
    each on ``threads`` worker threads: TARGET_BATCH_S / seconds_per_case, at most
    n_cases / (BATCHES_PER_THREAD x threads) and MAX_BATCH, at least 1."""
    by_cost = int(TARGET_BATCH_S // max(seconds_per_case, 1e-9))
    by_balance = n_cases // (BATCHES_PER_THREAD * max(threads, 1))
    return max(1, min(by_cost, by_balance, MAX_BATCH))


def window(threads: int) -> int:
    """How many batches the client keeps submitted at once for ``threads`` worker threads (at
    least 2: one running, one waiting, also while no worker is connected)."""
    return max(2, WINDOW_PER_THREAD * max(threads, 1))


def split(cases: list, size: int) -> list[list]:
    """``cases`` in consecutive batches of ``size`` (the last one shorter)."""
    return [cases[i:i + size] for i in range(0, len(cases), size)]


def batch_key(ids: list) -> str:
    """The Dask key of a batch: "case-" and its case ids joined with "," and a random suffix (a
    key is never reused: a batch submitted again after a stop is a new task)."""
    return f"case-{','.join(ids)}-{os.urandom(4).hex()}"
