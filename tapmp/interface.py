"""The settings table: every FMU variable's name, causality, unit, description, start value,
range and C struct field, defined once.

The FMU adapters register these, the build step writes units, ranges, model structure and the
DefaultExperiment from them, the SSP writer takes the connections from here and the docs list
them. Defaults come from the model's own parameter tuples, so nothing is typed twice. From the
same rows come the C code that reads an FMU's parameters into the model's settings struct
(:func:`settings_read_macro`, into model_vars.h), the C range checks every family and the Python
model run (:func:`settings_check_source`, tapmp_settings.h) and the Python side's filling of
those structs by field name (tapmp.cmodel.settings); those C generators live in tapmp.settings_c,
below the C model, and read the rows through the models' records (tapmp.models, filled by
tapmp.records). FMU_NAMES, ELEMENT, VARIABLES, SETTINGS_STRUCT and CONNECTIONS are views of the
records, read when used, so a registered model appears in each.
"""

from collections.abc import Mapping, Sequence
from typing import NamedTuple

from .models import CONTROLLER, DRIVE, PLANT, TRAJECTORY, names, record, system_models
from .settings_c import allowed_text, settings_check_source, settings_read_macro  # noqa: F401 (the table's API)
from .params import (ANTI_WINDUP_TIME, DEFAULT_MODAL_GAINS, GAIN_NAMES, GAIN_PRESETS, MODAL_GAIN_NAMES, PAPER_MODEL,
                     SERVO_STEP, START_TIME, STOP_TIME)
from . import laws, settings
from .plant import PlantConfig
from .trajectory import TrajectoryParams, circle_reference



class _Names(Sequence):
    """The base models' names in the registry's order (tapmp.models), read when used."""

    def __getitem__(self, i):
        return names()[i]

    def __len__(self):
        return len(names())

    def __repr__(self):
        return repr(names())


class _ByModel(Mapping):
    """{model name: one attribute of its record} over the base models, read when used."""

    def __init__(self, attribute: str):
        self._attribute = attribute

    def __getitem__(self, model: str):
        return getattr(record(model), self._attribute)

    def __iter__(self):
        return iter(names())

    def __len__(self):
        return len(names())


# Derived from the records (tapmp.models, filled by tapmp.records): the models in signal-flow order,
# each one's element name in the SSP system, its variables and its C settings struct.
FMU_NAMES = _Names()
ELEMENT = _ByModel("element")
# Orderings of one macro step of the FMI-free loop (tapmp.closed_loop), the master's own
# (orchestrator.engine.schedule.ORDERINGS; docs/master.md): one element after the other on the latest
# outputs, or all on the outputs at t (one extra step of delay in the feedback path).
ORDERINGS = ("gauss-seidel", "jacobi")
# Every modelDescription's DefaultExperiment [s]: the servo cycle as step, the paper's run as stop.
DEFAULT_EXPERIMENT = {"startTime": START_TIME, "stopTime": STOP_TIME, "stepSize": SERVO_STEP}


class Var(NamedTuple):
    """One FMI scalar variable."""

    name: str
    causality: str          # "input", "output" or "parameter"
    unit: str               # a key of UNITS, "" for dimensionless integers
    description: str
    start: float = 0.0
    type: str = "Real"      # "Real" or "Integer"
    variability: str = ""   # "" = continuous (in/out), "fixed" or "tunable" (parameters)
    min: float | None = None  # a parameter's one range rule: min <= value <= max (modelDescription
    max: float | None = None  # min/max; every family and the Python model refuse a value outside)
    field: str = ""           # a parameter's member in the model's C settings struct (SETTINGS_STRUCT)
    choices: str = ""         # an Integer parameter's allowed values in words, if they are named


# SI base-unit exponents of every unit used, for modelDescription UnitDefinitions.
UNITS = {
    "m": {"m": 1}, "m/s": {"m": 1, "s": -1}, "m/s2": {"m": 1, "s": -2},
    "rad": {"rad": 1}, "rad/s": {"rad": 1, "s": -1}, "rad/s2": {"rad": 1, "s": -2},
    "N": {"kg": 1, "m": 1, "s": -2}, "kg": {"kg": 1}, "kg.m2": {"kg": 1, "m": 2},
    "N.s/m": {"kg": 1, "s": -1}, "N/m": {"kg": 1, "s": -2}, "N/(m.s)": {"kg": 1, "s": -3},
    "1/s": {"s": -1}, "m/s3": {"m": 1, "s": -3}, "rad/s3": {"rad": 1, "s": -3},
    "Hz": {"s": -1}, "1": {}, "s": {"s": 1},
    # The controller's command u is a number (command units) with K_T F = u: K_T in 1/N, the
    # gains in command units per error unit, and gain / K_T the force gain in N/m, N s/m, N/(m s).
    "1/N": {"kg": -1, "m": -1, "s": 2}, "1/m": {"m": -1}, "s/m": {"m": -1, "s": 1},
    "1/(m.s)": {"m": -1, "s": -1},
}

