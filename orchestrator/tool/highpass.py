"""The effort metric's filter: a Butterworth high-pass as second-order sections, designed here
and run block by block in C (tapmp/c/tapmp_filter.c, through the C model's library), so that a
run needs neither scipy.signal (about 0.6 s to import) nor a Python loop over its samples.

Design (bilinear transform with the cut-off prewarped, as textbooks give it): the analog
Butterworth low-pass of order n has its poles on the unit circle at exp(j pi (2k + n + 1) / (2n)),
k = 0 .. n - 1; the high-pass at w_c = 2 f_s tan(pi f_c / f_s) [rad/s] maps each pole p to
w_c / p and puts n zeros at s = 0; the bilinear map z = (2 f_s + s) / (2 f_s - s) takes the
zeros to z = 1 and scales the gain so that the response is 1 at the Nyquist frequency.
"""

import cmath
import math

import numpy as np


def butter_highpass_sos(order: int, cutoff_hz: float, fs_hz: float) -> np.ndarray:
    """Second-order sections (order/2 rows of b0, b1, b2, a0, a1, a2; a0 = 1) of the digital
    Butterworth high-pass of even ``order`` with cut-off ``cutoff_hz`` [Hz] at the sample rate
    ``fs_hz`` [Hz] (cutoff below fs / 2); the pole pairs farthest from the unit circle first, the
    overall gain in the first section."""
    if order < 2 or order % 2:
        raise ValueError(f"order = {order!r} is invalid: allowed is an even integer >= 2")
    if not 0.0 < cutoff_hz < fs_hz / 2.0:
        raise ValueError(f"cutoff_hz = {cutoff_hz!r} is invalid: allowed is 0 < cutoff < fs / 2 = {fs_hz / 2.0!r}")
    fs2 = 2.0 * fs_hz
    wc = fs2 * math.tan(math.pi * cutoff_hz / fs_hz)
    # the upper half plane's analog low-pass poles (their conjugates make the pairs)
    analog = [cmath.exp(1j * math.pi * (2 * k + order + 1) / (2 * order)) for k in range(order // 2)]
    digital = []
    gain = 1.0
    for p in analog:
        s = wc / p  # the high-pass pole
        digital.append((fs2 + s) / (fs2 - s))
        gain *= (fs2 * fs2 / ((fs2 - s) * (fs2 - s.conjugate()))).real
    digital.sort(key=abs)  # farthest from the unit circle first
    sos = np.array([[1.0, -2.0, 1.0, 1.0, -2.0 * z.real, abs(z) ** 2] for z in digital])
    sos[0, :3] *= gain
    return sos


class HighPassRms:
    """RMS of several channels after the high-pass ``sos`` (butter_highpass_sos), streamed block
    by block from a zero state: add() blocks of samples, result() the RMS per channel."""

    def __init__(self, sos: np.ndarray, channels: int):
        from tapmp.cmodel import load
        self.ffi, self.lib = load()
        self.sos = np.ascontiguousarray(sos, dtype=float)
        self.channels = channels
        self.state = np.zeros((len(self.sos), channels, 2))
        self.sumsq = np.zeros(channels)
        self.n = 0

    def add(self, x: np.ndarray) -> None:
        """Filter the rows of ``x`` (samples x channels) on from where the last block ended."""
        x = np.ascontiguousarray(x, dtype=float)
        if x.ndim != 2 or x.shape[1] != self.channels:
            raise ValueError(f"x has shape {x.shape}: allowed is (samples, {self.channels})")
        ptr = self.ffi.cast("double *", self.ffi.from_buffer(self.sos))  # read only in C
        self.lib.tapmp_sos_sumsq(len(self.sos), ptr, self.channels,
                                 self.ffi.cast("double *", self.ffi.from_buffer(self.state)),
                                 self.ffi.cast("double *", self.ffi.from_buffer(x)), x.shape[0],
                                 self.ffi.cast("double *", self.ffi.from_buffer(self.sumsq)))
        self.n += x.shape[0]

    def result(self) -> list[float] | None:
        """RMS per channel of everything added so far (None before the first sample)."""
        return np.sqrt(self.sumsq / self.n).tolist() if self.n else None
