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
* a flexible mode of the platform in Z (flex_frequency [Hz], 0 = off): a part flex_mass [kg]
  of the platform's mass m_p on a spring-damper (ratio flex_damping) to the rest of it,
  deflected by z_f [m] from its static equilibrium (docs/native-fmus.md, "The flexible mode");
* measurement noise: white Gaussian noise of noise_rms [m] added to each measured
  position before quantization, seeded by noise_seed (the same seed gives the same
  sequence in every FMU family; 0 rms = off);
* encoder quantization of the measured positions to encoder_resolution [m]
  (grating ruler, 100 nm in the paper; 0 = off).

docs/disturbances.md gives each term's source or marks it as an assumption.
"""

import math
from typing import NamedTuple

from . import cmodel
from .dynamics import task_acceleration
from .errors import KinematicDomainError, require_finite
from .kinematics import inverse, joint_velocity, rotation_column, S3
from .models import PLANT
from .params import ModelParams

TWO_PI = 2.0 * math.pi
NOISE_SEED_MAX = 2147483647


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
    flex_frequency: float = 0.0       # the platform's flexible mode in Z: natural frequency [Hz], 0 = off (rigid)
    # its damping ratio: 2 %, a lightly damped structural mode (bolted steel and aluminium: 1-5 %)
    flex_damping: float = 0.02
    flex_mass: float = 0.5            # its modal mass [kg]: the part of m_p that moves on the mode (< m_p)

    def validated(self) -> "PlantConfig":
        """Return self after checking the ranges of the settings table (ModelInputError names the
        offender): the C model's generated tapmp_plant_settings_check, which every FMU runs too."""
        _settings(self)
        return self


IDEAL = PlantConfig(encoder_resolution=0.0, c_v1=0.0, c_v2=0.0, c_v3=0.0, F_c1=0.0, F_c2=0.0,
                    F_c3=0.0, force_limit=0.0, k_pull=0.0)


def quantize(q: float, resolution: float) -> float:
    """Round a position [m] to the nearest encoder count of ``resolution`` [m] (0 = exact)."""
    return cmodel.load()[1].tapmp_quantize(q, resolution)


def noise_sample(seed: int, sample: float, motor: int) -> float:
    """Standard normal number for (seed in [0, 2^31), sample index, motor 0..2): counter-based,
    so the sequence depends on nothing but these three (Box-Muller on two SplitMix64 outputs,
    Steele, Lea, Flood 2014). A sample index outside [0, 2^53) counts as 0."""
    return cmodel.load()[1].tapmp_noise_sample(seed, sample, motor)


def _attraction(force: float, gap: float, d12: float, d23: float) -> tuple[float, float]:
    """Attraction force [N] of the pairs (1, 2) and (2, 3): force (gap / g)^2 with the clear
    gap g = gap + d [m] (d: change of the gap from the initial pose); NaN once g <= 0
    (the movers touch), which the step reports as a state leaving the domain."""
    s12 = gap + d12
    s23 = gap + d23
    r12 = gap / s12 if s12 > 0.0 else math.nan
    r23 = gap / s23 if s23 > 0.0 else math.nan
    return force * (r12 * r12), force * (r23 * r23)


def _settings(cfg: PlantConfig, **others):
    """The C model's tapmp_plant_settings with ``cfg`` and ``others`` (name -> value) filled by name
    from the settings table, the rest at their defaults; ModelInputError for the first setting
    outside its range (tapmp_plant_settings_check)."""
    return cmodel.check_settings(PLANT, {**others, **cfg._asdict()})


