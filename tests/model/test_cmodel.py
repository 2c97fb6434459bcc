"""The C model (tapmp/c/tapmp_model.c), which every FMU family and the Python loop run, against
the readable Python reference of the equations (tapmp/kinematics.py, dynamics.py,
PlantModel.derivatives, control.py's laws, trajectory.py) and the reference step and sample
composed here from them.

The C functions are called through the package's own cffi binding (tapmp.cmodel: the
declarations are read from tapmp_model.h, nothing is mirrored by hand) and compared with their
Python counterparts on at least N_STATES random states (numpy default_rng with a fixed seed per
test; realistic ranges: positions +-0.02 m, B +-0.3 rad, rates +-0.5 m/s or rad/s, forces +-300 N,
model parameters the paper's +-20 %, random gains), each output component within RTOL relative:
|C - Python| <= RTOL * max(|Python|, TINY), state by state and component by component.
The closed loops (paper scenario, 2,000 steps, both laws) driven through the C functions
follow tapmp.closed_loop.simulate. The largest relative difference per function is
printed at the end of the module (pytest -s) and kept in MEASURED.
"""

import ctypes
import itertools
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from orchestrator.tool.scenario import load
from tapmp import cmodel, dynamics, kinematics
from tapmp.closed_loop import simulate
from tapmp.control import APDDC, AW_BACK, AW_CLAMP, AW_OFF, PIDDC, SCDC, VELOCITY_DIFFERENCE, VELOCITY_INPUT, Gains
from tapmp.control import ModalGains, sync_deviation
from tests.support.control_reference import apd_command, feedforward, pid_command, scdc_command
from tests.support.control_reference import sync_errors
from tapmp.errors import KinematicDomainError
from tapmp.params import ANTI_WINDUP_TIME, GAIN_NAMES, PAPER_MODEL, ModelParams
from tapmp.plant import IDEAL, PlantConfig, PlantModel
from ctoolchain import CFLAGS, compile_c
from tapmp.trajectory import TrajectoryParams, _c_trajectory, circle_reference, move_plan, move_reference

ROOT = Path(__file__).resolve().parents[2]
MODEL_HEADER = ROOT / "tapmp" / "c" / "tapmp_model.h"
PAPER_SCENARIO = ROOT / "scenarios" / "paper_simulation.toml"

N_STATES = 1000          # random states per function (and per variant)
RTOL = 1e-12             # the project's bound for C against Python, relative
TINY = sys.float_info.min
CLOSED_LOOP_STEPS = 2000
POSITION_TOL = 1e-12     # [m] true motor positions in the closed loop
COMMAND_TOL = 1e-6       # [N] force commands in the closed loop

# function -> {"states": n, "worst": largest relative difference, "identical": all bit-equal}
MEASURED: dict[str, dict] = {}


# --- the binding: tapmp.cmodel's cffi declarations of tapmp_model.h --------------------------

FFI, LIB = cmodel.load()
STRUCTS = ("tapmp_params", "tapmp_plant_config", "tapmp_plant", "tapmp_gains", "tapmp_trajectory",
           "tapmp_controller_state")


def D3(*values):
    return FFI.new("double[3]", values)


def c_params(p: ModelParams):
    return FFI.new("tapmp_params *", tuple(map(float, p)))


def c_config(cfg: PlantConfig):
    return FFI.new("tapmp_plant_config *", (
        cfg.encoder_resolution, (cfg.c_v1, cfg.c_v2, cfg.c_v3), (cfg.F_c1, cfg.F_c2, cfg.F_c3), cfg.v_s,
        cfg.force_limit, cfg.k_pull, cfg.attraction_force, cfg.attraction_gap, cfg.cogging_amplitude,
        cfg.cogging_pitch, (cfg.cogging_phase1, cfg.cogging_phase2, cfg.cogging_phase3),
        (cfg.disturbance_force1, cfg.disturbance_force2, cfg.disturbance_force3), cfg.disturbance_time,
        cfg.noise_rms, cfg.substeps, cfg.noise_seed, cfg.flex_frequency, cfg.flex_damping, cfg.flex_mass))


def c_gains(g: Gains, m: ModalGains = ModalGains()):
    return FFI.new("tapmp_gains *", (*(tuple(values) for values in g), *map(float, m)))


def c_trajectory(tp: TrajectoryParams):
    """tp as tapmp_trajectory, its move planned by the C (tapmp_move_plan)."""
    return _c_trajectory(tp)


def c_controller_state():
    return FFI.new("tapmp_controller_state *")


class Native:
    """The C functions with Python-shaped arguments and results (tuples of floats)."""

    def __init__(self, lib):
        self.lib = lib

    def inverse(self, X, Z, B, L1):
        q = D3()
        self.lib.tapmp_inverse(X, Z, B, L1, q)
        return tuple(q)

    def forward(self, q, L1):
        """(ok, x, arg)"""
        x, arg = D3(), FFI.new("double *")
        ok = self.lib.tapmp_forward(q, L1, x, arg)
        return ok, tuple(x), arg[0]

    def rotation_column(self, B, L1):
        a1, a3 = FFI.new("double *"), FFI.new("double *")
        self.lib.tapmp_rotation_column(B, L1, a1, a3)
        return a1[0], a3[0]

    def joint_velocity(self, B, dX, dZ, dB, L1):
        dq = D3()
        self.lib.tapmp_joint_velocity(B, dX, dZ, dB, L1, dq)
        return tuple(dq)

    def task_velocity(self, B, dq, L1):
        dx = D3()
        self.lib.tapmp_task_velocity(B, dq, L1, dx)
        return tuple(dx)

    def solve_transpose(self, B, v, L1):
        w = D3()
        self.lib.tapmp_solve_transpose(B, v, L1, w)
        return tuple(w)

    def mass_matrix(self, B, p):
        M = FFI.new("double[9]")
        self.lib.tapmp_mass_matrix(B, c_params(p), M)
        return tuple(M)

    def task_acceleration(self, B, dB, u, p):
        xdd = D3()
        self.lib.tapmp_task_acceleration(B, dB, u, c_params(p), xdd)
        return tuple(xdd)

    def generalized_force(self, B, dB, xdd, dBv, p):
        out = D3()
        self.lib.tapmp_generalized_force(B, dB, xdd, dBv, c_params(p), out)
        return tuple(out)

    def quantize(self, q, resolution):
        return self.lib.tapmp_quantize(q, resolution)

    def plant(self, p, cfg, pose0, rate0):
        pl = FFI.new("tapmp_plant *")
        pl.p, pl.c = c_params(p)[0], c_config(cfg)[0]
        self.lib.tapmp_plant_init(pl, pose0, rate0)
        return pl

    def plant_rhs(self, pl, s, F):
        ds = FFI.new("double[8]")
        self.lib.tapmp_plant_rhs(pl, s, F, ds)
        return tuple(ds)

    def plant_step(self, pl, h, F, t=0.0):
        """(ok, new state) of the step from t [s] over h [s]"""
        s_new = FFI.new("double[8]")
        ok = self.lib.tapmp_plant_step(pl, t, h, F, s_new)
        return ok, tuple(s_new)

    def plant_outputs(self, pl):
        out = FFI.new("double[15]")
        self.lib.tapmp_plant_outputs(pl, out)
        return tuple(out)

    def feedforward(self, q, dq, dx_d, ddx_d, p):
        """(ok, u_d, arg)"""
        u_d, arg = D3(), FFI.new("double *")
        ok = self.lib.tapmp_feedforward(q, dq, dx_d, ddx_d, c_params(p), u_d, arg)
        return ok, tuple(u_d), arg[0]

    def scdc_command(self, e, de, c, integral_c, u_d, g):
        u = D3()
        self.lib.tapmp_scdc_command(e, de, c, integral_c, u_d, c_gains(g), u)
        return tuple(u)

    def pid_command(self, e, de, integral_e, u_d, g, m):
        u = D3()
        self.lib.tapmp_pid_command(e, de, integral_e, u_d, c_gains(g, m), u)
        return tuple(u)

    def apd_command(self, e, de, u_d, g):
        u = D3()
        self.lib.tapmp_apd_command(e, de, u_d, c_gains(g), u)
        return tuple(u)

    def controller_sample(self, p, g, law, velocity_source, force_limit, st, h, ref, q, dq_in,
                          advance, next_st, anti_windup=AW_OFF, anti_windup_time=ANTI_WINDUP_TIME):
        """(ok, (F, u, e, e_s) as 12 values, arg); the new state goes to next_st."""
        out, arg = FFI.new("double[12]"), FFI.new("double *")
        ok = self.lib.tapmp_controller_sample(p, g, law, velocity_source, force_limit, anti_windup,
                                              anti_windup_time, st, h, tuple(ref),
                                              tuple(q), tuple(dq_in), int(advance), out, next_st, arg)
        return ok, tuple(out), arg[0]

    def reference(self, t, tp):
        ref = FFI.new("double[9]")
        self.lib.tapmp_reference(t, tp, ref)
        return tuple(ref)


