"""Progress of a long task on stderr."""

import sys
import threading
import time


class Progress:
    """Progress of a long task on stderr: a tqdm bar on a terminal; otherwise one line at
    each 10 % of a task that has run for more than ``quiet_s`` seconds (none for short ones),
    also on any progress ``every_s`` seconds [s] after the last line, and, while nothing moves,
    the last state again every ``every_s`` seconds with the time so far (a task of slow items is
    never silent for longer), read from ``count()`` if given. ``done`` may be fractional (runs
    part done)."""

    def __init__(self, desc: str, unit: str = "step", total: int | None = None, quiet_s: float = 2.0,
                 every_s: float | None = None, count=None):
        self.desc, self.unit, self.total, self.quiet_s, self.every_s = desc, unit, total, quiet_s, every_s
        self.count = count  # count() -> the count done now: read by the repeating line (no stale count)
        self.start, self.shown, self.done = time.monotonic(), 0, 0
        self.said = self.start  # when the last line was printed
        self.bar, self.watcher, self.lock, self.closed = None, None, threading.RLock(), threading.Event()
        if sys.stderr.isatty():
            from tqdm import tqdm
            self.bar = tqdm(total=total, desc=desc, unit=unit, delay=1.0, mininterval=0.5, leave=False)
        elif every_s is not None:
            self.watcher = threading.Thread(target=self._watch, daemon=True)
            self.watcher.start()

    def __call__(self, done: float, total: int | None = None) -> None:
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
        with self.lock:  # the caller and the repeating thread
            now = time.monotonic()
            tenth = int(10 * done / self.total)
            moved = tenth > self.shown or (self.every_s is not None and now - self.said >= self.every_s)
            if moved and now - self.start > self.quiet_s:
                self._say(self.line(10 * tenth if tenth > self.shown else None))
                self.shown = max(self.shown, tenth)

    def line(self, percent: int | None = None) -> str:
        """The state as one line: at a tenth ``percent``, the share and the count; between tenths,
        the share, the count and the seconds so far."""
        done = f"{self.done:.1f}".removesuffix(".0") if isinstance(self.done, float) else str(self.done)
        if percent is not None:
            return f"{self.desc}: {percent} % ({done}/{self.total} {self.unit}s)"
        return (f"{self.desc}: {int(100 * self.done / self.total)} % ({done}/{self.total} {self.unit}s, "
                f"{time.monotonic() - self.start:.0f} s)")

    def _say(self, line: str) -> None:
        with self.lock:
            self.said = time.monotonic()
            print(line, file=sys.stderr, flush=True)

    def _watch(self) -> None:
        while not self.closed.wait(1.0):
            if self.count is not None:
                self(self.count())  # a tenth passed, or every_s since the last line: a line
            elif self.total and time.monotonic() - self.said >= self.every_s:
                self._say(self.line())

    def update(self, n: int = 1) -> None:
        """Add ``n`` to the count done."""
        self(self.done + n)

    def close(self) -> None:
        self.closed.set()
        if self.watcher is not None:
            self.watcher.join()
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
