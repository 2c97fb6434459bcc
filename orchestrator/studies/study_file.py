"""The study file (see orchestrator.studies.study): [study], [set], [grid], [monte_carlo] and
[tune] as pydantic models whose rules give the one-line messages of
orchestrator.tool.config; load_study validates a file, then looks for its base scenario
and checks it with the study's changes (the only steps that read files)."""

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, TypeAdapter, ValidationError, model_validator
from pydantic.dataclasses import dataclass as pydantic_dataclass

from tapmp.errors import allowed_are, suggestion
from tapmp.laws import LAWS
from tapmp.params import GAIN_NAMES

from ..tool.config import finite_number, is_int, is_number, known_keys, one_line, read_toml, require, rule
from ..tool.scenario import SECTION_PARAMS, Scenario, ScenarioError, load
from ..errors import UserError

DISTRIBUTIONS = ("uniform", "loguniform", "normal")
_SECTIONS = ("plant", "controller", "trajectory")


class StudyError(ValueError, UserError):
    """A study file or value is invalid, or its output folder is in the way; the message says which."""


def _targets(targets, info) -> list:
    where = f"monte_carlo.vary.{info.data['name']}"
    require(isinstance(targets, list) and targets and all(isinstance(t, str) for t in targets),
            f"{where}.targets = {targets!r} is invalid: allowed is a list of dotted scenario keys")
    for t in targets:
        check_key(t, f"{where}.targets")
        require(t.partition(".")[0] in (*_SECTIONS, "gain_overrides"), f"{where}.targets: {t} is invalid: a "
                "sampled target must be a number in gain_overrides, plant, controller or trajectory")
    return list(targets)


def _distribution(dist, info) -> str:
    if dist not in DISTRIBUTIONS:
        raise ValueError(f"monte_carlo.vary.{info.data['name']}.distribution = {dist!r} is invalid: "
                         + allowed_are(dist, DISTRIBUTIONS))
    return dist


@pydantic_dataclass
class Factor:
    """A Monte Carlo factor: one draw per sample, applied to every target.

    distribution "uniform" / "loguniform" take low, high; "normal" takes mean, std.
    relative = true multiplies each target's base value by the draw.
    """

    name: str
    targets: Annotated[list, BeforeValidator(_targets)]
    distribution: Annotated[str, BeforeValidator(_distribution)]
    low: Any = None  # finite numbers, required by the distribution that uses them (the others are 0)
    high: Any = None
    mean: Any = None
    std: Any = None
    relative: Annotated[bool, BeforeValidator(bool)] = False

    @model_validator(mode="after")
    def _numbers(self) -> "Factor":
        where = f"monte_carlo.vary.{self.name}"
        if self.distribution == "normal":
            self.mean, self.std = finite_number(f"{where}.mean", self.mean), finite_number(f"{where}.std", self.std)
            require(self.std >= 0.0, f"{where}.std = {self.std!r} is invalid: allowed is a number >= 0")
            self.low = self.high = 0.0
        else:
            self.low, self.high = finite_number(f"{where}.low", self.low), finite_number(f"{where}.high", self.high)
            require(self.high >= self.low, f"{where}.high = {self.high!r} is invalid: allowed is a number >= low = "
                    f"{self.low!r}")
            require(self.distribution != "loguniform" or self.low > 0.0,
                    f"{where}.low = {self.low!r} is invalid for loguniform: allowed is a number > 0")
            self.mean = self.std = 0.0
        return self

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """n draws from the distribution."""
        if self.distribution == "uniform":
            return rng.uniform(self.low, self.high, n)
        if self.distribution == "loguniform":
            return np.exp(rng.uniform(math.log(self.low), math.log(self.high), n))
        return rng.normal(self.mean, self.std, n)


@dataclass
class Study:
    """A validated study file."""

    name: str
    source: str
    base: str                      # the base scenario file (absolute)
    output: str
    description: str = ""
    keep_results: bool = False     # keep each case's results.csv (else run.json + metrics.json only)
    set: dict = field(default_factory=dict)
    grid: dict = field(default_factory=dict)
    samples: int = 0
    seed: int = 0
    factors: list = field(default_factory=list)
    tune: dict = field(default_factory=dict)

    @property
    def kind(self) -> str:
        """"tune", or "grid", "monte_carlo" or "grid+monte_carlo"."""
        if self.tune:
            return "tune"
        return "+".join(k for k, on in (("grid", self.grid), ("monte_carlo", self.samples)) if on)

    def base_scenario(self) -> Scenario:
        """The base scenario with the study's [set] changes."""
        return apply_changes(load(self.base), self.set, "set")


