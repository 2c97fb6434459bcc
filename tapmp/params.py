"""Model parameters and gain presets: the one place these numbers are defined.

Identified parameters are from the paper's Section 5.1; gain presets are Eq. 40-43
plus a default set that is stable in a loop sampled at 0.1 ms (see README).
"""

import math
from typing import NamedTuple

from . import cmodel
from .laws import BY_NAME as _LAW
from .settings import GAIN_NAMES, MODAL_GAIN_NAMES


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
        """Return self after checking every field's range in the settings table (ModelInputError
        otherwise; the C model's generated tapmp_plant_settings_check, which every FMU runs too)."""
        from .models import PLANT
        cmodel.check_settings(PLANT, self._asdict())
        return self


PAPER_MODEL = ModelParams()

# The servo cycle: the controller's sample period T_s and the communication step of every run
# and FMU DefaultExperiment [s]; the paper's run ends at STOP_TIME [s] (one period of its 0.4 Hz
# reference).
SERVO_STEP = 1e-4
START_TIME = 0.0
STOP_TIME = 2.5
# The controller's back-calculation anti-windup, its default tracking time T_t [s]: about sqrt(Ti Td) (Astrom and
# Hagglund's rule) of the default gains, 2.7 ms on SC-DC's differential modes (Ti = kp_d/ki_d = 26 ms,
# Td = kv_d/kp_d = 0.28 ms) and on pid-dc-full's common mode (ki_c = ki_d: Ti = 6.7 ms, Td = 1.1 ms).
ANTI_WINDUP_TIME = 0.003

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

# GAIN_NAMES (the per-motor gains, every preset's keys) and MODAL_GAIN_NAMES come from the gains table
# (tapmp.settings). PID-DC (law 2) modal gains: K = k_c Pi_c + k_d Pi_d with Pi_c = 1 1^T / 3 (common
# mode) and Pi_d = I - Pi_c (the two differential modes of L = 3 I - 1 1^T = 3 Pi_d); same units and
# K_T scaling as Lambda: kp [N/m], kv [N s/m], ki [N/(m s)] on u, F = u / K_T.


def scdc_modal_image(preset: dict) -> dict[str, float]:
    """The PID-DC gains that reproduce SC-DC exactly, for uniform SC-DC gains.

    Written in e, SC-DC (Eq. 22-25) is u = K_T u_d + Lambda_v de + [Lambda_v D I +
    (Lambda_v b + Lambda_p) L] e + Lambda_v D b L int(e) with L = 3 Pi_d, so per mode:
    common kp_c = Lambda_v D, kv_c = Lambda_v, ki_c = 0; differential
    kp_d = Lambda_v D + 3 (Lambda_v b + Lambda_p), kv_d = Lambda_v, ki_d = 3 Lambda_v D b.
    ``preset`` maps Lambda_p, Lambda_v, b, D to (motor 1, 2, 3); ValueError if a gain
    differs between motors (then the modes of L are not the modes of the law).
    """
    v = {}
    for name in _LAW["sc-dc"].tunable:
        values = tuple(float(x) for x in preset[name])
        if not values[0] == values[1] == values[2]:
            raise ValueError(f"{name} = {values!r} is not uniform: allowed are equal gains on all motors "
                             "(only then is SC-DC a modal PID)")
        v[name] = values[0]
    return scdc_mode_gains(v["Lambda_p"], v["Lambda_v"], v["b"], v["D"])


def scdc_mode_gains(lp: float, lv: float, b: float, D: float) -> dict[str, float]:
    """Per-mode PID gains of SC-DC for one motor's Lambda_p [u/m], Lambda_v [u s/m], b and
    D [1/s] (formulas in scdc_modal_image; units as MODAL_GAIN_NAMES)."""
    common, differential = (lv * D, lv, 0.0), (lv * D + 3.0 * (lv * b + lp), lv, 3.0 * lv * D * b)
    return dict(zip(MODAL_GAIN_NAMES, common + differential))  # kp, kv, ki of each mode


# The PID-DC defaults are the modal image of the default SC-DC gains, so that law = 2 on
# its own runs "PID-DC mode-matched": kp_c 324, kv 0.36, ki_c 0, kp_d 1278, ki_d 48600.
DEFAULT_MODAL_GAINS = scdc_modal_image(GAIN_PRESETS["default"])


def gain_preset(name: str) -> dict[str, tuple[float, float, float]]:
    """Return a copy of the named gain preset; ValueError lists the known names."""
    try:
        return {k: tuple(v) for k, v in GAIN_PRESETS[name].items()}
    except KeyError:
        raise ValueError(
            f"gain preset {name!r} is unknown: allowed are {', '.join(sorted(GAIN_PRESETS))}") from None


DEG = math.pi / 180.0
