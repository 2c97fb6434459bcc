"""Reference trajectories of the paper (Section 5.2 and 6.2), analytic to 2nd order.

XZ plane: a circle of radius R around (X_c, Z_c), angle theta = 2 pi f_xz t + phase_xz:
    X_d = X_c + R sin(theta),   Z_d = Z_c + R cos(theta)
With the paper's centre (0, -0.01) m and R = 0.01 m and phase 0, it starts at the top
of the circle, the home pose (0, 0), moving in +X at R 2 pi f_xz (25.1 mm/s at 0.4 Hz)
with dZ = 0, i.e. clockwise seen with X to the right and Z up.
B axis: B_d = B_offset + A sin(2 pi f_B t + phase_B), starting at B_offset with rate
A 2 pi f_B (0.219 rad/s for 5 deg at 0.4 Hz).
"""

import math
from typing import NamedTuple

from .errors import ModelInputError, require_finite
from .params import DEG

TWO_PI = 2.0 * math.pi


class TrajectoryParams(NamedTuple):
    """Parameters of the reference; defaults are the paper's simulation (Section 5.2)."""

    X_c: float = 0.0          # circle centre X [m]
    Z_c: float = -0.01        # circle centre Z [m]
    radius: float = 0.01      # circle radius [m]
    f_xz: float = 0.4         # circle frequency [Hz]
    phase_xz: float = 0.0     # circle phase [rad]
    B_amplitude: float = 5.0 * DEG  # B sinusoid amplitude [rad]
    f_B: float = 0.4          # B sinusoid frequency [Hz] (0.18 in the experiment)
    phase_B: float = 0.0      # B sinusoid phase [rad]
    B_offset: float = 0.0     # B sinusoid offset [rad]

    def validated(self) -> "TrajectoryParams":
        """Return self after range checks (ModelInputError names the offender)."""
        for name, v in zip(self._fields, self):
            require_finite(name, v)
        for name in ("radius", "f_xz", "B_amplitude", "f_B"):
            if getattr(self, name) < 0.0:
                raise ModelInputError(name, getattr(self, name), "a finite number >= 0")
        if not abs(self.B_offset) + self.B_amplitude < 0.5 * math.pi:
            raise ModelInputError("B_amplitude", self.B_amplitude,
                                  "|B_offset| + B_amplitude < pi/2 rad (kinematic domain)")
        return self


def reference(t: float, tp: TrajectoryParams) -> tuple[float, ...]:
    """Desired pose and its derivatives at time t [s].

    Returns (X_d, Z_d, B_d, dX_d, dZ_d, dB_d, ddX_d, ddZ_d, ddB_d) in m, rad and
    their first and second time derivatives.
    """
    w = TWO_PI * tp.f_xz
    th = w * t + tp.phase_xz
    s, c = math.sin(th), math.cos(th)
    R = tp.radius
    wb = TWO_PI * tp.f_B
    thb = wb * t + tp.phase_B
    sb, cb = math.sin(thb), math.cos(thb)
    A = tp.B_amplitude
    return (tp.X_c + R * s, tp.Z_c + R * c, tp.B_offset + A * sb,
            R * w * c, -R * w * s, A * wb * cb,
            -R * w * w * s, -R * w * w * c, -A * wb * wb * sb)