_AXES = (("X", "m", "platform displacement along X"), ("Z", "m", "platform displacement along Z"),
         ("B", "rad", "platform rotation about Y"))
_RATE = {"m": "m/s", "rad": "rad/s"}
_ACC = {"m": "m/s2", "rad": "rad/s2"}

_MODEL_DOC = {
    "m_p": ("kg", "platform mass"), "m_1": ("kg", "left auxiliary block (mover 1) mass"),
    "m_2": ("kg", "middle auxiliary block (mover 2) mass"),
    "m_3": ("kg", "right auxiliary block (mover 3) mass"),
    "I_y": ("kg.m2", "platform moment of inertia about Y"), "L_1": ("m", "platform width"),
    "g": ("m/s2", "gravitational acceleration"),
}


def _model_params(whose: str, variability: str) -> list[Var]:
    return [Var(n, "parameter", _MODEL_DOC[n][0], f"{whose} {_MODEL_DOC[n][1]} (paper Section 5.1)",
                getattr(PAPER_MODEL, n), variability=variability) for n in PAPER_MODEL._fields]


def _pose(suffix: str, causality: str, what: str) -> list[Var]:
    out = []
    for order, units in ((0, None), (1, _RATE), (2, _ACC)):
        for axis, unit, desc in _AXES:
            prefix = ("", "d", "dd")[order]
            kind = ("", "rate of ", "acceleration of ")[order]
            out.append(Var(f"{prefix}{axis}{suffix}", causality, units[unit] if units else unit,
                           f"{what} {kind}{desc}" if what else f"{kind}{desc}"))
    return out


_CFG = PlantConfig()
# The plant's default initial state (X0, Z0, B0 [m, m, rad], dX0, dZ0, dB0 [m/s, m/s, rad/s]):
# the default reference's pose and velocity at the DefaultExperiment's start, so that the three
# FMUs wired with their defaults run the paper's simulation (scenarios/paper_simulation.toml,
# start_on_trajectory) with no start transient. The readable circle formula gives the same
# doubles as the C model's tapmp_reference (dZ0 is -0.0), without loading the C library here.
INITIAL_STATE: tuple[float, ...] = circle_reference(START_TIME, TrajectoryParams())[:6]
_PLANT_CFG_DOC = {
    "encoder_resolution": ("m", "encoder (grating ruler) resolution of the measured q; 0 = no quantization"),
    "c_v1": ("N.s/m", "viscous friction coefficient of mover 1"),
    "c_v2": ("N.s/m", "viscous friction coefficient of mover 2"),
    "c_v3": ("N.s/m", "viscous friction coefficient of mover 3"),
    "F_c1": ("N", "Coulomb friction force of mover 1"), "F_c2": ("N", "Coulomb friction force of mover 2"),
    "F_c3": ("N", "Coulomb friction force of mover 3"),
    "v_s": ("m/s", "velocity scale of the tanh-smoothed Coulomb friction"),
    "force_limit": ("N", "motor force saturation |F_i| <= force_limit; 0 = no saturation"),
    "k_pull": ("N/m", "mutual pulling stiffness between adjacent movers on the change of gap q2-q1, q3-q2 "
                      "(> 0 restoring, < 0 negative stiffness); 0 = off"),
    "attraction_force": ("N", "magnetic attraction between adjacent movers at the initial gap, "
                              "attraction_force (g_a/g)^2 pulling each pair together; 0 = off"),
    "attraction_gap": ("m", "clear gap g_a between adjacent movers at the initial pose (attraction law)"),
    "cogging_amplitude": ("N", "force ripple (cogging) amplitude, A sin(2 pi q_i/cogging_pitch + phase_i); 0 = off"),
    "cogging_pitch": ("m", "force ripple (cogging) period in the motor position"),
    "cogging_phase1": ("rad", "force ripple (cogging) phase of motor 1"),
    "cogging_phase2": ("rad", "force ripple (cogging) phase of motor 2"),
    "cogging_phase3": ("rad", "force ripple (cogging) phase of motor 3"),
    **{f"disturbance_force{i}": ("N", f"external force step on mover {i} from disturbance_time on (not limited "
                                      "by force_limit); 0 = off") for i in (1, 2, 3)},
    "disturbance_time": ("s", "time at which the external force step starts"),
    "noise_rms": ("m", "measurement noise: rms of the white Gaussian noise added to each measured position "
                       "before quantization; 0 = off"),
}

