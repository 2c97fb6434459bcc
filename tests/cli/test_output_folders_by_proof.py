"""An output folder is tapmp's only by proof, through the real `tapmp` command line: its marker
(run.json, comparison.json, plots.json) lists every file tapmp wrote there with its size and sha256;
a hand-written marker or a run in a subfolder proves nothing, --overwrite and reuse remove only the
listed files still as written, and no file is ever written through a symbolic link."""

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from orchestrator.cli import main

pytestmark = pytest.mark.slow  # real runs, comparisons and figures through the FMUs

ROOT = Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")
SHORT = ["--set", "stop_time=0.002", "--no-progress"]


def tapmp(built, command, out, *extra) -> int:
    return main([command, PAPER, "--ssp", str(built["ssp"]), "--out", str(out), *SHORT, *extra])


def snapshot(folder: Path) -> dict:
    """{relative path: bytes, or ("link", target), or None for a folder} of everything below ``folder``."""
    out = {}
    for p in sorted(folder.rglob("*")):
        key = str(p.relative_to(folder))
        out[key] = ("link", os.readlink(p)) if p.is_symlink() else (p.read_bytes() if p.is_file() else None)
    return out


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.endswith("\n") and err.count("\n") == 1, err
    return err


# (1) a user's folder is never taken for a comparison because of a subfolder

def test_a_run_json_in_a_subfolder_does_not_make_a_users_folder_a_comparison(built, tmp_path, capsys):
    notes = tmp_path / "notes"
    (notes / "sub").mkdir(parents=True)
    (notes / "comparison.md").write_text("MY OWN NOTES\n")
    (notes / "sub" / "run.json").write_text('{"kind":"run","status":"interrupted"}')
    before = snapshot(notes)
    for extra in ([], ["--overwrite"]):
        assert tapmp(built, "compare", notes, *extra) == 2
        assert "holds comparison.md, which tapmp did not write" in one_error_line(capsys)
        assert snapshot(notes) == before  # not even a lock file


def test_overwrite_with_a_real_run_in_a_subfolder_keeps_the_users_comparison_md_and_figure(built, tmp_path, capsys):
    notes = tmp_path / "notes"
    assert tapmp(built, "run", notes / "sc-dc") == 0  # a real run of tapmp's below the user's folder
    (notes / "comparison.md").write_text("MY OWN NOTES\n")
    (notes / "fig4_trajectory.png").write_bytes(b"my own figure")
    capsys.readouterr()
    before = snapshot(notes)
    assert tapmp(built, "compare", notes, "--overwrite") == 2
    assert "holds comparison.md, fig4_trajectory.png, which tapmp did not write" in one_error_line(capsys)
    assert snapshot(notes) == before


# (4) a marker is not one JSON key

@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_a_hand_written_run_json_does_not_let_a_run_replace_the_users_results_csv(built, tmp_path, capsys, overwrite):
    out = tmp_path / "d"
    out.mkdir()
    (out / "run.json").write_text('{"kind":"run"}')
    (out / "results.csv").write_text("my measurements\n")
    before = snapshot(out)
    assert tapmp(built, "run", out, *overwrite) == 2
    assert one_error_line(capsys) == (
        f"error: output folder {out} holds results.csv, run.json, which tapmp did not write (no run.json of tapmp "
        "marks the folder as a single run) and would replace: nothing was changed; move them away or choose another "
        "folder with --out\n")
    assert snapshot(out) == before


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_the_marker_lists_every_file_tapmp_wrote_with_its_size_and_sha256(built, tmp_path, capsys):
    out = tmp_path / "run"
    assert tapmp(built, "run", out) == 0
    assert main(["plot", str(out), "--signals", "X,Z"]) == 0
    files = json.loads((out / "run.json").read_text())["tapmp_files"]
    assert sorted(files) == ["metrics.json", "results.csv", "signals.png"]
    for name, rec in files.items():
        assert rec == {"size": (out / name).stat().st_size, "sha256": sha256(out / name)}, name


# (2) never written through a symbolic link

@pytest.fixture
def outside(tmp_path):
    """A file outside every output folder that a planted link points to: (path, its bytes)."""
    target = tmp_path / "elsewhere" / "precious.txt"
    target.parent.mkdir()
    target.write_bytes(b"not a figure\n")
    return target, target.read_bytes()


def plant_link(path: Path, target: Path) -> None:
    path.unlink(missing_ok=True)
    path.symlink_to(target)


def link_refused(path: Path, target: Path) -> str:
    return (f"error: {path} is a symbolic link (to {target}): tapmp never writes through a link; nothing was "
            "written there; remove the link or choose another folder with --out\n")


@pytest.mark.parametrize("figure, extra", [("run_fig4_trajectory.png", []), ("signals.png", ["--signals", "X,Z"])])
def test_plot_refuses_a_figure_that_is_a_symbolic_link_and_its_target_stays(built, tmp_path, capsys, outside,
                                                                            figure, extra):
    target, content = outside
    out = tmp_path / "run"
    assert tapmp(built, "run", out) == 0
    assert main(["plot", str(out), *extra]) == 0
    plant_link(out / figure, target)
    capsys.readouterr()
    before = snapshot(out)
    assert main(["plot", str(out), *extra]) == 2
    assert one_error_line(capsys) == link_refused(out / figure, target)
    assert target.read_bytes() == content and snapshot(out) == before


