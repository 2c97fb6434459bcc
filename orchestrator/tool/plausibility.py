"""Plausibility of a scenario's parameters for this machine (not validity: see scenario.Scenario).

A value can be valid (finite, of the right sign) and still far from anything the TAPMP of
the paper could have, usually a unit slip: ``encoder_resolution = 0.5`` (metres, not
micrometres) quantizes the motor positions to half a metre. Such a run is allowed (a study
may want it) but gets one warning line per parameter, naming the value and the usual range.

The usual ranges are a column of the settings table (tapmp.settings.USUAL, in the units of the
FMU variables); USUAL here says which sections' settings are checked against them.
"""

from tapmp import settings
from tapmp.interface import ELEMENT, VARIABLES

from .scenario import Scenario

_MODEL = ("m_p", "m_1", "m_2", "m_3", "I_y", "L_1", "g")  # the plant and the controller's nominal model have them
# The settings checked, by section, in the order of the warnings.
_CHECKED = (("plant", _MODEL), ("controller", _MODEL),
            ("plant", ("encoder_resolution", "c_v1", "c_v2", "c_v3", "F_c1", "F_c2", "F_c3", "v_s", "force_limit",
                       "k_pull")),
            ("controller", ("force_limit",)), ("trajectory", ("radius", "B_amplitude")))


def _unit(section: str, name: str) -> str:
    """The unit of the setting ``name`` of the element ``section`` as a message writes it."""
    model = next(m for m, element in ELEMENT.items() if element == section)
    return settings.unit_text(next(v.unit for v in VARIABLES[model] if v.name == name))


# (section, name) -> (lowest usual, highest usual, unit). 0 for a value that 0 switches off
# (encoder_resolution, force_limit, friction, k_pull) is always plausible.
USUAL = {(section, name): (*settings.USUAL[name], _unit(section, name)) for section, names in _CHECKED for name in names}
_OFF_AT_ZERO = {"encoder_resolution", "force_limit", "k_pull", "c_v1", "c_v2", "c_v3", "F_c1", "F_c2", "F_c3",
                "radius"}


def implausible(scenario: Scenario) -> list[str]:
    """One line per parameter the scenario sets outside USUAL: "plant.encoder_resolution =
    0.5 m is far outside the usual range for this machine (1e-09 to 0.0001 m); running anyway"."""
    lines = []
    for (section, name), (lo, hi, unit) in USUAL.items():
        table = getattr(scenario, section, None) or {}
        if name not in table:
            continue
        value = table[name]
        if value == 0.0 and name in _OFF_AT_ZERO:
            continue
        if not lo <= value <= hi:
            lines.append(f"{section}.{name} = {value:g} {unit} is far outside the usual range for this machine "
                         f"({lo:g} to {hi:g} {unit}); running anyway")
    return lines