def compile_shared(sources, output: Path) -> ctypes.CDLL:
    """A shared library by the project's toolchain with the native FMUs' CFLAGS and -lm (only
    -fvisibility=hidden left out, so that its symbols can be read)."""
    flags = [f for f in CFLAGS if not f.startswith("-fvisibility")]
    compile_c(sources, output, flags=flags, includes=[MODEL_HEADER.parent], libs=["m"])
    return ctypes.CDLL(str(output))


@pytest.fixture(scope="session")
def native_lib():
    """The C model as the package loads it (tapmp.cmodel)."""
    return LIB


@pytest.fixture(scope="session")
def native(native_lib) -> Native:
    return Native(native_lib)


@pytest.fixture(scope="module", autouse=True)
def report_measured():
    """Print the largest relative difference per function once the module is done (pytest -s)."""
    yield
    if MEASURED:
        print("\nC model against Python: largest relative difference per function")
        for name, m in MEASURED.items():
            kind = "bit-identical" if m["identical"] else f"max diff {m['worst']:.3g}"
            print(f"  {name:<58} {m['states']:>6} states  {kind}")


# --- comparison -----------------------------------------------------------------------------

class Agreement:
    """Compares the C results with the Python results state by state and counts the states.

    check() fails at the first state where a component differs by more than
    RTOL * max(|Python|, TINY); done() fails if fewer than the required states were compared.
    """

    def __init__(self, function: str, record: bool = True):
        self.function = function
        self.record = record
        self.states = 0
        self.worst = 0.0
        self.identical = True

    def check(self, c_values, py_values, inputs) -> None:
        c = np.asarray(c_values, dtype=float).ravel()
        py = np.asarray(py_values, dtype=float).ravel()
        assert c.shape == py.shape, f"{self.function}: C gives {c.size} values, Python {py.size}"
        diff = np.abs(c - py)
        scale = np.maximum(np.abs(py), TINY)
        ok = diff <= RTOL * scale  # NaN compares False: a NaN on one side fails
        rel = diff / scale
        self.states += 1
        self.identical = self.identical and bool(np.array_equal(c, py))
        assert ok.all(), (
            f"{self.function}: C and Python disagree beyond {RTOL:g} relative in component(s) "
            f"{np.flatnonzero(~ok).tolist()} for inputs {inputs!r}:\n  C      {c.tolist()!r}\n"
            f"  Python {py.tolist()!r}\n  relative difference {rel.tolist()!r}")
        self.worst = max(self.worst, float(rel.max()))

    def done(self, minimum: int = N_STATES) -> None:
        assert self.states >= minimum, f"{self.function}: only {self.states} states compared, need {minimum}"
        if self.record:
            m = MEASURED.setdefault(self.function, {"states": 0, "worst": 0.0, "identical": True})
            m["states"] += self.states
            m["worst"] = max(m["worst"], self.worst)
            m["identical"] = m["identical"] and self.identical


# --- random states over realistic ranges ------------------------------------------------------

def u(rng, lo, hi, n=None):
    return float(rng.uniform(lo, hi)) if n is None else tuple(float(v) for v in rng.uniform(lo, hi, n))


def random_params(rng) -> ModelParams:
    """The paper's parameters, each scaled by a factor in [0.8, 1.2]."""
    return ModelParams(*(v * u(rng, 0.8, 1.2) for v in PAPER_MODEL))


def random_pose(rng):
    return u(rng, -0.02, 0.02), u(rng, -0.02, 0.02), u(rng, -0.3, 0.3)


def random_rates(rng):
    return u(rng, -0.5, 0.5, 3)


def random_forces(rng):
    return u(rng, -300.0, 300.0, 3)


def random_accelerations(rng):
    return u(rng, -5.0, 5.0, 3)


def random_gains(rng) -> Gains:
    """Log-uniform per motor over ranges spanning the presets (default, Eq. 40-43)."""
    ranges = {"Lambda_p": (1.0, 1e4), "Lambda_v": (0.1, 200.0), "b": (1e-4, 60.0), "D": (10.0, 1e3),
              "K_T": (1e-5, 1e-4)}
    return Gains(*(tuple(float(math.exp(rng.uniform(math.log(lo), math.log(hi)))) for _ in range(3))
                   for lo, hi in (ranges[n] for n in GAIN_NAMES)))


def random_modal_gains(rng) -> ModalGains:
    """Log-uniform over ranges spanning the modal images of the presets; a gain is 0 one time in five."""
    ranges = {"kp": (1.0, 1e5), "kv": (0.1, 200.0), "ki": (1.0, 1e6)}
    return ModalGains(*(0.0 if rng.random() < 0.2 else float(math.exp(rng.uniform(*map(math.log, ranges[n[:2]]))))
                        for n in ModalGains._fields))


def random_trajectory(rng) -> TrajectoryParams:
    return TrajectoryParams(u(rng, -0.01, 0.01), u(rng, -0.02, 0.0), u(rng, 0.0, 0.02), u(rng, 0.0, 2.0),
                            u(rng, -math.pi, math.pi), u(rng, 0.0, 0.2), u(rng, 0.0, 2.0),
                            u(rng, -math.pi, math.pi), u(rng, -0.1, 0.1))


