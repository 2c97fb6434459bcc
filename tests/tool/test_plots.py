"""Figures: µm (never "um") on every axis, a quantity and unit on every axis label, the force
commands per motor with the chatter envelope, a zoom panel and the force limit, legends outside
the axes, titles naming the laws and never starting a line with a separator, SC-DC on the top
layer, distinct styles per run, the runs a comparison figure shows; built from real runs and
inspected before saving."""

import json
import re
from pathlib import Path

import numpy as np
import pytest
import matplotlib.pyplot as plt
from matplotlib.transforms import Bbox

from orchestrator.cli import main
from orchestrator.tool.plots import (CHATTER_WINDOW, ZOOM_SAMPLES, figures, force_figure, load_folder,
                                            select_runs, sliding_mean_rms)

pytestmark = pytest.mark.slow  # compare runs and figures drawn with matplotlib

ROOT = Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")


@pytest.fixture(scope="module")
def comparison(built, tmp_path_factory):
    out = tmp_path_factory.mktemp("plots") / "cmp"
    assert main(["compare", PAPER, "--ssp", str(built["ssp"]), "--out", str(out), "--set", "stop_time=0.02",
                 "--no-progress", "--format", "mat"]) == 0
    return out


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


def texts(fig) -> list[str]:
    out = [fig._suptitle.get_text()] if fig._suptitle else []
    for ax in fig.axes:
        out += [ax.get_xlabel(), ax.get_ylabel(), ax.get_title()]
    for leg in fig.legends:
        out += [t.get_text() for t in leg.get_texts()]
    return [t for t in out if t]


LAWS = ["SC-DC (proposed)", "APD-DC", "APD-DC matched", "APD-DC diff. stiffness", "APD-DC mode-matched",
        "APD-DC Ms-matched", "PID-DC mode-matched", "PID-DC full integral", "SC-DC b = 0",
        "SC-DC Lambda_p = 0"]  # one per compare run, none merged


def test_comparison_figures_name_the_laws_in_titles_and_legends_and_use_micrometres(comparison):
    kind, runs = load_folder(comparison)
    assert kind == "comparison" and list(runs) == LAWS
    figs = figures(runs)
    assert list(figs) == ["fig4_trajectory", "fig5_tracking_errors", "fig6_sync_errors", "fig7_axis_errors",
                          "fig8_force_commands"]
    for name, fig in figs.items():
        all_text = texts(fig)
        assert not [t for t in all_text if "um]" in t or "urad" in t], name  # µm, µrad only
        assert all(law in fig._suptitle.get_text() for law in LAWS), name
        fig.canvas.draw()  # the title, broken between names, stays inside the figure
        box = fig._suptitle.get_window_extent()
        assert box.x0 >= 0 and box.x1 <= fig.bbox.x1, name
        if name == "fig8_force_commands":  # the runs, then the force limit line
            assert [t.get_text() for t in fig.legends[0].get_texts()] == LAWS + ["force limit 600 N"]
        elif name != "fig4_trajectory":
            assert [t.get_text() for t in fig.legends[0].get_texts()] == LAWS
    assert [ax.get_ylabel() for ax in figs["fig5_tracking_errors"].axes] == ["e1 [µm]", "e2 [µm]", "e3 [µm]"]
    assert [ax.get_ylabel() for ax in figs["fig7_axis_errors"].axes] == ["X [µm]", "Z [µm]", "B [µrad]"]
    assert [ax.get_ylabel() for ax in figs["fig8_force_commands"].axes] == [
        "F1 [N]", "F1 [N]", "peak |F1| [N]", "F2 [N]", "F2 [N]", "peak |F2| [N]", "F3 [N]", "F3 [N]", "peak |F3| [N]"]


UNIT = re.compile(r"^\S.* \[[^\[\]]+\]$")  # "quantity [unit]"


def test_every_axis_names_a_quantity_and_unit_and_no_title_line_starts_with_a_separator(comparison):
    _, runs = load_folder(comparison)
    for name, fig in figures(runs).items():
        for ax in fig.axes:
            assert UNIT.match(ax.get_ylabel()), (name, ax.get_ylabel())
            assert ax.get_xlabel() == "" or UNIT.match(ax.get_xlabel()), (name, ax.get_xlabel())
        bottom = [ax.get_xlabel() for ax in fig.axes if ax.get_xlabel()]
        assert bottom, name
        for line in fig._suptitle.get_text().splitlines():
            assert not line.startswith((",", " ", "vs")), (name, line)
    trajectory = figures(runs)["fig4_trajectory"]
    assert [(ax.get_xlabel(), ax.get_ylabel()) for ax in trajectory.axes] == [("X [mm]", "Z [mm]"),
                                                                               ("time [s]", "B [deg]")]