def base_value(scenario: Scenario, key: str):
    """The value a dotted key has in a scenario (the FMU default if the scenario does not set it)."""
    section, _, name = key.partition(".")
    if section == "gain_overrides":
        return list(getattr(scenario.gain_values(), name))
    if section in _SECTIONS:
        table = getattr(scenario, section)
        return table[name] if name in table else SECTION_PARAMS[section][name].start
    return getattr(scenario, key)


STUDY_KEYS = ("law", "ordering", "step", "stop_time", "start_time", "gains", "gains_file", "start_on_trajectory",
              "baseline", "drive")
BASELINE_KEY = "baseline"  # a grid key naming compare runs (orchestrator.tool.baselines), not a scenario field


def check_key(key: str, where: str) -> None:
    """Raise StudyError unless ``key`` is a dotted scenario key a study may vary."""
    section, dot, name = key.partition(".")
    if key == BASELINE_KEY and where != "grid":
        raise StudyError(f"{where}: {key} is allowed only in [grid] (a list of compare run names)")
    if not dot:
        if key not in STUDY_KEYS:
            raise StudyError(f"{where}: {key} is not a scenario key a study may set: allowed are "
                             f"{', '.join(STUDY_KEYS)} or SECTION.NAME (gain_overrides, plant, controller, "
                             f"trajectory){suggestion(key, STUDY_KEYS)}")
    elif section == "gain_overrides":
        if name not in GAIN_NAMES:
            raise StudyError(f"{where}: {key} is unknown: "
                             + allowed_are(key, [f"gain_overrides.{g}" for g in GAIN_NAMES]))
    elif section not in _SECTIONS or name not in SECTION_PARAMS[section]:
        raise StudyError(f"{where}: {key} is unknown: allowed are gain_overrides.NAME, "
                         + ", ".join(f"{s}.NAME" for s in _SECTIONS) + " with NAME a parameter of that FMU"
                         + (f" ({', '.join(SECTION_PARAMS[section])})" if section in _SECTIONS else "")
                         + (suggestion(name, SECTION_PARAMS[section]) if section in _SECTIONS
                            else suggestion(section, ("gain_overrides", *_SECTIONS))))


def apply_changes(scenario: Scenario, changes: dict, where: str = "case") -> Scenario:
    """A copy of ``scenario`` with dotted-key changes applied (validated; ScenarioError names the key)."""
    top = {}
    for key, value in changes.items():
        section, dot, name = key.partition(".")
        if not dot:
            top[key] = value
            continue
        table = dict(top.get(section, getattr(scenario, section)))
        table[name] = list(value) if isinstance(value, (list, tuple)) else value
        top[section] = table
    try:
        return scenario.with_changes(**top)
    except ScenarioError as err:
        raise ScenarioError(f"{where}: {err}") from None


_HEAD = ("name", "description", "base", "output", "keep_results")


class _Head(BaseModel):
    """The [study] table."""

    name: Any = None  # default: the study file's name
    description: Annotated[str, BeforeValidator(str)] = ""
    base: str
    output: Any = None  # default: results/studies/NAME
    keep_results: Annotated[bool, BeforeValidator(bool)] = False

    @model_validator(mode="before")
    @classmethod
    def _keys(cls, data):
        known_keys("study", _HEAD, data)
        require(isinstance(data.get("base"), str), "study.base is missing: allowed is the path of a scenario TOML "
                "file, relative to the study file")
        return data


def _set(table: dict) -> dict:
    for key in table:
        check_key(key, "set")
    return dict(table)


def _grid(table: dict) -> dict:
    for key, values in table.items():
        check_key(key, "grid")
        require(isinstance(values, list) and len(values) >= 1,
                f"grid.{key} = {values!r} is invalid: allowed is a non-empty list of values")
    if BASELINE_KEY in table:
        from ..tool.baselines import BY_NAME
        for v in table[BASELINE_KEY]:
            require(isinstance(v, str) and v in BY_NAME, f"grid.{BASELINE_KEY} = {v!r} is invalid: "
                    + allowed_are(str(v), list(BY_NAME)))
        require("law" not in table, f"grid: law and {BASELINE_KEY} cannot both vary: a baseline sets the law; "
                f"allowed is one of them")
    return {key: list(values) for key, values in table.items()}


def expand_baseline(scenario: Scenario, changes: dict) -> dict:
    """``changes`` with a ``baseline`` key replaced by what makes ``scenario`` (with the other
    changes) that compare run (orchestrator.tool.baselines.compare_runs): its law, gain
    overrides and [controller] table, as whole-table changes. The baseline's gains come from
    the scenario's nominal gains and controller model, so Monte Carlo draws applied later change
    the plant, never the matched gains (a controller designed once, run on every sampled plant)."""
    if BASELINE_KEY not in changes:
        return dict(changes)
    from ..tool.baselines import compare_runs
    rest = {k: v for k, v in changes.items() if k != BASELINE_KEY}
    at = apply_changes(scenario, rest, "grid") if rest else scenario
    run = compare_runs(at)[changes[BASELINE_KEY]]
    return {**rest, "law": run.law, "gain_overrides": dict(run.gain_overrides), "controller": dict(run.controller)}


