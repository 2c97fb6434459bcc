"""Stability pre-check: the spectral radius of the sampled closed loop, linearized.

The check linearizes the *one-step map* of the loop that ``tapmp run`` simulates,
built from the same model functions the FMUs run (``tapmp.plant.PlantModel``,
``tapmp.control.ControllerModel``, stepped exactly as ``tapmp.closed_loop.simulate``
does), by central finite differences about the scenario's start point. The map
takes the loop state at a communication point t to the state at t + h [s]:

* the plant state (X, Z, B, dX, dZ, dB) [m, m, rad, m/s, m/s, rad/s], integrated by
  RK4 over the step under the held force (rigid-body dynamics with the exact mass
  matrix, viscous friction c_v and the mover pulling k_pull, both linear, and the
  smooth position-dependent forces: the mover attraction, whose stiffness at the
  start is -2 attraction_force / attraction_gap, and the cogging, whose local
  stiffness at the start pose is +-2 pi A / pitch and varies along the path);
* the controller's discrete states: the integral of c (Eq. 22, SC-DC, motors
  with b_i > 0) or of e (PID-DC, all three motors unless ki_c = ki_d = 0; the
  right-rectangle sum of ControllerModel) [m s] and the previous
  encoder sample of the backward-difference velocity [m] (velocity_source = 0);
* with the ``jacobi`` ordering, the command held from the previous sample [N]
  (the extra step of delay); ``gauss-seidel`` has only the zero-order hold;
* with the drive in the loop (a scenario's ``drive``, TAPMP_Drive, fmu_plant/drive.c), per motor
  the commands of its computation delay (delay_samples of them) [N] and its current loop's force y
  and rate y' / w_n [N] (when current_bandwidth > 0), stepped as the FMU steps them (exact
  discretization, the mean of y over the step times 1 + force_constant_error to the plant), its
  current limit left out like the other saturations; with ``jacobi`` also the drive's force held
  from the previous step [N];
* with the plant's flexible mode on (flex_frequency > 0), its deflection z_f [m] and
  rate dz_f [m/s], last.

The Jacobian is taken at the start pose and velocity of the plant, with the
reference of the start time, the integral at zero and the previous sample one
backward-difference step behind (a consistent velocity). Its eigenvalues (LAPACK
through scipy.linalg.eigvals) decide: the loop is small-signal stable if the
spectral radius rho < 1 - MARGIN, unstable if rho > 1 + MARGIN, marginal between.
MARGIN = 1e-6 is above the error of the finite differences (about 1e-9 here);
a stable loop's slowest mode decays with the time constant -h / ln(rho).

Nonlinear parts of the plant and controller are left out of the linearization:

* encoder quantization (resolution set to 0): a bounded measurement error of at
  most half a count; it sets a noise floor, not the loop's dynamics;
* Coulomb friction (F_c set to 0): a bounded force against the motion; the plant
  smooths sign() with tanh(dq / v_s), whose slope F_c / v_s at rest is an artefact
  of the smoothing width, so it is not taken as damping;
* force saturation (plant and controller limits set to 0 = off): the check is
  about small signals inside the limits. With saturation an unstable loop does
  not blow up but runs into the limit and chatters there (a limit cycle).

Structural eigenvalues 1 are removed. SC-DC: c sums to zero (Eq. 21), so the sum
of the three integrals of c never changes; the loop is analysed on the invariant
subspace where that sum is zero (the one the loop starts in, with the integral at
zero). PID-DC: an integral mode whose gain is zero (the common mode (1, 1, 1) if
ki_c = 0, the two differential modes if ki_d = 0) is summed but never fed back, an
exact eigenvector with eigenvalue 1 that is no growth mode of the loop; the loop is
analysed on the quotient by it. Either way the eigenvalues are those of T^T A T with
T an orthonormal basis of the complement of the removed directions.
"""

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg

from tapmp.control import VELOCITY_DIFFERENCE, ControllerModel, ModalGains
from tapmp.interface import DRIVE_DEFAULTS
from tapmp.laws import BY_ID
from tapmp.params import ANTI_WINDUP_TIME, ModelParams
from tapmp.plant import PlantConfig, PlantModel
from tapmp.trajectory import TrajectoryParams, reference