class PlantModel:
    """Integrates the plant over communication steps with fixed-step RK4.

    The step and the outputs are the C model's (tapmp_plant_step, tapmp_plant_outputs in
    tapmp/c/tapmp_model.c, the code the native FMUs run). :meth:`joint_forces` and
    :meth:`derivatives` compose the same equations from kinematics.py and dynamics.py with
    the paper's equation numbers: the readable reference the C is tested against.
    """

    def __init__(self, params: ModelParams, config: PlantConfig,
                 pose0=(0.0, 0.0, 0.0), rate0=(0.0, 0.0, 0.0)):
        given = dict(zip(("X0", "Z0", "B0", "dX0", "dZ0", "dB0"), (*pose0, *rate0)))
        s = _settings(config, **params._asdict(), **given)
        self.p = params
        ffi, self._lib = cmodel.load()
        self._pl = ffi.new("tapmp_plant *")
        self._pl.p = s.p
        self._cfg = config
        self._pl.c = s.c
        self._lib.tapmp_plant_init(self._pl, s.x0.pose, s.x0.rate)
        # a plain list that callers may change in place; it goes into the C struct at each call
        self.state = list(self._pl.s)[:6]  # [X, Z, B, dX, dZ, dB] [m, m, rad, m/s, m/s, rad/s]
        self.flex = [0.0, 0.0]  # the flexible mode's deflection z_f [m] and rate [m/s], at rest while it is off
        self.sample = 0.0  # completed steps: the index of the measurement noise
        self._s_new = ffi.new("double[8]")
        self._out = ffi.new("double[15]")

    @property
    def cfg(self) -> PlantConfig:
        """The plant's settings (PlantConfig); setting them checks their ranges."""
        return self._cfg

    @cfg.setter
    def cfg(self, config: PlantConfig) -> None:
        self._pl.c = _settings(config).c
        self._cfg = config

    @property
    def gap12_0(self) -> float:
        """q2 - q1 at the initial pose [m]: the reference gap of the pulling and the attraction."""
        return self._pl.gap12_0

    @property
    def gap23_0(self) -> float:
        """q3 - q2 at the initial pose [m]."""
        return self._pl.gap23_0

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

    def flex_acceleration(self, z_f: float, dz_f: float) -> float:
        """The flexible mode's spring-damper force per modal mass a_f = w_f^2 z_f + 2 zeta_f w_f dz_f
        [m/s^2] at its deflection z_f [m] and rate dz_f [m/s] (w_f = 2 pi flex_frequency)."""
        w_f = TWO_PI * self.cfg.flex_frequency
        return w_f * w_f * z_f + 2.0 * self.cfg.flex_damping * w_f * dz_f

    def derivatives(self, s, F1: float, F2: float, F3: float):
        """Right-hand side d/dt (X, Z, B, dX, dZ, dB) for held forces F [N]; for a state of 8 with the
        flexible mode's z_f, dz_f, d/dt of all 8: the platform's part m_p - m_f in M_22 with the
        mode's force m_f a_f on Z, and z_f'' = -Z'' - a_f (the mode at rest while it is off)."""
        X, Z, B, dX, dZ, dB = s[:6]
        on = self.cfg.flex_frequency > 0.0
        m_f = self.cfg.flex_mass if on else 0.0
        a_f = self.flex_acceleration(*s[6:]) if len(s) == 8 else 0.0
        L1 = self.p.L_1
        q = inverse(X, Z, B, L1)
        dq = joint_velocity(B, dX, dZ, dB, L1)
        f1, f2, f3 = self.joint_forces(F1, F2, F3, q, dq)
        a1, a3 = rotation_column(B, L1)
        ddX, ddZ, ddB = task_acceleration(B, dB, f1 + f2 + f3, S3 * (f1 - f3), a1 * f1 + a3 * f3, self.p,
                                          m_f, m_f * a_f if on else None)  # J^T F (Eq. 14)
        if len(s) == 6:
            return dX, dZ, dB, ddX, ddZ, ddB
        return dX, dZ, dB, ddX, ddZ, ddB, (s[7] if on else 0.0), (-ddZ - a_f if on else 0.0)

    def step(self, t: float, h: float, F1: float, F2: float, F3: float) -> None:
        """Advance the state from t to t + h [s] under forces F [N] held over the step
        (saturated, plus the force step from disturbance_time on; RK4 with ``substeps``).

        Raises ModelInputError for non-finite forces and KinematicDomainError when the
        pose leaves |B| < pi/2 or the state stops being finite.
        """
        if not (math.isfinite(F1) and math.isfinite(F2) and math.isfinite(F3)):
            for name, v in (("F1", F1), ("F2", F2), ("F3", F3)):
                require_finite(name, v, t)
        s = self._s_new
        self._pl.s = self.state + self.flex
        if not self._lib.tapmp_plant_step(self._pl, t, h, (F1, F2, F3), s):
            raise KinematicDomainError("plant state (X, Z, B, dX, dZ, dB)", tuple(s)[:6],
                                       "finite values with |B| < pi/2 rad", t + h)
        self.state = list(s[0:6])
        self.flex = list(s[6:8])
        self.sample += 1.0

    def outputs(self) -> tuple[float, ...]:
        """The 15 outputs in the FMU's order: measured positions q1..q3 [m] (true + noise of this
        sample, quantized), true positions, motor velocities [m/s], then the state."""
        pl = self._pl
        pl.s, pl.sample = self.state + self.flex, self.sample
        self._lib.tapmp_plant_outputs(pl, self._out)
        return tuple(self._out)

    def joint_positions(self) -> tuple[float, float, float]:
        """True motor positions q [m] (Eq. 2)."""
        return self.outputs()[3:6]

    def measured_positions(self) -> tuple[float, float, float]:
        """Encoder readings of the motor positions [m]: plus the measurement noise of this
        sample (if noise_rms > 0), quantized to the resolution."""
        return self.outputs()[0:3]

    def joint_velocities(self) -> tuple[float, float, float]:
        """True motor velocities [m/s] (Eq. 3)."""
        return self.outputs()[6:9]
