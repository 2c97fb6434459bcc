"""Reference trajectories: the paper's circle and sinusoid (Section 5.2 and 6.2) and
point-to-point moves, analytic to 2nd order (the feedforward needs the velocity and the
acceleration).

profile = 0 (the paper's motion). XZ plane: a circle of radius R around (X_c, Z_c),
angle theta = 2 pi f_xz t + phase_xz:
    X_d = X_c + R sin(theta),   Z_d = Z_c + R cos(theta)
With the paper's centre (0, -0.01) m and R = 0.01 m and phase 0, it starts at the top
of the circle, the home pose (0, 0), moving in +X at R 2 pi f_xz (25.1 mm/s at 0.4 Hz)
with dZ = 0, i.e. clockwise seen with X to the right and Z up.
B axis: B_d = B_offset + A sin(2 pi f_B t + phase_B), starting at B_offset with rate
A 2 pi f_B (0.219 rad/s for 5 deg at 0.4 Hz).

profile = 1, 2, 3: a move from pose A (X_a, Z_a, B_a) to pose B (X_b, Z_b, B_b) that
starts at t_move [s]; before it the reference rests at A, after it at B (exactly).
* 1, step: the pose jumps from A to B at t_move; velocity and acceleration are 0.
* 2, ramp: every axis moves at constant velocity; the axis that needs longest at its
  v_max sets the duration T = max |B - A| / v_max, the others move at |B - A| / T.
* 3, S-curve: the jerk-limited, time-optimal rest-to-rest profile of each axis (up to
  seven phases of jerk +-j_max or 0; acceleration bounded by a_max, velocity by v_max;
  Biagiotti and Melchiorri, Trajectory Planning for Automatic Machines and Robots,
  Section 3.4), then stretched in time to the duration of the slowest axis, so all
  axes start and stop together (a time stretch by 1/s scales v, a, j by s, s^2, s^3 <=
  their limits). Position, velocity and acceleration are continuous; the jerk is
  piecewise constant within +-j_max.
Limits per axis: v_max_X, v_max_Z [m/s], v_max_B [rad/s]; a_max_* [m/s^2, rad/s^2];
j_max_* [m/s^3, rad/s^3], all > 0 (a step uses none, a ramp only v_max).

:func:`reference` is the C model's (tapmp_reference and tapmp_move_plan in
tapmp/c/tapmp_model.c, what every FMU family runs); :func:`circle_reference`,
:func:`move_plan` and :func:`move_reference` write the same equations readably in Python,
the reference the C is tested against (tests/model/test_cmodel.py).
"""

import math
from functools import lru_cache
from typing import NamedTuple

from . import cmodel
from .models import TRAJECTORY
from .params import DEG

TWO_PI = 2.0 * math.pi
PROFILES = {"circle": 0, "step": 1, "ramp": 2, "s-curve": 3}  # values of the profile parameter
AXES = ("X", "Z", "B")


class TrajectoryParams(NamedTuple):
    """Parameters of the reference; defaults are the paper's simulation (Section 5.2).

    The point-to-point fields (profile to j_max_B) are used when profile > 0 (module doc);
    their defaults are limits the paper's platform follows without saturating its motors.
    """

    X_c: float = 0.0          # circle centre X [m]
    Z_c: float = -0.01        # circle centre Z [m]
    radius: float = 0.01      # circle radius [m]
    f_xz: float = 0.4         # circle frequency [Hz]
    phase_xz: float = 0.0     # circle phase [rad]
    B_amplitude: float = 5.0 * DEG  # B sinusoid amplitude [rad]
    f_B: float = 0.4          # B sinusoid frequency [Hz] (0.18 in the experiment)
    phase_B: float = 0.0      # B sinusoid phase [rad]
    B_offset: float = 0.0     # B sinusoid offset [rad]
    profile: int = 0          # 0 circle/sinusoid, 1 step, 2 ramp, 3 S-curve
    X_a: float = 0.0          # move start pose [m, m, rad]
    Z_a: float = 0.0
    B_a: float = 0.0
    X_b: float = 0.0          # move end pose [m, m, rad]
    Z_b: float = 0.0
    B_b: float = 0.0
    t_move: float = 0.0       # time the move starts [s]
    v_max_X: float = 0.1      # velocity limits [m/s, m/s, rad/s]
    v_max_Z: float = 0.1
    v_max_B: float = 1.0
    a_max_X: float = 1.0      # acceleration limits [m/s^2, m/s^2, rad/s^2]
    a_max_Z: float = 1.0
    a_max_B: float = 10.0
    j_max_X: float = 100.0    # jerk limits [m/s^3, m/s^3, rad/s^3]
    j_max_Z: float = 100.0
    j_max_B: float = 1000.0

    def validated(self) -> "TrajectoryParams":
        """Return self after the range checks of the settings table (ModelInputError names the
        offender; the C model's generated tapmp_trajectory_settings_check, which every FMU runs too)."""
        cmodel.check_settings(TRAJECTORY, self._asdict())
        return self


