"""Figures: µm (never "um") on every axis, the force commands per motor, legends outside the axes,
titles naming the laws; built from real runs and inspected before saving."""

from pathlib import Path

import numpy as np
import pytest
import matplotlib.pyplot as plt
from matplotlib.transforms import Bbox

from orchestrator.cli import main
from orchestrator.experiments.plots import figures, load_folder

ROOT = Path(__file__).resolve().parent.parent
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
        "APD-DC Ms-matched", "PID-DC mode-matched", "SC-DC b = 0", "SC-DC Lambda_p = 0"]  # one per compare run, none merged


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
        if name != "fig4_trajectory":
            assert [t.get_text() for t in fig.legends[0].get_texts()] == LAWS
    assert [ax.get_ylabel() for ax in figs["fig5_tracking_errors"].axes] == ["e1 [µm]", "e2 [µm]", "e3 [µm]"]
    assert [ax.get_ylabel() for ax in figs["fig7_axis_errors"].axes] == ["X [µm]", "Z [µm]", "B [µrad]"]
    assert [ax.get_ylabel() for ax in figs["fig8_force_commands"].axes] == ["F1 [N]", "F2 [N]", "F3 [N]"]


def test_the_force_figure_plots_each_motors_command_of_each_law(comparison):
    _, runs = load_folder(comparison)
    fig = figures(runs)["fig8_force_commands"]
    for i, ax in enumerate(fig.axes):
        for line, (law, run) in zip(ax.get_lines(), runs.items()):
            col = run["columns"].index(f"controller.F{i + 1}")
            assert np.array_equal(line.get_ydata(), run["data"][:, col]) and line.get_label() == law
    assert runs["SC-DC (proposed)"]["data"][:, runs["SC-DC (proposed)"]["columns"].index("controller.F1")].std() > 0


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


def test_plot_writes_pngs(comparison, capsys):
    assert main(["plot", str(comparison)]) == 0
    written = capsys.readouterr().out.split()
    pngs = [Path(w) for w in written if w.endswith(".png")]
    assert len(pngs) == 5 and all(p.stat().st_size > 10000 and p.read_bytes()[:4] == b"\x89PNG" for p in pngs)
