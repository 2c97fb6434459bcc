"""The control laws written out in Python from the paper's equations: the tests' independent
reference for the C model's laws (tapmp/c/tapmp_model.c) that every FMU family runs.

Units: positions [m], velocities [m/s], forces and commands [N]; K_T F = u (tapmp.control)."""

from tapmp.control import Gains, ModalGains
from tapmp.dynamics import generalized_force
from tapmp.kinematics import forward, solve_transpose, task_velocity
from tapmp.params import ModelParams


def sync_errors(e1: float, e2: float, e3: float) -> tuple[float, float, float]:
    """Synchronization errors in adjacent order, Eq. 18 [m]. They sum to zero."""
    return e1 - e2, e2 - e3, e3 - e1


def feedforward(q, dq, dx_d, ddx_d, p: ModelParams) -> tuple[float, float, float]:
    """Dynamics compensation u_d of Eq. 26 / 39 [N].

    u_d = J^-T(x) (M(x) xdd_d + C(x, xd) xd_d + G(x)) with x = FK(q) (Eq. 1) and
    xd = J(x)^-1 dq from the measured motor positions q [m] and rates dq [m/s];
    dx_d, ddx_d are the desired task rates and accelerations (X, Z, B).
    """
    L1 = p.L_1
    _, _, B = forward(q[0], q[1], q[2], L1)
    dB = task_velocity(B, dq[0], dq[1], dq[2], L1)[2]
    gX, gZ, gB = generalized_force(B, dB, ddx_d[0], ddx_d[1], ddx_d[2], dx_d[2], p)
    return solve_transpose(B, gX, gZ, gB, L1)


def scdc_command(e, de, c, integral_c, u_d, g: Gains) -> tuple[float, float, float]:
    """SC-DC command u of Eq. 22-25 (one value per motor).

    e, de: tracking error [m] and its rate [m/s]; c: Eq. 21 [m]; integral_c: the
    running integral of c [m s]; u_d: Eq. 26 [N].
    """
    u = [0.0, 0.0, 0.0]
    for i in range(3):
        b = g.b[i]
        e_c = e[i] + b * integral_c[i]  # Eq. 22
        de_c = de[i] + b * c[i]         # Eq. 23
        n = de_c + g.D[i] * e_c         # Eq. 24
        u[i] = g.K_T[i] * u_d[i] + g.Lambda_v[i] * n + g.Lambda_p[i] * c[i]  # Eq. 25
    return u[0], u[1], u[2]


def apd_command(e, de, u_d, g: Gains) -> tuple[float, float, float]:
    """APD-DC command of Eq. 38 with k_v = Lambda_v, k_p = Lambda_p, K_T1 = K_T (Eq. 41)."""
    return tuple(g.K_T[i] * u_d[i] + g.Lambda_v[i] * de[i] + g.Lambda_p[i] * e[i] for i in range(3))


def _modal(k_c: float, k_d: float, x, i: int, mean: float) -> float:
    """Row i of (k_c Pi_c + k_d Pi_d) x, with mean = (x1 + x2 + x3) / 3 (Pi_c x = mean 1)."""
    return k_c * mean + k_d * (x[i] - mean)


def pid_command(e, de, integral_e, u_d, m: ModalGains, K_T) -> tuple[float, float, float]:
    """PID-DC command u = K_T u_d + K_P e + K_V de + K_I int(e) (one value per motor).

    Each K = k_c Pi_c + k_d Pi_d acts on the common mode (the mean of the three motors)
    with k_c and on the differential modes (the deviations from the mean) with k_d.
    e [m], de [m/s], integral_e [m s] (right-rectangle sum of e), u_d [N] (Eq. 26/39),
    K_T per motor. With ModalGains.matching_scdc(g) it equals scdc_command for uniform g.
    """
    me = (e[0] + e[1] + e[2]) / 3.0
    mv = (de[0] + de[1] + de[2]) / 3.0
    mi = (integral_e[0] + integral_e[1] + integral_e[2]) / 3.0
    return tuple(K_T[i] * u_d[i] + _modal(m.kp_c, m.kp_d, e, i, me) + _modal(m.kv_c, m.kv_d, de, i, mv)
                 + _modal(m.ki_c, m.ki_d, integral_e, i, mi) for i in range(3))
