"""Kinematics of the TAPMP (paper Section 2.2, Eq. 1-4).

Task space x = (X, Z, B): platform displacement X, Z [m] and rotation B [rad].
Joint space q = (q1, q2, q3): displacements of the three movers on the common
stator [m]. L1 is the platform width [m]. Closed-form scalar expressions are used
on purpose: at 3x3 they are far cheaper than numpy calls in the 10 kHz loop.
"""

import math

from .errors import KinematicDomainError

SQRT3 = math.sqrt(3.0)
S3 = SQRT3 / 3.0  # sqrt(3)/3, the slope of the outer links


def inverse(X: float, Z: float, B: float, L1: float) -> tuple[float, float, float]:
    """Inverse kinematics, Eq. 2: pose (X [m], Z [m], B [rad]) -> motor positions q [m]."""
    c = math.cos(B)
    s = math.sin(B)
    q1 = X + S3 * Z + L1 * (1.0 - c + S3 * s)
    q3 = X - S3 * Z - L1 * (1.0 - c - S3 * s)
    return q1, X, q3


def forward(q1: float, q2: float, q3: float, L1: float) -> tuple[float, float, float]:
    """Forward kinematics, Eq. 1: motor positions q [m] -> pose (X [m], Z [m], B [rad]).

    Raises KinematicDomainError when |sqrt(3)/(2 L1) (2 q2 - q1 - q3)| >= 1, where
    the arcsine of Eq. 1 has no solution (and the Jacobian is singular at the bound).
    """
    arg = SQRT3 / (2.0 * L1) * (2.0 * q2 - q1 - q3)
    if not abs(arg) < 1.0:  # also catches NaN
        raise KinematicDomainError(
            "sqrt(3)/(2 L1)*(2 q2 - q1 - q3)", arg,
            f"|value| < 1 (q = [{q1!r}, {q2!r}, {q3!r}] m, L1 = {L1!r} m)")
    B = -math.asin(arg)
    Z = 0.5 * SQRT3 * (q1 - q3 - 2.0 * L1 + 2.0 * L1 * math.cos(B))
    return q2, Z, B


def rotation_column(B: float, L1: float) -> tuple[float, float]:
    """Third column of J (Eq. 4), rows 1 and 3: (dq1/dB, dq3/dB) [m/rad].

    The first two columns of J are constant: (1, S3, .), (1, 0, 0), (1, -S3, .).
    """
    c = math.cos(B)
    s = math.sin(B)
    return L1 * (S3 * c + s), L1 * (S3 * c - s)


def rotation_column_dB(B: float, L1: float) -> tuple[float, float]:
    """Derivative of :func:`rotation_column` with respect to B [m/rad^2]."""
    c = math.cos(B)
    s = math.sin(B)
    return L1 * (c - S3 * s), -L1 * (S3 * s + c)


def jacobian(B: float, L1: float) -> tuple[tuple[float, float, float], ...]:
    """Velocity Jacobian J(x) of Eq. 3-4 as a 3x3 tuple: qdot = J xdot."""
    a1, a3 = rotation_column(B, L1)
    return ((1.0, S3, a1), (1.0, 0.0, 0.0), (1.0, -S3, a3))


def joint_velocity(B: float, dX: float, dZ: float, dB: float, L1: float) -> tuple[float, float, float]:
    """qdot = J(x) xdot (Eq. 3): task rates [m/s, m/s, rad/s] -> motor rates [m/s]."""
    a1, a3 = rotation_column(B, L1)
    return dX + S3 * dZ + a1 * dB, dX, dX - S3 * dZ + a3 * dB


def task_velocity(B: float, dq1: float, dq2: float, dq3: float, L1: float) -> tuple[float, float, float]:
    """xdot = J(x)^-1 qdot: motor rates [m/s] -> task rates [m/s, m/s, rad/s]."""
    a1, a3 = rotation_column(B, L1)
    dB = (dq1 + dq3 - 2.0 * dq2) / (a1 + a3)  # a1 + a3 = 2 S3 L1 cos B > 0 in the domain
    dZ = (dq1 - dq2 - a1 * dB) / S3
    return dq2, dZ, dB


def solve_transpose(B: float, v1: float, v2: float, v3: float, L1: float) -> tuple[float, float, float]:
    """w = J(x)^-T v (Eq. 14): generalized forces [N, N, N m] -> motor forces [N]."""
    a1, a3 = rotation_column(B, L1)
    d = v2 / S3  # w1 - w3
    w1 = (v3 + a3 * d) / (a1 + a3)
    w3 = w1 - d
    return w1, v1 - w1 - w3, w3
