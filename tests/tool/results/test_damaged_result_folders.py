"""`tapmp plot` on a damaged result folder: one line `error: ...` naming the damaged file and what
is wrong with it, exit 2, no figure written, never a traceback (before: StopIteration, IndexError,
KeyError, ValueError, UnicodeDecodeError, AttributeError, and a results.csv linking to a system
file was read). A link out of the folder is refused, not followed."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from orchestrator.cli import main

pytestmark = pytest.mark.slow  # real runs through the FMUs

ROOT = Path(__file__).resolve().parents[3]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")


@pytest.fixture(scope="module")
def runs(built, tmp_path_factory):
    """{"csv" | "mat": a completed run folder of that format}."""
    base = tmp_path_factory.mktemp("runs")
    for fmt in ("csv", "mat"):
        assert main(["run", PAPER, "--ssp", str(built["ssp"]), "--out", str(base / fmt), "--set", "stop_time=0.01",
                     "--format", fmt, "--no-progress"]) == 0
    return {fmt: base / fmt for fmt in ("csv", "mat")}


def csv_lines(d: Path) -> list[bytes]:
    return (d / "results.csv").read_bytes().splitlines(keepends=True)


def replace_field(d: Path) -> None:
    lines = csv_lines(d)
    fields = lines[5].split(b",")
    fields[3] = b"abc"
    (d / "results.csv").write_bytes(b"".join(lines[:5]) + b",".join(fields) + b"".join(lines[6:]))


def part(d: Path, array) -> None:
    """A killed MAT run: no results file, the rows so far in results.part.npy."""
    (d / "results.mat").unlink()
    (d / "metrics.json").unlink()
    if isinstance(array, bytes):
        (d / "results.part.npy").write_bytes(array)
    else:
        np.save(d / "results.part.npy", array)


def comparison(d: Path, content: str) -> Path:
    """A comparison folder around the run ``d`` whose comparison.json holds ``content``."""
    top = d.parent / "cmp"
    top.mkdir()
    d.rename(top / "sc-dc")
    (top / "comparison.json").write_text(content)
    return top


# name: (format of the run it starts from, damage(folder) -> folder to plot or None, words of the one line)
VARIANTS = {
    "csv empty": ("csv", lambda d: (d / "results.csv").write_bytes(b""),
                  "results.csv is damaged: it has no header line of column names"),
    "csv header only": ("csv", lambda d: (d / "results.csv").write_bytes(csv_lines(d)[0]),
                        "results.csv holds no rows (only the column names)"),
    "csv cut mid-row": ("csv", lambda d: (d / "results.csv").write_bytes(b"".join(csv_lines(d))[:-200]),
                        "results.csv is damaged: line 102 holds"),
    "csv garbled bytes": ("csv", lambda d: (d / "results.csv").write_bytes(bytes(range(256)) * 20),
                          "results.csv is damaged: it is not text"),
    "csv non-numeric field": ("csv", replace_field, "results.csv is damaged: could not convert string 'abc'"),
    "csv ragged row": ("csv", lambda d: (d / "results.csv").write_bytes(
        b"".join(csv_lines(d)[:5]) + csv_lines(d)[5].rsplit(b",", 3)[0] + b"\n" + b"".join(csv_lines(d)[6:])),
        "results.csv is damaged: line 6 holds 37 values, not 40 (a row cut or garbled)"),
    "csv column missing": ("csv", lambda d: (d / "results.csv").write_bytes(
        csv_lines(d)[0].replace(b"plant.", b"p.") + b"".join(csv_lines(d)[1:])),
        "results.csv is damaged: it has no column plant.q1_true (allowed are the columns tapmp records)"),
    "csv link to a system file": ("csv", lambda d: ((d / "results.csv").unlink(),
                                                    (d / "results.csv").symlink_to("/etc/passwd")),
                                  "results.csv is a symbolic link to /etc/passwd, outside the result folder: allowed "
                                  "is a file tapmp wrote there (a link out of the folder is not followed)"),
    "csv link to a device": ("csv", lambda d: ((d / "results.csv").unlink(), (d / "results.csv").symlink_to("/dev/zero")),
                             "results.csv is a symbolic link to /dev/zero, outside the result folder"),
    "mat truncated": ("mat", lambda d: (d / "results.mat").write_bytes((d / "results.mat").read_bytes()[:3000]),
                      "results.mat is damaged: "),
    "mat garbled": ("mat", lambda d: (d / "results.mat").write_bytes(bytes(range(256)) * 20),
                    "results.mat is damaged: "),
    "mat without columns": ("mat", lambda d: __import__("scipy.io").io.savemat(d / "results.mat", {"x": np.zeros(3)}),
                            "results.mat is damaged: it has no variable 'columns'"),
    "run.json garbled": ("csv", lambda d: ((d / "run.json").write_text("{not json"), (d / "results.csv").unlink()),
                         "run.json is damaged: "),
    "run.json a list": ("csv", lambda d: (d / "run.json").write_text("[1, 2]"),
                        "run.json is damaged: it holds a JSON list, not an object (allowed is the JSON object tapmp "
                        "wrote)"),
    "metrics.json a number": ("csv", lambda d: (d / "metrics.json").write_text("42"),
                              "metrics.json is damaged: it holds a JSON int, not an object"),
    "comparison.json a list": ("csv", lambda d: comparison(d, "[]"),
                               "comparison.json is damaged: it holds a JSON list, not an object"),
    "comparison.json runs outside": ("csv", lambda d: comparison(d, json.dumps({"kind": "comparison",
                                                                               "runs": {"../..": "sc-dc"}})),
                                     "comparison.json is damaged: its runs are not a table of run folder names"),
    "part.npy of Python objects": ("mat", lambda d: part(d, np.array([{"a": 1}], dtype=object)),
                                   "results.part.npy is damaged: "),
    "part.npy 1-D": ("mat", lambda d: part(d, np.zeros(10)),
                     "results.part.npy is damaged: it holds a 1-D float64 array, not rows of numbers"),
    "part.npy too few columns": ("mat", lambda d: part(d, np.zeros((10, 3))),
                                 "results.part.npy is damaged: its rows hold 3 values but it names 40 columns"),
    "part.npy garbled": ("mat", lambda d: part(d, b"\x93NUMPY" + bytes(range(200))), "results.part.npy is damaged: "),
}


@pytest.mark.parametrize("variant", VARIANTS)
def test_plot_of_a_damaged_result_folder_is_one_line_naming_the_file(runs, tmp_path, capsys, variant):
    fmt, damage, words = VARIANTS[variant]
    folder = tmp_path / "run"
    shutil.copytree(runs[fmt], folder)
    target = damage(folder)
    folder = target if isinstance(target, Path) else folder
    capsys.readouterr()
    assert main(["plot", str(folder)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ") and words in err, err
    assert "Traceback" not in err
    assert not list(folder.rglob("*.png"))


def test_the_undamaged_runs_plot(runs, tmp_path, capsys):
    for fmt, run in runs.items():
        folder = shutil.copytree(run, tmp_path / fmt)
        assert main(["plot", str(folder)]) == 0
        assert len(list(folder.glob("run_fig*.png"))) == 5