def test_compare_overwrite_refuses_a_figure_that_is_a_symbolic_link_and_its_target_stays(built, tmp_path, capsys,
                                                                                       outside):
    target, content = outside
    out = tmp_path / "cmp"
    assert tapmp(built, "compare", out, "--no-noise") == 0
    plant_link(out / "fig5_tracking_errors.png", target)
    capsys.readouterr()
    before = snapshot(out)
    assert tapmp(built, "compare", out, "--no-noise", "--overwrite") == 2
    assert one_error_line(capsys) == link_refused(out / "fig5_tracking_errors.png", target)
    assert target.read_bytes() == content and snapshot(out) == before


def test_files_are_replaced_by_rename_never_rewritten_in_place(built, tmp_path, capsys):
    out, keep = tmp_path / "run", tmp_path / "kept"
    keep.mkdir()
    assert tapmp(built, "run", out) == 0
    assert main(["plot", str(out)]) == 0
    for name in ("results.csv", "run.json", "run_fig4_trajectory.png"):
        os.link(out / name, keep / name)  # a second name of the same inode
    before = snapshot(keep)
    assert main(["plot", str(out), "--window", "0:0.001"]) == 0  # other figures, under the same names
    assert (out / "run_fig4_trajectory.png").read_bytes() != before["run_fig4_trajectory.png"]
    assert tapmp(built, "run", out, "--overwrite") == 0
    assert snapshot(keep) == before  # new files were renamed into the folder; the old inodes were not written


# --overwrite and reuse remove only the listed files still as tapmp wrote them

def test_overwrite_keeps_a_listed_figure_the_user_changed_and_removes_the_unchanged_ones(built, tmp_path, capsys):
    out = tmp_path / "run"
    assert tapmp(built, "run", out) == 0
    assert main(["plot", str(out)]) == 0
    (out / "run_fig5_tracking_errors.png").write_bytes(b"my annotated figure")
    assert tapmp(built, "run", out, "--overwrite") == 0
    assert sorted(p.name for p in out.iterdir()) == [".tapmp.lock", "metrics.json", "results.csv", "run.json",
                                                     "run_fig5_tracking_errors.png"]
    assert (out / "run_fig5_tracking_errors.png").read_bytes() == b"my annotated figure"
    capsys.readouterr()
    assert main(["plot", str(out)]) == 2  # it is the user's now: plot does not replace it either
    assert "holds run_fig5_tracking_errors.png, which tapmp did not write or which was changed since (run.json " \
           "does not list it as tapmp wrote it)" in one_error_line(capsys)
    assert (out / "run_fig5_tracking_errors.png").read_bytes() == b"my annotated figure"


def test_overwrite_refuses_a_result_file_the_user_changed(built, tmp_path, capsys):
    out = tmp_path / "run"
    assert tapmp(built, "run", out) == 0
    with open(out / "results.csv", "a") as f:
        f.write("my extra row\n")
    capsys.readouterr()
    before = snapshot(out)
    assert tapmp(built, "run", out, "--overwrite") == 2
    assert one_error_line(capsys) == (
        f"error: output folder {out} holds results.csv, which tapmp did not write or which was changed since "
        "(run.json does not list it as tapmp wrote it) and would replace: nothing was changed; move it away or "
        "choose another folder with --out\n")
    assert snapshot(out) == before


def test_a_killed_run_is_reused_its_result_file_on_record_by_its_inode(built, tmp_path, capsys):
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator", "run", PAPER, "--ssp", str(built["ssp"]), "--out",
                             str(out), "--set", "stop_time=30", "--no-progress"], stderr=subprocess.DEVNULL)
    results = out / "results.csv"
    while proc.poll() is None and (not results.exists() or results.stat().st_size < 100_000):
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=60)
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "running"
    assert info["tapmp_files"] == {"results.csv": {"writing": True, "inode": results.stat().st_ino}}
    assert tapmp(built, "run", out) == 0  # never finished: reused without --overwrite
    assert len(results.read_text().splitlines()) == 1 + 21


HOLD = ("import sys; from orchestrator.tool.folders import output_lock\n"
        "with output_lock(sys.argv[1]):\n    print('held', flush=True); sys.stdin.read()\n")


def test_plot_is_refused_while_another_process_writes_the_folder(built, tmp_path, capsys):
    out = tmp_path / "run"
    assert tapmp(built, "run", out) == 0
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(out)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              text=True)
    try:
        assert holder.stdout.readline() == "held\n"
        capsys.readouterr()
        before = snapshot(out)
        assert main(["plot", str(out)]) == 2
        assert one_error_line(capsys) == (
            f"error: output folder {out} is in use by tapmp (pid {holder.pid}): allowed is one writer per output "
            "folder; wait for it to end or choose another --out\n")
        assert snapshot(out) == before  # no figure, and run.json's record unchanged
    finally:
        holder.communicate("", timeout=30)