# Plant non-idealities: each switched on alone, all together, or none (paper values +-20 %;
# attraction and cogging at random levels; "repulsion" is k_pull < 0, a negative stiffness).
PLANT_VARIANTS = ("ideal", "friction", "pulling", "repulsion", "attraction", "cogging", "force_limit", "flex", "all")


def random_config(rng, variant: str, substeps: int = 1) -> PlantConfig:
    friction = variant in ("friction", "all")
    pulling = variant in ("pulling", "all")
    limited = variant in ("force_limit", "all")
    attracting = variant in ("attraction", "all")
    cogging = variant in ("cogging", "all")
    flex = variant in ("flex", "all")
    d = PlantConfig()
    k_pull = d.k_pull * u(rng, 0.8, 1.2) if pulling else (-u(rng, 100.0, 5000.0) if variant == "repulsion" else 0.0)
    return IDEAL._replace(
        encoder_resolution=d.encoder_resolution * u(rng, 0.8, 1.2) if variant == "all" else 0.0,
        c_v1=d.c_v1 * u(rng, 0.8, 1.2) if friction else 0.0,
        c_v2=d.c_v2 * u(rng, 0.8, 1.2) if friction else 0.0,
        c_v3=d.c_v3 * u(rng, 0.8, 1.2) if friction else 0.0,
        F_c1=d.F_c1 * u(rng, 0.8, 1.2) if friction else 0.0,
        F_c2=d.F_c2 * u(rng, 0.8, 1.2) if friction else 0.0,
        F_c3=d.F_c3 * u(rng, 0.8, 1.2) if friction else 0.0,
        v_s=d.v_s * u(rng, 0.8, 1.2),
        force_limit=u(rng, 50.0, 600.0) if limited else 0.0,  # below 300 N it saturates often
        k_pull=k_pull,
        attraction_force=u(rng, 1.0, 50.0) if attracting else 0.0,
        attraction_gap=u(rng, 0.1, 0.3),  # above the random gap changes (|q| < 0.05 m): no contact
        cogging_amplitude=u(rng, 0.5, 10.0) if cogging else 0.0,
        cogging_pitch=u(rng, 0.005, 0.05),
        cogging_phase1=u(rng, -math.pi, math.pi), cogging_phase2=u(rng, -math.pi, math.pi),
        cogging_phase3=u(rng, -math.pi, math.pi),
        disturbance_force1=u(rng, -20.0, 20.0) if variant == "all" else 0.0,
        disturbance_force2=u(rng, -20.0, 20.0) if variant == "all" else 0.0,
        disturbance_force3=u(rng, -20.0, 20.0) if variant == "all" else 0.0,
        noise_rms=u(rng, 1e-8, 1e-6) if variant == "all" else 0.0,
        noise_seed=int(rng.integers(0, 2**31)),
        # the modal mass below 0.8 m_p of the paper: random_params scales m_p by at least 0.8
        flex_frequency=u(rng, 50.0, 2000.0) if flex else 0.0, flex_damping=u(rng, 0.0, 0.3),
        flex_mass=u(rng, 0.01, 0.8) * PAPER_MODEL.m_p,
        substeps=substeps)


def saturated(F, lim):
    return tuple(min(max(f, -lim), lim) for f in F) if lim > 0.0 else tuple(F)


# --- the Python references of what the C composes: step, outputs, noise, controller sample ----

def reference_step(plant: PlantModel, t: float, h: float, F):
    """(ok, new state): PlantModel.step written with the composed PlantModel.derivatives, the
    state left alone. The held command saturates once, the force step is added after it (not
    through the motor), then classic RK4 with ``substeps`` steps."""
    c = plant.cfg
    F = list(saturated(F, c.force_limit))
    d = (c.disturbance_force1, c.disturbance_force2, c.disturbance_force3)
    if any(d) and t >= c.disturbance_time:
        F = [f + x for f, x in zip(F, d)]
    unsaturated = PlantModel(plant.p, c._replace(force_limit=0.0))  # F is saturated already
    unsaturated._pl.gap12_0, unsaturated._pl.gap23_0 = plant.gap12_0, plant.gap23_0
    f = unsaturated.derivatives
    n = c.substeps
    dt = h / n
    s = plant.state + plant.flex
    for _ in range(n):
        k1 = f(s, *F)
        k2 = f([x + 0.5 * dt * k for x, k in zip(s, k1)], *F)
        k3 = f([x + 0.5 * dt * k for x, k in zip(s, k2)], *F)
        k4 = f([x + dt * k for x, k in zip(s, k3)], *F)
        s = [x + dt / 6.0 * (a + 2.0 * b + 2.0 * cc + e) for x, a, b, cc, e in zip(s, k1, k2, k3, k4)]
    return int(abs(s[2]) < 0.5 * math.pi and math.isfinite(s[0] + s[1] + s[3] + s[4] + s[5] + s[6] + s[7])), tuple(s)


def reference_quantize(q: float, resolution: float) -> float:
    return q if resolution == 0.0 else resolution * math.floor(q / resolution + 0.5)


_MASK64 = (1 << 64) - 1


def _splitmix64(x: int) -> int:
    x = (x + 0x9E3779B97F4A7C15) & _MASK64
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & _MASK64
    return x ^ (x >> 31)


def reference_noise_sample(seed: int, sample: float, motor: int) -> float:
    """Box-Muller on two SplitMix64 outputs of key = splitmix64(seed) + 2 (3 k + motor)."""
    k = int(sample) if 0.0 <= sample < float(1 << 53) else 0
    key = _splitmix64(seed)
    n = (2 * (3 * k + motor)) & _MASK64
    u1 = ((_splitmix64((key + n) & _MASK64) >> 11) + 1) * 2.0 ** -53
    u2 = (_splitmix64((key + n + 1) & _MASK64) >> 11) * 2.0 ** -53
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


def reference_outputs(plant: PlantModel):
    """The 15 plant outputs from kinematics.py and the reference noise and quantization."""
    X, Z, B, dX, dZ, dB = plant.state
    c = plant.cfg
    q = kinematics.inverse(X, Z, B, plant.p.L_1)
    noisy = [x + c.noise_rms * reference_noise_sample(c.noise_seed, plant.sample, i) if c.noise_rms > 0.0 else x
             for i, x in enumerate(q)]
    return (*(reference_quantize(x, c.encoder_resolution) for x in noisy), *q,
            *kinematics.joint_velocity(B, dX, dZ, dB, plant.p.L_1), *plant.state)


