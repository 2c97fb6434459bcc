"""Scenarios: one TOML file each, validated before anything runs.

Top-level keys: name, description, law ("sc-dc", "apd-dc" or "pid-dc"), gains (a preset of
tapmp.params.GAIN_PRESETS), gains_file (a gain preset file, see load_gain_file; it
replaces the preset named by gains), stop_time, start_time, step, ordering, output,
start_on_trajectory, record_every (store every Nth step in results.csv; metrics
always use every step), clock and connection_start (conventions of other masters, see
orchestrator.engine.master; e.g. ordering = "jacobi" with clock = "accumulated" is Ecos's),
open_inputs (a list of "element.variable" FMU inputs that no connection of the SSP
drives, deliberately: they keep their start values; the master refuses any other
undriven input, and an entry that is no input of the system or that a connection drives),
fmus (the FMU family whose built SSP a run uses: "native" (default), "fmi3" or "python";
see orchestrator.builder.families; `--fmus` and `--ssp` on the command line override it),
format (the result file: "csv" (default) or "mat", see orchestrator.tool.results;
`--format` overrides it), plant_interface (the plant FMU's interface: "cs", Co-Simulation with its own
RK4 (default), or "me", Model Exchange integrated by the master with CVODE, see
orchestrator.engine.model_exchange; the native FMUs offer it), settling_bands (the bands of the move
metrics of a point-to-point run, trajectory.profile 1-3, see orchestrator.tool.metrics.MoveMetrics; default
[1e-6, 1e-7], in m, rad for B). output is the scenario's result folder (default
results/<name>): `tapmp run` writes into output/<law>, `tapmp compare` into output/compare.
Tables: [gain_overrides] (Lambda_p, Lambda_v, b, D, K_T as a
number or a list of three), [trajectory], [plant] and [controller] with the
parameters of the respective FMU (names as in its modelDescription.xml), and
[limits] (the divergence envelope, see LIMITS), [mismatch] (the controller's model
error, see MISMATCH_RANGE and docs/disturbances.md). drive = true (or a [drive] table of the drive's
settings, DRIVE_PARAMS) puts the servo drive TAPMP_Drive between controller and plant (docs/native-fmus.md).
"""

import copy
import dataclasses
import math
import re
from dataclasses import field
import sys
from pathlib import Path
from typing import Annotated

from pydantic import BeforeValidator, model_validator
from pydantic.dataclasses import dataclass

from tapmp.control import Gains, ModalGains
from tapmp.errors import ModelInputError, suggestion
from tapmp import cmodel
# ORDERINGS: the model's (tapmp.closed_loop's), which the master's own (engine.schedule) equals (a test)
from tapmp.interface import (CONTROLLER, DRIVE_VARS, ELEMENT, ORDERINGS, PLANT, TRAJECTORY, VARIABLES, allowed_text,
                             step_order)
from tapmp.models import DRIVE
from tapmp.laws import C_IDS
from tapmp.params import ANTI_WINDUP_TIME, GAIN_NAMES, GAIN_PRESETS, ModelParams
from tapmp.plant import PlantConfig
from tapmp.trajectory import PROFILES, TrajectoryParams, move_duration, reference

from ..engine.clocks import CLOCKS, nanoseconds_problem
from ..builder.families import FAMILIES, with_drive
from ..engine.schedule import CONNECTION_STARTS
from ..errors import UserError
from .folders import RESULT_FORMATS
from .roles import ROLES
from .config import build, check_type, is_number, known, one_of, read_toml, require, rule, three_numbers

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

LAWS = C_IDS  # law -> the controller's law setting (tapmp.laws); PID-DC: modal gains in [controller] kp_c .. ki_d
# [mismatch]: relative model error of the controller's nominal parameters. For each listed
# field of tapmp.params.ModelParams the controller gets (plant value) x factor; the plant
# keeps its own. A factor within MISMATCH_RANGE; not together with [controller] NAME.
MISMATCH_RANGE = (0.01, 100.0)
# The top-level keys of a scenario file and their TOML types (checked strictly when read).
TOP = {"name": str, "description": str, "law": str, "gains": str, "gains_file": str, "stop_time": float,
       "start_time": float, "step": float, "ordering": str, "output": str,
       "start_on_trajectory": bool, "record_every": int, "clock": str, "connection_start": str,
       "open_inputs": list, "fmus": str, "format": str, "settling_bands": list, "event_mode": bool,
       "plant_interface": str}
