"""tapmp never deletes or replaces a file it did not write. A folder is tapmp's only if tapmp marked
it (run.json, comparison.json listing the files it wrote); `run` and `compare` refuse a folder they
did not mark that holds anything, in one line, exit 2, with nothing changed there (not even a lock
file). --overwrite writes beside foreign files but never replaces one, and in a folder tapmp marked
it removes only the files its marker lists (the names of folders.tapmp_names that tapmp wrote)."""

import json
from pathlib import Path

import pytest

from orchestrator.cli import main
from orchestrator.tool import folders, plots

pytestmark = pytest.mark.slow  # real runs and comparisons through the FMUs

ROOT = Path(__file__).resolve().parents[3]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")
SHORT = ["--set", "stop_time=0.002", "--no-progress"]


def snapshot(folder: Path) -> dict:
    """{relative path: bytes} of every file below ``folder`` (folders as None)."""
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None) for p in sorted(folder.rglob("*"))}


def tapmp(built, command, out, *extra):
    return main([command, PAPER, "--ssp", str(built["ssp"]), "--out", str(out), *SHORT, *extra])


@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_a_run_into_a_folder_with_a_results_csv_tapmp_did_not_write_changes_nothing(built, tmp_path, capsys,
                                                                                   overwrite):
    out = tmp_path / "d"
    out.mkdir()
    (out / "results.csv").write_text("my measurements\n")
    (out / "run_fig_mine.png").write_bytes(b"my figure")
    before = snapshot(out)
    assert tapmp(built, "run", out, *overwrite) == 2
    assert capsys.readouterr().err == (
        f"error: output folder {out} holds results.csv, which tapmp did not write (no run.json of tapmp marks the "
        "folder as a single run) and would replace: nothing was changed; move it away or choose another folder "
        "with --out\n")
    assert snapshot(out) == before  # no lock file either


@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_a_comparison_into_a_folder_with_a_run_file_tapmp_did_not_write_changes_nothing(built, tmp_path, capsys,
                                                                                      overwrite):
    out = tmp_path / "X"
    (out / "sc-dc").mkdir(parents=True)
    (out / "sc-dc" / "results.csv").write_text("my measurements\n")
    before = snapshot(out)
    assert tapmp(built, "compare", out, *overwrite) == 2
    assert capsys.readouterr().err == (
        f"error: output folder {out} holds sc-dc/results.csv, which tapmp did not write (no comparison.json of tapmp "
        "marks the folder as a comparison) and would replace: nothing was changed; move it away or choose another "
        "folder with --out\n")
    assert snapshot(out) == before


def test_a_folder_with_other_files_is_written_into_only_with_overwrite_and_they_stay(built, tmp_path, capsys):
    out = tmp_path / "d"
    out.mkdir()
    (out / "notes.txt").write_text("my notes\n")
    assert tapmp(built, "run", out) == 2
    assert capsys.readouterr().err == (
        f"error: output folder {out} holds files tapmp did not write (notes.txt; no run.json of tapmp marks it as a "
        "single run): nothing was changed; choose a new or empty folder with --out, or pass --overwrite to write "
        "beside them\n")
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    assert tapmp(built, "run", out, "--overwrite") == 0
    assert (out / "notes.txt").read_text() == "my notes\n"
    assert json.loads((out / "run.json").read_text())["status"] == "completed"


def test_overwrite_removes_only_the_files_tapmp_wrote_in_its_run_folder(built, tmp_path, capsys):
    out = tmp_path / "run"
    assert tapmp(built, "run", out) == 0
    assert main(["plot", str(out), "--svg"]) == 0
    (out / "notes.txt").write_text("my notes\n")
    (out / "run_fig_mine.png").write_bytes(b"my figure")
    (out / "mine").mkdir()
    old_figure = (out / "run_fig4_trajectory.png").stat().st_mtime_ns
    assert tapmp(built, "run", out, "--overwrite", "--format", "mat") == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == [".tapmp.lock", "metrics.json", "mine", "notes.txt", "results.mat", "run.json",
                     "run_fig_mine.png"]  # the old results.csv and figures went: tapmp wrote them
    assert (out / "notes.txt").read_text() == "my notes\n" and (out / "run_fig_mine.png").read_bytes() == b"my figure"
    assert old_figure  # the figures existed before


def test_a_failed_run_is_reused_and_a_users_file_there_stays(built, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", PAPER, "--ssp", str(tmp_path / "no.ssp"), "--out", str(out), *SHORT]) == 2
    (out / "notes.txt").write_text("why it failed\n")
    assert tapmp(built, "run", out) == 0
    assert (out / "notes.txt").read_text() == "why it failed\n"


def test_overwrite_of_a_comparison_keeps_the_users_files_in_it_and_its_runs(built, tmp_path, capsys):
    out = tmp_path / "cmp"
    assert tapmp(built, "compare", out) == 0
    (out / "notes.txt").write_text("a\n")
    (out / "sc-dc" / "notes.txt").write_text("b\n")
    assert tapmp(built, "compare", out, "--overwrite") == 0
    assert (out / "notes.txt").read_text() == "a\n" and (out / "sc-dc" / "notes.txt").read_text() == "b\n"
    assert json.loads((out / "comparison.json").read_text())["status"] == "completed"


def test_a_run_json_tapmp_did_not_write_does_not_mark_a_folder(built, tmp_path, capsys):
    out = tmp_path / "d"
    out.mkdir()
    (out / "run.json").write_text('{"mine": true}\n')
    before = snapshot(out)
    assert tapmp(built, "run", out, "--overwrite") == 2
    assert "holds run.json, which tapmp did not write" in capsys.readouterr().err
    assert snapshot(out) == before


def test_the_figure_names_tapmp_removes_are_those_plot_writes():
    assert set(plots._makers()) == set(folders.FIGURE_STEMS)
