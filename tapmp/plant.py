"""The TAPMP plant: rigid-body dynamics plus what a real platform adds.

State: pose x = (X, Z, B) [m, m, rad] and rate xd. Inputs: motor force commands
F1..F3 [N], held over a step. Non-idealities, each switched off by a zero:

* force saturation: |F_i| <= force_limit [N] (0 = off);
* friction per motor: c_v_i qd_i + F_c_i tanh(qd_i / v_s) [N]; the tanh smooths the
  Coulomb sign() so RK4 sees a Lipschitz right-hand side (v_s [m/s] is its width);
* mutual pulling between adjacent movers on the common stator, linear: k_pull [N/m]
  times the change of each adjacent gap (q2 - q1, q3 - q2) from its initial value,
  acting equal and opposite on the two movers of a pair. k_pull > 0 is a restoring
  spring (the pair is pulled back to its initial gap), k_pull < 0 a negative
  stiffness (a widening gap is pushed wider, a shrinking one pulled closer);
* magnetic attraction between adjacent movers: F_a = attraction_force (g_a / g)^2
  pulling the two movers of a pair together [N], g = attraction_gap + change of the
  gap (g_a = attraction_gap [m] is the clear gap at the initial pose); its stiffness
  there is -2 attraction_force / attraction_gap (negative: it grows as g shrinks);
* force ripple (cogging) of iron-core linear motors, periodic in the motor position:
  cogging_amplitude sin(2 pi q_i / cogging_pitch + cogging_phase_i) [N] on mover i;
* an external force step on each mover, disturbance_force_i [N] from disturbance_time
  [s] on (held over a step like the command, added after the saturation: it does not go
  through the motor; 0 = off);
* measurement noise: white Gaussian noise of noise_rms [m] added to each measured
  position before quantization, seeded by noise_seed (the same seed gives the same
  sequence in every FMU family; 0 rms = off);
* encoder quantization of the measured positions to encoder_resolution [m]
  (grating ruler, 100 nm in the paper; 0 = off).

docs/disturbances.md gives each term's source or marks it as an assumption.
"""

import math
from typing import NamedTuple

from .dynamics import task_acceleration
from .errors import KinematicDomainError, ModelInputError, require_finite, require_nonnegative
from .kinematics import inverse, joint_velocity, rotation_column, S3
from .params import ModelParams

HALF_PI = 0.5 * math.pi
TWO_PI = 2.0 * math.pi
NOISE_SEED_MAX = 2147483647
_MASK64 = (1 << 64) - 1
_SAMPLE_MAX = float(1 << 53)  # sample counts beyond this are not whole numbers in a double


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
    k_pull: float = 200.0             # adjacent-mover pulling stiffness [N/m] (< 0: negative), 0 = off
    attraction_force: float = 0.0     # adjacent-mover magnetic attraction at the initial gap [N], 0 = off
    attraction_gap: float = 0.01      # clear gap between adjacent movers at the initial pose [m]
    cogging_amplitude: float = 0.0    # force ripple amplitude per motor [N], 0 = off
    cogging_pitch: float = 0.024      # force ripple period in the motor position [m]
    cogging_phase1: float = 0.0       # force ripple phase, motor 1 [rad]
    cogging_phase2: float = 0.0       # force ripple phase, motor 2 [rad]
    cogging_phase3: float = 0.0       # force ripple phase, motor 3 [rad]
    disturbance_force1: float = 0.0   # external force step on mover 1 [N], 0 = off
    disturbance_force2: float = 0.0   # external force step on mover 2 [N], 0 = off
    disturbance_force3: float = 0.0   # external force step on mover 3 [N], 0 = off
    disturbance_time: float = 0.0     # when the force step starts [s]
    noise_rms: float = 0.0            # measurement noise, rms per measured position [m], 0 = off
    substeps: int = 1                 # RK4 steps per communication step
    noise_seed: int = 0               # seed of the measurement noise

    def validated(self) -> "PlantConfig":
        """Return self after checking the ranges (ModelInputError names the offender)."""
        for name in self._fields[:-2]:
            if name == "k_pull" or name.startswith(("cogging_phase", "disturbance_force")):
                require_finite(name, getattr(self, name))
            else:
                require_nonnegative(name, getattr(self, name))
        for name in ("v_s", "attraction_gap", "cogging_pitch"):
            if getattr(self, name) <= 0.0:
                raise ModelInputError(name, getattr(self, name), "a finite number > 0")
        if not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise ModelInputError("substeps", self.substeps, "an integer >= 1")
        if not (isinstance(self.noise_seed, int) and 0 <= self.noise_seed <= NOISE_SEED_MAX):
            raise ModelInputError("noise_seed", self.noise_seed, f"an integer in [0, {NOISE_SEED_MAX}]")
        return self