class AxisPlan(NamedTuple):
    """One axis of a move: from q0 to q1 [m or rad]; sign s of q1 - q0; distance D = |q1 - q0|;
    S-curve phase times Tj (jerk), Ta (acceleration = deceleration), Tv (constant velocity) and
    end T = 2 Ta + Tv [s]; jerk J, peak acceleration alim, peak velocity vlim (a ramp: vlim only)."""

    q0: float
    q1: float
    s: float
    D: float
    Tj: float
    Ta: float
    Tv: float
    T: float
    J: float
    alim: float
    vlim: float


def scurve_times(D: float, V: float, A: float, J: float) -> tuple[float, float, float]:
    """(Tj, Ta, Tv) [s] of the time-optimal rest-to-rest S-curve over the distance D > 0 with the
    limits V, A, J (velocity, acceleration, jerk; Biagiotti and Melchiorri, Section 3.4)."""
    if V * J >= A * A:  # the acceleration limit is reached before the velocity limit
        Tj = A / J
        Ta = Tj + V / A
    else:
        Tj = math.sqrt(V / J)
        Ta = 2.0 * Tj
    vlim = J * Tj * (Ta - Tj)
    Tv = D / vlim - Ta
    if Tv >= 0.0:
        return Tj, Ta, Tv
    # the velocity limit is not reached: no constant-velocity phase
    Tj = A / J
    if D >= 2.0 * A * A * A / (J * J):  # still reaches the acceleration limit
        v = (math.sqrt(A * A * A * A / (J * J) + 4.0 * D * A) - A * A / J) / 2.0
        Ta = Tj + v / A
    else:
        Tj = (D / (2.0 * J)) ** (1.0 / 3.0)
        Ta = 2.0 * Tj
    return Tj, Ta, 0.0


def _limit(tp: TrajectoryParams, kind: str, axis: int) -> float:
    return getattr(tp, f"{kind}_max_{AXES[axis]}")