class ReferenceController:
    """ControllerModel.sample composed from control.py's laws (Eq. 15-26, 38), with its state, and the
    anti-windup written out from its definition (tapmp_model.h, TAPMP_AW_*)."""

    def __init__(self, p, g, law, velocity_source, force_limit=0.0, modal=ModalGains(), anti_windup=AW_OFF,
                 anti_windup_time=ANTI_WINDUP_TIME):
        self.p, self.g, self.law, self.velocity_source, self.force_limit, self.modal = (
            p, g, law, velocity_source, force_limit, modal)
        self.anti_windup, self.anti_windup_time = anti_windup, anti_windup_time
        self.integral = [0.0, 0.0, 0.0]
        self.q_prev = None
        self.unwound = 0  # samples on which the anti-windup changed the integral

    def integral_gain(self, i):
        """Motor i's own integral gain: Lambda_v D b (SC-DC); the diagonal of ki_c Pi_c + ki_d Pi_d (PID-DC),
        Pi_c = 1 1^T / 3, Pi_d = I - Pi_c."""
        g, m = self.g, self.modal
        return g.Lambda_v[i] * g.D[i] * g.b[i] if self.law == SCDC else m.ki_c / 3.0 + m.ki_d * 2.0 / 3.0

    def unwind(self, candidate, x, uu, h, command):
        """(integral, u) after the anti-windup: clamping keeps the old integral of a motor beyond the limit
        whose increment h x drives it further out (SC-DC: of all three, u recomputed), back-calculation adds
        (1 - exp(-h/T_t)) (F_sat - F) K_T / k_i to a motor beyond the limit (SC-DC: less the corrections'
        mean, so the integrals' sum stays; expm1: the C model's rounding)."""
        lim, integral = self.force_limit, list(candidate)
        held, dI = False, [0.0, 0.0, 0.0]
        for i in range(3):
            F, k = uu[i] / self.g.K_T[i], self.integral_gain(i)
            if abs(F) <= lim or k <= 0.0:
                continue
            if self.anti_windup == AW_CLAMP and x[i] * F > 0.0:
                integral[i], held = self.integral[i], True
            elif self.anti_windup == AW_BACK:
                dI[i] = -math.expm1(-h / self.anti_windup_time) * (min(max(F, -lim), lim) - F) * self.g.K_T[i] / k
        if self.law == SCDC:
            mean = (dI[0] + dI[1] + dI[2]) / 3.0
            integral = list(self.integral) if held else [integral[i] + (dI[i] - mean) for i in range(3)]
        else:
            integral = [integral[i] + dI[i] for i in range(3)]
        if integral != list(candidate):
            self.unwound += 1
            if self.anti_windup == AW_CLAMP:
                uu = command(integral)
        return integral, uu

    def sample(self, t, h, ref, q, dq_in, advance=True):
        L1 = self.p.L_1
        q_d = kinematics.inverse(ref[0], ref[1], ref[2], L1)
        dq_d = kinematics.joint_velocity(ref[2], ref[3], ref[4], ref[5], L1)
        if self.velocity_source == VELOCITY_DIFFERENCE and self.q_prev is not None and advance:
            dq = tuple((q[i] - self.q_prev[i]) / h for i in range(3))
        else:
            dq = dq_in
        e = tuple(q_d[i] - q[i] for i in range(3))
        de = tuple(dq_d[i] - dq[i] for i in range(3))
        e_s = sync_errors(*e)
        u_d = feedforward(q, dq, ref[3:6], ref[6:9], self.p)
        integral = self.integral
        if self.law == SCDC:
            c = x = sync_deviation(*e_s)
            if advance:
                integral = [integral[i] + h * c[i] for i in range(3)]
            command = lambda integral: scdc_command(e, de, c, integral, u_d, self.g)  # noqa: E731
        elif self.law == PIDDC:
            x = e
            if advance:
                integral = [integral[i] + h * e[i] for i in range(3)]
            command = lambda integral: pid_command(e, de, integral, u_d, self.modal, self.g.K_T)  # noqa: E731
        else:
            command = lambda integral: apd_command(e, de, u_d, self.g)  # noqa: E731
        uu = command(integral)
        if advance and self.anti_windup != AW_OFF and self.force_limit > 0.0 and self.law != APDDC:
            integral, uu = self.unwind(integral, x, uu, h, command)
        if advance:
            self.integral, self.q_prev = integral, tuple(q)
        F = saturated([uu[i] / self.g.K_T[i] for i in range(3)], self.force_limit)
        return F, tuple(uu), e, e_s


def domain_violating_q(rng, L1):
    """Motor positions whose arcsine argument of Eq. 1 has |arg| >= 1; one time in ten it is
    meant to be exactly 1, which round-off puts on either side of the bound."""
    q1, q3 = u(rng, -0.02, 0.02), u(rng, -0.02, 0.02)
    a = float(rng.choice([-1.0, 1.0])) * (1.0 if rng.random() < 0.1 else u(rng, 1.0, 3.0))
    return q1, (a * 2.0 * L1 / kinematics.SQRT3 + q1 + q3) / 2.0, q3


# --- the library ------------------------------------------------------------------------------

def test_the_c_model_is_compiled_like_the_fmus_without_fast_math_or_fused_multiply_add():
    assert "-ffp-contract=off" in CFLAGS
    assert not any("fast-math" in f or f.startswith("-Ofast") for f in CFLAGS)


def test_cffi_structures_have_the_layout_the_c_compiler_gives_them(tmp_path):
    """sizeof and every field offset of the header's structs as the C compiler sees them equal
    cffi's (ABI mode computes the layout from the declarations read from the header)."""
    probe = tmp_path / "layout_probe.c"
    entries, expected = [], []
    for cname in STRUCTS:
        entries.append(f"sizeof({cname})")
        expected.append(FFI.sizeof(cname))
        for field, _ in FFI.typeof(cname).fields:
            entries.append(f"offsetof({cname}, {field})")
            expected.append(FFI.offsetof(cname, field))
    probe.write_text('#include <stddef.h>\n#include "tapmp_model.h"\n'
                     f"const size_t tapmp_layout[] = {{{', '.join(entries)}}};\n")
    lib = compile_shared([probe], tmp_path / "liblayout.so")
    assert list((ctypes.c_size_t * len(entries)).in_dll(lib, "tapmp_layout")) == expected


def test_every_function_of_the_header_is_exported_and_declared_to_cffi(native_lib):
    declared = re.findall(r"^(?:TAPMP_LINKAGE\s+)?(?:void|int|double)\s+(tapmp_\w+)\(", MODEL_HEADER.read_text(), re.M)
    assert len(declared) >= 20
    for name in declared:
        assert FFI.typeof(getattr(native_lib, name)).kind == "function", name


# --- kinematics -------------------------------------------------------------------------------

def test_inverse_kinematics_matches_python(native):
    rng, check = np.random.default_rng(101), Agreement("tapmp_inverse")
    for _ in range(N_STATES):
        X, Z, B = random_pose(rng)
        L1 = random_params(rng).L_1
        check.check(native.inverse(X, Z, B, L1), kinematics.inverse(X, Z, B, L1), (X, Z, B, L1))
    check.done()


def test_forward_kinematics_matches_python_inside_the_domain(native):
    rng, check = np.random.default_rng(102), Agreement("tapmp_forward")
    for _ in range(N_STATES):
        L1 = random_params(rng).L_1
        q = kinematics.inverse(*random_pose(rng), L1)
        ok, x, _ = native.forward(q, L1)
        assert ok == 1, (q, L1)
        check.check(x, kinematics.forward(*q, L1), (q, L1))
    check.done()