def _vary(tables) -> dict:
    """[monte_carlo.vary.NAME] tables as Factors (targets default to [NAME])."""
    require(isinstance(tables, dict) and tables, "[monte_carlo.vary.NAME] tables are missing: allowed is at least "
            "one factor")
    factors = {}
    for name, table in tables.items():
        where = f"monte_carlo.vary.{name}"
        require(isinstance(table, dict), f"{where} must be a table")
        known_keys(where, ("targets", "distribution", "low", "high", "mean", "std", "relative"), table)
        factors[name] = _FACTOR.validate_python({"targets": [name], **table, "name": name})
    return factors


_FACTOR = TypeAdapter(Factor)


class _MonteCarlo(BaseModel):
    """The [monte_carlo] table."""

    samples: Annotated[int, rule(lambda v: is_int(v, 1), "an integer >= 1", "monte_carlo.")] = None
    seed: Annotated[int, rule(lambda v: is_int(v, 0), "an integer >= 0 (stated, so the draws can be repeated)",
                              "monte_carlo.")] = None
    vary: Annotated[dict, BeforeValidator(_vary)] = None
    model_config = ConfigDict(validate_default=True)  # a missing samples, seed or vary is refused by its rule

    @model_validator(mode="before")
    @classmethod
    def _keys(cls, data):
        known_keys("monte_carlo", ("samples", "seed", "vary"), data)
        return data


# pid-dc-full: the PID-DC law with one integral gain ki on every mode (ki_c = ki_d = ki, compare's baseline of
# that name), tuned on its modal gains [u/m, u s/m, u/(m s)] in the controller table rather than on Gains
FULL_PID = "pid-dc-full"
FULL_PID_GAINS = ("kp_c", "kp_d", "kv_c", "kv_d", "ki")
_TUNABLE = {**{law.name: law.tunable for law in LAWS if law.tunable},  # the laws tuned on Gains (tapmp.laws)
            FULL_PID: FULL_PID_GAINS}
_KEYS = ("laws", "bounds", "population", "generations", "seed", "write_to", "compare_stop_time", "ms_bound",
         "delay_margin_min")
MS_BOUND = 2.0  # default tune.ms_bound: the usual guideline Ms < 2 (6 dB; Skogestad and Postlethwaite, Sec. 2.4.3)


def _write_to(w) -> str:
    require(isinstance(w, str) and w, "tune.write_to is missing: allowed is a folder for the preset files, "
            "comparison.md and objective.png (relative to the working directory)")
    return w


def _laws(laws) -> list:
    require(isinstance(laws, list) and laws and all(law in _TUNABLE for law in laws),
            f"tune.laws = {laws!r} is invalid: allowed is a list of {', '.join(_TUNABLE)}"
            + next((suggestion(law, _TUNABLE) for law in (laws if isinstance(laws, list) else [])
                    if law not in _TUNABLE), ""))
    return list(laws)


def _bounds(bounds, info) -> dict:
    """{law: {gain: [low, high]}} for every tuned law (0 < low < high: searched on a log scale)."""
    out = {}
    for law in info.data.get("laws", ()):
        b = bounds.get(law)
        require(isinstance(b, dict) and b, f"tune.bounds.{law} is missing: allowed is a table of "
                f"gain = [low, high] for {', '.join(_TUNABLE[law])}")
        out[law] = {}
        for gain, lim in b.items():
            if gain not in _TUNABLE[law]:
                unused = [n for n in GAIN_NAMES if n != "K_T" and n not in _TUNABLE[law]]
                raise ValueError(f"tune.bounds.{law}.{gain} is invalid: allowed are {', '.join(_TUNABLE[law])} "
                                 f"({law} " + (f"does not use {' or '.join(unused)}; " if unused else "")
                                 + "K_T is not tuned: only Lambda / K_T matters)" + suggestion(gain, _TUNABLE[law]))
            require(isinstance(lim, list) and len(lim) == 2 and all(is_number(v) and math.isfinite(v) for v in lim)
                    and 0.0 < lim[0] < lim[1], f"tune.bounds.{law}.{gain} = {lim!r} is invalid: allowed is "
                    "[low, high] with 0 < low < high (searched on a log scale)")
            out[law][gain] = [float(lim[0]), float(lim[1])]
    return out