_FLEX_DOC = {
    "flex_frequency": ("Hz", "natural frequency of the platform's flexible mode in Z (flex_mass on a spring-damper "
                             "to the rest of the platform, the platform held still); 0 = off (rigid platform)"),
    "flex_damping": ("1", "damping ratio of the platform's flexible mode"),
    "flex_mass": ("kg", "modal mass of the platform's flexible mode: the part of m_p that moves on it (< m_p)"),
}

PLANT_VARS: tuple[Var, ...] = tuple(
    [Var(f"F{i}", "input", "N", f"force command of motor {i}") for i in (1, 2, 3)]
    + [Var(f"q{i}", "output", "m", f"measured (encoder-quantized) position of motor {i}") for i in (1, 2, 3)]
    + [Var(f"q{i}_true", "output", "m", f"true position of motor {i}") for i in (1, 2, 3)]
    + [Var(f"dq{i}", "output", "m/s", f"velocity of motor {i}") for i in (1, 2, 3)]
    + [v for v in _pose("", "output", "")[:6]]
    + _model_params("plant", "fixed")
    + [Var(f"{a}0", "parameter", u, f"initial {d} (default: the reference's at the start time)",
           x, variability="fixed") for (a, u, d), x in zip(_AXES, INITIAL_STATE[:3])]
    + [Var(f"d{a}0", "parameter", _RATE[u], f"initial rate of {d} (default: the reference's at the start time)",
           x, variability="fixed") for (a, u, d), x in zip(_AXES, INITIAL_STATE[3:])]
    + [Var(n, "parameter", u, d, getattr(_CFG, n), variability="fixed") for n, (u, d) in _PLANT_CFG_DOC.items()]
    + [Var("substeps", "parameter", "", "RK4 integration steps per communication step (>= 1)",
           _CFG.substeps, type="Integer", variability="fixed"),
       Var("noise_seed", "parameter", "", "seed of the measurement noise (the same seed gives the same noise "
           "in every FMU family)", _CFG.noise_seed, type="Integer", variability="fixed")]
    + [Var(n, "parameter", u, d, getattr(_CFG, n), variability="fixed") for n, (u, d) in _FLEX_DOC.items()]
)

# Gains act on the command u (command units, K_T F = u); "{i}" is the motor number (tapmp.settings).
GAIN_DOC = settings.gain_doc()
_DEFAULT_GAINS = GAIN_PRESETS["default"]
_MODAL_DOC = settings.modal_doc()

CONTROLLER_VARS: tuple[Var, ...] = tuple(
    _pose("_d", "input", "desired")
    + [Var(f"q{i}", "input", "m", f"measured position of motor {i}") for i in (1, 2, 3)]
    + [Var(f"dq{i}", "input", "m/s", f"measured velocity of motor {i} (used if velocity_source = 1)")
       for i in (1, 2, 3)]
    + [Var(f"F{i}", "output", "N", f"force command of motor {i}, F{i} = u{i}/K_T{i} (limited to "
           "force_limit), held between samples") for i in (1, 2, 3)]
    + [Var(f"u{i}", "output", "1", f"control command u of motor {i} (Eq. 25, 38 or PID-DC) in command "
           f"units, K_T{i} F{i} = u{i}") for i in (1, 2, 3)]
    + [Var(f"e{i}", "output", "m", f"tracking error e = q_d - q of motor {i} (Eq. 15)") for i in (1, 2, 3)]
    + [Var(f"es{i}", "output", "m", f"synchronization error of motor {i} (Eq. 18)") for i in (1, 2, 3)]
    + [Var(f"{n}{i}", "parameter", GAIN_DOC[n][0], GAIN_DOC[n][1].format(i=i),
           _DEFAULT_GAINS[n][i - 1], variability="tunable") for n in GAIN_NAMES for i in (1, 2, 3)]
    + [Var("law", "parameter", "", laws.setting_description(), 0, type="Integer", variability="tunable"),
       Var("velocity_source", "parameter", "",
           "joint velocity: 0 = backward difference of q over the time between samples, 1 = dq inputs", 0,
           type="Integer", variability="tunable"),
       Var("force_limit", "parameter", "N", "force command limit |F_i| <= force_limit; 0 = no limit",
           0.0, variability="tunable")]
    + _model_params("controller nominal", "fixed")
    + [Var(n, "parameter", _MODAL_DOC[n][0], _MODAL_DOC[n][1], DEFAULT_MODAL_GAINS[n], variability="tunable")
       for n in MODAL_GAIN_NAMES]
    + [Var("T_s", "parameter", "s", "sample period: the controller samples only at communication points on "
           "its grid t0 + k T_s (within 1e-4 T_s; t0 = start time) and holds its outputs in between; the "
           "velocity estimate and the integral use the time between samples, (k - k_prev) T_s, never the "
           "host's step; a host whose steps skip sample instants gets one logged warning", SERVO_STEP,
           variability="fixed"),
       Var("anti_windup", "parameter", "", "anti-windup of the integral (SC-DC's of c, PID-DC's of e) at this "
           "controller's force_limit (it cannot read the plant's: set it, e.g. to the plant's 600 N): 0 = off, 1 = "
           "conditional integration (a motor beyond the limit does not integrate an error that drives it further "
           "out), 2 = back-calculation (its integral term is pulled back toward the limit with the time constant "
           "anti_windup_time)", 0, type="Integer", variability="tunable"),
       Var("anti_windup_time", "parameter", "s", "tracking time constant T_t of the back-calculation "
           "(anti_windup = 2): each sample takes back the fraction 1 - exp(-(k - k_prev) T_s / T_t) of the command "
           "beyond force_limit from the integral term", ANTI_WINDUP_TIME, variability="tunable")]
)

