"""Study figures from a real grid study on a Dask LocalCluster: swept keys labelled with their
quantity and unit, MAE in µm, every cell label inside its cell (flagged cells included)."""

from pathlib import Path

import matplotlib.pyplot as plt
import pytest

from orchestrator.studies.run import run_study
from orchestrator.studies.study import close_client, load_study, open_client, read_study_csv
from orchestrator.studies.study_plots import key_label, study_figures

pytestmark = pytest.mark.slow  # a grid study on a Dask LocalCluster

ROOT = Path(__file__).resolve().parents[2]
BASE = ROOT / "scenarios" / "paper_simulation.toml"


@pytest.mark.parametrize("key, label", [
    ("gain_overrides.D", "D, error-filter gain (all motors) [1/s]"),
    ("gain_overrides.Lambda_v", "Λv, velocity gain (all motors) [s/m]"),
    ("gain_overrides.Lambda_p2", "Λp, position gain (motor 2) [1/m]"),
    ("plant.m_p", "m_p, plant platform mass [kg]"),
    ("trajectory.radius", "radius, circle radius [m]"),
    ("plant.k_pull", "k_pull, mutual pulling stiffness between ... [N/m]"),
    ("stop_time", "stop time [s]"),
])
def test_a_swept_key_is_labelled_with_its_quantity_and_unit(key, label):
    assert key_label(key) == label


@pytest.fixture(scope="module")
def client():
    """A real LocalCluster with one worker process."""
    c = open_client(workers=1)
    yield c
    close_client(c)


SUMMARIES = {}  # study name: what run_study returned


def run(folder: Path, name: str, text: str, ssp, client):
    path = folder / f"{name}.toml"
    path.write_text(f'[study]\nname = "{name}"\nbase = "{BASE}"\noutput = "{folder / name}"\n[set]\n'
                    f'stop_time = 0.01\n{text}')
    study = load_study(path)
    SUMMARIES[name] = run_study(study, ssp, client, progress=False)
    return folder / name, study


@pytest.fixture(scope="module")
def sweep(built, client, tmp_path_factory):
    """A 2 x 2 grid over Lambda_v and D, 0.01 s each; Lambda_v = 5.76 is beyond the stability
    limit at 0.1 ms (studies/gain_sweep.toml), so two cells are flagged."""
    return run(tmp_path_factory.mktemp("sweep"), "s", '[grid]\n"gain_overrides.Lambda_v" = [0.36, 5.76]\n'
               '"gain_overrides.D" = [450.0, 900.0]\n', built["ssp"], client)


def test_a_one_key_sweep_and_a_monte_carlo_study_label_their_axes_with_units(built, client, tmp_path):
    out, study = run(tmp_path, "line", '[grid]\nlaw = ["sc-dc", "apd-dc"]\n"plant.k_pull" = [0.0, 200.0]\n',
                     built["ssp"], client)
    (path, fig), = study_figures(out, study).items()
    assert path.name == "sweep.png"
    for ax in fig.axes:
        assert ax.get_xlabel() == "k_pull, mutual pulling stiffness between ... [N/m]"
        assert ax.get_ylabel().endswith("MAE (mean of q1-q3) [µm]")
        assert [t.get_text() for t in ax.get_legend().get_texts()] == ["law = sc-dc", "law = apd-dc"]
    plt.close(fig)
    out, study = run(tmp_path, "mc", '[monte_carlo]\nsamples = 3\nseed = 1\n[monte_carlo.vary.m]\n'
                     'targets = ["plant.m_p"]\ndistribution = "uniform"\nlow = 0.9\nhigh = 1.1\nrelative = true\n',
                     built["ssp"], client)
    (path, fig), = study_figures(out, study).items()
    assert path.name == "robustness.png"
    assert [(ax.get_xlabel(), ax.get_ylabel()) for ax in fig.axes] == [
        ("tracking MAE (mean of q1-q3) [µm]", "cases [count]"), ("synchronization MAE (mean of q1-q3) [µm]",
                                                                "cases [count]")]
    plt.close(fig)


def test_sweep_axes_carry_units_and_cell_labels_stay_inside_their_cells(sweep):
    out, study = sweep
    assert (out / "sweep.png").stat().st_size > 10_000
    rows = read_study_csv(out / "study.csv")
    assert [r["flag"] for r in rows if r["flag"]] == ["unstable+saturated"] * 2
    assert SUMMARIES["s"]["unstable"] == 2  # the summary line counts them (`tapmp study` prints it)
    (path, fig), = study_figures(out, study).items()
    assert path == out / "sweep.png"
    renderer = fig.canvas.get_renderer()
    heatmaps = [ax for ax in fig.axes if ax.images]
    assert len(heatmaps) == 2
    for ax in heatmaps:
        assert ax.get_xlabel() == "Λv, velocity gain (all motors) [s/m]"
        assert ax.get_ylabel() == "D, error-filter gain (all motors) [1/s]"
        assert ax.get_title().startswith(("tracking MAE (mean of q1-q3) [µm]", "synchronization MAE"))
        labels = [t for t in ax.texts]
        assert len(labels) == 4 and sum("unstable" in t.get_text() for t in labels) == 2
        for t in labels:
            j, i = t.get_position()
            (x0, y0), (x1, y1) = ax.transData.transform([(j - 0.5, i - 0.5), (j + 0.5, i + 0.5)])
            box = t.get_window_extent(renderer)
            assert x0 <= box.x0 and box.x1 <= x1 and y0 <= box.y0 and box.y1 <= y1, t.get_text()
    colorbars = [ax for ax in fig.axes if not ax.images]
    assert all(ax.get_ylabel() == "log10 of the MAE in µm [-]" for ax in colorbars)
    box = fig._suptitle.get_window_extent(renderer)
    assert box.x0 >= 0 and box.x1 <= fig.bbox.x1
    plt.close(fig)
