"""Plausibility of a scenario's parameters for this machine (not validity: see scenario.Scenario).

A value can be valid (finite, of the right sign) and still far from anything the TAPMP of
the paper could have, usually a unit slip: ``encoder_resolution = 0.5`` (metres, not
micrometres) quantizes the motor positions to half a metre. Such a run is allowed (a study
may want it) but gets one warning line per parameter, naming the value and the usual range.

USUAL holds the ranges, in one place: generous bands around the paper's Section 5.1 values
(masses 1.835 / 4.776 / 1.946 / 4.775 kg, I_y = 7.768e-3 kg m^2, L_1 = 0.09 m) and the plant's
defaults (100 nm grating ruler, 5 N s/m viscous and 2 N Coulomb friction, 600 N force limit,
200 N/m pulling), wide enough that only an error of units or orders of magnitude leaves them.
"""

from .scenario import Scenario

_MODEL = {  # the rigid-body parameters; the plant and the controller's nominal model both have them
    "m_p": (0.1, 50.0, "kg"), "m_1": (0.1, 50.0, "kg"), "m_2": (0.1, 50.0, "kg"), "m_3": (0.1, 50.0, "kg"),
    "I_y": (1e-5, 1.0, "kg m^2"), "L_1": (0.01, 1.0, "m"), "g": (9.7, 9.9, "m/s^2"),
}
# (section, name) -> (lowest usual, highest usual, unit). 0 for a value that 0 switches off
# (encoder_resolution, force_limit, friction, k_pull) is always plausible.
USUAL = {
    **{("plant", n): r for n, r in _MODEL.items()},
    **{("controller", n): r for n, r in _MODEL.items()},
    ("plant", "encoder_resolution"): (1e-9, 1e-4, "m"),
    **{("plant", f"c_v{i}"): (0.01, 1000.0, "N s/m") for i in (1, 2, 3)},
    **{("plant", f"F_c{i}"): (0.01, 200.0, "N") for i in (1, 2, 3)},
    ("plant", "v_s"): (1e-6, 0.1, "m/s"),
    ("plant", "force_limit"): (10.0, 1e4, "N"),
    ("plant", "k_pull"): (-1e5, 1e5, "N/m"),  # negative: a net attraction (negative stiffness)
    ("controller", "force_limit"): (10.0, 1e4, "N"),
    ("trajectory", "radius"): (1e-5, 0.04, "m"),
    ("trajectory", "B_amplitude"): (0.0, 0.35, "rad"),
}
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