_TP = TrajectoryParams()
_TRAJ_DOC = {
    "X_c": ("m", "circle centre X"), "Z_c": ("m", "circle centre Z"), "radius": ("m", "circle radius"),
    "f_xz": ("Hz", "circle frequency"), "phase_xz": ("rad", "circle phase (0 = top of the circle)"),
    "B_amplitude": ("rad", "B sinusoid amplitude"), "f_B": ("Hz", "B sinusoid frequency"),
    "phase_B": ("rad", "B sinusoid phase"), "B_offset": ("rad", "B sinusoid offset"),
    "profile": ("", "reference: 0 = XZ circle and B sinusoid, 1 = step, 2 = ramp, 3 = jerk-limited S-curve "
                    "from pose A to pose B"),
    **{f"{a}_{w}": (u, f"point-to-point move {what} pose {a}") for w, what in (("a", "start"), ("b", "end"))
       for a, u in (("X", "m"), ("Z", "m"), ("B", "rad"))},
    "t_move": ("s", "time the point-to-point move starts (the reference rests at pose A before)"),
    **{f"{k}_max_{a}": (u, f"point-to-point {what} limit of axis {a} (> 0)")
       for k, what, units in (("v", "velocity", ("m/s", "rad/s")), ("a", "acceleration", ("m/s2", "rad/s2")),
                              ("j", "jerk", ("m/s3", "rad/s3")))
       for a, u in (("X", units[0]), ("Z", units[0]), ("B", units[1]))},
}
_TRAJ_INTEGER = {"profile"}

TRAJECTORY_VARS: tuple[Var, ...] = tuple(
    _pose("_d", "output", "desired")
    + [Var(f"q{i}_d", "output", "m", f"desired position of motor {i} (inverse kinematics, Eq. 2)")
       for i in (1, 2, 3)]
    + [Var(n, "parameter", u, d, getattr(_TP, n), variability="fixed",
           type="Integer" if n in _TRAJ_INTEGER else "Real") for n, (u, d) in _TRAJ_DOC.items()]
    + [Var("L_1", "parameter", "m", "platform width used for q_d", PAPER_MODEL.L_1, variability="fixed")]
)

