"""The controller's gains, one row each: name, unit, range, description and figure label.

Every list of gain names (tapmp.params.GAIN_NAMES, MODAL_GAIN_NAMES), the fields of
tapmp.control.Gains and ModalGains, the FMU variables' units, descriptions and ranges
(tapmp.interface) and the figures' axis labels are read from GAINS. USUAL holds the usual
range of the settings whose implausible values the tool warns about (orchestrator.tool.plausibility).

Units are those of the FMU variables (keys of tapmp.interface.UNITS); the command u is in
command units with K_T F = u, so a gain divided by K_T is its force gain. This module imports
nothing from tapmp: every other module may read it.
"""

from typing import NamedTuple


class Setting(NamedTuple):
    """One gain: ``description`` and ``label`` may hold "{i}", the motor number (per-motor gains)."""

    name: str
    unit: str                    # a key of tapmp.interface.UNITS
    range: tuple[float, float]   # the one range rule: min <= value <= max (NaN and infinities refused)
    description: str             # the FMU variable's description
    label: str                   # a figure's axis label of the quantity (without unit)
    per_motor: bool = True       # one value per motor (NAME1 .. NAME3) or one for all
    integral: bool = False       # multiplies only the integral state (zero initially)


_MODE = {"c": "common mode (1,1,1)/sqrt(3)", "d": "differential modes (I - 1 1^T/3)"}
_TERMS = (("p", "1/m", "proportional", "m", "N/m", "P"), ("v", "s/m", "derivative", "m/s", "N.s/m", "V"),
          ("i", "1/(m.s)", "integral", "m.s", "N/(m.s)", "I"))

# Per-motor gains (Gains, in this order) then PID-DC's modal gains (ModalGains, in this order).
GAINS: tuple[Setting, ...] = (
    Setting("Lambda_p", "1/m", (0.0, 1e12),
            "SC-DC Lambda_p on c (Eq. 25), APD-DC k_p on e (Eq. 38) of motor {i}, in command units per m: the "
            "force gain is Lambda_p{i}/K_T{i} N/m", "Λp, position gain"),
    Setting("Lambda_v", "s/m", (0.0, 1e12),
            "SC-DC Lambda_v on n (Eq. 25), APD-DC k_v on de (Eq. 38) of motor {i}, in command units per m/s: the "
            "force gain (damping) is Lambda_v{i}/K_T{i} N.s/m", "Λv, velocity gain"),
    Setting("b", "1/s", (0.0, 1e9), "coupling coefficient b of B = diag(b) (Eq. 22), motor {i}",
            "b, coupling coefficient"),
    Setting("D", "1/s", (0.0, 1e9), "D of n = de_c + D e_c (Eq. 24), motor {i}", "D, error-filter gain"),
    Setting("K_T", "1/N", (1e-12, 1e12),
            "command per newton of motor {i}: K_T{i} F{i} = u{i} (Eq. 25/38), so F{i} = u{i}/K_T{i} and every gain "
            "of motor {i} divided by K_T{i} is its force gain", "K_T, command per newton"),
    *(Setting(f"k{k}_{m}", unit, (0.0, 1e15),
              f"PID-DC (law 2) {what} gain on the {_MODE[m]}, in command units per {per}: the force gain is "
              f"k{k}_{m}/K_T {force}", f"k{k}_{m}, {'common' if m == 'c' else 'differential'}-mode {term} gain",
              per_motor=False, integral=k == "i")
      for m in "cd" for k, unit, what, per, force, term in _TERMS),
)
SETTING = {s.name: s for s in GAINS}
GAIN_NAMES = tuple(s.name for s in GAINS if s.per_motor)
MODAL_GAIN_NAMES = tuple(s.name for s in GAINS if not s.per_motor)

# Usual range (lowest, highest) of a setting on the TAPMP of the paper, by name (the same name is the
# same quantity in every model): generous bands around the paper's Section 5.1 values (masses 1.835 /
# 4.776 / 1.946 / 4.775 kg, I_y = 7.768e-3 kg m^2, L_1 = 0.09 m) and the plant's defaults (100 nm
# grating ruler, 5 N s/m viscous and 2 N Coulomb friction, 600 N force limit, 200 N/m pulling), wide
# enough that only an error of units or orders of magnitude leaves them. Units: the FMU variable's.
USUAL: dict[str, tuple[float, float]] = {
    "m_p": (0.1, 50.0), "m_1": (0.1, 50.0), "m_2": (0.1, 50.0), "m_3": (0.1, 50.0),
    "I_y": (1e-5, 1.0), "L_1": (0.01, 1.0), "g": (9.7, 9.9),
    "encoder_resolution": (1e-9, 1e-4),
    **{f"c_v{i}": (0.01, 1000.0) for i in (1, 2, 3)},
    **{f"F_c{i}": (0.01, 200.0) for i in (1, 2, 3)},
    "v_s": (1e-6, 0.1),
    "force_limit": (10.0, 1e4),
    "k_pull": (-1e5, 1e5),  # negative: a net attraction (negative stiffness)
    "radius": (1e-5, 0.04),
    "B_amplitude": (0.0, 0.35),
}
# How a message writes a unit of the table (the FMU units' dots and exponents as a reader writes them).
_UNIT_TEXT = {"kg.m2": "kg m^2", "m/s2": "m/s^2", "N.s/m": "N s/m"}


def unit_text(unit: str) -> str:
    """``unit`` (a key of tapmp.interface.UNITS) as messages write it: "N.s/m" -> "N s/m"."""
    return _UNIT_TEXT.get(unit, unit)


def gain_doc() -> dict[str, tuple[str, str]]:
    """{gain: (unit, description)} of the per-motor gains, "{i}" in the description the motor."""
    return {s.name: (s.unit, s.description) for s in GAINS if s.per_motor}


def modal_doc() -> dict[str, tuple[str, str]]:
    """{gain: (unit, description)} of PID-DC's modal gains."""
    return {s.name: (s.unit, s.description) for s in GAINS if not s.per_motor}


def ranges() -> dict[str, tuple[float, float]]:
    """{FMU variable: (min, max)} of every gain: Lambda_p1 .. K_T3, then kp_c .. ki_d."""
    return {f"{s.name}{i}" if s.per_motor else s.name: s.range
            for s in GAINS for i in ((1, 2, 3) if s.per_motor else (None,))}
