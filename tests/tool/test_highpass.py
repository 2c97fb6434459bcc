"""The effort metric's filter (orchestrator.tool.highpass): the Butterworth design against
scipy.signal's, the compiled block-by-block filter against scipy's sosfilt over the whole
signal, and its gain on sines far from the cut-off, derived by hand."""

import numpy as np
import pytest
from scipy import signal

from orchestrator.tool.highpass import HighPassRms, butter_highpass_sos


@pytest.mark.parametrize("order, cutoff, fs", [(4, 100.0, 10_000.0), (4, 100.0, 1_000.0), (2, 50.0, 4_000.0),
                                               (6, 300.0, 10_000.0), (4, 100.0, 250.0)])
def test_the_design_is_scipys_butterworth_highpass(order, cutoff, fs):
    ours = butter_highpass_sos(order, cutoff, fs)
    theirs = signal.butter(order, cutoff, "highpass", fs=fs, output="sos")
    np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-14)


def test_the_block_by_block_filter_is_scipys_sosfilt_over_the_whole_signal():
    rng = np.random.default_rng(7)
    x = rng.normal(size=(5003, 3)) * [1.0, 10.0, 0.1] + np.linspace(0, 5, 5003)[:, None]
    sos = butter_highpass_sos(4, 100.0, 10_000.0)
    f = HighPassRms(sos, 3)
    for a, b in [(0, 1), (1, 1000), (1000, 1001), (1001, 4000), (4000, 5003)]:  # blocks of every size
        f.add(x[a:b])
    y = signal.sosfilt(signal.butter(4, 100.0, "highpass", fs=10_000.0, output="sos"), x, axis=0)
    np.testing.assert_allclose(f.result(), np.sqrt((y ** 2).mean(0)), rtol=1e-11)


def test_a_sine_far_above_the_cutoff_keeps_its_rms_and_one_far_below_loses_it():
    # |H(f)| of an n-th order Butterworth high-pass: 1 / sqrt(1 + (f_c / f)^(2n)) (prewarped: about)
    fs, n = 10_000.0, 20_000
    t = np.arange(n) / fs
    f = HighPassRms(butter_highpass_sos(4, 100.0, fs), 2)
    f.add(np.column_stack([3.0 * np.sin(2 * np.pi * 2_000.0 * t), 3.0 * np.sin(2 * np.pi * 1.0 * t)]))
    high, low = f.result()
    assert high == pytest.approx(3.0 / np.sqrt(2.0), rel=1e-3)  # (100/2000)^8 = 4e-11: the sine passes whole
    # (1/100)^4 = 1e-8 of the amplitude in steady state; what is left is the start's transient
    # (the sine starts at a slope of 19 m/s: about 19 / (2 pi 100) = 0.03 for a few ms)
    assert low < 1e-3


def test_nothing_added_gives_no_rms():
    assert HighPassRms(butter_highpass_sos(4, 100.0, 10_000.0), 3).result() is None


@pytest.mark.parametrize("order, cutoff, fs, message", [
    (3, 100.0, 10_000.0, "order = 3 is invalid: allowed is an even integer >= 2"),
    (4, 5_000.0, 10_000.0, "cutoff_hz = 5000.0 is invalid: allowed is 0 < cutoff < fs / 2 = 5000.0"),
    (4, 0.0, 10_000.0, "cutoff_hz = 0.0 is invalid"),
])
def test_a_design_it_cannot_make_is_refused_naming_the_value(order, cutoff, fs, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)").replace(".", r"\.")):
        butter_highpass_sos(order, cutoff, fs)


def test_samples_of_the_wrong_width_are_refused():
    with pytest.raises(ValueError, match=r"x has shape \(4, 2\): allowed is \(samples, 3\)"):
        HighPassRms(butter_highpass_sos(4, 100.0, 10_000.0), 3).add(np.zeros((4, 2)))