# The one range rule of every parameter, by name (the same name means the same quantity in
# every model): min <= value <= max, so NaN and infinities are refused too. The bounds keep each
# model's arithmetic finite: with errors within the motor travel, no product of these values
# overflows a double. Every FMU family writes them into modelDescription.xml as min/max and
# checks them with the C model's generated checks (settings_check_source), which the Python
# model, scenarios, studies and `tapmp check` run too: at fmi2SetReal for a tunable parameter in
# Step Mode, else when the model is set up.
# Masses from 1e-12: the paper-gain reading (orchestrator/paper/paper_gains.py) gives the
# controller its nominal masses times K_T, e.g. I_y K_T = 3.2e-7 in command units.
_MASS = (1e-12, 1e6)
RANGES: dict[str, tuple[float, float]] = {
    "m_p": _MASS, "m_1": _MASS, "m_2": _MASS, "m_3": _MASS, "I_y": _MASS, "L_1": (1e-6, 1e3),
    "g": (1e-6, 1e6),
    "X0": (-1.0, 1.0), "Z0": (-1.0, 1.0), "B0": (-1.5, 1.5),
    "dX0": (-1e3, 1e3), "dZ0": (-1e3, 1e3), "dB0": (-1e3, 1e3),
    "encoder_resolution": (0.0, 1.0), "c_v1": (0.0, 1e9), "c_v2": (0.0, 1e9), "c_v3": (0.0, 1e9),
    "F_c1": (0.0, 1e9), "F_c2": (0.0, 1e9), "F_c3": (0.0, 1e9), "v_s": (1e-12, 1e3),
    "force_limit": (0.0, 1e9), "k_pull": (-1e12, 1e12),
    "attraction_force": (0.0, 1e6), "attraction_gap": (1e-6, 1.0),
    "cogging_amplitude": (0.0, 1e6), "cogging_pitch": (1e-6, 1.0),
    "cogging_phase1": (-1e6, 1e6), "cogging_phase2": (-1e6, 1e6), "cogging_phase3": (-1e6, 1e6),
    "disturbance_force1": (-1e6, 1e6), "disturbance_force2": (-1e6, 1e6), "disturbance_force3": (-1e6, 1e6),
    "disturbance_time": (0.0, 1e9), "noise_rms": (0.0, 1e-3), "noise_seed": (0, 2147483647),
    # one doStep runs substeps RK4 steps and cannot be interrupted: bounded so that it
    # stays below a millisecond of CPU per step or so
    "substeps": (1, 10000),
    # the mode's frequency up to 100 kHz: RK4 stays stable for 2 pi f h / substeps < 2.8
    "flex_frequency": (0.0, 1e5), "flex_damping": (0.0, 10.0), "flex_mass": (0.0, 1e6),
    **settings.ranges(),
    "law": laws.C_RANGE, "velocity_source": (0, 1), "T_s": (1e-9, 1e3),
    "anti_windup": (0, 2), "anti_windup_time": (1e-9, 1e3),
    "X_c": (-1.0, 1.0), "Z_c": (-1.0, 1.0), "radius": (0.0, 1.0), "f_xz": (0.0, 1e4),
    "phase_xz": (-1e6, 1e6), "B_amplitude": (0.0, 1.5), "f_B": (0.0, 1e4), "phase_B": (-1e6, 1e6),
    "B_offset": (-1.5, 1.5),
    "profile": (0, 3), "X_a": (-1.0, 1.0), "Z_a": (-1.0, 1.0), "B_a": (-1.5, 1.5),
    "X_b": (-1.0, 1.0), "Z_b": (-1.0, 1.0), "B_b": (-1.5, 1.5), "t_move": (0.0, 1e6),
    # > 0: a zero limit would make the move endless; the upper bounds keep a move's times finite
    **{f"{k}_max_{a}": (1e-12, 1e9) for k in "vaj" for a in "XZB"},
    # the drive (TAPMP_Drive): its delay buffer holds 3 commands; a current loop up to 100 kHz, far above any
    # drive's, and damped (> 0: stable); a motor's force constant from 0.1 to 2 times the nominal one
    "delay_samples": (0, 3), "current_bandwidth": (0.0, 1e5), "current_damping": (0.01, 10.0),
    **{f"force_constant_error{i}": (-0.9, 1.0) for i in (1, 2, 3)},
}


# Each model's C settings struct (tapmp_model.h, ModelRecord.settings_struct), with a parameter's
# member in it (Var.field).
SETTINGS_STRUCT = _ByModel("settings_struct")
_ARRAYS = ("c_v", "F_c", "cogging_phase", "disturbance_force", *GAIN_NAMES)  # per-motor C arrays [3]
_INITIAL = ("X0", "Z0", "B0", "dX0", "dZ0", "dB0")
_CHOICES = {"law": laws.choices_text(),
            "velocity_source": "0 (backward difference of q) or 1 (dq inputs)",
            "anti_windup": "0 (off), 1 (conditional integration) or 2 (back-calculation)",
            "profile": "0 (circle and sinusoid), 1 (step), 2 (ramp) or 3 (S-curve)"}