from .scenario import Scenario, model_tuple

MARGIN = 1e-6  # verdict band around rho = 1, above the finite-difference error


def radius_text(rho: float) -> str:
    """The spectral radius ``rho`` (per step) with the digits that tell it from 1: at least six
    decimals, and two significant digits of |rho - 1| beyond (1.000019, not "1")."""
    gap = abs(rho - 1.0)
    digits = 6 if gap == 0.0 or not math.isfinite(gap) else max(6, 1 - math.floor(math.log10(gap)))
    return f"{rho:.{digits}f}"
# Finite-difference steps per kind of state (also the scaling of the coordinates).
_DELTA = {"pose": 1e-8, "rate": 1e-6, "integral": 1e-10, "q_prev": 1e-8, "F_held": 1e-3}


@dataclass
class StabilityReport:
    """Result of the pre-check for one scenario.

    spectral_radius: max |eigenvalue| of the linearized one-step map (1 per step);
    stable: spectral_radius < 1 - MARGIN; verdict: "stable", "marginal" or
    "unstable"; ordering, h [s], law as in the scenario; time [s]: where the loop
    was linearized; states: names of the state components; eigenvalues: all of
    them, largest magnitude first.
    """

    spectral_radius: float
    stable: bool
    verdict: str
    ordering: str
    h: float
    law: str
    time: float
    states: list = field(default_factory=list)
    eigenvalues: list = field(default_factory=list)

    @property
    def margin(self) -> float:
        """1 - spectral radius: > 0 means stable (decay per step of the slowest mode)."""
        return 1.0 - self.spectral_radius

    @property
    def time_constant(self) -> float:
        """-h / ln(rho) [s]: decay (> 0, stable) or growth (< 0, unstable) time of the worst mode."""
        rho = self.spectral_radius
        if rho == 0.0:
            return 0.0
        if rho == 1.0:
            return math.inf
        return -self.h / math.log(rho)

    def summary(self) -> str:
        """One line: verdict, spectral radius, margin and what it means in time."""
        tc = self.time_constant
        what = (f"slowest mode decays with time constant {tc * 1e3:.4g} ms" if tc > 0
                else f"worst mode grows x{radius_text(self.spectral_radius)} per step (e-fold time "
                f"{-tc * 1e3:.4g} ms)")
        return (f"{self.verdict}: spectral radius {radius_text(self.spectral_radius)} (margin 1 - rho = "
                f"{self.margin:.3g}; stable if rho < 1 - {MARGIN:g}) at h = {self.h:g} s, "
                f"{self.ordering}, {self.law}; {what}")

    def to_dict(self) -> dict:
        """Plain data (for JSON and study rows)."""
        return {"spectral_radius": self.spectral_radius, "stable": self.stable, "verdict": self.verdict,
                "margin": self.margin, "time_constant_s": self.time_constant, "ordering": self.ordering,
                "h": self.h, "law": self.law, "time": self.time, "states": list(self.states),
                "eigenvalues": [[z.real, z.imag] for z in self.eigenvalues]}


def loop_models(scenario: Scenario, linear: bool = False):
    """(plant, controller, trajectory params) of a scenario, as the FMUs would build them.

    With linear=True the nonlinear parts (quantization, Coulomb friction, both force
    saturations) are switched off, as the linearization treats them (module doc). The
    measurement noise is always off: the check is of the loop without it.
    """
    par = scenario.parameters()
    pl, ct, tr = par["plant"], par["controller"], par["trajectory"]
    config = model_tuple(PlantConfig, pl)._replace(noise_rms=0.0)
    force_limit, anti_windup = ct.get("force_limit", 0.0), ct.get("anti_windup", 0)
    if linear:  # no limit: nothing for the anti-windup to act at
        config = config._replace(encoder_resolution=0.0, F_c1=0.0, F_c2=0.0, F_c3=0.0, force_limit=0.0)
        force_limit, anti_windup = 0.0, 0
    plant = PlantModel(model_tuple(ModelParams, pl), config,
                       tuple(pl.get(k, 0.0) for k in ("X0", "Z0", "B0")),
                       tuple(pl.get(k, 0.0) for k in ("dX0", "dZ0", "dB0")))
    ctrl = ControllerModel(model_tuple(ModelParams, ct), scenario.gain_values(), ct["law"],
                           ct.get("velocity_source", VELOCITY_DIFFERENCE), force_limit,
                           model_tuple(ModalGains, ct), ct["T_s"], scenario.start_time, anti_windup,
                           ct.get("anti_windup_time", ANTI_WINDUP_TIME))
    return plant, ctrl, model_tuple(TrajectoryParams, tr)