IDEAL = PlantConfig(encoder_resolution=0.0, c_v1=0.0, c_v2=0.0, c_v3=0.0, F_c1=0.0, F_c2=0.0,
                    F_c3=0.0, force_limit=0.0, k_pull=0.0)


def quantize(q: float, resolution: float) -> float:
    """Round a position [m] to the nearest encoder count of ``resolution`` [m] (0 = exact)."""
    if resolution == 0.0:
        return q
    return resolution * math.floor(q / resolution + 0.5)


def _splitmix64(x: int) -> int:
    """One SplitMix64 output for the 64-bit input x (Steele, Lea, Flood 2014)."""
    x = (x + 0x9E3779B97F4A7C15) & _MASK64
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & _MASK64
    return x ^ (x >> 31)


def noise_sample(seed: int, sample: float, motor: int) -> float:
    """Standard normal number for (seed, sample index, motor 0..2): counter-based, so the
    sequence depends on nothing but these three (Box-Muller on two SplitMix64 outputs; the C
    model computes the same). A sample index outside [0, 2^53) counts as 0."""
    k = int(sample) if 0.0 <= sample < _SAMPLE_MAX else 0
    key = _splitmix64(seed)
    n = (2 * (3 * k + motor)) & _MASK64
    u1 = ((_splitmix64((key + n) & _MASK64) >> 11) + 1) * 2.0 ** -53   # (0, 1]
    u2 = (_splitmix64((key + n + 1) & _MASK64) >> 11) * 2.0 ** -53     # [0, 1)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(TWO_PI * u2)


