"""Progress of a long task on stderr."""

import sys
import time


class Progress:
    """Progress of a long task on stderr: a tqdm bar on a terminal; otherwise one line at
    each 10 % of a task that has run for more than ``quiet_s`` seconds (none for short ones)."""

    def __init__(self, desc: str, unit: str = "step", total: int | None = None, quiet_s: float = 2.0):
        self.desc, self.unit, self.total, self.quiet_s = desc, unit, total, quiet_s
        self.start, self.shown, self.done = time.monotonic(), 0, 0
        self.bar = None
        if sys.stderr.isatty():
            from tqdm import tqdm
            self.bar = tqdm(total=total, desc=desc, unit=unit, delay=1.0, mininterval=0.5, leave=False)

    def __call__(self, done: int, total: int | None = None) -> None:
        """Set the count done (of ``total`` if given)."""
        if total is not None:
            self.total = total
        self.done = done
        if self.bar is not None:
            self.bar.total, self.bar.n = self.total, done
            self.bar.refresh()
            return
        if not self.total:
            return
        tenth = int(10 * done / self.total)
        if tenth > self.shown and time.monotonic() - self.start > self.quiet_s:
            self.shown = tenth
            print(f"{self.desc}: {10 * tenth} % ({done}/{self.total} {self.unit}s)", file=sys.stderr, flush=True)

    def update(self, n: int = 1) -> None:
        """Add ``n`` to the count done."""
        self(self.done + n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def progress_bar(desc: str, enabled: bool):
    """(update, close) of a run's progress: a bar on a terminal (for runs longer than a
    second), else one line per 10 % of a run longer than two seconds; nothing if not enabled."""
    if not enabled:
        return None, lambda: None
    bar = Progress(desc, "step")
    return bar, bar.close


def say(line: str) -> None:
    """One line on stderr saying what a long command starts doing."""
    print(line, file=sys.stderr, flush=True)