# The plant's FMI interface in a run: "cs" (Co-Simulation, its own RK4) or "me" (Model Exchange,
# integrated by the master with CVODE: orchestrator.engine.model_exchange)
PLANT_INTERFACES = ("cs", "me")
TABLES = {"gain_overrides", "trajectory", "plant", "controller", "limits", "mismatch"}
# The divergence envelope the master checks every step (0 switches a limit off):
# |q_i| of every motor (true position) and |B| of the platform. The paper's motion
# needs 20 mm of travel and 5 deg; a breach means the loop is running away.
LIMITS = {"motor_travel": (0.05, "m", "largest |q1|, |q2|, |q3| (true motor positions)"),
          "platform_angle": (0.35, "rad", "largest |B| of the platform")}
# Parameters a scenario may set per section; the controller's gains, law and the
# plant's initial state are set through the scenario's own keys instead.
SECTION_PARAMS = {
    "trajectory": {v.name: v for v in VARIABLES[TRAJECTORY] if v.causality == "parameter"},
    "plant": {v.name: v for v in VARIABLES[PLANT] if v.causality == "parameter"},
    "controller": {v.name: v for v in VARIABLES[CONTROLLER] if v.causality == "parameter"
                   and not v.name[:-1] in GAIN_NAMES and v.name not in ("law", "T_s")},
}
# drive = true, or a [drive] table of these settings: the servo drive between controller and plant
# (TAPMP_Drive, in the SSP TAPMP_Drive.ssp of the native families), stepped Gauss-Seidel in DRIVE_ORDER
DRIVE_PARAMS = {v.name: v for v in DRIVE_VARS if v.causality == "parameter"}
DRIVE_ORDER = step_order(DRIVE)  # controller, drive, plant, trajectory
# Set from the scenario's own keys, never in [controller]: the controller samples once per step.
_FROM_SCENARIO = {"law": "law", "T_s": "step"}
# The largest integer setting: an FMI Integer (int32), and for record_every far more steps than any run
# records, checked before the number reaches numpy or C.
MAX_INT = 2**31 - 1
STEP_TOLERANCE = 1e-9  # relative: how far (stop_time - start_time) / step may be from a whole number
_OPEN_INPUT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\.[^\s.][^\s]*")


def model_tuple(kind, table: dict):
    """A tapmp parameter NamedTuple of ``kind`` with the values of ``table`` over its defaults."""
    return kind(*(table.get(n, d) for n, d in zip(kind._fields, kind())))


class ScenarioError(ValueError, UserError):
    """A scenario file or value is invalid; the message names the key and what is allowed."""


def load_gain_file(path) -> dict:
    """Read a gain preset file: a TOML table [gains] with Lambda_p, Lambda_v, b, D, K_T,
    each a number or a list of three (per motor; units as in tapmp.control.Gains).

    Other top-level keys (e.g. law, objective, command) are kept as documentation only.
    Returns {name: (motor 1, motor 2, motor 3)}; ScenarioError names what is wrong.
    """
    path = Path(path)
    data = read_toml(path, f"gains_file = {str(path)!r}", ScenarioError,
                     allowed=": allowed is a TOML gain preset file with a [gains] table")
    table = data.get("gains")
    require(isinstance(table, dict), f"gains_file = {str(path)!r} has no [gains] table: allowed is a table with "
            f"{', '.join(GAIN_NAMES)}", ScenarioError)
    for name in GAIN_NAMES:
        require(name in table, f"gains_file {path}: gains.{name} is missing: allowed is a number or a list of 3 "
                "numbers", ScenarioError)
    preset = {}
    for name, v in table.items():
        known(name, GAIN_NAMES, f"gains_file {path}: gains.", ScenarioError)
        preset[name] = tuple(three_numbers(f"gains_file {path}: gains.{name}", v, ScenarioError))
    try:
        Gains.from_preset(preset).validated()
    except ModelInputError as err:
        raise ScenarioError(f"gains_file {path}: gains.{err}") from None
    return preset