def test_the_proposed_law_is_on_top_and_every_run_has_its_own_style(comparison):
    _, runs = load_folder(comparison)
    for name, fig in figures(runs).items():
        if name == "fig4_trajectory":
            continue
        ax = fig.axes[0]
        lines = {line.get_label(): line for line in ax.get_lines() if line.get_label() in LAWS}
        assert list(lines) == LAWS, name
        sc = lines["SC-DC (proposed)"]
        assert all(sc.get_zorder() > line.get_zorder() for law, line in lines.items() if law != "SC-DC (proposed)")
        assert len({line.get_marker() for line in lines.values()}) == len(LAWS), name  # one marker per run
        assert sc.get_linestyle() == "-" and all(line.get_linestyle() != "-" for law, line in lines.items()
                                                 if law != "SC-DC (proposed)"), name


def test_the_force_figure_shows_the_chatter_envelope_a_zoom_of_every_sample_and_the_force_limit(comparison):
    _, runs = load_folder(comparison)
    fig = force_figure(runs)
    axes = np.array(fig.axes).reshape(3, 3)
    sc = runs["SC-DC (proposed)"]
    t = sc["data"][:, 0]
    for i in range(3):
        envelope, zoom, headroom = axes[i]
        for line, (law, run) in zip(envelope.get_lines(), runs.items()):
            f = run["data"][:, run["columns"].index(f"controller.F{i + 1}")]
            w = round(CHATTER_WINDOW / 1e-4)  # samples in the window at the 0.1 ms step
            k = len(f) // 2
            assert line.get_label() == law
            assert line.get_ydata()[k] == pytest.approx(f[k - w // 2:k - w // 2 + w].mean(), rel=1e-9)
        for line, (law, run) in zip(zoom.get_lines(), runs.items()):  # every sample of the zoom window
            f = run["data"][:, run["columns"].index(f"controller.F{i + 1}")]
            x = line.get_xdata()
            assert len(x) == ZOOM_SAMPLES and line.get_marker() not in ("", "None")
            start = int(np.argmin(np.abs(t * 1e3 - x[0])))
            assert np.array_equal(line.get_ydata(), f[start:start + ZOOM_SAMPLES])
        limit = [line for line in headroom.get_lines() if line.get_label() == "force limit 600 N"]
        assert len(limit) == 1 and list(limit[0].get_ydata()) == [600, 600]
        peaks = [patch.get_height() for patch in headroom.patches]
        assert peaks == pytest.approx([np.abs(run["data"][:, run["columns"].index(f"controller.F{i + 1}")]).max()
                                       for run in runs.values()])
        assert any("force limit 600 N" == text.get_text() for text in headroom.texts)
    assert sc["data"][:, sc["columns"].index("controller.F1")].std() > 0


def test_the_sliding_rms_is_the_chatter_about_the_sliding_mean():
    t = np.arange(2001) * 1e-4
    f = 5.0 + 2.0 * np.where(np.arange(2001) % 2, 1.0, -1.0)  # a 5 N mean with +-2 N chatter every step
    mean, rms = sliding_mean_rms(t, f, window=0.01)  # 100 samples: half +2, half -2
    assert mean[500:1500] == pytest.approx(5.0, abs=1e-12)
    assert rms[500:1500] == pytest.approx(2.0, abs=1e-9)


def test_legends_lie_outside_every_axes(comparison):
    _, runs = load_folder(comparison)
    for name, fig in figures(runs).items():
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        for leg in fig.legends:
            box = leg.get_window_extent(renderer)
            for ax in fig.axes:
                assert not Bbox.intersection(box, ax.get_window_extent(renderer)), name


def test_a_single_run_gets_its_law_in_every_title(comparison):
    kind, runs = load_folder(comparison / "apd-dc-matched")
    assert kind == "run" and list(runs) == ["APD-DC matched"]
    for fig in figures(runs).values():
        assert "APD-DC matched" in fig._suptitle.get_text()


def mean_tracking_mae(folder: Path) -> float:
    return float(np.mean(json.loads((folder / "metrics.json").read_text())["tracking_mae_um"]))


def test_a_comparison_shows_sc_dc_apd_dc_and_the_better_fair_baseline_by_default(comparison):
    names = ["sc-dc", "apd-dc", "apd-dc-matched", "apd-dc-diff-stiffness", "apd-dc-mode-matched",
             "apd-dc-ms-matched", "pid-dc-mode-matched", "sc-dc-b0", "sc-dc-lp0"]
    better = min(("apd-dc-mode-matched", "apd-dc-ms-matched"), key=lambda n: mean_tracking_mae(comparison / n))
    assert select_runs(comparison, names) == ["sc-dc", "apd-dc", better]
    assert select_runs(comparison, names, ["all"]) == names
    assert select_runs(comparison, names, ["apd-dc", "sc-dc-lp0"]) == ["apd-dc", "sc-dc-lp0"]
    with pytest.raises(ValueError, match=r"^--runs: 'sc-dc-lp' is not a run of .*\(did you mean sc-dc-lp0\?\)"):
        select_runs(comparison, names, ["sc-dc-lp"])
    # every run still ran and is in comparison.md
    text = (comparison / "comparison.md").read_text()
    for row in ("SC-DC ablation, b = 0", "SC-DC ablation, Lambda_p = 0", "APD-DC robustness-matched",
                "PID-DC mode-matched", "differential-mode stiffness"):
        assert row in text
    assert all((comparison / n / "metrics.json").is_file() for n in names)


def test_plot_writes_pngs_of_the_chosen_runs_beside_the_comparisons_own(comparison, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    own = {p.name: p.read_bytes() for p in comparison.glob("*.png")}
    assert main(["plot", str(comparison), "--runs", "sc-dc,pid-dc-mode-matched", "--svg"]) == 0
    written = capsys.readouterr().out.split()
    assert {p.name: p.read_bytes() for p in comparison.glob("*.png")} == own  # the comparison's figures stay
    assert all(Path(w).parent == Path("results/plots/sc-dc_vs_pid-dc-mode-matched") for w in written if "." in w)
    pngs = [Path(w) for w in written if w.endswith(".png")]
    svgs = [Path(w) for w in written if w.endswith(".svg")]
    assert len(pngs) == 5 and all(p.stat().st_size > 10000 and p.read_bytes()[:4] == b"\x89PNG" for p in pngs)
    assert len(svgs) == 5 and all(b"<svg" in p.read_bytes()[:1000] for p in svgs)
    assert [p.with_suffix("") for p in svgs] == [p.with_suffix("") for p in pngs]


def test_compare_refuses_an_unknown_run_before_running_anything(built, tmp_path, capsys):
    out = tmp_path / "cmp"
    assert main(["compare", PAPER, "--ssp", str(built["ssp"]), "--out", str(out), "--set", "stop_time=0.02",
                 "--no-progress", "--runs", "sc-dc,apd-dc-mode-matchd"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'apd-dc-mode-matchd'" in err[0] and "did you mean apd-dc-mode-matched?" in err[0]
    assert not out.exists()


def test_compare_with_no_figures_writes_the_runs_and_comparison_md_and_plot_draws_them_later(built, tmp_path,
                                                                                           capsys):
    """--no-figures: every run folder and comparison.md, no PNG; `tapmp plot` on the folder then
    draws the five comparison figures from the files; --runs with --no-figures is refused."""
    out = tmp_path / "cmp"
    assert main(["compare", PAPER, "--ssp", str(built["ssp"]), "--out", str(out), "--set", "stop_time=0.02",
                 "--no-progress", "--no-figures"]) == 0
    printed = capsys.readouterr().out
    assert (out / "comparison.md").is_file() and (out / "sc-dc" / "metrics.json").is_file()
    assert not list(out.rglob("*.png")) and "results and the full tables (comparison.md) in" in printed
    assert main(["plot", str(out)]) == 0
    assert sorted(p.name for p in out.glob("*.png")) == ["fig4_trajectory.png", "fig5_tracking_errors.png",
                                                         "fig6_sync_errors.png", "fig7_axis_errors.png",
                                                         "fig8_force_commands.png"]
    capsys.readouterr()
    assert main(["compare", PAPER, "--ssp", str(built["ssp"]), "--out", str(tmp_path / "other"),
                 "--no-progress", "--no-figures", "--runs", "sc-dc"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: --runs chooses the runs the figures show: it cannot go with --no-figures"]
    assert not (tmp_path / "other").exists()


def test_figures_drawn_while_the_runs_go_on_are_the_pictures_plot_draws_from_the_files(built, tmp_path):
    """compare draws its figures from the rows the runs hand back, starting while the other runs
    still run (the runs they show start first); `tapmp plot` on the finished folder reads the
    rows from the result files: the same five PNG files, byte for byte."""
    out = tmp_path / "cmp"
    assert main(["compare", PAPER, "--ssp", str(built["ssp"]), "--out", str(out), "--set", "stop_time=0.05",
                 "--no-progress"]) == 0
    drawn = {p.name: p.read_bytes() for p in out.glob("*.png")}
    assert len(drawn) == 5
    assert main(["plot", str(out)]) == 0
    assert {p.name: p.read_bytes() for p in out.glob("*.png")} == drawn
