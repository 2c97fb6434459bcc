"""Task-space dynamics of the TAPMP (paper Section 3, Eq. 5-14).

    M(x) xdd + C(x, xd) xd + G(x) = J(x)^T F

with x = (X, Z, B) and F the three motor forces [N]. The mass matrix is the exact
M = diag(m_p, m_p, I_y) + J^T diag(m_1, m_2, m_3) J. Eq. 13 is that matrix only
when m_1 = m_3, which the identified masses (4.776 vs 4.775 kg) are not, so the
exact form is used everywhere and Eq. 13 is kept for comparison in tests.

C = J^T diag(m) dJ/dt. Since J depends on B alone, this is the factorization for
which dM/dt - 2C is skew-symmetric (the Christoffel-consistent one) and it equals
Eq. 13's C exactly when m_1 = m_3.
"""

import math

from .kinematics import S3, rotation_column, rotation_column_dB
from .params import ModelParams

Mat3 = tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]]


def mass_matrix(B: float, p: ModelParams, m_f: float = 0.0) -> Mat3:
    """Exact task-space mass matrix M(x) [kg, kg, kg m^2 blocks] (Eq. 12, general m_1, m_3); with
    the flexible mode's modal mass m_f [kg], the platform's rigid part m_p - m_f in M_22 (the part
    on the mode moves with the platform in X and, a point at its reference point, adds no I_y)."""
    a1, a3 = rotation_column(B, p.L_1)
    m1, m2, m3 = p.m_1, p.m_2, p.m_3
    M11 = p.m_p + m1 + m2 + m3
    M12 = S3 * (m1 - m3)
    M13 = m1 * a1 + m3 * a3
    M22 = (p.m_p - m_f) + (m1 + m3) / 3.0  # m_p - 0.0 is m_p: the rigid model's bits
    M23 = S3 * (m1 * a1 - m3 * a3)
    M33 = p.I_y + m1 * a1 * a1 + m3 * a3 * a3
    return ((M11, M12, M13), (M12, M22, M23), (M13, M23, M33))


def coriolis_matrix(B: float, dB: float, p: ModelParams) -> Mat3:
    """C(x, xd) = J^T diag(m) dJ/dt; only its third column is non-zero."""
    d1, d3 = rotation_column_dB(B, p.L_1)
    a1, a3 = rotation_column(B, p.L_1)
    w1 = p.m_1 * d1 * dB
    w3 = p.m_3 * d3 * dB
    return ((0.0, 0.0, w1 + w3), (0.0, 0.0, S3 * (w1 - w3)), (0.0, 0.0, a1 * w1 + a3 * w3))


def coriolis_times(B: float, dB: float, v3: float, p: ModelParams) -> tuple[float, float, float]:
    """C(x, xd) v for a vector v whose third (B) component is v3 (the others do not enter)."""
    d1, d3 = rotation_column_dB(B, p.L_1)
    a1, a3 = rotation_column(B, p.L_1)
    w1 = p.m_1 * d1 * dB * v3
    w3 = p.m_3 * d3 * dB * v3
    return w1 + w3, S3 * (w1 - w3), a1 * w1 + a3 * w3


def mass_matrix_eq13(B: float, p: ModelParams) -> Mat3:
    """The paper's closed-form M of Eq. 13, which assumes m_1 = m_3 (uses m_1 for both)."""
    L, m1, c, s = p.L_1, p.m_1, math.cos(B), math.sin(B)
    k = 2.0 * math.sqrt(3.0) * m1 * L / 3.0
    M11 = p.m_p + p.m_1 + p.m_2 + p.m_3
    M33 = p.I_y + 2.0 * m1 * (L * L * c * c / 3.0 + L * L * s * s)
    return ((M11, 0.0, k * c), (0.0, p.m_p + 2.0 * m1 / 3.0, k * s), (k * c, k * s, M33))


def solve_sym3(M: Mat3, r1: float, r2: float, r3: float) -> tuple[float, float, float]:
    """Solve M y = r for a symmetric positive definite 3x3 M by its adjugate."""
    (a, b, c), (_, d, e), (_, _, f) = M
    A11 = d * f - e * e
    A12 = c * e - b * f
    A13 = b * e - c * d
    A22 = a * f - c * c
    A23 = b * c - a * e
    A33 = a * d - b * b
    det = a * A11 + b * A12 + c * A13
    return ((A11 * r1 + A12 * r2 + A13 * r3) / det,
            (A12 * r1 + A22 * r2 + A23 * r3) / det,
            (A13 * r1 + A23 * r2 + A33 * r3) / det)


def task_acceleration(B: float, dB: float, uX: float, uZ: float, uB: float,
                      p: ModelParams, m_f: float = 0.0, f_f: float | None = None) -> tuple[float, float, float]:
    """Forward dynamics (Eq. 11): xdd [m/s^2, m/s^2, rad/s^2] for generalized force u = J^T F.

    Only B and its rate dB [rad/s] enter: M depends on B alone and C has only a B column. With the
    flexible mode on: its modal mass m_f [kg] leaves M_22 (mass_matrix) and its spring-damper
    force f_f [N] acts on the platform in Z; the weight stays m_p g (the mode's spring carries
    m_f g at its static equilibrium).
    """
    cx, cz, cb = coriolis_times(B, dB, dB, p)
    rZ = uZ - cz - p.m_p * p.g
    if f_f is not None:
        rZ += f_f
    return solve_sym3(mass_matrix(B, p, m_f), uX - cx, rZ, uB - cb)


def generalized_force(B: float, dB: float, ddX: float, ddZ: float, ddB: float,
                      dBv: float, p: ModelParams) -> tuple[float, float, float]:
    """Inverse dynamics M(x) xdd + C(x, xd) v + G [N, N, N m].

    dB is the B rate of xd [rad/s]; dBv the B component of v, the only one C uses.
    With v = xd this is the left side of Eq. 11; with v = xd_d it is the bracket of Eq. 26.
    """
    (M11, M12, M13), (_, M22, M23), (_, _, M33) = mass_matrix(B, p)
    cx, cz, cb = coriolis_times(B, dB, dBv, p)
    return (M11 * ddX + M12 * ddZ + M13 * ddB + cx,
            M12 * ddX + M22 * ddZ + M23 * ddB + cz + p.m_p * p.g,
            M13 * ddX + M23 * ddZ + M33 * ddB + cb)


def energy(Z: float, B: float, dX: float, dZ: float, dB: float, p: ModelParams) -> float:
    """Total mechanical energy 1/2 xd^T M xd + m_p g Z [J] (Eq. 5, 6, 9)."""
    (M11, M12, M13), (_, M22, M23), (_, _, M33) = mass_matrix(B, p)
    kinetic = 0.5 * (M11 * dX * dX + M22 * dZ * dZ + M33 * dB * dB) \
        + M12 * dX * dZ + M13 * dX * dB + M23 * dZ * dB
    return kinetic + p.m_p * p.g * Z