# Field rules: each returns the checked value (a new table or list, numbers as their FMU type)
# or raises ValueError with the one-line message.

def _gain_overrides(table: dict) -> dict:
    out = {}
    for k, v in table.items():
        known(k, GAIN_NAMES, "gain_overrides.")
        out[k] = three_numbers(f"gain_overrides.{k}", v)
    return out


def _section(table: dict, info) -> dict:
    """[trajectory], [plant], [controller]: parameters of that FMU, as its Real or Integer."""
    section, allowed, out = info.field_name, SECTION_PARAMS[info.field_name], {}
    for k, v in table.items():
        if section == "controller" and k in _FROM_SCENARIO:
            key = _FROM_SCENARIO[k]
            raise ValueError(f"controller.{k} is set by the scenario's {key} = {info.data.get(key)!r}: "
                             f"allowed is to set {key}")
        known(k, allowed, f"{section}.")
        out[k] = check_type(f"{section}.{k}", v, int if allowed[k].type == "Integer" else float)
        if allowed[k].type == "Integer":  # before the value reaches C (fmi2Integer is an int32)
            require(-MAX_INT - 1 <= out[k] <= MAX_INT, f"{section}.{k} = {v!r} is invalid: allowed is an FMI "
                    f"Integer, from {-MAX_INT - 1} to {MAX_INT}")
    return out


def _drive(value) -> dict | None:
    """drive = true (the drive at its defaults), false (no drive) or a [drive] table of its settings (the drive
    with them): None (no drive) or {setting: value}, each within its range."""
    if value is None or value is False:
        return None
    if value is True:
        return {}
    require(isinstance(value, dict), f"drive = {value!r} is invalid: allowed is true, false or a [drive] table of "
            f"the drive's settings ({', '.join(DRIVE_PARAMS)})")
    out = {}
    for k, v in value.items():
        known(k, DRIVE_PARAMS, "drive.")
        var = DRIVE_PARAMS[k]
        out[k] = check_type(f"drive.{k}", v, int if var.type == "Integer" else float)
        require(var.min <= out[k] <= var.max, f"drive.{k} = {v!r} is invalid: allowed is {allowed_text(var)}")
    return out


def _mismatch(table: dict, info) -> dict:
    """[mismatch] names ModelParams fields with a factor in MISMATCH_RANGE, none also set in [controller]."""
    lo, hi = MISMATCH_RANGE
    controller, out = info.data.get("controller", {}), {}
    for k, v in table.items():
        known(k, ModelParams._fields, "mismatch.")
        v = out[k] = check_type(f"mismatch.{k}", v, float)
        require(math.isfinite(v) and lo <= v <= hi, f"mismatch.{k} = {v!r} is invalid: allowed is a factor in "
                f"[{lo:g}, {hi:g}] (controller value = plant value x factor)")
        require(k not in controller, f"mismatch.{k} = {v!r} conflicts with controller.{k} = {controller.get(k)!r}: "
                "allowed is one of them (the factor sets the controller's value)")
    return out


def _limits(table: dict) -> dict:
    out = {}
    for k, v in table.items():
        known(k, LIMITS, "limits.")
        v = out[k] = check_type(f"limits.{k}", v, float)
        require(math.isfinite(v) and v >= 0.0, f"limits.{k} = {v!r} is invalid: allowed is a number >= 0 "
                f"[{LIMITS[k][1]}] (0 = no limit)")
    return out


def _open_inputs(entries) -> list:
    """open_inputs is a list of distinct "element.variable" strings (whether each is an
    input of the system is checked by the master against the SSP)."""
    require(isinstance(entries, list), f"open_inputs = {entries!r} is invalid: allowed is a list of "
            "\"element.variable\" strings, e.g. [\"controller.dq1\"]")
    for i, entry in enumerate(entries):
        require(isinstance(entry, str) and _OPEN_INPUT.fullmatch(entry), f"open_inputs[{i}] = {entry!r} is "
                "invalid: allowed is \"element.variable\", an FMU input of the system, e.g. \"controller.dq1\"")
        require(entry not in entries[:i], f"open_inputs[{i}] = {entry!r} is listed twice: allowed is each input once")
    return list(entries)


