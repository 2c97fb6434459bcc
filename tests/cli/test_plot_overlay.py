"""`tapmp plot RUN [RUN ...]`: any run folders overlaid, labels, signals, a time window, the horizon
check, PNG and SVG, and one-line refusals (exit 2, nothing written) for input it cannot use; the
min/max decimation keeps the range of every sample. Built from real runs through the FMUs."""

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest

from orchestrator.cli import main
from orchestrator.tool.plots import (COLUMNS, _load_run, decimate, error_figure, parse_window,
                                            resolve_signal, signals_figure)
from orchestrator.tool.reading import read_results

pytestmark = pytest.mark.slow  # tapmp plot over real run folders

ROOT = Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")
STOP = 0.4  # [s]: 4001 samples at 0.1 ms, more than 4 per pixel column, so the figures decimate


@pytest.fixture(scope="module")
def runs(built, tmp_path_factory):
    """Three run folders: sc-dc and apd-dc over 0.4 s, and sc-dc over 0.3 s (another horizon)."""
    base = tmp_path_factory.mktemp("overlay")
    for name, sets in (("sc-dc", []), ("apd-dc", ['law="apd-dc"']), ("short", ["stop_time=0.3"])):
        args = ["run", PAPER, "--ssp", str(built["ssp"]), "--out", str(base / name), "--no-progress",
                "--format", "mat", "--set", f"stop_time={STOP}"]
        for s in sets:
            args += ["--set", s]
        assert main(args) == 0
    return base


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


def written(capsys) -> list[Path]:
    return [Path(line.split(" ", 1)[1]) for line in capsys.readouterr().out.splitlines() if line.startswith("wrote ")]


def test_two_runs_overlaid_into_results_plots_named_after_the_runs(runs, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["plot", str(runs / "sc-dc"), str(runs / "apd-dc")]) == 0
    paths = written(capsys)
    assert [p.name for p in paths] == ["fig4_trajectory.png", "fig5_tracking_errors.png", "fig6_sync_errors.png",
                                       "fig7_axis_errors.png", "fig8_force_commands.png"]
    assert all(p.parent == Path("results/plots/sc-dc_vs_apd-dc") for p in paths)
    assert all((tmp_path / p).read_bytes()[:4] == b"\x89PNG" for p in paths)


def test_labels_signals_window_and_svg(runs, tmp_path, capsys):
    out = tmp_path / "fig"
    assert main(["plot", str(runs / "sc-dc"), str(runs / "apd-dc"), "--label", "proposed", "--label", "baseline",
                 "--signals", "q1_err,F1,es2", "--window", "0.1:0.2", "--svg", "--out", str(out)]) == 0
    assert written(capsys) == [out / "signals.png", out / "signals.svg"]
    assert b"<svg" in (out / "signals.svg").read_bytes()[:1000]
    # the figure drawn: one panel per signal, every sample in the window (0.1 s = 1001 samples, too
    # few per pixel column to decimate), the values of the run's own columns in µm and N
    columns, data = read_results(runs / "sc-dc")
    run = _load_run(runs / "sc-dc", None, parse_window("0.1:0.2"))
    keys = [resolve_signal(s, columns) for s in ("q1_err", "F1", "es2")]
    assert keys == [("e1", "e1 [µm]"), ("F1", "F1 [N]"), ("es2", "es2 [µm]")]
    fig = signals_figure({"proposed": run}, keys)
    rows = (data[:, 0] >= 0.1) & (data[:, 0] <= 0.2)
    c = {n: i for i, n in enumerate(columns)}
    e1 = (data[rows, c["trajectory.q1_d"]] - data[rows, c["plant.q1_true"]]) * 1e6
    e2 = data[rows, c["trajectory.q2_d"]] - data[rows, c["plant.q2_true"]]
    e3 = data[rows, c["trajectory.q3_d"]] - data[rows, c["plant.q3_true"]]
    expected = [e1, data[rows, c["controller.F1"]], (e2 - e3) * 1e6]
    for ax, want, ylabel in zip(fig.axes, expected, ("e1 [µm]", "F1 [N]", "es2 [µm]")):
        line = ax.get_lines()[0]
        assert ax.get_ylabel() == ylabel and line.get_label() == "proposed"
        assert np.allclose(line.get_ydata(), want, rtol=1e-12, atol=1e-12)
        assert line.get_xdata()[0] >= 0.1 and line.get_xdata()[-1] <= 0.2 and len(line.get_xdata()) == rows.sum()
    assert fig.axes[-1].get_xlabel() == "time [s]"
    assert "proposed" in fig._suptitle.get_text()