def _field(model: str, name: str) -> str:
    """The member of SETTINGS_STRUCT[model] that holds the parameter ``name``."""
    if name[:-1] in _ARRAYS:                      # c_v1 -> c_v[0], D3 -> D[2]
        member = f"{name[:-1]}[{int(name[-1]) - 1}]"
    elif name[1:].startswith("_max_"):            # v_max_Z -> v_max[1]
        member = f"{name[:5]}[{'XZB'.index(name[-1])}]"
    elif name in _INITIAL:                        # X0 -> pose[0], dB0 -> rate[2]
        member = f"{'rate' if name[0] == 'd' else 'pose'}[{'XZB'.index(name[-2])}]"
    else:
        member = name
    if model == TRAJECTORY:
        return member
    if name in PAPER_MODEL._fields:
        return f"p.{member}"
    if model == PLANT:
        return f"x0.{member}" if name in _INITIAL else f"c.{member}"
    return f"k.{member}" if name in ("law", "velocity_source", "force_limit", "T_s", "anti_windup",
                                     "anti_windup_time") else f"g.{member}"


def _ranged(model: str, table: tuple[Var, ...]) -> tuple[Var, ...]:
    return tuple(v._replace(min=RANGES[v.name][0], max=RANGES[v.name][1], field=_field(model, v.name),
                            choices=_CHOICES.get(v.name, "")) if v.causality == "parameter" else v
                 for v in table)


# The connected outputs' values at the start of the paper's run (t = START_TIME, every FMU at its defaults,
# the outputs propagated in Initialization Mode): the start values of the inputs they feed, so that a host
# that initializes each FMU alone, in any order and without propagating, computes the paper run's first
# command and steps the plant with it. The reference is the circle formula's (the C trajectory's doubles);
# the encoder positions and joint velocities (the plant's at INITIAL_STATE) and the first command (the
# controller's from those) are the C models' doubles, written out here because this table must not load
# the C library, and compared with the models' own outputs by tests/fmu/test_start_values.py.
START_OUTPUTS: dict[str, float] = {
    **{v.name: x for v, x in zip(_pose("_d", "output", ""), circle_reference(START_TIME, TrajectoryParams()))},
    "q1": 0.0, "q2": 0.0, "q3": 0.0,
    "dq1": 0.03652917874424646, "dq2": 0.025132741228718346, "dq3": 0.03652917874424646,
    "F1": 15.319857683838286, "F2": 1.7763568394002505e-15, "F3": -15.319889823145402,
}


def _started(table: tuple[Var, ...]) -> tuple[Var, ...]:
    """``table`` with every input starting at the value of the output connected to it (START_OUTPUTS)."""
    return tuple(v._replace(start=START_OUTPUTS[v.name]) if v.causality == "input" else v for v in table)


PLANT_VARS, CONTROLLER_VARS = _started(PLANT_VARS), _started(CONTROLLER_VARS)

# The servo drive between controller and plant (TAPMP_Drive, fmu_plant/drive.c; docs/native-fmus.md). Its
# defaults are a typical drive's: one sample of computation delay, a 2 kHz current loop damped 0.7, no
# force-constant error and the plant's own force limit. The force-constant error is per motor: the motors'
# mismatch is what the synchronization controller sees.
DRIVE_DEFAULTS = {"delay_samples": 1, "current_bandwidth": 2000.0, "current_damping": 0.7,
                  **{f"force_constant_error{i}": 0.0 for i in (1, 2, 3)}, "force_limit": _CFG.force_limit}
DRIVE_VARS: tuple[Var, ...] = tuple(
    [Var(f"F_cmd{i}", "input", "N", f"force command of motor {i} (the controller's F{i})",
         START_OUTPUTS[f"F{i}"]) for i in (1, 2, 3)]
    + [Var(f"F{i}", "output", "N", f"force of motor {i}: (1 + force_constant_error{i}) times the mean over the "
           "communication step of the current loop's force, driven by the command of delay_samples steps before, "
           "limited to force_limit; held over the step") for i in (1, 2, 3)]
    + [Var("delay_samples", "parameter", "", "computation delay in communication steps (servo cycles) from "
           "command to current loop", DRIVE_DEFAULTS["delay_samples"], type="Integer", variability="fixed"),
       Var("current_bandwidth", "parameter", "Hz", "natural frequency f_n of the second-order current (force) "
           "loop (the -3 dB frequency at damping 0.707, 1.01 f_n at 0.7); 0 = ideal loop (force = command)",
           DRIVE_DEFAULTS["current_bandwidth"], variability="fixed"),
       Var("current_damping", "parameter", "1", "damping ratio of the current (force) loop",
           DRIVE_DEFAULTS["current_damping"], variability="fixed")]
    + [Var(f"force_constant_error{i}", "parameter", "1", f"relative error of motor {i}'s force constant: its "
           f"force is (1 + error) times the loop's (0.05 = +5 %)", 0.0, variability="fixed") for i in (1, 2, 3)]
    + [Var("force_limit", "parameter", "N", "current (force) limit on the command before the current loop, "
           "|command| <= force_limit; 0 = no limit", DRIVE_DEFAULTS["force_limit"], variability="fixed")]
)
DRIVE_VARS = tuple(v._replace(min=RANGES[v.name][0], max=RANGES[v.name][1]) if v.causality == "parameter" else v
                   for v in DRIVE_VARS)
