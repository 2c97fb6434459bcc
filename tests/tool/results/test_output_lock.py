"""One writer per output folder: the lock is re-entrant in a thread, refused to another
thread or process with the holder's pid, and never left stale by a killed holder."""

import os
import signal
import subprocess
import sys
import threading

import pytest

from orchestrator.tool.folders import LOCK_FILE, OutputInUseError, output_lock

HOLD = ("import sys; from orchestrator.tool.folders import output_lock\n"
        "with output_lock(sys.argv[1]):\n    print('held', flush=True); sys.stdin.read()\n")


def test_the_lock_is_reentrant_in_one_thread_and_refused_to_another(tmp_path):
    refused = []

    def other():
        try:
            with output_lock(tmp_path):
                refused.append(None)
        except OutputInUseError as err:
            refused.append(str(err))

    with output_lock(tmp_path):
        with output_lock(tmp_path):
            assert (tmp_path / LOCK_FILE).read_text() == f"{os.getpid()}\n"
        thread = threading.Thread(target=other)
        thread.start()
        thread.join()
    assert refused == [f"output folder {tmp_path} is in use by another thread of this process (pid {os.getpid()}): "
                       "allowed is one writer per output folder"]
    assert (tmp_path / LOCK_FILE).read_text() == ""  # released: no pid on record, the file stays


def test_a_lock_held_by_a_killed_process_does_not_block_the_next_writer(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(tmp_path)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "held\n"
        with pytest.raises(OutputInUseError, match=rf"in use by tapmp \(pid {holder.pid}\)"):
            with output_lock(tmp_path):
                pass
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    assert (tmp_path / LOCK_FILE).read_text() == f"{holder.pid}\n"  # its pid stays on record, stale
    with output_lock(tmp_path):
        assert (tmp_path / LOCK_FILE).read_text() == f"{os.getpid()}\n"