def test_a_recorded_column_is_a_signal_with_its_unit(runs):
    columns, _ = read_results(runs / "sc-dc")
    assert resolve_signal("plant.dq2", columns) == ("plant.dq2", "plant.dq2 [m/s]")


def test_the_decimated_trace_keeps_the_range_of_every_sample(runs):
    run = _load_run(runs / "apd-dc")
    t, y = run["time"], run["tracking"][:, 0] * 1e6
    assert len(t) == round(STOP / 1e-4) + 1
    line = error_figure({"APD-DC": run}, "tracking").axes[0].get_lines()[0]
    x, yd = line.get_xdata(), line.get_ydata()
    assert len(x) < len(t)  # decimated
    index = np.searchsorted(t, x)
    assert np.array_equal(t[index], x) and np.array_equal(y[index], yd)  # drawn points are samples
    m = -(-len(t) // COLUMNS)
    for g in range(len(t) // m):  # each pixel column's minimum and maximum are drawn
        seg = y[g * m:(g + 1) * m]
        drawn = yd[(index >= g * m) & (index < (g + 1) * m)]
        assert drawn.min() == seg.min() and drawn.max() == seg.max()
    assert np.array_equal(decimate(t[:100], y[:100])[1], y[:100])  # few samples: unchanged


def test_one_run_folder_still_gets_its_own_figures(runs, capsys):
    assert main(["plot", str(runs / "sc-dc")]) == 0
    assert [p.name for p in written(capsys)] == ["run_fig4_trajectory.png", "run_fig5_tracking_errors.png",
                                                 "run_fig6_sync_errors.png", "run_fig7_axis_errors.png",
                                                 "run_fig8_force_commands.png"]


def test_runs_of_different_horizons_only_when_asked(runs, tmp_path, capsys):
    out = tmp_path / "fig"
    assert main(["plot", str(runs / "sc-dc"), str(runs / "short"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "different horizons" in err[0] and "0 to 0.4 s" in err[0] and "0 to 0.3 s" in err[0]
    assert "--allow-different-horizons" in err[0] and not out.exists()
    assert main(["plot", str(runs / "sc-dc"), str(runs / "short"), "--out", str(out),
                 "--allow-different-horizons", "--signals", "e1"]) == 0
    assert (out / "signals.png").stat().st_size > 10000


@pytest.mark.parametrize("extra, message", [
    (["--signals", "q1_er"], "--signals: 'q1_er' is not a signal (did you mean q1_err?): allowed are e1..e3"),
    (["--signals", "F4"], "--signals: 'F4' is not a signal (did you mean F3?)"),
    (["--window", "0.3:0.1"], "--window = '0.3:0.1' is invalid: allowed is START:STOP in seconds with START < STOP"),
    (["--window", "a:b"], "--window = 'a:b' is invalid"),
    (["--window", "5:6"], "--window = 5:6 s holds 0 sample(s) of"),
    (["--label", "only-one"], "--label given 1 time(s) for 2 folder(s)"),
    (["--runs", "sc-dc"], "--runs selects the runs of one comparison folder"),
])
def test_bad_input_is_one_line_exit_2_and_nothing_written(runs, tmp_path, capsys, extra, message):
    out = tmp_path / "fig"
    assert main(["plot", str(runs / "sc-dc"), str(runs / "apd-dc"), "--out", str(out)] + extra) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not out.exists()


def test_a_folder_that_is_no_run_is_refused(runs, tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    for folder, message in ((empty, "holds no results of tapmp run or tapmp compare"),
                            (tmp_path / "missing", "does not exist")):
        assert main(["plot", str(runs / "sc-dc"), str(folder), "--out", str(tmp_path / "fig")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(folder) in err[0] and message in err[0]
    assert not (tmp_path / "fig").exists()
