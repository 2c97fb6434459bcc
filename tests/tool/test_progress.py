"""The progress lines of long tasks off a terminal (tool/progress.py): between the tenths, a task
of slow items still says where it is (a study's cases, a comparison's runs)."""

import time

from orchestrator.tool.progress import Progress


def test_a_task_whose_items_are_slow_repeats_its_state_with_the_seconds_so_far(capsys):
    bar = Progress("gain_sweep", "case", total=40, quiet_s=0.0, every_s=1.0)
    bar(1)  # 2 %: no tenth yet, but the first line comes (every_s after the start)
    time.sleep(2.5)  # nothing moves: the state again, with the seconds
    bar.close()
    err = capsys.readouterr().err.splitlines()
    assert err and all(line.startswith("gain_sweep: 2 % (1/40 cases, ") and line.endswith(" s)") for line in err), err


def test_a_share_of_runs_done_moves_the_progress_between_whole_runs(capsys):
    bar = Progress("paper_simulation runs", "run", total=10, quiet_s=0.0)
    for done in (0.4, 1.3, 2.5):
        bar(done)
    bar.close()
    assert capsys.readouterr().err.splitlines() == ["paper_simulation runs: 10 % (1.3/10 runs)",
                                                    "paper_simulation runs: 20 % (2.5/10 runs)"]


def test_without_every_s_a_task_says_nothing_between_tenths(capsys):
    bar = Progress("paper_simulation runs", "run", total=10, quiet_s=0.0)
    bar(0.5)
    time.sleep(1.2)
    bar.close()
    assert capsys.readouterr().err == ""