class _Tune(BaseModel):
    """The [tune] table: the gains of each law searched by differential evolution (tuning.py)."""

    laws: Annotated[list, BeforeValidator(_laws)] = [law for law in _TUNABLE if law != FULL_PID]  # on Gains
    bounds: Annotated[dict, BeforeValidator(_bounds)] = Field(default_factory=dict, validate_default=True)
    population: Annotated[int, rule(lambda v: is_int(v, 2), "an integer >= 2", "tune.")] = 6
    generations: Annotated[int, rule(lambda v: is_int(v, 1), "an integer >= 1", "tune.")] = 5
    seed: Annotated[int, rule(lambda v: is_int(v, 0), "an integer >= 0", "tune.")] = 0
    write_to: Annotated[str, BeforeValidator(_write_to)] = Field(None, validate_default=True)
    compare_stop_time: Annotated[float, rule(lambda v: is_number(v) and v > 0, "a number > 0 [s]", "tune.")] = 2.5
    # the largest peak sensitivity Ms allowed on any mode of a candidate (tuning.py); a design beyond is not run
    ms_bound: Annotated[float, rule(lambda v: is_number(v) and math.isfinite(v) and v >= 1.0,
                                    "a finite number >= 1 (the largest peak sensitivity Ms on any mode)",
                                    "tune.")] = MS_BOUND
    # the smallest delay margin [s] with every motor delayed at once (analysis.delay_margin) a candidate must
    # have, on the loop the check linearizes (with the drive's own delay if the base has the drive); None: no bound
    delay_margin_min: Annotated[float, rule(lambda v: is_number(v) and math.isfinite(v) and v > 0.0,
                                            "a finite number > 0 [s] (the smallest delay margin, all motors)",
                                            "tune.")] = None

    @model_validator(mode="before")
    @classmethod
    def _keys(cls, data):
        require(isinstance(data, dict), "tune must be a table")
        known_keys("tune", _KEYS, data)
        return data


class _StudyFile(BaseModel):
    """A study file: [study], [set], [grid], [monte_carlo], [tune]."""

    study: _Head = Field(default_factory=dict, validate_default=True)  # base is required
    set: Annotated[dict, BeforeValidator(_set)] = {}
    grid: Annotated[dict, BeforeValidator(_grid)] = {}
    monte_carlo: _MonteCarlo | None = None
    tune: _Tune | None = None

    @model_validator(mode="before")
    @classmethod
    def _sections(cls, data):
        allowed = ("study", "set", "grid", "monte_carlo", "tune")
        for key in data:
            if key not in allowed:
                raise ValueError(f"[{key}] is unknown: allowed are " + ", ".join(f"[{k}]" for k in allowed)
                                 + suggestion(key, allowed))
        return data

    @model_validator(mode="after")
    def _varies(self) -> "_StudyFile":
        require(self.tune is None or not (self.grid or self.monte_carlo),
                "[tune] cannot be combined with [grid] or [monte_carlo]: use separate studies")
        require(self.grid or self.monte_carlo or self.tune,
                "nothing varies: allowed is a [grid], a [monte_carlo] or a [tune] table")
        return self


def load_study(path) -> Study:
    """Read and validate a study file, then look for its base scenario and check it with the
    study's [set] changes; StudyError names the key and what is allowed."""
    path = Path(path)
    data = read_toml(path, f"study file {path}", StudyError)
    try:
        f = _StudyFile.model_validate(data)
    except ValidationError as err:
        raise StudyError(f"{path}: {one_line(err)}") from None
    head, mc = f.study, f.monte_carlo
    name = path.stem if head.name is None else head.name
    study = Study(name=name, source=str(path.resolve()), base=str((path.parent / head.base).resolve()),
                  output=str(f"results/studies/{name}" if head.output is None else head.output),
                  description=head.description, keep_results=head.keep_results,
                  set={k: _resolve_path(k, v, path) for k, v in f.set.items()},
                  grid={k: [_resolve_path(k, v, path) for v in values] for k, values in f.grid.items()},
                  samples=mc.samples if mc else 0, seed=mc.seed if mc else 0,
                  factors=list(mc.vary.values()) if mc else [], tune=f.tune.model_dump() if f.tune else {})
    require(Path(study.base).exists(), f"{path}: study.base = {head.base!r} does not exist (looked for "
            f"{study.base})", StudyError)
    try:
        study.base_scenario()
    except ScenarioError as err:
        raise StudyError(f"{path}: {err}") from None
    return study


def _resolve_path(key: str, value, study_path: Path):
    """gains_file values in a study are relative to the study file."""
    if key == "gains_file" and isinstance(value, str) and value and not Path(value).is_absolute():
        return str((study_path.parent / value).resolve())
    return value