def _order(order):
    """``order`` is a list of distinct element names (whether it names every element of the
    SSP exactly once is checked by the master)."""
    if order is None:
        return None
    require(isinstance(order, list) and order and all(isinstance(e, str) for e in order),
            f"order = {order!r} is invalid: allowed is a list of the SSP element names in the order they step, "
            "e.g. [\"controller\", \"plant\", \"trajectory\"]")
    twice = sorted({e for e in order if order.count(e) > 1})
    require(not twice, f"order = {order!r} names {', '.join(twice)} more than once: allowed is every element "
            "exactly once")
    return list(order)


def _elements(tables: dict) -> dict:
    """Every [ELEMENT] table is named like an SSP element and holds numbers or booleans
    (whether each is a parameter of that element's FMU is checked by the master)."""
    for element, table in tables.items():
        require(_OPEN_INPUT.fullmatch(f"{element}.x") and isinstance(table, dict), f"[{element}] is invalid: "
                "allowed is a table of FMU parameters named after an SSP element ([A-Za-z_][A-Za-z0-9_]*)")
        for k, v in table.items():
            if not isinstance(v, (int, float, bool)) or isinstance(v, float) and not math.isfinite(v):
                raise ValueError(f"{element}.{k} = {v!r} is invalid: allowed is a finite number, an integer or a "
                                 f"boolean (a parameter of the FMU of SSP element {element})"
                                 f"{suggestion(element, sorted(TABLES))}")
    return copy.deepcopy(tables)


def _settling_bands(bands) -> list:
    require(isinstance(bands, list) and bands, f"settling_bands = {bands!r} is invalid: allowed is a non-empty "
            "list of numbers > 0 [m; rad for B], e.g. [1e-6, 1e-7]")
    out = [check_type(f"settling_bands[{i}]", b, float) for i, b in enumerate(bands)]
    for i, b in enumerate(out):
        require(math.isfinite(b) and b > 0.0, f"settling_bands[{i}] = {b!r} is invalid: allowed is a finite "
                "number > 0 [m; rad for B]")
    return out