class DriveModel:
    """TAPMP_Drive's equations (fmu_plant/drive.c, docs/native-fmus.md) on the loop state, per motor:
    the computation delay of ``delay`` communication steps, the second-order current loop discretized
    exactly over the step h [s] (its force y and y' / w_n [N]) and the force-constant error. The limit
    is applied only if ``limit`` (the check's linear loop leaves it out)."""

    def __init__(self, settings: dict, h: float, limit: bool = False):
        s = {**DRIVE_DEFAULTS, **settings}
        self.delay = int(s["delay_samples"])
        self.wn = 2.0 * math.pi * s["current_bandwidth"]
        self.gain = np.array([1.0 + s[f"force_constant_error{i}"] for i in (1, 2, 3)])
        self.limit = s["force_limit"] if limit else 0.0
        a, z = self.wn * h, s["current_damping"]
        # z = (y, y'/wn, s, mean of y over the step): the FMU's exp(M h), here by scipy's expm
        self.phi = linalg.expm(np.array([[0.0, a, 0.0, 0.0], [-a, -2.0 * z * a, a, 0.0], [0.0] * 4,
                                         [1.0, 0.0, 0.0, 0.0]]))

    @property
    def size(self) -> int:
        """States per motor: the delayed commands, then the loop's two (if it is not ideal)."""
        return self.delay + (2 if self.wn > 0.0 else 0)

    def rest(self, u) -> np.ndarray:
        """The state at rest on the commands u [N] (the FMU's start), as 3 x size."""
        u = np.asarray(u, dtype=float)
        cols = [u] * self.delay + ([self._limited(u), np.zeros(3)] if self.wn > 0.0 else [])
        return np.array(cols).T.reshape(3, self.size)

    def _limited(self, c):
        return np.clip(c, -self.limit, self.limit) if self.limit > 0.0 else c

    def step(self, state: np.ndarray, u) -> tuple:
        """(state after the step, force to the plant [N]) from the state (3 x size) and the commands u [N]."""
        u = np.asarray(u, dtype=float)
        d = self.delay
        c = state[:, d - 1] if d else u
        s = self._limited(c)
        new = np.empty_like(state)
        if d:
            new[:, 0], new[:, 1:d] = u, state[:, :d - 1]
        mean = s
        if self.wn > 0.0:
            z = np.stack([state[:, d], state[:, d + 1], s, np.zeros(3)])
            nz = self.phi @ z
            new[:, d], new[:, d + 1], mean = nz[0], nz[1], nz[3]
        return new, self.gain * mean


