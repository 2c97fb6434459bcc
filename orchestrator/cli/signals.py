"""The command's one signal handler: SIGINT, SIGTERM and SIGHUP stop the run in progress."""

import os
import signal
import threading
from contextlib import contextmanager


@contextmanager
def signals_interrupt():
    """For the duration, SIGINT, SIGTERM and SIGHUP stop the run in progress on the main thread
    at its next step boundary (stops.deliver_signal) or, without one, raise Interrupted once and
    let the clean-up (folders, locks, a study's workers) finish undisturbed by repeats. The only
    signal handler of the package; main thread only. A worker process forked by `tapmp compare`
    inherits it: there a signal stops the worker's run, or is ignored while it is idle (the
    parent stops the set)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    from ..tool.stops import STOP_SIGNALS, Interrupted, deliver_signal
    command = os.getpid()

    def interrupt(signum, frame):
        if deliver_signal(signum) or os.getpid() != command:
            return
        for s in STOP_SIGNALS:
            signal.signal(s, signal.SIG_IGN)
        raise Interrupted(signum)

    previous = {s: signal.signal(s, interrupt) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)