PLANT_VARS, CONTROLLER_VARS, TRAJECTORY_VARS = (_ranged(m, t) for m, t in (
    (PLANT, PLANT_VARS), (CONTROLLER, CONTROLLER_VARS), (TRAJECTORY, TRAJECTORY_VARS)))
VARIABLES = _ByModel("variables")  # {model: its Var rows}, from the records


def connections(extra: str = "") -> tuple[tuple[str, str, str, str], ...]:
    """(source model, source variable, destination model, destination variable) of every connected
    input: each record's ``sources`` (input -> (model, output)), in registry and variable order; with the
    optional model ``extra`` inserted, the inputs it feeds (its record's ``feeds``) come from it."""
    feeds = {key: (extra, output) for key, output in record(extra).feeds.items()} if extra else {}
    return tuple((*feeds.get((r.name, v.name), r.sources.get(v.name, ())), r.name, v.name)
                 for r in system_models(extra) for v in r.variables
                 if v.causality == "input" and (v.name in r.sources or (r.name, v.name) in feeds))


class _Connections(Sequence):
    """:func:`connections`, read when used."""

    def __getitem__(self, i):
        return connections()[i]

    def __len__(self):
        return len(connections())

    def __repr__(self):
        return repr(connections())


# The TAPMP loop's inputs, by the output that feeds each (the records' sources, tapmp.records).
CONTROLLER_SOURCES = {**{v.name: (TRAJECTORY, v.name) for v in TRAJECTORY_VARS[:9]},
                      **{f"{d}q{i}": (PLANT, f"{d}q{i}") for d in ("", "d") for i in (1, 2, 3)}}
PLANT_SOURCES = {f"F{i}": (CONTROLLER, f"F{i}") for i in (1, 2, 3)}
# The drive's system: the controller's commands into the drive, the drive's forces into the plant.
DRIVE_SOURCES = {f"F_cmd{i}": (CONTROLLER, f"F{i}") for i in (1, 2, 3)}
DRIVE_FEEDS = {(PLANT, f"F{i}"): f"F{i}" for i in (1, 2, 3)}


def step_order(extra: str) -> list[str]:
    """The elements of the system with the optional model ``extra`` in the Gauss-Seidel order it must step in:
    the controller (the loop's sampler) first, ``extra`` next, then the models it feeds, then the others in
    registry order. ``extra`` declares no direct feedthrough (its output after doStep(t, h) is held over the
    step, like the controller's), so a master ordering by the declared dependencies would step its consumers
    first, on its output of the step before."""
    fed = list(dict.fromkeys(model for model, _ in record(extra).feeds))
    first = [CONTROLLER, extra, *fed]
    return [record(m).element for m in first] + [r.element for r in system_models(extra) if r.name not in first]
CONNECTIONS = _Connections()


# --- Model structure: what every output depends on (FMI <ModelStructure>) ---------------
# One definition for every family's modelDescription.xml and the container FMU's. Knowns are
# named as variables; TIME is the independent variable, which the FMI 3.0 FMUs and the
# container declare (FMI 2.0 FMUs declare none, so it is left out of theirs).
TIME = "time"


class Dependencies(NamedTuple):
    """The knowns one output depends on, by name, in the order of the variable table."""

    step: tuple[str, ...]     # at a communication point (<Outputs>/<Output>): inputs, time
    initial: tuple[str, ...]  # in Initialization Mode (<InitialUnknowns>): inputs, parameters, time


def _ordered(table, names) -> tuple[str, ...]:
    wanted = set(names)
    return tuple(v.name for v in table if v.name in wanted) + ((TIME,) if TIME in wanted else ())


def _pose_inputs(motor: int, prefix: str = "", suffix: str = "_d") -> set:
    """Pose variables that motor ``motor``'s position (Eq. 2) or rate (Eq. 3) reads: q2 = X
    and dq2 = dX; motors 1 and 3 read X, Z and B (rates: dX, dZ, dB and B)."""
    names = {f"{prefix}X{suffix}"} if motor == 2 else {f"{prefix}{a}{suffix}" for a in "XZB"}
    return names | ({f"B{suffix}"} if prefix and motor != 2 else set())


