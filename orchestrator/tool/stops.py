"""Stopping runs at a step boundary: stop requests, and the exception a stop ends in.

A run never installs a signal handler: the command line (orchestrator.cli) installs the
one handler of SIGINT, SIGTERM and SIGHUP and hands a signal to the run in progress on the
main thread (deliver_signal), which stops at its next step boundary, never inside an FMU
call (an exception there would turn into a failed FMI call). Without a run in progress
the handler raises Interrupted, and the commands and studies react to that exception.
A study stops the runs of its worker processes with request_stop(token).
"""

import signal
import threading
from contextlib import contextmanager

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  # end a run at a step boundary


class Interrupted(KeyboardInterrupt):
    """A run or command stopped by a signal (SIGINT, SIGTERM, SIGHUP) at a step boundary;
    ``exit_code`` = 128 + the signal's number, as a shell reports a process the signal ended."""

    def __init__(self, signum: int, message: str = ""):
        self.signum = int(signum)
        self.signal_name = signal.Signals(self.signum).name
        self.exit_code = 128 + self.signum
        super().__init__(message or f"interrupted by {self.signal_name}")


class StopRequest:
    """Set by a stop signal or request_stop; the run loop stops at the next step boundary."""

    def __init__(self):
        self.signal = None   # the signal number that asked to stop
        self.reason = ""     # why, if not a signal to this process
        self.handled = False  # the run loop has acted on it

    def __call__(self, signum, frame=None):
        if self.signal is None:
            self.signal = signum

    def check(self, t: float) -> None:
        """Raise Interrupted if a stop was asked for; ``t`` is the current time [s]."""
        if self.signal is not None:
            self.handled = True
            name = signal.Signals(self.signal).name
            raise Interrupted(self.signal, f"interrupted by {name}{self.reason} at t = {t:.6g} s")


# What a process knows about its runs: a stop request must reach runs it did not start
# (a study's client calls request_stop in its workers; the CLI's handler calls deliver_signal).
_lock = threading.Lock()
_STOPPED = {}   # stop token -> signal number, for runs of a stopped study (in a worker process)
_ACTIVE = {}    # stop token -> the StopRequest of every run of this process started with it
_MAIN_RUNS = []  # StopRequests of the runs in progress on the main thread, innermost last


def request_stop(token: str, signum: int = signal.SIGTERM) -> None:
    """Stop every run of this process started with ``stop_token=token`` at its next step
    boundary, and any that starts later: a study's client calls this on every worker when
    it is stopped, so the cases end cleanly (FMUs freed, temporary folders removed)."""
    with _lock:
        _STOPPED[token] = int(signum)
        for stop in _ACTIVE.get(token, ()):
            stop.reason = " (the study was stopped)"
            stop(signum)


def stop_requested(token: str | None) -> bool:
    """Whether request_stop(token) was called in this process."""
    return token is not None and token in _STOPPED


def deliver_signal(signum: int) -> bool:
    """Hand the stop signal ``signum`` to the run in progress on the main thread; False if
    there is none. Called by the command line's signal handler."""
    if not _MAIN_RUNS:
        return False
    _MAIN_RUNS[-1](signum)
    return True


@contextmanager
def stop_scope(stop: StopRequest, token: str | None):
    """For the duration, ``stop`` receives request_stop(token) and (on the main thread) the
    signals the command line delivers. A signal that came after the run loop's last check is
    raised again on the way out, so the command line's handler sees it: it is never lost."""
    with _lock:
        if token is not None:
            _ACTIVE.setdefault(token, []).append(stop)
            if token in _STOPPED:
                stop.reason = " (the study was stopped)"
                stop(_STOPPED[token])
    main = threading.current_thread() is threading.main_thread()
    if main:
        _MAIN_RUNS.append(stop)
    try:
        yield
    finally:
        if main:
            _MAIN_RUNS.remove(stop)
        with _lock:
            if token is not None:
                _ACTIVE[token].remove(stop)
                if not _ACTIVE[token]:
                    del _ACTIVE[token]
        if main and stop.signal is not None and not stop.handled and not stop.reason:
            signal.raise_signal(stop.signal)
