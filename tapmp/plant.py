"""The TAPMP plant: rigid-body dynamics plus what a real platform adds.

State: pose x = (X, Z, B) [m, m, rad] and rate xd. Inputs: motor force commands
F1..F3 [N], held over a step. Non-idealities, each switched off by a zero:

* force saturation: |F_i| <= force_limit [N] (0 = off);
* friction per motor: c_v_i qd_i + F_c_i tanh(qd_i / v_s) [N]; the tanh smooths the
  Coulomb sign() so RK4 sees a Lipschitz right-hand side (v_s [m/s] is its width);
* mutual pulling between adjacent movers on the common stator: a linearized
  attraction k_pull [N/m] times the change of each adjacent gap (q2 - q1, q3 - q2)
  from its initial value, acting equal and opposite on the two movers of a pair;
* encoder quantization of the measured positions to encoder_resolution [m]
  (grating ruler, 100 nm in the paper; 0 = off).
"""

import math
from typing import NamedTuple

from .dynamics import task_acceleration
from .errors import KinematicDomainError, ModelInputError, require_finite, require_nonnegative
from .kinematics import inverse, joint_velocity, rotation_column, S3
from .params import ModelParams

HALF_PI = 0.5 * math.pi


class PlantConfig(NamedTuple):
    """Non-ideality and integration settings of the plant (SI units)."""

    encoder_resolution: float = 1e-7  # [m], 0 = no quantization
    c_v1: float = 5.0                 # viscous friction, mover 1 [N s/m]
    c_v2: float = 5.0                 # viscous friction, mover 2 [N s/m]
    c_v3: float = 5.0                 # viscous friction, mover 3 [N s/m]
    F_c1: float = 2.0                 # Coulomb friction, mover 1 [N]
    F_c2: float = 2.0                 # Coulomb friction, mover 2 [N]
    F_c3: float = 2.0                 # Coulomb friction, mover 3 [N]
    v_s: float = 1e-3                 # Coulomb smoothing velocity [m/s]
    force_limit: float = 600.0        # motor force saturation [N], 0 = off
    k_pull: float = 200.0             # adjacent-mover pulling stiffness [N/m], 0 = off
    substeps: int = 1                 # RK4 steps per communication step

    def validated(self) -> "PlantConfig":
        """Return self after checking the ranges (ModelInputError names the offender)."""
        for name in self._fields[:-1]:
            require_nonnegative(name, getattr(self, name))
        if self.v_s <= 0.0:
            raise ModelInputError("v_s", self.v_s, "a finite number > 0")
        if not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise ModelInputError("substeps", self.substeps, "an integer >= 1")
        return self


IDEAL = PlantConfig(encoder_resolution=0.0, c_v1=0.0, c_v2=0.0, c_v3=0.0, F_c1=0.0, F_c2=0.0,
                    F_c3=0.0, force_limit=0.0, k_pull=0.0)


def quantize(q: float, resolution: float) -> float:
    """Round a position [m] to the nearest encoder count of ``resolution`` [m] (0 = exact)."""
    if resolution == 0.0:
        return q
    return resolution * math.floor(q / resolution + 0.5)


