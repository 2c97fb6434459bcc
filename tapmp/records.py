"""The TAPMP models' records (tapmp.models.ModelRecord): the plant, the controller, the reference
trajectory, the drive (optional) and the clocked controller, registered in signal-flow order when the package is imported
(tapmp/__init__.py). Each record names its variables and output dependencies (tapmp.interface), its
C files, its settings struct, its description, its documentation's text and equations and its icon.
A new model is one more record, in its own module or here (docs/architecture.md, "Adding a model").
"""

from .interface import (CONTROLLER_SOURCES, CONTROLLER_VARS, DRIVE_FEEDS, DRIVE_SOURCES, DRIVE_VARS, PLANT_SOURCES,
                        PLANT_VARS, TRAJECTORY_VARS, _controller_dependencies, _drive_dependencies,
                        _plant_dependencies, _trajectory_dependencies, step_order)
from .models import CLOCKED, CONTROLLER, DRIVE, PLANT, TRAJECTORY, ModelRecord, record, register
from . import laws

CLOCK_NAME = "sample_clock"   # fmu_controller/controller.h: MODEL_CLOCK_NAME
_NATIVE = "(native C, no Python at run time)"


def _n(model: str, name: str) -> str:
    """The start value of ``model``'s parameter ``name`` as the documentation writes it."""
    return f"{next(v.start for v in record(model).variables if v.name == name):g}"


def _plant_what() -> str:
    n = lambda name: _n(PLANT, name)  # noqa: E731
    return ("The plant of the three-axis parallel motion platform (TAPMP) of Zhou, Gao and Zhang, "
                f"<i>Actuators</i> 2024, 13, 166: a platform (m_p = {n('m_p')} kg, I_y = {n('I_y')} kg m2, "
                f"width L_1 = {n('L_1')} m) on three linear motors whose movers (m_1 = {n('m_1')} kg, "
                f"m_2 = {n('m_2')} kg, m_3 = {n('m_3')} kg) slide on one axis; the platform moves in X and Z and "
                "rotates about Y by B. The motor forces F1..F3 [N] drive it; it outputs the encoder positions, "
                "the true positions and velocities of the motors, and the pose. Inside, fixed-step RK4 "
                "integrates the dynamics over each communication step with the force of that step.")


def _controller_what() -> str:
    return ("The SC-DC synchronization controller with dynamics compensation of the TAPMP (Zhou, Gao, "
                     "Zhang, <i>Actuators</i> 2024, 13, 166), with the APD-DC and modal PID-DC baselines: it "
                     f"samples the reference pose and the measured motor positions every T_s = "
                     f"{float(_n(CONTROLLER, 'T_s')) * 1e3:g} ms and holds the force commands F1..F3 [N] between "
                     "samples.")


def _trajectory_what() -> str:
    return ("The reference of the TAPMP paper's simulation (Section 5.2): a circle in the XZ plane and a "
                     "sinusoid in B; outputs the desired pose with its first two derivatives and the desired motor "
                     "positions q_d (Eq. 2).")


def _drive_what() -> str:
    d = lambda name: _n(DRIVE, name)  # noqa: E731
    return ("The servo drive of each of the TAPMP's three linear motors, between the controller's force commands "
            "F_cmd1..F_cmd3 [N] and the plant's forces F1..F3 [N]: a computation delay of delay_samples = "
            f"{d('delay_samples')} communication step(s), a current (force) limit of {d('force_limit')} N, a "
            f"second-order current loop (natural frequency {d('current_bandwidth')} Hz, damping "
            f"{d('current_damping')}) and a force-constant error per motor. It is not part of TAPMP.ssp: "
            "TAPMP_Drive.ssp is the closed loop with it (trajectory -> controller -> drive -> plant), stepped "
            f"Gauss-Seidel in the order {', '.join(step_order(DRIVE))}.")