class OneStepMap:
    """The closed loop's map from the state at t to the state at t + h, on a state vector.

    Runs one macro step of ``tapmp.closed_loop.simulate`` (same calls, same order)
    from a loop state given as a vector; see the module doc for its components.
    """

    def __init__(self, scenario: Scenario, linear: bool = True):
        self.plant, self.ctrl, self.traj = loop_models(scenario, linear)
        self.h = scenario.step
        self.t = scenario.start_time
        self.jacobi = scenario.ordering == "jacobi"
        self.law = BY_ID[self.ctrl.law]
        # the integral states fed back, and their directions with a structural eigenvalue 1 (module doc)
        self.integrals, self.constant_directions = self.law.integral(self.ctrl.g, self.ctrl.modal)
        self.difference = self.ctrl.velocity_source == VELOCITY_DIFFERENCE
        names = ["X", "Z", "B", "dX", "dZ", "dB"]
        kinds = ["pose"] * 3 + ["rate"] * 3
        names += [f"integral_{self.law.integrates}{i + 1}" for i in self.integrals]
        kinds += ["integral"] * len(self.integrals)
        if self.difference:
            names += ["q1_prev", "q2_prev", "q3_prev"]
            kinds += ["q_prev"] * 3
        if self.jacobi:
            names += ["F1_held", "F2_held", "F3_held"]
            kinds += ["F_held"] * 3
        self.drive = DriveModel(scenario.drive, self.h, not linear) if scenario.drive is not None else None
        if self.drive is not None:
            names += [f"drive{i + 1}_{k}" for i in range(3) for k in
                      [f"command_{j + 1}" for j in range(self.drive.delay)] + (["y", "dy"] if self.drive.wn > 0 else [])]
            kinds += ["F_held"] * 3 * self.drive.size
            if self.jacobi:
                names += ["D1_held", "D2_held", "D3_held"]
                kinds += ["F_held"] * 3
        self.flex = self.plant.cfg.flex_frequency > 0.0
        if self.flex:
            names += ["z_f", "dz_f"]
            kinds += ["pose", "rate"]
        self.names = names
        self.scale = np.array([_DELTA[k] for k in kinds])
        self.ref = reference(self.t, self.traj)

    def at(self, t: float) -> "OneStepMap":
        """Move the map to the communication point t [s] (the reference sampled there); returns self."""
        self.t = t
        self.ref = reference(t, self.traj)
        return self

    def start_state(self) -> np.ndarray:
        """The linearization point: the scenario's start (see the module doc)."""
        s0 = list(self.plant.state)
        x = s0 + [0.0] * len(self.integrals)
        q = self.plant.joint_positions()
        dq = self.plant.joint_velocities()
        if self.difference:
            x += [q[i] - self.h * dq[i] for i in range(3)]
        u0 = self.ctrl.sample(self.t, self.h, self.ref, q, dq, advance=False)[0]
        if self.jacobi:
            x += list(u0)
        if self.drive is not None:
            x += list(self.drive.rest(u0).ravel())
            if self.jacobi:  # the force at rest on the first command
                x += list(self.drive.step(self.drive.rest(u0), u0)[1])
        if self.flex:
            x += list(self.plant.flex)
        return np.array(x, dtype=float)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The loop state at t + h from the state x at the map's time t (see ``at``)."""
        return self.split_step(x)[0]

    def split_step(self, x: np.ndarray, w=None):
        """(loop state at t + h, controller force y [N]) from the state x at the map's time t.

        y is the force the loop hands the plant (the command of this sample, or with Jacobi the
        one held from the previous sample; with the drive, the drive's force); the plant steps under ``w`` [N] if given (the loop
        opened at the plant input, orchestrator.tool.analysis), else under y."""
        plant, ctrl = self.plant, self.ctrl
        plant.state = [float(v) for v in x[:6]]
        k = 6
        integral = [0.0, 0.0, 0.0]
        for i in self.integrals:
            integral[i] = float(x[k])
            k += 1
        ctrl.integral = integral
        if self.difference:
            ctrl.q_prev = tuple(float(v) for v in x[k:k + 3])
            k += 3
        else:
            ctrl.q_prev = None
        F_held = tuple(float(v) for v in x[k:k + 3]) if self.jacobi else None
        k += 3 if self.jacobi else 0
        if self.drive is not None:
            n = 3 * self.drive.size
            drive_state = np.asarray(x[k:k + n], dtype=float).reshape(3, self.drive.size)
            D_held = tuple(float(v) for v in x[k + n:k + n + 3]) if self.jacobi else None
        if self.flex:
            plant.flex = [float(v) for v in x[-2:]]
        q = plant.measured_positions()
        dq = plant.joint_velocities()
        F = ctrl.sample(self.t, self.h, self.ref, q, dq)[0]
        y = F_held if self.jacobi else F
        if self.drive is not None:  # the drive steps after the controller (on the command held with jacobi)
            drive_state, D = self.drive.step(drive_state, y)
            y = D_held if self.jacobi else tuple(float(v) for v in D)
        plant.step(self.t, self.h, *(y if w is None else (float(v) for v in w)))
        out = list(plant.state) + [ctrl.integral[i] for i in self.integrals]
        if self.difference:
            out += list(ctrl.q_prev)
        if self.jacobi:
            out += list(F)
        if self.drive is not None:
            out += list(drive_state.ravel())
            if self.jacobi:
                out += list(D)
        if self.flex:
            out += list(plant.flex)
        return np.array(out, dtype=float), np.array(y, dtype=float)

    def jacobian(self, x0: np.ndarray) -> np.ndarray:
        """Central-difference Jacobian in scaled coordinates x = x0 + diag(scale) z."""
        n = len(x0)
        A = np.empty((n, n))
        for j in range(n):
            d = np.zeros(n)
            d[j] = self.scale[j]
            A[:, j] = (self(x0 + d) - self(x0 - d)) / 2.0 / self.scale
        return A