@lru_cache(maxsize=64)
def move_plan(tp: TrajectoryParams) -> tuple[AxisPlan, AxisPlan, AxisPlan]:
    """The move of ``tp`` (profile 1, 2 or 3) axis by axis (X, Z, B), synchronized: every axis
    ends at the time the slowest one needs (module doc)."""
    q0s = (tp.X_a, tp.Z_a, tp.B_a)
    q1s = (tp.X_b, tp.Z_b, tp.B_b)
    own = []  # per axis: (Tj, Ta, Tv, duration) at its own limits
    for i in range(3):
        D = abs(q1s[i] - q0s[i])
        if D == 0.0:
            own.append((0.0, 0.0, 0.0, 0.0))
        elif tp.profile == 2:
            own.append((0.0, 0.0, D / _limit(tp, "v", i), D / _limit(tp, "v", i)))
        else:
            Tj, Ta, Tv = scurve_times(D, _limit(tp, "v", i), _limit(tp, "a", i), _limit(tp, "j", i))
            own.append((Tj, Ta, Tv, 2.0 * Ta + Tv))
    T = max(o[3] for o in own)
    plans = []
    for i in range(3):
        q0, q1 = q0s[i], q1s[i]
        D = abs(q1 - q0)
        s = 1.0 if q1 >= q0 else -1.0
        if D == 0.0 or tp.profile == 1:
            plans.append(AxisPlan(q0, q1, s, D, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        elif tp.profile == 2:
            plans.append(AxisPlan(q0, q1, s, D, 0.0, 0.0, T, T, 0.0, 0.0, D / T))
        else:
            Tj, Ta, Tv, Ti = own[i]
            lam = Ti / T  # time stretch to the common duration (1 for the slowest axis)
            Tj = Tj / lam
            Ta = Ta / lam
            J = _limit(tp, "j", i) * lam * lam * lam
            alim = J * Tj
            vlim = alim * (Ta - Tj)
            Tv = max(D / vlim - Ta, 0.0)
            plans.append(AxisPlan(q0, q1, s, D, Tj, Ta, Tv, 2.0 * Ta + Tv, J, alim, vlim))
    return tuple(plans)


def move_duration(tp: TrajectoryParams) -> float:
    """How long the move of ``tp`` takes [s] (0 for a step or the circle); it ends at t_move + this."""
    if tp.profile in (0, 1):
        return 0.0
    return max(p.T for p in move_plan(tp))


def _axis(tr: float, p: AxisPlan, profile: int) -> tuple[float, float, float]:
    """(position, velocity, acceleration) of one axis at the time tr [s] since the move started."""
    if tr < 0.0:
        return p.q0, 0.0, 0.0
    if tr >= p.T:
        return p.q1, 0.0, 0.0
    if profile == 2:
        return p.q0 + p.s * p.vlim * tr, p.s * p.vlim, 0.0
    J, Tj, Ta, T, alim, vlim, s = p.J, p.Tj, p.Ta, p.T, p.alim, p.vlim, p.s
    if tr < Tj:
        q, v, a = J * tr * tr * tr / 6.0, J * tr * tr / 2.0, J * tr
        return p.q0 + s * q, s * v, s * a
    if tr < Ta - Tj:
        q = alim / 6.0 * (3.0 * tr * tr - 3.0 * Tj * tr + Tj * Tj)
        return p.q0 + s * q, s * (alim * (tr - Tj / 2.0)), s * alim
    if tr < Ta:
        u = Ta - tr
        q = vlim * Ta / 2.0 - vlim * u + J * u * u * u / 6.0
        return p.q0 + s * q, s * (vlim - J * u * u / 2.0), s * (J * u)
    if tr < Ta + p.Tv:
        q = vlim * Ta / 2.0 + vlim * (tr - Ta)
        return p.q0 + s * q, s * vlim, 0.0
    u = tr - T + Ta  # time into the deceleration
    if u < Tj:
        q = vlim * Ta / 2.0 - vlim * u + J * u * u * u / 6.0
        return p.q1 - s * q, s * (vlim - J * u * u / 2.0), -s * (J * u)
    if u < Ta - Tj:
        q = vlim * Ta / 2.0 - vlim * u + alim / 6.0 * (3.0 * u * u - 3.0 * Tj * u + Tj * Tj)
        return p.q1 - s * q, s * (vlim - alim * (u - Tj / 2.0)), -s * alim
    w = T - tr
    return p.q1 - s * (J * w * w * w / 6.0), s * (J * w * w / 2.0), -s * (J * w)


def move_reference(t: float, tp: TrajectoryParams) -> tuple[float, ...]:
    """The point-to-point reference of ``tp`` at t [s], in the order of ``reference``."""
    tr = t - tp.t_move
    if tp.profile == 1:
        pose = (tp.X_a, tp.Z_a, tp.B_a) if tr < 0.0 else (tp.X_b, tp.Z_b, tp.B_b)
        return (*pose, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    x, z, b = (_axis(tr, p, tp.profile) for p in move_plan(tp))
    return x[0], z[0], b[0], x[1], z[1], b[1], x[2], z[2], b[2]


@lru_cache(maxsize=64)
def _c_trajectory(tp: TrajectoryParams):
    """``tp`` as the C model's tapmp_trajectory (tapmp_trajectory_init: its move planned by
    tapmp_move_plan), from its settings struct filled by name."""
    ffi, lib = cmodel.load()
    c = ffi.new("tapmp_trajectory *")
    lib.tapmp_trajectory_init(c, cmodel.settings(TRAJECTORY, tp._asdict()))
    return c


def reference(t: float, tp: TrajectoryParams) -> tuple[float, ...]:
    """Desired pose and its derivatives at time t [s] (the C model's tapmp_reference).

    Returns (X_d, Z_d, B_d, dX_d, dZ_d, dB_d, ddX_d, ddZ_d, ddB_d) in m, rad and
    their first and second time derivatives.
    """
    ffi, lib = cmodel.load()
    ref = ffi.new("double[9]")
    lib.tapmp_reference(t, _c_trajectory(tp), ref)
    return tuple(ref)


def circle_reference(t: float, tp: TrajectoryParams) -> tuple[float, ...]:
    """The circle and sinusoid of profile 0 at t [s], in the order of :func:`reference`."""
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