@dataclass
class Scenario:
    """A validated scenario: every field is checked by its rule when the scenario is made,
    then the rules that relate fields (_CROSS_CHECKS). Make one with create, from_dict or load
    (they report the first error as ScenarioError and read the gains_file)."""

    name: str
    description: str = ""
    law: Annotated[str, one_of(LAWS)] = "sc-dc"
    gains: Annotated[str, one_of(sorted(GAIN_PRESETS))] = "default"
    gains_file: str = ""
    gain_overrides: Annotated[dict, BeforeValidator(_gain_overrides)] = field(default_factory=dict)
    start_time: Annotated[float, rule(lambda v: is_number(v) and math.isfinite(v), "a finite number [s]")] = 0.0
    stop_time: Annotated[float, rule(lambda v: is_number(v) and math.isfinite(v), "a finite number [s]")] = 2.5
    step: Annotated[float, rule(lambda v: is_number(v) and math.isfinite(v) and v > 0.0, "a number > 0 [s]")] = 1e-4
    ordering: Annotated[str, one_of(ORDERINGS)] = "gauss-seidel"
    output: str = ""  # "" = results/<name>
    start_on_trajectory: bool = True
    clock: Annotated[str, one_of(CLOCKS)] = "exact"
    connection_start: Annotated[str, one_of(CONNECTION_STARTS)] = "propagated"
    # FMI 3.0 Event Mode: FMUs with hasEventMode get eventModeUsed; the master handles their time events and
    # ticks their input clocks (orchestrator.engine.master)
    event_mode: bool = False
    # the servo drive between controller and plant: None (none) or its settings ({} = its defaults)
    drive: Annotated[dict | None, BeforeValidator(_drive)] = None
    trajectory: Annotated[dict, BeforeValidator(_section)] = field(default_factory=dict)
    plant: Annotated[dict, BeforeValidator(_section)] = field(default_factory=dict)
    controller: Annotated[dict, BeforeValidator(_section)] = field(default_factory=dict)
    limits: Annotated[dict, BeforeValidator(_limits)] = field(default_factory=dict)
    # ModelParams field -> controller/plant factor
    mismatch: Annotated[dict, BeforeValidator(_mismatch)] = field(default_factory=dict)
    record_every: Annotated[int, rule(lambda v: is_number(v) and 1 <= v <= MAX_INT,
                                      f"an integer from 1 to {MAX_INT}")] = 1
    # "element.variable" inputs left undriven on purpose
    open_inputs: Annotated[list, BeforeValidator(_open_inputs)] = field(default_factory=list)
    # explicit Gauss-Seidel step order: every SSP element name once
    order: Annotated[list | None, BeforeValidator(_order)] = None
    # [ELEMENT] tables: FMU parameters by SSP element name
    elements: Annotated[dict, BeforeValidator(_elements)] = field(default_factory=dict)
    fmus: Annotated[str, one_of(FAMILIES)] = "native"  # FMU family: python, native or fmi3 (builder.families)
    plant_interface: Annotated[str, one_of(PLANT_INTERFACES)] = "cs"  # the plant as Co-Simulation or Model Exchange
    format: Annotated[str, one_of(RESULT_FORMATS)] = "csv"   # result file: csv or mat (RESULT_FORMATS)
    # point-to-point runs: settling bands [m for X, Z and the motors, rad for B] of the move metrics
    settling_bands: Annotated[list, BeforeValidator(_settling_bands)] = field(default_factory=lambda: [1e-6, 1e-7])
    source: str = ""
    # the gains_file's preset, filled by read_gains_file after validation
    gain_file_values: dict = field(default_factory=dict, repr=False)

    @model_validator(mode="after")
    def _cross_checks(self) -> "Scenario":
        for check in _CROSS_CHECKS:
            check(self)
        return self

    @property
    def n_steps(self) -> int:
        """Number of macro steps from start_time to stop_time."""
        return int(round((self.stop_time - self.start_time) / self.step))

    def limit_values(self) -> dict:
        """The divergence envelope {name: limit} with defaults from LIMITS (0 = off)."""
        return {k: self.limits.get(k, d[0]) for k, d in LIMITS.items()}

    def gain_values(self) -> Gains:
        """The preset (gains_file if given, else the named one) with the overrides applied."""
        preset = dict(self.gain_file_values if self.gains_file else GAIN_PRESETS[self.gains])
        for k, v in self.gain_overrides.items():
            preset[k] = tuple(v)
        return Gains.from_preset(preset)

    def with_changes(self, **changes) -> "Scenario":
        """A copy with top-level fields replaced (validated again, its gains_file read again)."""
        return create(**{**dataclasses.asdict(self), "gain_file_values": {}, **changes})

    def parameters(self) -> dict:
        """FMU parameters by SSP element name, ready for the master algorithm."""
        return self._parameters(gains=True)

    def _parameters(self, gains: bool) -> dict:
        """parameters(); without the controller's gains if not ``gains`` (a gains_file not read yet)."""
        traj = dict(self.trajectory)
        plant = dict(self.plant)
        if self.start_on_trajectory:
            ref = reference(self.start_time, model_tuple(TrajectoryParams, traj))
            for name, value in zip(("X0", "Z0", "B0", "dX0", "dZ0", "dB0"), ref[:6]):
                plant[name] = value
        ctrl = dict(self.controller)
        ctrl.update(self.mismatched_params())
        ctrl["law"] = LAWS[self.law]
        ctrl["T_s"] = self.step  # the controller's sample period: one sample per macro step
        for name, values in zip(GAIN_NAMES, self.gain_values() if gains else ()):
            for i, v in enumerate(values, start=1):
                ctrl[f"{name}{i}"] = v
        if "L_1" in self.controller and "L_1" not in traj:
            traj["L_1"] = self.controller["L_1"]  # q_d is the controller's view of the reference
        drive = {ELEMENT[DRIVE]: dict(self.drive)} if self.drive is not None else {}
        return {"trajectory": traj, "controller": ctrl, "plant": plant, **drive, **copy.deepcopy(self.elements)}

    def step_order(self) -> list | None:
        """The Gauss-Seidel step order: ``order``, else with the drive DRIVE_ORDER (the drive steps after the
        controller and before the plant, which uses its force of the step), else None (the master's own)."""
        if self.order is None and self.drive is not None and self.ordering == "gauss-seidel":
            return list(DRIVE_ORDER)
        return self.order

    def plain_models(self):
        """(PlantModel, ControllerModel, TrajectoryParams) with this scenario's parameters,
        for the FMI-free loop ``tapmp.closed_loop.simulate`` (same values the FMUs get)."""
        from tapmp.control import ControllerModel
        from tapmp.plant import PlantModel

        par = self.parameters()
        pl, ct, tr = par["plant"], par["controller"], par["trajectory"]
        plant = PlantModel(model_tuple(ModelParams, pl), model_tuple(PlantConfig, pl),
                           tuple(pl[k] for k in ("X0", "Z0", "B0")),
                           tuple(pl[k] for k in ("dX0", "dZ0", "dB0")))
        ctrl = ControllerModel(model_tuple(ModelParams, ct), self.gain_values(), ct["law"],
                               ct.get("velocity_source", 0), ct.get("force_limit", 0.0),
                               model_tuple(ModalGains, ct), ct["T_s"], self.start_time,
                               ct.get("anti_windup", 0), ct.get("anti_windup_time", ANTI_WINDUP_TIME))
        return plant, ctrl, model_tuple(TrajectoryParams, tr)

    def mismatched_params(self) -> dict:
        """The controller's nominal model parameters set by [mismatch]: {name: plant value x factor}."""
        plant = model_tuple(ModelParams, self.plant)
        return {n: getattr(plant, n) * f for n, f in self.mismatch.items()}

    def to_dict(self) -> dict:
        """The resolved scenario as plain data (for run.json)."""
        d = {k: copy.deepcopy(getattr(self, k)) for k in self.__dataclass_fields__}
        d["gain_values"] = self.gain_values()._asdict()
        d["n_steps"] = self.n_steps
        return d



