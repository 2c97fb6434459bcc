"""Encoder quantization pinned directly: every measured position q_i the
plant FMU publishes is a whole number of encoder counts, q_i / encoder_resolution within 1e-6
of an integer, for both FMU families, the default and an odd resolution; the true positions
are not (the quantization is really applied to q_i only)."""

import numpy as np
import pytest
from tests.support.runs import orchestrator_rows, paper_scenario

from tapmp.interface import PLANT_VARS

DEFAULT_RESOLUTION = next(v.start for v in PLANT_VARS if v.name == "encoder_resolution")


@pytest.mark.parametrize("family", ["python", "native"])
@pytest.mark.parametrize("resolution", [None, 3.7e-7])
def test_measured_positions_are_whole_encoder_counts(built, native_built, family, resolution):
    ssp = built["ssp"] if family == "python" else native_built["fmi2"]["ssp"]
    sc = paper_scenario(0.05, *([f"plant.encoder_resolution={resolution}"] if resolution else []))
    res = resolution or DEFAULT_RESOLUTION
    assert res > 0
    names = [f"plant.q{i}" for i in (1, 2, 3)] + [f"plant.q{i}_true" for i in (1, 2, 3)]
    rows = orchestrator_rows(ssp, sc, names, ordering="gauss-seidel")
    counts = rows[:, :3] / res
    assert np.abs(counts - np.round(counts)).max() < 1e-6
    assert np.ptp(np.round(counts), axis=0).min() >= 10       # the motors moved over many counts
    true_counts = rows[:, 3:] / res
    assert np.abs(true_counts - np.round(true_counts)).max() > 0.1   # the true positions are not quantized
    assert np.abs(rows[:, :3] - rows[:, 3:]).max() <= 0.5 * res * (1 + 1e-9)  # rounding, half a count at most