class PlantModel:
    """Integrates the plant over communication steps with fixed-step RK4."""

    def __init__(self, params: ModelParams, config: PlantConfig,
                 pose0=(0.0, 0.0, 0.0), rate0=(0.0, 0.0, 0.0)):
        self.p = params.validated()
        self.cfg = config.validated()
        for name, v in zip(("X0", "Z0", "B0", "dX0", "dZ0", "dB0"), (*pose0, *rate0)):
            require_finite(name, v)
        if not abs(pose0[2]) < HALF_PI:
            raise KinematicDomainError("B0", pose0[2], "|B0| < pi/2 rad")
        self.state = [float(v) for v in (*pose0, *rate0)]
        q1, q2, q3 = inverse(pose0[0], pose0[1], pose0[2], self.p.L_1)
        self.gap12_0 = q2 - q1
        self.gap23_0 = q3 - q2

    def joint_forces(self, F1: float, F2: float, F3: float, q, dq) -> tuple[float, float, float]:
        """Net force on each mover [N]: saturated command - friction + pulling."""
        c = self.cfg
        lim = c.force_limit
        if lim > 0.0:
            F1 = min(max(F1, -lim), lim)
            F2 = min(max(F2, -lim), lim)
            F3 = min(max(F3, -lim), lim)
        vs = c.v_s
        F1 -= c.c_v1 * dq[0] + c.F_c1 * math.tanh(dq[0] / vs)
        F2 -= c.c_v2 * dq[1] + c.F_c2 * math.tanh(dq[1] / vs)
        F3 -= c.c_v3 * dq[2] + c.F_c3 * math.tanh(dq[2] / vs)
        if c.k_pull:
            p12 = c.k_pull * (q[1] - q[0] - self.gap12_0)  # pulls mover 1 towards mover 2
            p23 = c.k_pull * (q[2] - q[1] - self.gap23_0)
            F1 += p12
            F2 += p23 - p12
            F3 -= p23
        return F1, F2, F3

    def derivatives(self, s, F1: float, F2: float, F3: float):
        """Right-hand side d/dt (X, Z, B, dX, dZ, dB) for held forces F [N]."""
        X, Z, B, dX, dZ, dB = s
        L1 = self.p.L_1
        q = inverse(X, Z, B, L1)
        dq = joint_velocity(B, dX, dZ, dB, L1)
        f1, f2, f3 = self.joint_forces(F1, F2, F3, q, dq)
        a1, a3 = rotation_column(B, L1)
        ddX, ddZ, ddB = task_acceleration(
            B, dB, f1 + f2 + f3, S3 * (f1 - f3), a1 * f1 + a3 * f3, self.p)  # J^T F (Eq. 14)
        return dX, dZ, dB, ddX, ddZ, ddB

    def step(self, t: float, h: float, F1: float, F2: float, F3: float) -> None:
        """Advance the state from t to t + h [s] under forces F [N] held over the step.

        Raises ModelInputError for non-finite forces and KinematicDomainError when the
        pose leaves |B| < pi/2 or the state stops being finite.
        """
        for name, v in (("F1", F1), ("F2", F2), ("F3", F3)):
            require_finite(name, v, t)
        n = self.cfg.substeps
        dt = h / n
        s = self.state
        f = self.derivatives
        for _ in range(n):
            k1 = f(s, F1, F2, F3)
            k2 = f([a + 0.5 * dt * b for a, b in zip(s, k1)], F1, F2, F3)
            k3 = f([a + 0.5 * dt * b for a, b in zip(s, k2)], F1, F2, F3)
            k4 = f([a + dt * b for a, b in zip(s, k3)], F1, F2, F3)
            s = [a + dt / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
                 for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4)]
        if not (abs(s[2]) < HALF_PI and all(map(math.isfinite, s))):
            raise KinematicDomainError("plant state (X, Z, B, dX, dZ, dB)", tuple(s),
                                       "finite values with |B| < pi/2 rad", t + h)
        self.state = s

    def joint_positions(self) -> tuple[float, float, float]:
        """True motor positions q [m] (Eq. 2)."""
        X, Z, B = self.state[:3]
        return inverse(X, Z, B, self.p.L_1)

    def measured_positions(self) -> tuple[float, float, float]:
        """Encoder readings of the motor positions [m], quantized to the resolution."""
        r = self.cfg.encoder_resolution
        return tuple(quantize(q, r) for q in self.joint_positions())

    def joint_velocities(self) -> tuple[float, float, float]:
        """True motor velocities [m/s] (Eq. 3)."""
        X, Z, B, dX, dZ, dB = self.state
        return joint_velocity(B, dX, dZ, dB, self.p.L_1)
