"""The models: one record per FMU, in one ordered registry (FMI-free, imports nothing of tapmp).

A record holds every fact about one model that the builders, the modelDescription writers, the
documentation, the SSP writer and the scenario roles read: its name (the FMU's modelName and model
identifier), its element (role) in the SSP system, its variables and what each output depends on,
its C settings struct, its C files, its description, its documentation's text and equations, its
icon label, the FMI versions it is built for and its pythonfmu twin. Nothing else lists the
models: :data:`MODELS` is the list, in the order of the signal flow (the SSP's elements, the
container's components), and :func:`register` adds one (docs/architecture.md, "Adding a model").

The three TAPMP records are filled in by tapmp.interface (where their variables are defined) when
the package is imported; this module sits below every model so that the models can name themselves
without importing the table that reads them.
"""

from dataclasses import dataclass, field
from typing import Callable

# The TAPMP models' names (FMU modelName and model identifier).
PLANT = "TAPMP_Plant"
CONTROLLER = "TAPMP_Controller"
TRAJECTORY = "TAPMP_Trajectory"
# The native FMI 3.0 controller with a periodic input clock: a variant of CONTROLLER (same variables,
# same C files) under its own model identifier (orchestrator/builder/build_native.py).
CLOCKED = "TAPMP_ControllerClocked"
# The servo drive between controller and plant: an optional element, in its own SSP (TAPMP_Drive.ssp).
DRIVE = "TAPMP_Drive"


@dataclass(frozen=True)
class ModelRecord:
    """One model (one FMU): the facts every builder, writer and document reads.

    Paths are relative to the package root (the repository in a checkout)."""

    name: str                   # modelName and model identifier, e.g. "TAPMP_Plant"
    element: str                # its element (role) in the SSP system and the scenario's table name
    variables: tuple = ()       # its tapmp.interface.Var rows, in value-reference order
    dependencies: Callable | None = None  # output name -> tapmp.interface.Dependencies
    sources: dict = field(default_factory=dict)  # input name -> (model, output) feeding it in the SSP system
    source: str = ""            # the model's C file, e.g. "fmu_plant/plant.c"
    header: str = ""            # the model's C header, e.g. "fmu_plant/plant.h"
    settings_struct: str = ""   # the C settings struct its parameters are read into ("" = none)
    settings_relations: str = ""  # C function checking relations between its settings ("" = none)
    description: str = ""       # the modelDescription's description (native FMUs)
    what: Callable[[], str] | str = ""  # its documentation's introduction (HTML; a callable: computed)
    equations: Callable[[], list] | tuple = ()  # its documentation's (equation, meaning) pairs
    icon_label: str = ""        # the word on its icon
    diagram_note: str = ""      # the line under its name in the documentation's closed-loop diagram
    fmi_versions: tuple[str, ...] = ("fmi2", "fmi3")  # the native families it is built for
    adapter: str = ""           # its pythonfmu twin's script ("" = none), e.g. "fmu_plant/TAPMP_Plant.py"
    me_states: tuple[str, ...] = ()  # its Model Exchange states (none: Co-Simulation only)
    variant_of: str = ""        # the model whose variables and C files it shares (the clocked controller)
    # An optional element (the drive): built in every family of fmi_versions but outside the default system
    # (TAPMP.ssp, the container, the diagram); its own system is the default one with it inserted, where it
    # feeds these inputs of other models in place of their sources: {(model, input): its output}.
    optional: bool = False
    feeds: dict = field(default_factory=dict)

    def text(self, attribute: str):
        """``what`` or ``equations``, computed if given as a function."""
        value = getattr(self, attribute)
        return value() if callable(value) else value


# The registry, in the order of the signal flow (trajectory -> controller -> plant -> controller).
MODELS: list[ModelRecord] = []


def register(record: ModelRecord) -> ModelRecord:
    """Add ``record`` at the end of the registry (replacing the record of the same name in place)."""
    for i, old in enumerate(MODELS):
        if old.name == record.name:
            MODELS[i] = record
            return record
    MODELS.append(record)
    return record


def unregister(name: str) -> None:
    """Remove the record ``name`` (a test's temporary model)."""
    MODELS[:] = [r for r in MODELS if r.name != name]


def record(name: str) -> ModelRecord:
    """The record of the model ``name``; KeyError naming the known models if there is none."""
    for r in MODELS:
        if r.name == name:
            return r
    raise KeyError(f"no model {name!r}: the models are {', '.join(r.name for r in MODELS)}")


def base_models() -> tuple[ModelRecord, ...]:
    """The default system's models, in registry order (every model but the variants and the optional ones)."""
    return tuple(r for r in MODELS if not r.variant_of and not r.optional)


def system_models(extra: str = "") -> tuple[ModelRecord, ...]:
    """The models of a system in registry order: the default one, with the optional model ``extra`` if given."""
    return tuple(r for r in MODELS if not r.variant_of and (not r.optional or r.name == extra))


def built_models() -> tuple[ModelRecord, ...]:
    """Every model with variables of their own, in registry order (the base and the optional models)."""
    return tuple(r for r in MODELS if not r.variant_of)


def optional_names() -> tuple[str, ...]:
    """The optional models' names, in registry order (each has a system of its own)."""
    return tuple(r.name for r in MODELS if r.optional and not r.variant_of)


def names() -> tuple[str, ...]:
    """The base models' names, in registry order (the SSP's elements)."""
    return tuple(r.name for r in base_models())


def models_table() -> str:
    """The models as docs/architecture.md lists them ("Adding a model"): a Markdown table, one row per
    record in registry order (tests/project compare the page with it)."""
    version = {"fmi2": "2.0", "fmi3": "3.0"}
    rows = ["| model | SSP element | C file | native FMI | pythonfmu twin | variant of |", "|---|---|---|---|---|---|"]
    for r in MODELS:
        rows.append(f"| `{r.name}` | `{r.element}` | `{r.source}` | {', '.join(version[f] for f in r.fmi_versions)} | "
                    + (f"`{r.adapter}`" if r.adapter else "-") + " | " + (f"`{r.variant_of}`" if r.variant_of else "-")
                    + " |")
    return "\n".join(rows) + "\n"