# Rules that relate fields, in the order they are checked (after every field passed its own).

def _check_times(s: Scenario) -> None:
    """stop_time > start_time, and stop_time - start_time a whole number (>= 1) of steps: a run
    never goes past stop_time and never completes zero steps; otherwise the nearest valid stop
    times are named (or, where a double cannot tell them apart, that the grid cannot be
    represented there). With clock = "nanoseconds" every time must fit its int64 count."""
    require(s.stop_time > s.start_time,
            f"stop_time = {s.stop_time!r} is invalid: allowed is a number > start_time = {s.start_time!r} [s]")
    k = _whole_steps(s.start_time, s.stop_time, s.step)
    if k is None:
        n = (s.stop_time - s.start_time) / s.step
        lo, hi = max(1, math.floor(n)), max(1, math.ceil(n))
        nearest = sorted({t for t in (s.start_time + lo * s.step, s.start_time + hi * s.step)
                          if _whole_steps(s.start_time, t, s.step) is not None})
        where = (f"stop_time = {s.stop_time!r} is invalid: stop_time - start_time = {s.stop_time - s.start_time!r} s "
                 f"is not a whole number of steps of {s.step!r} s")
        if not nearest:  # t0 + k h rounds too coarsely at this magnitude to land on the grid
            big = max(abs(s.start_time), abs(s.stop_time))
            raise ValueError(f"{where}, and no stop time near it is: at |t| = {big:g} s a double resolves "
                             f"{math.ulp(big):.3g} s, too coarse for steps of {s.step!r} s to be counted within "
                             f"{STEP_TOLERANCE:g}: allowed are times nearer to 0 or a larger step")
        raise ValueError(f"{where}: allowed are e.g. {' or '.join(_time_text(t, nearest) for t in nearest)}")
    if s.clock == "nanoseconds":
        problem = nanoseconds_problem(s.start_time, s.step, k)
        require(problem is None, problem or "")


