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
see orchestrator.engine.families; `--fmus` and `--ssp` on the command line override it),
format (the result file: "csv" (default) or "mat", see orchestrator.experiments.results;
`--format` overrides it), settling_bands (the bands of the move metrics of a point-to-point
run, trajectory.profile 1-3, see orchestrator.experiments.metrics.MoveMetrics; default
[1e-6, 1e-7], in m, rad for B). output is the scenario's result folder (default
results/<name>): `tapmp run` writes into output/<law>, `tapmp compare` into output/compare.
Tables: [gain_overrides] (Lambda_p, Lambda_v, b, D, K_T as a
number or a list of three), [trajectory], [plant] and [controller] with the
parameters of the respective FMU (names as in its modelDescription.xml), and
[limits] (the divergence envelope, see LIMITS), [mismatch] (the controller's model
error, see MISMATCH_RANGE and docs/disturbances.md).
"""

import copy
import math
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

from tapmp.control import Gains, ModalGains
from tapmp.errors import ModelInputError, allowed_are, suggestion
from tapmp.interface import CONNECTION_STARTS, CONTROLLER, ORDERINGS, PLANT, TRAJECTORY, VARIABLES
from tapmp.params import GAIN_NAMES, GAIN_PRESETS, ModelParams
from tapmp.plant import PlantConfig
from tapmp.trajectory import TrajectoryParams, reference

from ..engine.clocks import CLOCKS

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

LAWS = {"sc-dc": 0, "apd-dc": 1, "pid-dc": 2}  # PID-DC: modal gains in [controller] kp_c .. ki_d
# [mismatch]: relative model error of the controller's nominal parameters. For each listed
# field of tapmp.params.ModelParams the controller gets (plant value) x factor; the plant
# keeps its own. A factor within MISMATCH_RANGE; not together with [controller] NAME.
MISMATCH_RANGE = (0.01, 100.0)
_TOP = {"name": str, "description": str, "law": str, "gains": str, "gains_file": str, "stop_time": float,
        "start_time": float, "step": float, "ordering": str, "output": str,
        "start_on_trajectory": bool, "record_every": int, "clock": str, "connection_start": str,
        "open_inputs": list, "fmus": str, "format": str, "settling_bands": list}
RESULT_FORMATS = ("csv", "mat")  # results.csv or results.mat (orchestrator.experiments.results)
_TABLES = {"gain_overrides", "trajectory", "plant", "controller", "limits", "mismatch"}
# The divergence envelope the master checks every step (0 switches a limit off):
# |q_i| of every motor (true position) and |B| of the platform. The paper's motion
# needs 20 mm of travel and 5 deg; a breach means the loop is running away.
LIMITS = {"motor_travel": (0.05, "m", "largest |q1|, |q2|, |q3| (true motor positions)"),
          "platform_angle": (0.35, "rad", "largest |B| of the platform")}
# Parameters a scenario may set per section; the controller's gains, law and the
# plant's initial state are set through the scenario's own keys instead.
_SECTION_PARAMS = {
    "trajectory": {v.name: v for v in VARIABLES[TRAJECTORY] if v.causality == "parameter"},
    "plant": {v.name: v for v in VARIABLES[PLANT] if v.causality == "parameter"},
    "controller": {v.name: v for v in VARIABLES[CONTROLLER] if v.causality == "parameter"
                   and not v.name[:-1] in GAIN_NAMES and v.name not in ("law", "T_s")},
}
# Set from the scenario's own keys, never in [controller]: the controller samples once per step.
_FROM_SCENARIO = {"law": "law", "T_s": "step"}


def model_tuple(kind, table: dict):
    """A tapmp parameter NamedTuple of ``kind`` with the values of ``table`` over its defaults."""
    return kind(*(table.get(n, d) for n, d in zip(kind._fields, kind())))


class ScenarioError(ValueError):
    """A scenario file or value is invalid; the message names the key and what is allowed."""


def read_toml(path: Path, subject: str, error=None, allowed: str = "") -> dict:
    """Parse a TOML file; a missing or malformed file raises ``error`` (ScenarioError by
    default) as "<subject> does not exist<allowed>" or "<subject> is not valid TOML: ..."."""
    error = error or ScenarioError
    try:
        return tomllib.loads(Path(path).read_text())
    except FileNotFoundError:
        raise error(f"{subject} does not exist{allowed}") from None
    except tomllib.TOMLDecodeError as err:
        raise error(f"{subject} is not valid TOML: {err}") from None


def load_gain_file(path) -> dict:
    """Read a gain preset file: a TOML table [gains] with Lambda_p, Lambda_v, b, D, K_T,
    each a number or a list of three (per motor; units as in tapmp.control.Gains).

    Other top-level keys (e.g. law, objective, command) are kept as documentation only.
    Returns {name: (motor 1, motor 2, motor 3)}; ScenarioError names what is wrong.
    """
    path = Path(path)
    data = read_toml(path, f"gains_file = {str(path)!r}",
                     allowed=": allowed is a TOML gain preset file with a [gains] table")
    table = data.get("gains")
    if not isinstance(table, dict):
        raise ScenarioError(f"gains_file = {str(path)!r} has no [gains] table: allowed is a table with "
                            f"{', '.join(GAIN_NAMES)}")
    preset = {}
    for name in GAIN_NAMES:
        if name not in table:
            raise ScenarioError(f"gains_file {path}: gains.{name} is missing: allowed is a number or a list of 3 numbers")
    for name, v in table.items():
        if name not in GAIN_NAMES:
            raise ScenarioError(f"gains_file {path}: gains.{name} is unknown: {allowed_are(name, GAIN_NAMES)}")
        vals = [v] * 3 if isinstance(v, (int, float)) and not isinstance(v, bool) else v
        if not (isinstance(vals, list) and len(vals) == 3):
            raise ScenarioError(f"gains_file {path}: gains.{name} = {v!r} is invalid: allowed is a number "
                                "or a list of 3 numbers")
        preset[name] = tuple(_check_type(f"gains_file {path}: gains.{name}", x, float) for x in vals)
    try:
        Gains.from_preset(preset).validated()
    except ModelInputError as err:
        raise ScenarioError(f"gains_file {path}: gains.{err}") from None
    return preset


@dataclass
class Scenario:
    """A validated scenario."""

    name: str
    description: str = ""
    law: str = "sc-dc"
    gains: str = "default"
    gains_file: str = ""
    gain_overrides: dict = field(default_factory=dict)
    start_time: float = 0.0
    stop_time: float = 2.5
    step: float = 1e-4
    ordering: str = "gauss-seidel"
    output: str = ""  # "" = results/<name>
    start_on_trajectory: bool = True
    clock: str = "exact"
    connection_start: str = "propagated"
    trajectory: dict = field(default_factory=dict)
    plant: dict = field(default_factory=dict)
    controller: dict = field(default_factory=dict)
    limits: dict = field(default_factory=dict)
    mismatch: dict = field(default_factory=dict)  # ModelParams field -> controller/plant factor
    record_every: int = 1
    open_inputs: list = field(default_factory=list)  # "element.variable" inputs left undriven on purpose
    order: list | None = None  # explicit Gauss-Seidel step order: every SSP element name once
    elements: dict = field(default_factory=dict)  # [ELEMENT] tables: FMU parameters by SSP element name
    fmus: str = "native"  # FMU family: python, native or fmi3 (orchestrator.engine.families)
    format: str = "csv"   # result file: csv or mat (RESULT_FORMATS)
    # point-to-point runs: settling bands [m for X, Z and the motors, rad for B] of the move metrics
    settling_bands: list = field(default_factory=lambda: [1e-6, 1e-7])
    source: str = ""
    gain_file_values: dict = field(default_factory=dict, repr=False)  # filled from gains_file by validate

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
        """A copy with top-level fields replaced (and validated again)."""
        new = copy.deepcopy(self)
        for k, v in changes.items():
            setattr(new, k, v)
        return validate(new)

    def parameters(self) -> dict:
        """FMU parameters by SSP element name, ready for the master algorithm."""
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
        for name, values in zip(GAIN_NAMES, self.gain_values()):
            for i, v in enumerate(values, start=1):
                ctrl[f"{name}{i}"] = v
        if "L_1" in self.controller and "L_1" not in traj:
            traj["L_1"] = self.controller["L_1"]  # q_d is the controller's view of the reference
        return {"trajectory": traj, "controller": ctrl, "plant": plant, **copy.deepcopy(self.elements)}

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
                               model_tuple(ModalGains, ct), ct["T_s"], self.start_time)
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


def _check_type(key: str, value, kind):
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if kind is int and isinstance(value, float) and value.is_integer():
        return int(value)
    if not isinstance(value, kind) or (kind is not bool and isinstance(value, bool)):
        raise ScenarioError(f"{key} = {value!r} has the wrong type: allowed is {kind.__name__}")
    return value


_OPEN_INPUT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\.[^\s.][^\s]*")


def _check_open_inputs(entries) -> None:
    """open_inputs is a list of distinct "element.variable" strings (whether each is an
    input of the system is checked by the master against the SSP)."""
    if not isinstance(entries, list):
        raise ScenarioError(f"open_inputs = {entries!r} is invalid: allowed is a list of \"element.variable\" "
                            "strings, e.g. [\"controller.dq1\"]")
    for i, entry in enumerate(entries):
        if not isinstance(entry, str) or not _OPEN_INPUT.fullmatch(entry):
            raise ScenarioError(f"open_inputs[{i}] = {entry!r} is invalid: allowed is \"element.variable\", an "
                                "FMU input of the system, e.g. \"controller.dq1\"")
        if entry in entries[:i]:
            raise ScenarioError(f"open_inputs[{i}] = {entry!r} is listed twice: allowed is each input once")


STEP_TOLERANCE = 1e-9  # relative: how far (stop_time - start_time) / step may be from a whole number


def _check_whole_steps(s: Scenario) -> None:
    """stop_time - start_time must be a whole number (>= 1) of steps: a run never goes past
    stop_time and never completes zero steps; otherwise the nearest valid stop times are named."""
    n = (s.stop_time - s.start_time) / s.step
    k = round(n)
    if k >= 1 and abs(n - k) <= STEP_TOLERANCE * max(1.0, k):
        return
    lo, hi = max(1, math.floor(n)), max(1, math.ceil(n))
    nearest = sorted({s.start_time + lo * s.step, s.start_time + hi * s.step})
    raise ScenarioError(f"stop_time = {s.stop_time!r} is invalid: stop_time - start_time = "
                        f"{s.stop_time - s.start_time!r} s is not a whole number of steps of {s.step!r} s: "
                        f"allowed are e.g. {' or '.join(f'{t:.12g}' for t in nearest)}")


def _check_mismatch(s: Scenario) -> None:
    """[mismatch] names ModelParams fields with a factor in MISMATCH_RANGE, none also set in [controller]."""
    lo, hi = MISMATCH_RANGE
    for k, v in s.mismatch.items():
        if k not in ModelParams._fields:
            raise ScenarioError(f"mismatch.{k} is unknown: {allowed_are(k, ModelParams._fields)}")
        v = s.mismatch[k] = _check_type(f"mismatch.{k}", v, float)
        if not (math.isfinite(v) and lo <= v <= hi):
            raise ScenarioError(f"mismatch.{k} = {v!r} is invalid: allowed is a factor in [{lo:g}, {hi:g}] "
                                "(controller value = plant value x factor)")
        if k in s.controller:
            raise ScenarioError(f"mismatch.{k} = {v!r} conflicts with controller.{k} = {s.controller[k]!r}: "
                                "allowed is one of them (the factor sets the controller's value)")


def _check_disturbance(s: Scenario) -> None:
    """A force step (any plant.disturbance_force_i != 0) starts within the run."""
    if any(s.plant.get(f"disturbance_force{i}", 0.0) for i in (1, 2, 3)):
        t = s.plant.get("disturbance_time", 0.0)
        if not (s.start_time <= t < s.stop_time):
            raise ScenarioError(f"plant.disturbance_time = {t!r} is invalid: allowed is a time in [start_time, "
                                f"stop_time) = [{s.start_time:g}, {s.stop_time:g}) s (the force step must start "
                                "within the run)")


def _check_addressing(s: Scenario) -> None:
    """``order`` is a list of distinct element names, for Gauss-Seidel only (whether it names
    every element of the SSP exactly once is checked by the master); every [ELEMENT] table is
    named like an SSP element and holds numbers or booleans (whether each is a parameter of
    that element's FMU is checked by the master against the SSP)."""
    if s.order is not None:
        if not (isinstance(s.order, list) and s.order and all(isinstance(e, str) for e in s.order)):
            raise ScenarioError(f"order = {s.order!r} is invalid: allowed is a list of the SSP element names "
                                "in the order they step, e.g. [\"controller\", \"plant\", \"trajectory\"]")
        twice = sorted({e for e in s.order if s.order.count(e) > 1})
        if twice:
            raise ScenarioError(f"order = {s.order!r} names {', '.join(twice)} more than once: allowed is "
                                "every element exactly once")
        if s.ordering != "gauss-seidel":
            raise ScenarioError(f"order = {s.order!r} is invalid with ordering = {s.ordering!r}: allowed is an "
                                "order only with ordering = \"gauss-seidel\" (Jacobi steps all at once)")
    for element, table in s.elements.items():
        if not _OPEN_INPUT.fullmatch(f"{element}.x") or not isinstance(table, dict):
            raise ScenarioError(f"[{element}] is invalid: allowed is a table of FMU parameters named after an "
                                "SSP element ([A-Za-z_][A-Za-z0-9_]*)")
        for k, v in table.items():
            if isinstance(v, float) and not math.isfinite(v) or not isinstance(v, (int, float, bool)):
                raise ScenarioError(f"{element}.{k} = {v!r} is invalid: allowed is a finite number, an integer "
                                    "or a boolean (a parameter of the FMU of SSP element "
                                    f"{element}){suggestion(element, sorted(_TABLES))}")


def _check_move(s: Scenario) -> None:
    """settling_bands: numbers > 0; a point-to-point move (trajectory.profile 1-3) ends before
    stop_time, so that the run sees it end and settle."""
    bands = s.settling_bands
    if not (isinstance(bands, list) and bands):
        raise ScenarioError(f"settling_bands = {bands!r} is invalid: allowed is a non-empty list of numbers > 0 "
                            "[m; rad for B], e.g. [1e-6, 1e-7]")
    for i, b in enumerate(bands):
        b = bands[i] = _check_type(f"settling_bands[{i}]", b, float)
        if not (math.isfinite(b) and b > 0.0):
            raise ScenarioError(f"settling_bands[{i}] = {b!r} is invalid: allowed is a finite number > 0 "
                                "[m; rad for B]")
    from tapmp.trajectory import PROFILES, move_duration
    tp = model_tuple(TrajectoryParams, s.trajectory)
    if not tp.profile:
        return
    end = tp.t_move + move_duration(tp)
    if not end < s.stop_time:
        name = {v: k for k, v in PROFILES.items()}[tp.profile]
        raise ScenarioError(f"stop_time = {s.stop_time!r} is invalid: the {name} move from t_move = {tp.t_move:g} s "
                            f"ends at t = {end:.6g} s: allowed is a stop_time after the move's end (or raise the "
                            "trajectory's v_max_*, a_max_*, j_max_*)")


def validate(s: Scenario) -> Scenario:
    """Check every value of a scenario; raise ScenarioError naming the key."""
    if s.law not in LAWS:
        raise ScenarioError(f"law = {s.law!r} is invalid: {allowed_are(s.law, LAWS)}")
    if s.gains not in GAIN_PRESETS:
        raise ScenarioError(f"gains = {s.gains!r} is invalid: {allowed_are(s.gains, sorted(GAIN_PRESETS))}")
    if s.gains_file:
        s.gain_file_values = load_gain_file(s.gains_file)
    if s.ordering not in ORDERINGS:
        raise ScenarioError(f"ordering = {s.ordering!r} is invalid: {allowed_are(s.ordering, ORDERINGS)}")
    if s.clock not in CLOCKS:
        raise ScenarioError(f"clock = {s.clock!r} is invalid: {allowed_are(s.clock, CLOCKS)}")
    if s.connection_start not in CONNECTION_STARTS:
        raise ScenarioError(f"connection_start = {s.connection_start!r} is invalid: "
                            f"{allowed_are(s.connection_start, CONNECTION_STARTS)}")
    if not (math.isfinite(s.step) and s.step > 0.0):
        raise ScenarioError(f"step = {s.step!r} is invalid: allowed is a number > 0 [s]")
    if not (math.isfinite(s.start_time) and math.isfinite(s.stop_time) and s.stop_time > s.start_time):
        raise ScenarioError(f"stop_time = {s.stop_time!r} is invalid: allowed is a number > start_time "
                            f"= {s.start_time!r} [s]")
    _check_whole_steps(s)
    for k, v in s.gain_overrides.items():
        if k not in GAIN_NAMES:
            raise ScenarioError(f"gain_overrides.{k} is unknown: {allowed_are(k, GAIN_NAMES)}")
        vals = [v] * 3 if isinstance(v, (int, float)) and not isinstance(v, bool) else v
        if not (isinstance(vals, list) and len(vals) == 3):
            raise ScenarioError(f"gain_overrides.{k} = {v!r} is invalid: allowed is a number or a list of 3 numbers")
        s.gain_overrides[k] = [_check_type(f"gain_overrides.{k}", x, float) for x in vals]
    for section in ("trajectory", "plant", "controller"):
        table = getattr(s, section)
        allowed = _SECTION_PARAMS[section]
        for k, v in table.items():
            if section == "controller" and k in _FROM_SCENARIO:
                raise ScenarioError(f"controller.{k} is set by the scenario's {_FROM_SCENARIO[k]} = "
                                    f"{getattr(s, _FROM_SCENARIO[k])!r}: allowed is to set {_FROM_SCENARIO[k]}")
            if k not in allowed:
                raise ScenarioError(f"{section}.{k} is unknown: {allowed_are(k, allowed)}")
            table[k] = _check_type(f"{section}.{k}", v, int if allowed[k].type == "Integer" else float)
    _check_mismatch(s)
    _check_disturbance(s)
    checks = (("gain_overrides", lambda: s.gain_values().validated()),
              ("controller", lambda: model_tuple(ModalGains, s.controller).validated()),
              ("controller", lambda: model_tuple(ModelParams, {**s.controller,
                                                              **s.mismatched_params()}).validated()),
              ("plant", lambda: model_tuple(ModelParams, s.plant).validated()),
              ("plant", lambda: model_tuple(PlantConfig, s.plant).validated()),
              ("trajectory", lambda: model_tuple(TrajectoryParams, s.trajectory).validated()))
    for section, check in checks:
        try:
            check()
        except ModelInputError as err:
            raise ScenarioError(f"{section}.{err}") from None
    _check_move(s)
    for k, v in s.limits.items():
        if k not in LIMITS:
            raise ScenarioError(f"limits.{k} is unknown: {allowed_are(k, LIMITS)}")
        v = s.limits[k] = _check_type(f"limits.{k}", v, float)
        if not (math.isfinite(v) and v >= 0.0):
            raise ScenarioError(f"limits.{k} = {v!r} is invalid: allowed is a number >= 0 "
                                f"[{LIMITS[k][1]}] (0 = no limit)")
    _check_open_inputs(s.open_inputs)
    _check_addressing(s)
    from ..engine.families import FAMILIES
    if s.fmus not in FAMILIES:
        raise ScenarioError(f"fmus = {s.fmus!r} is invalid: {allowed_are(s.fmus, FAMILIES)}")
    if s.format not in RESULT_FORMATS:
        raise ScenarioError(f"format = {s.format!r} is invalid: {allowed_are(s.format, RESULT_FORMATS)}")
    if s.record_every < 1:
        raise ScenarioError(f"record_every = {s.record_every!r} is invalid: allowed is an integer >= 1")
    vs = s.controller.get("velocity_source", 0)
    if vs not in (0, 1):
        raise ScenarioError(f"controller.velocity_source = {vs!r} is invalid: allowed are 0 or 1")
    if s.controller.get("force_limit", 0.0) < 0.0:
        raise ScenarioError(f"controller.force_limit = {s.controller['force_limit']!r} is invalid: "
                            "allowed is a number >= 0")
    return s


def from_dict(data: dict, source: str = "") -> Scenario:
    """Build and validate a scenario from parsed TOML data."""
    kwargs = {"source": source}
    for key, value in data.items():
        if key in _TOP:
            kwargs[key] = _check_type(key, value, _TOP[key])
        elif key in _TABLES:
            if not isinstance(value, dict):
                raise ScenarioError(f"{key} must be a table ([{key}])")
            kwargs[key] = dict(value)
        elif key == "order":
            kwargs[key] = value
        elif isinstance(value, dict):  # a table named after an SSP element (checked by the master)
            kwargs.setdefault("elements", {})[key] = dict(value)
        else:
            names = [*_TOP, *sorted(_TABLES), "order"]
            raise ScenarioError(f"{key} is unknown: allowed are {', '.join(names[:-1])}, order, or a table "
                                f"named after an SSP element{suggestion(key, names)}")
    if "name" not in kwargs:
        kwargs["name"] = Path(source).stem if source else "scenario"
    if kwargs.get("gains_file") and source and not Path(kwargs["gains_file"]).is_absolute():
        kwargs["gains_file"] = str(Path(source).parent / kwargs["gains_file"])  # relative to the scenario file
    return validate(Scenario(**kwargs))


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
    data = read_toml(path, f"scenario file {path}")
    for text in overrides:
        keys, value = parse_override(text)
        node = data
        for k in keys[:-1]:
            node = node.setdefault(k, {})
            if not isinstance(node, dict):
                raise ScenarioError(f"--set {text!r}: {k} is not a table")
        node[keys[-1]] = value
    return from_dict(data, str(path))