def test_forward_kinematics_refuses_the_same_positions_with_the_same_arcsine_argument(native):
    rng, check = np.random.default_rng(103), Agreement("tapmp_forward (domain error arg)")
    inside = Agreement("tapmp_forward", record=False)
    while check.states < N_STATES:
        L1 = random_params(rng).L_1
        q = domain_violating_q(rng, L1)
        ok, x, arg = native.forward(q, L1)
        try:
            py = kinematics.forward(*q, L1)
        except KinematicDomainError as err:
            assert ok == 0, (q, L1)
            check.check(arg, err.value, (q, L1))
        else:  # |arg| = 1 - round-off at the bound: inside for both
            assert ok == 1, (q, L1, arg)
            inside.check(x, py, (q, L1))
    check.done()
    assert inside.states > 0  # the bound itself was tried
    ok, _, arg = native.forward((0.0, math.nan, 0.0), 0.09)  # NaN is outside the domain too
    assert ok == 0 and math.isnan(arg)
    with pytest.raises(KinematicDomainError):
        kinematics.forward(0.0, math.nan, 0.0, 0.09)


def test_rotation_column_matches_python(native):
    rng, check = np.random.default_rng(104), Agreement("tapmp_rotation_column")
    for _ in range(N_STATES):
        B, L1 = u(rng, -0.3, 0.3), random_params(rng).L_1
        check.check(native.rotation_column(B, L1), kinematics.rotation_column(B, L1), (B, L1))
    check.done()


def test_joint_velocity_matches_python(native):
    rng, check = np.random.default_rng(105), Agreement("tapmp_joint_velocity")
    for _ in range(N_STATES):
        B, (dX, dZ, dB), L1 = u(rng, -0.3, 0.3), random_rates(rng), random_params(rng).L_1
        check.check(native.joint_velocity(B, dX, dZ, dB, L1), kinematics.joint_velocity(B, dX, dZ, dB, L1),
                    (B, dX, dZ, dB, L1))
    check.done()


def test_task_velocity_matches_python(native):
    rng, check = np.random.default_rng(106), Agreement("tapmp_task_velocity")
    for _ in range(N_STATES):
        B, dq, L1 = u(rng, -0.3, 0.3), random_rates(rng), random_params(rng).L_1
        check.check(native.task_velocity(B, dq, L1), kinematics.task_velocity(B, *dq, L1), (B, dq, L1))
    check.done()


def test_solve_transpose_matches_python(native):
    rng, check = np.random.default_rng(107), Agreement("tapmp_solve_transpose")
    for _ in range(N_STATES):
        B, L1 = u(rng, -0.3, 0.3), random_params(rng).L_1
        v = (u(rng, -300.0, 300.0), u(rng, -300.0, 300.0), u(rng, -30.0, 30.0))  # N, N, N m
        check.check(native.solve_transpose(B, v, L1), kinematics.solve_transpose(B, *v, L1), (B, v, L1))
    check.done()


# --- dynamics ---------------------------------------------------------------------------------

def test_mass_matrix_matches_python(native):
    rng, check = np.random.default_rng(201), Agreement("tapmp_mass_matrix")
    for _ in range(N_STATES):
        B, p = u(rng, -0.3, 0.3), random_params(rng)
        check.check(native.mass_matrix(B, p), dynamics.mass_matrix(B, p), (B, p))
    check.done()


def test_task_acceleration_matches_python(native):
    rng, check = np.random.default_rng(202), Agreement("tapmp_task_acceleration")
    for _ in range(N_STATES):
        B, dB, p = u(rng, -0.3, 0.3), u(rng, -0.5, 0.5), random_params(rng)
        uu = (u(rng, -300.0, 300.0), u(rng, -300.0, 300.0), u(rng, -30.0, 30.0))
        check.check(native.task_acceleration(B, dB, uu, p), dynamics.task_acceleration(B, dB, *uu, p),
                    (B, dB, uu, p))
    check.done()


def test_generalized_force_matches_python(native):
    rng, check = np.random.default_rng(203), Agreement("tapmp_generalized_force")
    for _ in range(N_STATES):
        B, dB, dBv, p = u(rng, -0.3, 0.3), u(rng, -0.5, 0.5), u(rng, -0.5, 0.5), random_params(rng)
        xdd = random_accelerations(rng)
        check.check(native.generalized_force(B, dB, xdd, dBv, p), dynamics.generalized_force(B, dB, *xdd, dBv, p),
                    (B, dB, xdd, dBv, p))
    check.done()


# --- plant ------------------------------------------------------------------------------------

def test_quantize_matches_python_including_ties_and_no_quantization(native):
    rng, check = np.random.default_rng(301), Agreement("tapmp_quantize")
    for i in range(N_STATES):
        r = [0.0, 1e-7 * u(rng, 0.8, 1.2), 1e-9, 1e-6][i % 4]
        q = u(rng, -0.02, 0.02)
        if r and i % 3 == 0:
            q = (int(rng.integers(-200000, 200000)) + 0.5) * r  # half a count: rounds up in both
        check.check(native.quantize(q, r), reference_quantize(q, r), (q, r))
    check.done()


def test_plant_init_sets_the_state_and_reference_gaps_like_python(native):
    rng, check = np.random.default_rng(302), Agreement("tapmp_plant_init")
    for _ in range(N_STATES):
        p, cfg = random_params(rng), random_config(rng, "all")
        pose0, rate0 = random_pose(rng), random_rates(rng)
        pl, q = native.plant(p, cfg, pose0, rate0), kinematics.inverse(*pose0, p.L_1)
        check.check((*pl.s, pl.gap12_0, pl.gap23_0), (*pose0, *rate0, 0.0, 0.0, q[1] - q[0], q[2] - q[1]),
                    (p, cfg, pose0, rate0))
    check.done()


def random_plant_case(rng, native, variant, substeps=1):
    """A Python plant and its C twin, both initialized at one random pose (the reference gaps)
    and then put at another random state s (with the flexible mode's z_f, dz_f: 8 values), so pulling
    acts; returns (plant, pl, s)."""
    p, cfg = random_params(rng), random_config(rng, variant, substeps)
    pose0, rate0 = random_pose(rng), random_rates(rng)
    plant, pl = PlantModel(p, cfg, pose0, rate0), native.plant(p, cfg, pose0, rate0)
    s = (*random_pose(rng), *random_rates(rng), u(rng, -1e-5, 1e-5), u(rng, -1e-2, 1e-2))
    plant.state, plant.flex = list(s[:6]), list(s[6:])
    pl.s[0:8] = s
    return plant, pl, s


@pytest.mark.parametrize("variant", PLANT_VARIANTS)
def test_plant_rhs_matches_the_composed_python_derivatives(native, variant):
    """PlantModel.derivatives saturates the forces itself; tapmp_plant_rhs gets them saturated."""
    rng, check = np.random.default_rng(303 + PLANT_VARIANTS.index(variant)), Agreement("tapmp_plant_rhs vs derivatives")
    for _ in range(N_STATES):
        plant, pl, s = random_plant_case(rng, native, variant)
        F = random_forces(rng)
        check.check(native.plant_rhs(pl, s, saturated(F, plant.cfg.force_limit)), plant.derivatives(s, *F),
                    (plant.p, plant.cfg, plant.gap12_0, plant.gap23_0, s, F))
    check.done()


# every variant and substep count in the full suite; the fast subset keeps two (about 2 s each)
FAST_PLANT_STEPS = (("ideal", 1), ("all", 3))