def _attraction(force: float, gap: float, d12: float, d23: float) -> tuple[float, float]:
    """Attraction force [N] of the pairs (1, 2) and (2, 3): force (gap / g)^2 with the clear
    gap g = gap + d [m] (d: change of the gap from the initial pose); NaN once g <= 0
    (the movers touch), which the step reports as a state leaving the domain."""
    s12 = gap + d12
    s23 = gap + d23
    r12 = gap / s12 if s12 > 0.0 else math.nan
    r23 = gap / s23 if s23 > 0.0 else math.nan
    return force * (r12 * r12), force * (r23 * r23)


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
        self.sample = 0.0  # completed steps: the index of the measurement noise
        q1, q2, q3 = inverse(pose0[0], pose0[1], pose0[2], self.p.L_1)
        self.gap12_0 = q2 - q1
        self.gap23_0 = q3 - q2
        self._rhs = self._make_rhs()

    def joint_forces(self, F1: float, F2: float, F3: float, q, dq) -> tuple[float, float, float]:
        """Net force on each mover [N]: saturated command - friction + pulling + attraction
        + cogging, at true motor positions q [m] and rates dq [m/s]."""
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
        if c.attraction_force:
            a12, a23 = _attraction(c.attraction_force, c.attraction_gap, q[1] - q[0] - self.gap12_0,
                                   q[2] - q[1] - self.gap23_0)
            F1 += a12                                       # pulls mover 1 towards mover 2
            F2 += a23 - a12
            F3 -= a23
        if c.cogging_amplitude:
            A, pitch = c.cogging_amplitude, c.cogging_pitch
            F1 += A * math.sin(TWO_PI * q[0] / pitch + c.cogging_phase1)
            F2 += A * math.sin(TWO_PI * q[1] / pitch + c.cogging_phase2)
            F3 += A * math.sin(TWO_PI * q[2] / pitch + c.cogging_phase3)
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
        if not (math.isfinite(F1) and math.isfinite(F2) and math.isfinite(F3)):
            for name, v in (("F1", F1), ("F2", F2), ("F3", F3)):
                require_finite(name, v, t)
        lim = self.cfg.force_limit
        if lim > 0.0:  # the held command saturates once; joint_forces would redo it per stage
            F1 = min(max(F1, -lim), lim)
            F2 = min(max(F2, -lim), lim)
            F3 = min(max(F3, -lim), lim)
        c = self.cfg
        if (c.disturbance_force1 or c.disturbance_force2 or c.disturbance_force3) and t >= c.disturbance_time:
            F1 += c.disturbance_force1  # an external force: not limited by the motor
            F2 += c.disturbance_force2
            F3 += c.disturbance_force3
        n = self.cfg.substeps
        dt = h / n
        hdt = 0.5 * dt
        dt6 = dt / 6.0
        f = self._rhs
        X, Z, B, dX, dZ, dB = self.state
        for _ in range(n):  # classic RK4, unrolled on scalars (no per-stage lists)
            k1 = f(X, Z, B, dX, dZ, dB, F1, F2, F3)
            k2 = f(X + hdt * k1[0], Z + hdt * k1[1], B + hdt * k1[2],
                   dX + hdt * k1[3], dZ + hdt * k1[4], dB + hdt * k1[5], F1, F2, F3)
            k3 = f(X + hdt * k2[0], Z + hdt * k2[1], B + hdt * k2[2],
                   dX + hdt * k2[3], dZ + hdt * k2[4], dB + hdt * k2[5], F1, F2, F3)
            k4 = f(X + dt * k3[0], Z + dt * k3[1], B + dt * k3[2],
                   dX + dt * k3[3], dZ + dt * k3[4], dB + dt * k3[5], F1, F2, F3)
            X = X + dt6 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
            Z = Z + dt6 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
            B = B + dt6 * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
            dX = dX + dt6 * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3])
            dZ = dZ + dt6 * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4])
            dB = dB + dt6 * (k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5])
        s = [X, Z, B, dX, dZ, dB]
        if not (abs(B) < HALF_PI and math.isfinite(X + Z + dX + dZ + dB)):
            raise KinematicDomainError("plant state (X, Z, B, dX, dZ, dB)", tuple(s),
                                       "finite values with |B| < pi/2 rad", t + h)
        self.state = s
        self.sample += 1.0

    def _make_rhs(self):
        """The right-hand side of :meth:`derivatives` fused into one closure on scalars.

        Profiled: the composed version (inverse, joint_velocity, joint_forces,
        task_acceleration) evaluates cos/sin six times and builds a dozen tuples per
        call, two thirds of the plant's step time. This computes the same expressions
        in the same order, with forces already saturated, so results are bit-identical
        (tests/test_plant_model.py checks it against :meth:`derivatives`).
        """
        p, c = self.p, self.cfg
        L1, m1, m3, mpg = p.L_1, p.m_1, p.m_3, p.m_p * p.g
        M11 = p.m_p + p.m_1 + p.m_2 + p.m_3
        M12 = S3 * (m1 - m3)
        M22 = p.m_p + (m1 + m3) / 3.0
        I_y = p.I_y
        cv1, cv2, cv3, Fc1, Fc2, Fc3, vs = c.c_v1, c.c_v2, c.c_v3, c.F_c1, c.F_c2, c.F_c3, c.v_s
        k_pull, g12, g23 = c.k_pull, self.gap12_0, self.gap23_0
        F_att, gap_att = c.attraction_force, c.attraction_gap
        A_cog, pitch = c.cogging_amplitude, c.cogging_pitch
        ph1, ph2, ph3 = c.cogging_phase1, c.cogging_phase2, c.cogging_phase3
        positions = bool(k_pull or F_att or A_cog)
        cos, sin, tanh = math.cos, math.sin, math.tanh

        def rhs(X, Z, B, dX, dZ, dB, F1, F2, F3):
            cB = cos(B)
            sB = sin(B)
            a1 = L1 * (S3 * cB + sB)                     # rotation_column (Eq. 4)
            a3 = L1 * (S3 * cB - sB)
            dq1 = dX + S3 * dZ + a1 * dB                 # joint_velocity (Eq. 3)
            dq3 = dX - S3 * dZ + a3 * dB
            F1 -= cv1 * dq1 + Fc1 * tanh(dq1 / vs)       # joint_forces: friction
            F2 -= cv2 * dX + Fc2 * tanh(dX / vs)
            F3 -= cv3 * dq3 + Fc3 * tanh(dq3 / vs)
            if positions:
                q1 = X + S3 * Z + L1 * (1.0 - cB + S3 * sB)   # inverse (Eq. 2)
                q3 = X - S3 * Z - L1 * (1.0 - cB - S3 * sB)
                if k_pull:                               # joint_forces: mutual pulling
                    p12 = k_pull * (X - q1 - g12)
                    p23 = k_pull * (q3 - X - g23)
                    F1 += p12
                    F2 += p23 - p12
                    F3 -= p23
                if F_att:                                # joint_forces: attraction
                    a12, a23 = _attraction(F_att, gap_att, X - q1 - g12, q3 - X - g23)
                    F1 += a12
                    F2 += a23 - a12
                    F3 -= a23
                if A_cog:                                # joint_forces: cogging
                    F1 += A_cog * sin(TWO_PI * q1 / pitch + ph1)
                    F2 += A_cog * sin(TWO_PI * X / pitch + ph2)
                    F3 += A_cog * sin(TWO_PI * q3 / pitch + ph3)
            d1 = L1 * (cB - S3 * sB)                     # rotation_column_dB
            d3 = -L1 * (S3 * sB + cB)
            w1 = m1 * d1 * dB * dB                       # coriolis_times (C xd)
            w3 = m3 * d3 * dB * dB
            r1 = F1 + F2 + F3 - (w1 + w3)                # J^T F - C xd - G (Eq. 11, 14)
            r2 = S3 * (F1 - F3) - S3 * (w1 - w3) - mpg
            r3 = a1 * F1 + a3 * F3 - (a1 * w1 + a3 * w3)
            M13 = m1 * a1 + m3 * a3                      # mass_matrix (exact, Eq. 12)
            M23 = S3 * (m1 * a1 - m3 * a3)
            M33 = I_y + m1 * a1 * a1 + m3 * a3 * a3
            A11 = M22 * M33 - M23 * M23                  # solve_sym3 (adjugate)
            A12 = M13 * M23 - M12 * M33
            A13 = M12 * M23 - M13 * M22
            A22 = M11 * M33 - M13 * M13
            A23 = M12 * M13 - M11 * M23
            A33 = M11 * M22 - M12 * M12
            det = M11 * A11 + M12 * A12 + M13 * A13
            return (dX, dZ, dB, (A11 * r1 + A12 * r2 + A13 * r3) / det,
                    (A12 * r1 + A22 * r2 + A23 * r3) / det, (A13 * r1 + A23 * r2 + A33 * r3) / det)
        return rhs

    def joint_positions(self) -> tuple[float, float, float]:
        """True motor positions q [m] (Eq. 2)."""
        X, Z, B = self.state[:3]
        return inverse(X, Z, B, self.p.L_1)

    def measured_positions(self) -> tuple[float, float, float]:
        """Encoder readings of the motor positions [m]: plus the measurement noise of this
        sample (if noise_rms > 0), quantized to the resolution."""
        c = self.cfg
        q = self.joint_positions()
        if c.noise_rms > 0.0:
            q = tuple(x + c.noise_rms * noise_sample(c.noise_seed, self.sample, i) for i, x in enumerate(q))
        return tuple(quantize(x, c.encoder_resolution) for x in q)

    def joint_velocities(self) -> tuple[float, float, float]:
        """True motor velocities [m/s] (Eq. 3)."""
        X, Z, B, dX, dZ, dB = self.state
        return joint_velocity(B, dX, dZ, dB, self.p.L_1)