def _drive_equations() -> list[tuple[str, str]]:
    return [
        ("Computation delay", "c_k = F_cmd,i(t_(k-d)), d = delay_samples communication steps (c = F_cmd(t_0) "
                              "before the start)"),
        ("Current (force) limit", "s_k = min(max(c_k, -force_limit), force_limit); force_limit = 0: s_k = c_k"),
        ("Current (force) loop", "y'' = w_n^2 (s - y) - 2 zeta w_n y', w_n = 2 pi current_bandwidth, zeta = "
                                 "current_damping; current_bandwidth = 0: y = s"),
        ("Discretization", "s held over [t_k, t_k + h]; (y, y'/w_n, mean of y over the step) advanced exactly by "
                           "exp(M h), computed once per step size h"),
        ("Force", "F_i = (1 + force_constant_error_i) mean of y over [t_k, t_k + h], held over that step"),
        ("Start", "at rest on the initial command: y = s_0, y' = 0"),
    ]


def _kinematics() -> tuple[str, str]:
    return ("Inverse kinematics (Eq. 2)", "q1 = X + sqrt(3) Z + L_1 (1 - cos B + sqrt(3) sin B), q2 = X, "
            "q3 = X - sqrt(3) Z - L_1 (1 - cos B - sqrt(3) sin B), L_1 = " + _n(PLANT, "L_1") + " m")


def _plant_equations() -> list[tuple[str, str]]:
    p = lambda name: _n(PLANT, name)  # noqa: E731
    kinematics = _kinematics()
    return [
            kinematics,
            ("Dynamics (Eq. 5-14)", "M(x) ddx + C(x, dx) dx + G(x) = J(x)^T (F - F_f - F_pull + F_dist), "
                                    "x = (X, Z, B), dq = J(x) dx (Eq. 3), g = " + p("g") + " m/s2"),
            ("Friction", f"F_f,i = c_v,i dq_i + F_c,i tanh(dq_i / v_s), c_v = {p('c_v1')} N s/m, "
                         f"F_c = {p('F_c1')} N, v_s = {p('v_s')} m/s"),
            ("Saturation", f"|F_i| <= force_limit = {p('force_limit')} N"),
            ("Mutual pulling", f"k_pull = {p('k_pull')} N/m on the change of the gaps q2 - q1 and q3 - q2"),
            ("Encoder", f"q_i (measured) = r round(q_i / r), r = encoder_resolution = {p('encoder_resolution')} m"),
            ("Flexible mode (extends Eq. 11, 12)",
             "off while flex_frequency = 0; else a part m_f = flex_mass of the platform's mass m_p moves in Z on a "
             "spring-damper: Eq. 11 with m_p - m_f in M_22 (Eq. 12), the weight m_p g in G and f_f = m_f a_f added "
             "to the Z force, z_f'' = -Z'' - a_f, a_f = w_f^2 z_f + 2 zeta_f w_f z_f', w_f = 2 pi flex_frequency, "
             "zeta_f = flex_damping; z_f [m] the deflection from the static equilibrium, at rest at the start"),
            ("Integration", "RK4, `substeps` = " + p("substeps") + " step(s) per communication step"),
    ]


def _controller_equations() -> list[tuple[str, str]]:
    c = lambda name: _n(CONTROLLER, name)  # noqa: E731
    return [
            ("Errors (Eq. 15, 18, 21)", "e_i = q_d,i - q_i; e_s,i = e_i - e_(i+1); c = (e_s1 - e_s3, e_s2 - e_s1, "
                                        "e_s3 - e_s2)"),
            ("Coupled errors (Eq. 22-24)", "e_c = e + b int(c) dt, de_c = de + b c, n = de_c + D e_c, "
                                           f"b = {c('b1')} 1/s, D = {c('D1')} 1/s"),
            ("SC-DC command (Eq. 25)", f"u = K_T u_d + Lambda_v n + Lambda_p c, Lambda_p = {c('Lambda_p1')} 1/m, "
                                       f"Lambda_v = {c('Lambda_v1')} s/m, K_T = {c('K_T1')} 1/N; F = u / K_T"),
            ("Dynamics compensation (Eq. 26)", "u_d = J^-T(x) (M(x) ddx_d + C(x, dx) dx_d + G(x)), x = FK(q) (Eq. 1)"),
            *laws.equation_rows(),
            ("Sampling", f"at t0 + k T_s, T_s = {c('T_s')} s; velocity by backward difference of q"),
    ]