@pytest.mark.parametrize("variant,substeps", [
    pytest.param(v, n, marks=() if (v, n) in FAST_PLANT_STEPS else pytest.mark.slow)
    for n in (1, 3) for v in PLANT_VARIANTS])
def test_plant_step_matches_python_rk4(native, variant, substeps):
    """One communication step from a random state; the forces are saturated inside the step."""
    seed = 323 + 10 * substeps + PLANT_VARIANTS.index(variant)
    rng, check = np.random.default_rng(seed), Agreement("tapmp_plant_step")
    saturating = 0
    for _ in range(N_STATES):
        plant, pl, s = random_plant_case(rng, native, variant, substeps)
        h, F = u(rng, 5e-5, 1e-3), random_forces(rng)
        saturating += saturated(F, plant.cfg.force_limit) != F
        ok, s_new = native.plant_step(pl, h, F)
        ok_py, s_py = reference_step(plant, 0.0, h, F)
        assert ok == ok_py == 1, (plant.p, plant.cfg, s, h, F)
        assert tuple(pl.s) == s  # tapmp_plant_step leaves the plant's own state alone
        check.check(s_new, s_py, (plant.p, plant.cfg, plant.gap12_0, plant.gap23_0, s, h, F))
    check.done()
    if variant in ("force_limit", "all"):
        assert saturating > N_STATES // 10