def _whole_steps(start: float, stop: float, step: float) -> int | None:
    """The number (>= 1) of steps of ``step`` from ``start`` to ``stop`` [s], None unless whole
    within STEP_TOLERANCE (relative)."""
    n = (stop - start) / step
    k = round(n)
    return k if k >= 1 and abs(n - k) <= STEP_TOLERANCE * max(1.0, k) else None


def _time_text(t: float, others: list) -> str:
    """``t`` [s] in as few digits (at least the usual 12 significant) as tell it from ``others``."""
    for digits in range(12, 18):
        text = f"{t:.{digits}g}"
        if all(f"{o:.{digits}g}" != text for o in others if o != t):
            return text
    return repr(t)


def _check_disturbance(s: Scenario) -> None:
    """A force step (any plant.disturbance_force_i != 0) starts within the run."""
    if any(s.plant.get(f"disturbance_force{i}", 0.0) for i in (1, 2, 3)):
        t = s.plant.get("disturbance_time", 0.0)
        require(s.start_time <= t < s.stop_time, f"plant.disturbance_time = {t!r} is invalid: allowed is a time in "
                f"[start_time, stop_time) = [{s.start_time:g}, {s.stop_time:g}) s (the force step must start "
                "within the run)")


# The model's own checks of what a scenario gives each FMU: (section, the checked value).
# The gains of a gains_file are checked once read_gains_file has read them.
_MODEL_CHECKS = (
    ("gain_overrides", lambda s: s.gain_values() if s.gain_file_values or not s.gains_file else None),
    ("controller", lambda s: model_tuple(ModalGains, s.controller)),
    ("controller", lambda s: model_tuple(ModelParams, {**s.controller, **s.mismatched_params()})),
    ("plant", lambda s: model_tuple(ModelParams, s.plant)),
    ("plant", lambda s: model_tuple(PlantConfig, s.plant)),
    ("trajectory", lambda s: model_tuple(TrajectoryParams, s.trajectory)),
)


def _check_models(s: Scenario) -> None:
    for section, value in _MODEL_CHECKS:
        try:
            checked = value(s)
            if checked is not None:
                checked.validated()
        except ModelInputError as err:
            raise ValueError(f"{section}.{err}") from None


def _check_move(s: Scenario) -> None:
    """A point-to-point move (trajectory.profile 1-3) ends before stop_time, so that the run
    sees it end and settle."""
    tp = model_tuple(TrajectoryParams, s.trajectory)
    if not tp.profile:
        return
    end = tp.t_move + move_duration(tp)
    name = {v: k for k, v in PROFILES.items()}[tp.profile]
    require(end < s.stop_time, f"stop_time = {s.stop_time!r} is invalid: the {name} move from t_move = "
            f"{tp.t_move:g} s ends at t = {end:.6g} s: allowed is a stop_time after the move's end (or raise the "
            "trajectory's v_max_*, a_max_*, j_max_*)")


def _check_order(s: Scenario) -> None:
    """An explicit ``order`` is for Gauss-Seidel only."""
    require(s.order is None or s.ordering == "gauss-seidel", f"order = {s.order!r} is invalid with ordering = "
            f"{s.ordering!r}: allowed is an order only with ordering = \"gauss-seidel\" (Jacobi steps all at once)")


_INITIAL_STATE = ("X0", "Z0", "B0", "dX0", "dZ0", "dB0")  # the plant's initial pose and velocity


def _check_initial_state(s: Scenario) -> None:
    """With start_on_trajectory the plant starts on the reference: an initial state in [plant]
    would be replaced without a word, so it is refused."""
    given = [k for k in _INITIAL_STATE if k in s.plant]
    if s.start_on_trajectory and given:
        raise ValueError(f"plant.{given[0]} = {s.plant[given[0]]!r} is invalid with start_on_trajectory = true (the "
                         "plant starts on the reference's pose and velocity): allowed is start_on_trajectory = false "
                         "to set the plant's initial state")


def _check_settings(s: Scenario) -> None:
    """Every TAPMP FMU's settings exactly as the scenario hands them over (parameters()), through
    the C model's range check that every FMU family runs at initialization: one rule per setting,
    named by the scenario's table. A gains_file's gains are checked once read (read_gains_file)."""
    params = s._parameters(gains=not (s.gains_file and not s.gain_file_values))
    for element, model in ROLES.items():
        try:
            cmodel.check_settings(model, params[element])
        except ModelInputError as err:
            raise ValueError(f"{element}.{err}") from None