def _trajectory_equations() -> list[tuple[str, str]]:
    t = lambda name: _n(TRAJECTORY, name)  # noqa: E731
    kinematics = _kinematics()
    return [
            ("Circle", f"X_d = X_c + R sin(2 pi f_xz t + phase_xz), Z_d = Z_c + R cos(2 pi f_xz t + phase_xz), "
                       f"X_c = {t('X_c')} m, Z_c = {t('Z_c')} m, R = {t('radius')} m, f_xz = {t('f_xz')} Hz"),
            ("Rotation", f"B_d = B_offset + A sin(2 pi f_B t + phase_B), A = {t('B_amplitude')} rad (5 deg), "
                         f"f_B = {t('f_B')} Hz"),
            kinematics,
            ("Other profiles", "profile = 1 step, 2 ramp, 3 jerk-limited S-curve from pose A to pose B"),
    ]


_CONTROLLER_DESCRIPTION = f"{laws.controller_description()} {_NATIVE}"  # each law as its record says

# In signal-flow order: the SSP's elements and the container's components are listed so.
register(ModelRecord(
    name=TRAJECTORY, element="trajectory", variables=TRAJECTORY_VARS, dependencies=_trajectory_dependencies,
    source="fmu_controller/trajectory.c", header="fmu_controller/trajectory.h",
    settings_struct="tapmp_trajectory_settings", settings_relations="trajectory_domain_check",
    description=f"TAPMP reference trajectory (paper Section 5.2 / 6.2): XZ circle and B sinusoid {_NATIVE}",
    what=_trajectory_what, equations=_trajectory_equations, icon_label="ref",
    adapter="fmu_controller/TAPMP_Trajectory.py", diagram_note="X_d Z_d B_d (Eq. 1)"))
register(ModelRecord(
    name=CONTROLLER, element="controller", variables=CONTROLLER_VARS, dependencies=_controller_dependencies,
    sources=CONTROLLER_SOURCES,
    source="fmu_controller/controller.c", header="fmu_controller/controller.h",
    settings_struct="tapmp_controller_settings", settings_relations="controller_anti_windup_check",
    description=_CONTROLLER_DESCRIPTION,
    what=_controller_what, equations=_controller_equations, icon_label="SC-DC",
    adapter="fmu_controller/TAPMP_Controller.py", diagram_note="SC-DC (Eq. 15-26)"))
# The drive: optional (outside TAPMP.ssp), between controller and plant in its own system TAPMP_Drive.ssp.
register(ModelRecord(
    name=DRIVE, element="drive", variables=DRIVE_VARS, dependencies=_drive_dependencies, sources=DRIVE_SOURCES,
    source="fmu_plant/drive.c", header="fmu_plant/drive.h",
    description="Servo drive of the TAPMP's three linear motors: computation delay, current (force) limit, "
                f"second-order current loop and force-constant error between controller and plant {_NATIVE}",
    what=_drive_what, equations=_drive_equations, icon_label="drive", diagram_note="delay, current loop",
    optional=True, feeds=DRIVE_FEEDS))
register(ModelRecord(
    name=PLANT, element="plant", variables=PLANT_VARS, dependencies=_plant_dependencies, sources=PLANT_SOURCES,
    source="fmu_plant/plant.c", header="fmu_plant/plant.h", settings_struct="tapmp_plant_settings",
    settings_relations="plant_flex_check",
    description="Three-axis parallel motion platform (Zhou, Gao, Zhang, Actuators 2024, 13, 166): motor forces "
                f"in, encoder positions and platform pose out {_NATIVE}",
    what=_plant_what, equations=_plant_equations, icon_label="plant", adapter="fmu_plant/TAPMP_Plant.py",
    me_states=("X", "Z", "B", "dX", "dZ", "dB"), diagram_note="dynamics (Eq. 5-14), RK4"))
# The controller with a periodic input clock (FMI 3.0 only): its variables and C files are the controller's.
register(ModelRecord(
    name=CLOCKED, element="controller", variables=CONTROLLER_VARS, dependencies=_controller_dependencies,
    source="fmu_controller/controller.c", header="fmu_controller/controller.h",
    settings_struct="tapmp_controller_settings", settings_relations="controller_anti_windup_check",
    icon_label="SC-DC", fmi_versions=("fmi3",), variant_of=CONTROLLER,
    description=(_CONTROLLER_DESCRIPTION + "; samples at every tick of its periodic input clock "
                 f"{CLOCK_NAME} (interval T_s, activated by the host in Event Mode) and holds its outputs "
                 "between ticks"),
    what=_controller_what, equations=_controller_equations))