def _removed_directions(m: OneStepMap) -> list:
    """The integral directions (over the three integral states) that carry a structural
    eigenvalue 1 (module doc): SC-DC the sum; PID-DC each mode whose integral gain is 0 (the law's
    record, tapmp.laws.Law.integral)."""
    return m.constant_directions


def invariant_basis(m: OneStepMap) -> np.ndarray:
    """Orthonormal basis (scaled coordinates) of the complement of the removed directions."""
    n = len(m.names)
    removed = _removed_directions(m)
    if not removed:
        return np.eye(n)
    rows = np.zeros((len(removed), n))
    for r, d in enumerate(removed):
        rows[r, 6:9] = d
    return linalg.null_space(rows)


def verdict_for(rho: float) -> str:
    """The verdict for a spectral radius ``rho``: "stable" if rho < 1 - MARGIN, "unstable" if
    rho > 1 + MARGIN, "marginal" between (inclusive)."""
    return "stable" if rho < 1.0 - MARGIN else ("unstable" if rho > 1.0 + MARGIN else "marginal")


def check(scenario: Scenario) -> StabilityReport:
    """Linearize the scenario's sampled closed loop and judge it by its spectral radius.

    Raises tapmp's ModelInputError / KinematicDomainError if the start point itself is
    invalid (the scenario is validated before, so this means a pose outside the domain).
    """
    m = OneStepMap(scenario, linear=True)
    x0 = m.start_state()
    A = m.jacobian(x0)
    T = invariant_basis(m)
    eig = linalg.eigvals(T.T @ A @ T)
    eig = sorted(eig, key=lambda z: -abs(z))
    rho = float(abs(eig[0])) if eig else 0.0
    if not math.isfinite(rho):
        rho = math.inf
    verdict = verdict_for(rho)
    return StabilityReport(spectral_radius=rho, stable=verdict == "stable", verdict=verdict,
                           ordering=scenario.ordering, h=scenario.step, law=scenario.law,
                           time=scenario.start_time, states=m.names, eigenvalues=[complex(z) for z in eig])



_CHECKED: dict = {}  # key of cache_key -> StabilityReport, for cached_check
_CHECKED_MAX = 1024


def cache_key(scenario: Scenario) -> str:
    """What :func:`check` reads of a scenario, as text: the FMUs' parameter tables, the gains,
    the step [s], the start time [s], the ordering and the law. Two scenarios with the same key
    get the same report."""
    import json
    return json.dumps([scenario.parameters(), scenario.gain_values(), scenario.step, scenario.start_time,
                       scenario.ordering, scenario.law], sort_keys=True, default=repr)


def cached_check(scenario: Scenario) -> StabilityReport:
    """:func:`check`, computed once per process for each :func:`cache_key` (a study's cases that
    differ only in what the check does not read, e.g. the stop time, share one linearization).
    Returns a copy the caller may change."""
    import copy
    key = cache_key(scenario)
    report = _CHECKED.get(key)
    if report is None:
        report = check(scenario)
        if len(_CHECKED) >= _CHECKED_MAX:
            _CHECKED.pop(next(iter(_CHECKED)))  # the oldest first
        _CHECKED[key] = report
    return copy.deepcopy(report)