def _controller_dependencies(name: str) -> Dependencies:
    """No output depends on an input at the same communication point: the outputs change only
    in doStep (sampled at t, held after). In Initialization Mode the outputs are computed from
    the inputs (advance = False: the dq inputs, no integral) and the parameters."""
    table = CONTROLLER_VARS
    i = int(name[-1])
    if name[0] in "Fu":
        # u_d (Eq. 26) reads the whole pose and every measured rate; the laws couple the motors
        # through the errors (c, Eq. 21; the modal means of PID-DC) but each motor has its own
        # gains and only its own block mass in its feedforward. The integral is zero initially,
        # so the integral gains ki_c, ki_d do not enter.
        initial = {v.name for v in table if v.causality == "input"}
        initial |= {"m_p", f"m_{i}", "I_y", "L_1", "g", "law"}
        initial |= {n for n in MODAL_GAIN_NAMES if not settings.SETTING[n].integral} | {f"{n}{i}" for n in GAIN_NAMES}
        if name[0] == "F":
            initial.add("force_limit")
    elif name[1] == "s":  # es_i = e_i - e_(i+1) (Eq. 18), as computed: X_d cancels only to round-off
        initial = {"X_d", "Z_d", "B_d", f"q{i}", f"q{i % 3 + 1}", "L_1"}
    else:  # e_i = q_d,i - q_i (Eq. 15, q_d by Eq. 2)
        initial = _pose_inputs(i) | {f"q{i}"} | ({"L_1"} if i != 2 else set())
    return Dependencies((), _ordered(table, initial))


def _plant_dependencies(name: str) -> Dependencies:
    """Outputs come from the plant's state only (RK4 over doStep with the F of the step), so
    none depends on an input at a communication point; initially they come from the initial
    pose X0, Z0, B0 and rates dX0, dZ0, dB0 through the kinematics (Eq. 2-3)."""
    i = "".join(c for c in name if c.isdigit())  # the motor of q, q_true and dq
    if not i:  # the pose X, Z, B and its rates
        initial = {f"{name}0"}
    elif name.startswith("dq"):
        initial = _pose_inputs(int(i), "d", "0") | ({"L_1"} if i != "2" else set())
    else:  # q (measured: plus the noise of sample 0, quantized to encoder_resolution) and q_true
        initial = _pose_inputs(int(i), "", "0") | ({"L_1"} if i != "2" else set())
        if not name.endswith("_true"):
            initial |= {"encoder_resolution", "noise_rms", "noise_seed"}
    return Dependencies((), _ordered(PLANT_VARS, initial))


def _drive_dependencies(name: str) -> Dependencies:
    """The drive's forces change only in doStep, as the controller's commands (sampled at t, held over the
    step): none depends on an input at a communication point. Initially each is its motor's command,
    limited and scaled by its force constant."""
    i = name[-1]
    return Dependencies((), _ordered(DRIVE_VARS, {f"F_cmd{i}", "force_limit", f"force_constant_error{i}"}))


def _trajectory_dependencies(name: str) -> Dependencies:
    """The reference is a function of time: every output depends on time, at every
    communication point and initially, and on the trajectory's parameters (the width L_1
    only through the motor positions q_d)."""
    params = {v.name for v in TRAJECTORY_VARS if v.causality == "parameter"}
    if not (name.startswith("q") and name.endswith("_d")):
        params.discard("L_1")
    return Dependencies((TIME,), _ordered(TRAJECTORY_VARS, params | {TIME}))


def dependencies(model: str) -> dict[str, Dependencies]:
    """{output name: Dependencies} of ``model``: what each output depends on at a communication
    point and in Initialization Mode, as the FMUs of every family compute it."""
    depends = record(model).dependencies
    return {v.name: depends(v.name) for v in VARIABLES[model] if v.causality == "output"}


def dependency_attributes(names, reference: dict, position: dict | None = None) -> dict:
    """The XML attributes ``dependencies`` and ``dependenciesKind`` of one ModelStructure
    unknown: the knowns among ``names`` that the modelDescription declares (``reference``:
    name -> index (FMI 2.0) or value reference (FMI 3.0)), ordered by their place in
    ModelVariables (``position``: name -> place; default the reference itself). An empty
    list is written as dependencies="" (depends on no known); every listed known is
    "dependent" (no particular structure, the only kind valid for initial unknowns too)."""
    position = position or reference
    known = sorted((n for n in names if n in reference), key=lambda n: position[n])
    if not known:
        return {"dependencies": ""}
    return {"dependencies": " ".join(str(reference[n]) for n in known),
            "dependenciesKind": " ".join("dependent" for _ in known)}