def test_plant_step_refuses_a_state_leaving_the_domain_like_python(native):
    """Near the bound of B0 (1.5 rad) with a large rate the step crosses |B| = pi/2: Python raises, C returns 0;
    the same start states a little further from the bound are accepted by both, equal."""
    rng = np.random.default_rng(341)
    refused, accepted = 0, Agreement("tapmp_plant_step (near |B| = pi/2, accepted)")
    while refused < N_STATES:
        sign = float(rng.choice([-1.0, 1.0]))
        p, cfg = random_params(rng), random_config(rng, "all", int(rng.integers(1, 4)))
        s = (*random_pose(rng)[:2], sign * u(rng, 1.4, 1.5), *random_rates(rng)[:2], sign * u(rng, 10.0, 100.0))
        h, F = u(rng, 1e-4, 5e-3), random_forces(rng)
        plant, pl = PlantModel(p, cfg, s[:3], s[3:]), native.plant(p, cfg, s[:3], s[3:])
        ok, s_new = native.plant_step(pl, h, F)
        ok_py, s_py = reference_step(plant, 0.0, h, F)
        assert ok == ok_py, (p, cfg, s, h, F, s_new, s_py)
        if not ok:
            with pytest.raises(KinematicDomainError):  # PlantModel.step says so
                plant.step(0.0, h, *F)
            assert tuple(pl.s)[:6] == s and plant.state == list(s)
            refused += 1
        else:
            accepted.check(s_new, s_py, (p, cfg, s, h, F))
    accepted.done(minimum=N_STATES // 2)
    # forces that overflow the state to inf/NaN are refused by both as well
    plant, pl = PlantModel(PAPER_MODEL, IDEAL), native.plant(PAPER_MODEL, IDEAL, (0.0,) * 3, (0.0,) * 3)
    assert native.plant_step(pl, 1e-4, (1e308, -1e308, 1e308))[0] == 0
    assert reference_step(plant, 0.0, 1e-4, (1e308, -1e308, 1e308))[0] == 0
    with pytest.raises(KinematicDomainError):
        plant.step(0.0, 1e-4, 1e308, -1e308, 1e308)


def test_plant_outputs_match_python_measured_true_positions_velocities_and_state(native):
    rng, check = np.random.default_rng(351), Agreement("tapmp_plant_outputs")
    for i in range(N_STATES):
        cfg = random_config(rng, "all")._replace(encoder_resolution=[0.0, 1e-7, 1e-7 * u(rng, 0.8, 1.2)][i % 3])
        plant, pl, s = random_plant_case(rng, native, "ideal")
        plant.cfg, pl.c = cfg, c_config(cfg)[0]
        plant.sample = pl.sample = float(rng.integers(0, 10**6))  # the noise of that sample
        check.check(native.plant_outputs(pl), reference_outputs(plant), (plant.p, cfg, s))
        assert plant.outputs() == native.plant_outputs(pl)  # PlantModel's outputs are the C's
    check.done()


def test_noise_samples_are_the_same_numbers_in_c_and_python(native):
    """Bit for bit, including sample indices a deserialized state could hold (negative, huge)."""
    from tapmp.plant import noise_sample
    rng = np.random.default_rng(353)
    cases = [(int(rng.integers(0, 2**31)), float(rng.integers(0, 2**40)), int(rng.integers(0, 3)))
             for _ in range(2000)]
    cases += [(0, 0.0, 0), (2147483647, 0.0, 2), (5, -1.0, 1), (5, 2.0**53, 1), (5, 1e300, 0), (5, 2.5, 0)]
    for seed, k, motor in cases:
        expected = reference_noise_sample(seed, k, motor)
        assert native.lib.tapmp_noise_sample(seed, k, motor) == expected == noise_sample(seed, k, motor), \
            (seed, k, motor)


# --- control ----------------------------------------------------------------------------------

def test_feedforward_matches_python(native):
    rng, check = np.random.default_rng(401), Agreement("tapmp_feedforward")
    for _ in range(N_STATES):
        p = random_params(rng)
        q = kinematics.inverse(*random_pose(rng), p.L_1)
        dq, dx_d, ddx_d = random_rates(rng), random_rates(rng), random_accelerations(rng)
        ok, u_d, _ = native.feedforward(q, dq, dx_d, ddx_d, p)
        assert ok == 1, (q, p)
        check.check(u_d, feedforward(q, dq, dx_d, ddx_d, p), (q, dq, dx_d, ddx_d, p))
    check.done()


def test_feedforward_refuses_positions_outside_the_domain_like_python(native):
    rng, check = np.random.default_rng(402), Agreement("tapmp_feedforward (domain error arg)")
    inside = Agreement("tapmp_feedforward", record=False)
    while check.states < N_STATES:
        p = random_params(rng)
        q, dq, dx_d, ddx_d = domain_violating_q(rng, p.L_1), random_rates(rng), random_rates(rng), random_accelerations(rng)
        ok, u_d, arg = native.feedforward(q, dq, dx_d, ddx_d, p)
        try:
            py = feedforward(q, dq, dx_d, ddx_d, p)
        except KinematicDomainError as err:
            assert ok == 0, (q, p)
            check.check(arg, err.value, (q, p))
        else:  # at the bound, inside for both
            assert ok == 1, (q, p, arg)
            inside.check(u_d, py, (q, dq, dx_d, ddx_d, p))
    check.done()
    assert inside.states > 0  # the bound itself was tried


def test_scdc_command_matches_python(native):
    rng, check = np.random.default_rng(403), Agreement("tapmp_scdc_command")
    for _ in range(N_STATES):
        e, de, c = u(rng, -0.02, 0.02, 3), random_rates(rng), u(rng, -0.02, 0.02, 3)
        integral, u_d, g = u(rng, -1e-3, 1e-3, 3), random_forces(rng), random_gains(rng)
        check.check(native.scdc_command(e, de, c, integral, u_d, g), scdc_command(e, de, c, integral, u_d, g),
                    (e, de, c, integral, u_d, g))
    check.done()


def test_pid_command_matches_python(native):
    rng, check = np.random.default_rng(405), Agreement("tapmp_pid_command")
    for _ in range(N_STATES):
        e, de, integral = u(rng, -0.02, 0.02, 3), random_rates(rng), u(rng, -1e-3, 1e-3, 3)
        u_d, g, m = random_forces(rng), random_gains(rng), random_modal_gains(rng)
        check.check(native.pid_command(e, de, integral, u_d, g, m), pid_command(e, de, integral, u_d, m, g.K_T),
                    (e, de, integral, u_d, g, m))
    check.done()


def test_apd_command_matches_python(native):
    rng, check = np.random.default_rng(404), Agreement("tapmp_apd_command")
    for _ in range(N_STATES):
        e, de, u_d, g = u(rng, -0.02, 0.02, 3), random_rates(rng), random_forces(rng), random_gains(rng)
        check.check(native.apd_command(e, de, u_d, g), apd_command(e, de, u_d, g), (e, de, u_d, g))
    check.done()


def random_reference(rng):
    return (*random_pose(rng), *random_rates(rng), *random_accelerations(rng))


def assert_same_controller_state(st, ctrl: ReferenceController, check: Agreement, inputs):
    """The carried state: integral of c always; q_prev once there is one."""
    assert bool(st.has_q_prev) == (ctrl.q_prev is not None), inputs
    check.check((*st.integral, *(st.q_prev if st.has_q_prev else ())),
                (*ctrl.integral, *(ctrl.q_prev or ())), inputs)


SEQUENCE = 5  # samples per random controller


@pytest.mark.parametrize("anti_windup", (AW_OFF, AW_CLAMP, AW_BACK), ids=("no_anti_windup", "clamping",
                                                                       "back_calculation"))
@pytest.mark.parametrize("velocity_source", (VELOCITY_DIFFERENCE, VELOCITY_INPUT),
                         ids=("backward_difference", "dq_inputs"))
@pytest.mark.parametrize("law", (SCDC, APDDC, PIDDC), ids=("scdc", "apddc", "piddc"))
def test_controller_sample_sequences_match_python(native, law, velocity_source, anti_windup):
    """Random controllers, each sampled SEQUENCE times along a moving platform; the first sample
    is an initialization (advance False) half of the time, later ones advance 80 % of the time,
    so the integral and q_prev are carried, held and updated as in ControllerModel.sample.
    The C state is updated in place (next = st) or into a second struct, alternately. With an
    anti-windup, the laws with an integral have it act on some samples (their forces exceed the limit)."""
    rng = np.random.default_rng(411 + 2 * law + velocity_source + 10 * anti_windup)
    check, state_check = Agreement("tapmp_controller_sample"), Agreement("tapmp_controller_sample (state)")
    advances = {True: 0, False: 0}
    unwound = 0
    for k in range(N_STATES // SEQUENCE):
        p, g = random_params(rng), random_gains(rng)
        lim = u(rng, 50.0, 600.0) if rng.random() < 0.5 else 0.0
        h = 1e-4 * u(rng, 0.5, 2.0)
        resolution = 1e-7 if rng.random() < 0.5 else 0.0
        m = random_modal_gains(rng)
        aw_time = 10.0 ** u(rng, -5.0, -1.0) if anti_windup != AW_OFF else ANTI_WINDUP_TIME
        ctrl = ReferenceController(p, g, law, velocity_source, lim, m, anti_windup, aw_time)
        cp, cg, st = c_params(p), c_gains(g, m), c_controller_state()
        pose, rate = random_pose(rng), random_rates(rng)
        for i in range(SEQUENCE):
            advance = rng.random() < (0.5 if i == 0 else 0.8)
            advances[advance] += 1
            pose = tuple(x + h * v + u(rng, -1e-6, 1e-6) for x, v in zip(pose, rate))
            q = tuple(reference_quantize(x, resolution) for x in kinematics.inverse(*pose, p.L_1))
            dq_in = kinematics.joint_velocity(pose[2], *rate, p.L_1)
            ref = random_reference(rng)
            next_st = st if k % 2 else c_controller_state()
            inputs = (law, velocity_source, p, g, lim, h, k, i, ref, q, dq_in, advance)
            ok, out, _ = native.controller_sample(cp, cg, law, velocity_source, lim, st, h, ref, q, dq_in,
                                                  advance, next_st, anti_windup, aw_time)
            F, uu, e, e_s = ctrl.sample(i * h, h, ref, q, dq_in, advance)
            assert ok == 1, inputs
            check.check(out, (*F, *uu, *e, *e_s), inputs)
            st = next_st
            assert_same_controller_state(st, ctrl, state_check, inputs)
        unwound += ctrl.unwound
    check.done()
    state_check.done()
    assert advances[True] > N_STATES // 2 and advances[False] > N_STATES // 20
    assert (unwound > N_STATES // 50) == (anti_windup != AW_OFF and law != APDDC), unwound


def test_controller_sample_refuses_positions_outside_the_domain_like_python_keeping_its_state(native):
    rng, check = np.random.default_rng(421), Agreement("tapmp_controller_sample (domain error arg)")
    inside = Agreement("tapmp_controller_sample", record=False)
    for i in itertools.count():
        if check.states >= N_STATES:
            break
        p, g, law, vs = random_params(rng), random_gains(rng), i % 2, (i // 2) % 2
        ctrl, cp, cg, st = ReferenceController(p, g, law, vs), c_params(p), c_gains(g), c_controller_state()
        q0 = kinematics.inverse(*random_pose(rng), p.L_1)
        ref = random_reference(rng)
        assert native.controller_sample(cp, cg, law, vs, 0.0, st, 1e-4, ref, q0, (0.0,) * 3, True, st)[0] == 1
        ctrl.sample(0.0, 1e-4, ref, q0, (0.0,) * 3)
        q, dq = domain_violating_q(rng, p.L_1), random_rates(rng)
        ok, out, arg = native.controller_sample(cp, cg, law, vs, 0.0, st, 1e-4, ref, q, dq, True, st)
        inputs = (p, g, law, vs, ref, q0, q, dq)
        try:
            py = ctrl.sample(1e-4, 1e-4, ref, q, dq)
        except KinematicDomainError as err:
            assert ok == 0, inputs
            check.check(arg, err.value, inputs)
        else:  # at the bound, inside for both
            assert ok == 1, (inputs, arg)
            inside.check(out, [v for part in py for v in part], inputs)
        assert_same_controller_state(st, ctrl, inside, inputs)
    check.done()
    assert inside.states > 0


# --- trajectory -------------------------------------------------------------------------------

def test_reference_trajectory_matches_python(native):
    rng, check = np.random.default_rng(501), Agreement("tapmp_reference")
    for _ in range(N_STATES):
        tp, t = random_trajectory(rng), u(rng, 0.0, 10.0)
        check.check(native.reference(t, c_trajectory(tp)), circle_reference(t, tp), (t, tp))
    check.done()


@pytest.mark.parametrize("profile", (1, 2, 3), ids=("step", "ramp", "s-curve"))
def test_point_to_point_moves_match_python(native, profile):
    """Random moves (some axes not moving, short ones that never reach a limit) sampled at random
    times before, during and after: tapmp_move_plan and tapmp_reference against move_plan and
    move_reference."""
    rng, check = np.random.default_rng(502 + profile), Agreement("tapmp_move_plan + tapmp_reference")
    for i in range(N_STATES // 10):
        a = (u(rng, -0.02, 0.02), u(rng, -0.02, 0.02), u(rng, -0.3, 0.3))
        b = tuple(x if rng.random() < 0.2 else x + u(rng, -10.0, 10.0) ** 3 * 1e-5 for x in a)
        limits = {f"{k}_max_{ax}": u(rng, 0.3, 3.0) * base for k, base in (("v", 0.1), ("a", 1.0), ("j", 100.0))
                  for ax in "XZB"}
        tp = TrajectoryParams(profile=profile, X_a=a[0], Z_a=a[1], B_a=a[2], X_b=b[0], Z_b=b[1], B_b=b[2],
                              t_move=u(rng, 0.0, 0.1), **limits)
        c = c_trajectory(tp)
        end = tp.t_move + max(p.T for p in move_plan(tp)) + 0.01
        for t in (*(u(rng, 0.0, end) for _ in range(10)), 0.0, end):
            check.check(native.reference(t, c), move_reference(t, tp), (t, tp))
    check.done()


# --- the comparison itself --------------------------------------------------------------------

@pytest.mark.parametrize("field", ("L_1", "m_1", "m_3", "I_y", "g"))
def test_the_comparison_detects_a_deliberately_perturbed_parameter(native, field):
    """A parameter off by 1e-9 relative in the C plant (far above RTOL, far below any physical
    meaning) must fail the step comparison: the tests can tell the twins apart."""
    rng = np.random.default_rng(601)
    check = Agreement("perturbed", record=False)
    with pytest.raises(AssertionError, match="disagree beyond"):
        for _ in range(N_STATES):
            plant, pl, s = random_plant_case(rng, native, "all")
            setattr(pl.p, field, getattr(plant.p, field) * (1.0 + 1e-9))
            h, F = 1e-4, random_forces(rng)
            ok, s_new = native.plant_step(pl, h, F)
            check.check(s_new, reference_step(plant, 0.0, h, F)[1], (field, s, F))
    assert check.states < 10  # caught at once, not by luck


# --- closed loop ------------------------------------------------------------------------------

def c_closed_loop(native, scenario, n_steps):
    """tapmp.closed_loop.simulate with every model call a C function: reference, controller
    sample, plant step, quantized outputs. Rows (t, ref, F, q_meas, q_true) as recorded there."""
    plant, ctrl, traj = scenario.plain_models()  # only for the parameters and the initial state
    pl = native.plant(plant.p, plant.cfg, plant.state[:3], plant.state[3:])
    cp, cg, tp, st = c_params(ctrl.p), c_gains(ctrl.g, ctrl.modal), c_trajectory(traj), c_controller_state()
    law, vs, lim = ctrl.law, ctrl.velocity_source, ctrl.force_limit
    t0, h = scenario.start_time, scenario.step
    gauss_seidel = scenario.ordering == "gauss-seidel"

    def sample(t, ref, q, dq, advance):
        ok, out, arg = native.controller_sample(cp, cg, law, vs, lim, st, h, ref, q, dq, advance, st)
        assert ok == 1, (t, arg)
        return out[:3]

    ref = native.reference(t0, tp)
    out = native.plant_outputs(pl)
    q, dq = out[0:3], out[6:9]
    F = sample(t0, ref, q, dq, False)
    rows = [(t0, ref, F, q, out[3:6])]
    for k in range(n_steps):
        t = t0 + k * h
        F_held = F
        F = sample(t, ref, q, dq, True)
        ok, s_new = native.plant_step(pl, h, F if gauss_seidel else F_held)
        assert ok == 1, (t, s_new)
        pl.s[0:8] = s_new
        ref = native.reference(t + h, tp)
        out = native.plant_outputs(pl)
        q, dq = out[0:3], out[6:9]
        rows.append((t0 + (k + 1) * h, ref, F, q, out[3:6]))
    return rows


@pytest.mark.parametrize("ordering", ("gauss-seidel", "jacobi"))
@pytest.mark.parametrize("law", ("sc-dc", "apd-dc", "pid-dc", "sc-dc+disturbances"))
def test_closed_loop_through_the_c_functions_follows_the_python_loop(native, law, ordering):
    """Paper scenario, 2,000 steps of 0.1 ms: true motor positions within 1e-12 m and commands
    within 1e-6 N at every communication point (reference and encoder readings reported too).
    "+disturbances": attraction, cogging, negative k_pull and a 10 % mass mismatch on top."""
    overrides, label = [], law
    if law.endswith("+disturbances"):
        law = law.split("+")[0]
        overrides = ["plant.k_pull=-300.0", "plant.attraction_force=5.0", "plant.attraction_gap=0.01",
                     "plant.cogging_amplitude=2.0", "plant.cogging_phase2=1.0", "mismatch.m_p=1.1"]
    scenario = load(PAPER_SCENARIO, overrides).with_changes(law=law, ordering=ordering)
    plant, ctrl, traj = scenario.plain_models()
    py_rows = []
    simulate(plant, ctrl, traj, scenario.start_time, CLOSED_LOOP_STEPS, scenario.step, scenario.ordering,
             record=lambda *row: py_rows.append(row))
    c_rows = c_closed_loop(native, scenario, CLOSED_LOOP_STEPS)
    assert len(c_rows) == len(py_rows) == CLOSED_LOOP_STEPS + 1
    names = ("t", "ref", "F", "q_meas", "q_true")
    c_arr = {n: np.array([r[i] for r in c_rows], dtype=float) for i, n in enumerate(names)}
    py_arr = {n: np.array([r[i] for r in py_rows], dtype=float) for i, n in enumerate(names)}
    diff = {n: float(np.abs(c_arr[n] - py_arr[n]).max()) for n in names}
    assert np.abs(py_arr["q_true"]).max() > 1e-3 and np.abs(py_arr["F"]).max() > 1.0  # it moved
    assert diff["q_true"] <= POSITION_TOL, diff
    assert diff["F"] <= COMMAND_TOL, diff
    for n in ("ref", "q_meas", "t"):
        assert diff[n] <= RTOL * max(float(np.abs(py_arr[n]).max()), TINY), diff
    for n in ("q_true", "F"):
        key = f"closed loop {label} {ordering}: {n} (max abs diff)"
        MEASURED[key] = {"states": CLOSED_LOOP_STEPS + 1, "worst": diff[n],
                         "identical": bool(np.array_equal(c_arr[n], py_arr[n]))}


def test_the_law_numbers_of_python_are_the_c_models():
    _, lib = cmodel.load()
    assert (SCDC, APDDC, PIDDC) == (lib.TAPMP_SCDC, lib.TAPMP_APDDC, lib.TAPMP_PIDDC) == (0, 1, 2)
