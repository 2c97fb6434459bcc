"""Model parameters and gain presets: the one place these numbers are defined.

Identified parameters are from the paper's Section 5.1; gain presets are Eq. 40-43
plus a default set that is stable in a loop sampled at 0.1 ms (see README).
"""

import math
from typing import NamedTuple

from .errors import require_positive


class ModelParams(NamedTuple):
    """Rigid-body parameters of the TAPMP (paper Section 5.1)."""

    m_p: float = 1.835     # platform mass [kg]
    m_1: float = 4.776     # left auxiliary block (mover 1) mass [kg]
    m_2: float = 1.946     # middle auxiliary block (mover 2) mass [kg]
    m_3: float = 4.775     # right auxiliary block (mover 3) mass [kg]
    I_y: float = 7.768e-3  # platform inertia about Y, 77.68 kg cm^2 [kg m^2]
    L_1: float = 0.09      # platform width [m]
    g: float = 9.8         # gravitational acceleration [m/s^2]

    def validated(self) -> "ModelParams":
        """Return self after checking every field is finite and > 0 (ModelInputError otherwise)."""
        for name, value in zip(self._fields, self):
            require_positive(name, value)
        return self


PAPER_MODEL = ModelParams()

# Gains per motor, (motor 1, motor 2, motor 3). For APD-DC (law 1) the same
# parameters are read as k_p = Lambda_p, k_v = Lambda_v, K_T1 = K_T (Eq. 41).
GAIN_PRESETS: dict[str, dict[str, tuple[float, float, float]]] = {
    # Stable at h = 0.1 ms with the default plant (quantization, friction, pulling).
    "default": {
        "Lambda_p": (300.0, 300.0, 300.0),
        "Lambda_v": (0.36, 0.36, 0.36),
        "b": (50.0, 50.0, 50.0),
        "D": (900.0, 900.0, 900.0),
        "K_T": (4.1e-5, 4.1e-5, 4.1e-5),
    },
    # Eq. 40-41, the paper's simulation gains.
    "paper_simulation": {
        "Lambda_p": (8000.0, 8000.0, 8850.0),
        "Lambda_v": (150.0, 158.5, 108.5),
        "b": (0.0005, 8.1, 1.5),
        "D": (200.0, 200.0, 200.0),
        "K_T": (4.1e-5, 4.1e-5, 4.1e-5),
    },
    # Eq. 42-43, the paper's experimental gains.
    "paper_experiment": {
        "Lambda_p": (3.8, 3.0, 4.0),
        "Lambda_v": (30.0, 30.0, 28.0),
        "b": (0.00059, 0.00051, 0.00059),
        "D": (50.0, 50.0, 50.0),
        "K_T": (3e-5, 3e-5, 3e-5),
    },
}

GAIN_NAMES = ("Lambda_p", "Lambda_v", "b", "D", "K_T")


def gain_preset(name: str) -> dict[str, tuple[float, float, float]]:
    """Return a copy of the named gain preset; ValueError lists the known names."""
    try:
        return {k: tuple(v) for k, v in GAIN_PRESETS[name].items()}
    except KeyError:
        raise ValueError(
            f"gain preset {name!r} is unknown: allowed are {', '.join(sorted(GAIN_PRESETS))}") from None


DEG = math.pi / 180.0