def _check_plant_interface(s: Scenario) -> None:
    """Model Exchange has no communication step to draw the measurement noise at."""
    rms = s.plant.get("noise_rms", 0.0)
    require(s.plant_interface != "me" or rms == 0.0,
            f"plant.noise_rms = {rms!r} is invalid with plant_interface = \"me\": allowed is 0 (the noise is drawn "
            "once per communication step, which Model Exchange does not have; use plant_interface = \"cs\", or "
            "tapmp compare --no-noise)")


def _check_drive(s: Scenario) -> None:
    """The drive is a native FMU: the pythonfmu family has none."""
    require(s.drive is None or with_drive(s.fmus), f"drive = true is invalid with fmus = {s.fmus!r}: allowed is "
            "fmus = \"native\" or \"fmi3\" (the families with the drive FMU TAPMP_Drive), or drive = false")


_CROSS_CHECKS = (_check_drive, _check_times, _check_disturbance, _check_models, _check_initial_state, _check_settings, _check_move,
                 _check_order, _check_plant_interface)


def read_gains_file(s: Scenario) -> Scenario:
    """The explicit step after validation: a scenario with a gains_file gets the file's preset
    (gain_file_values, see load_gain_file) and is checked again with it (its gain_overrides
    apply on top); without a gains_file the scenario itself. ScenarioError names what is wrong."""
    if not s.gains_file:
        return s
    return build(dataclasses.replace, ScenarioError, s, gain_file_values=load_gain_file(s.gains_file))


def create(**fields) -> Scenario:
    """A scenario from its fields (as in Scenario), validated, with its gains_file read;
    ScenarioError names the first invalid value and what is allowed."""
    return read_gains_file(build(Scenario, ScenarioError, **fields))


def from_dict(data: dict, source: str = "") -> Scenario:
    """Build and validate a scenario from parsed TOML data (not changed)."""
    kwargs = {"source": source}
    for key, value in data.items():
        if key in TOP:
            kwargs[key] = check_type(key, value, TOP[key], ScenarioError)
        elif key in TABLES:
            require(isinstance(value, dict), f"{key} must be a table ([{key}])", ScenarioError)
            kwargs[key] = dict(value)
        elif key in ("order", "drive"):  # drive: true, false or a table
            kwargs[key] = value
        elif isinstance(value, dict):  # a table named after an SSP element (checked by the master)
            kwargs.setdefault("elements", {})[key] = dict(value)
        else:
            names = [*TOP, *sorted(TABLES), "drive", "order"]
            raise ScenarioError(f"{key} is unknown: allowed are {', '.join(names[:-1])}, order, or a table "
                                f"named after an SSP element{suggestion(key, names)}")
    if "name" not in kwargs:
        kwargs["name"] = Path(source).stem if source else "scenario"
    if kwargs.get("gains_file") and source and not Path(kwargs["gains_file"]).is_absolute():
        kwargs["gains_file"] = str(Path(source).parent / kwargs["gains_file"])  # relative to the scenario file
    return create(**kwargs)


def parse_override(text: str) -> tuple[list[str], object]:
    """Parse a --set KEY=VALUE string; VALUE is TOML (a bare word is taken as a string)."""
    if "=" not in text:
        raise ScenarioError(f"--set {text!r} is invalid: allowed is KEY=VALUE, e.g. plant.k_pull=0")
    key, raw = text.split("=", 1)
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key.strip().split("."), value


def load(path, overrides: list[str] = ()) -> Scenario:
    """Read, override (``--set`` strings) and validate a scenario TOML file."""
    path = Path(path)
    data = read_toml(path, f"scenario file {path}", ScenarioError)
    for text in overrides:
        keys, value = parse_override(text)
        node = data
        for k in keys[:-1]:
            node = node.setdefault(k, {})
            if not isinstance(node, dict):
                raise ScenarioError(f"--set {text!r}: {k} is not a table")
        node[keys[-1]] = value
    return from_dict(data, str(path))
