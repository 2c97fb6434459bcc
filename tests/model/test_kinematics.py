"""Kinematics (paper Eq. 1-4)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tapmp.errors import KinematicDomainError
from tapmp.kinematics import (S3, forward, inverse, jacobian, joint_velocity, rotation_column, solve_transpose,
                              task_velocity)

L1 = 0.09
poses = st.tuples(st.floats(-0.05, 0.05), st.floats(-0.05, 0.05), st.floats(-1.4, 1.4))


def transpose_times(B: float, F1: float, F2: float, F3: float, L1: float) -> tuple[float, float, float]:
    """J(x)^T F written out (Eq. 14): motor forces [N] -> generalized forces (u_X [N], u_Z [N],
    u_B [N m]), the reference solve_transpose inverts."""
    a1, a3 = rotation_column(B, L1)
    return F1 + F2 + F3, S3 * (F1 - F3), a1 * F1 + a3 * F3


@given(poses)
def test_forward_inverts_inverse_over_the_workspace(x):
    assert forward(*inverse(*x, L1), L1) == pytest.approx(x, abs=1e-12)


@given(st.floats(-0.05, 0.05), st.floats(-0.05, 0.05), st.floats(-0.05, 0.05))
def test_inverse_inverts_forward_inside_the_domain(q1, q2, q3):
    arg = math.sqrt(3) / (2 * L1) * (2 * q2 - q1 - q3)
    if abs(arg) >= 0.99:
        return
    assert inverse(*forward(q1, q2, q3, L1), L1) == pytest.approx((q1, q2, q3), abs=1e-12)


def test_home_pose_maps_to_zero_motor_positions():
    assert inverse(0.0, 0.0, 0.0, L1) == (0.0, 0.0, 0.0)
    # Hand-derived: X = 1 mm moves all three movers by 1 mm; Z = 1 mm moves q1 by +S3 mm, q3 by -S3 mm.
    assert inverse(1e-3, 0.0, 0.0, L1) == pytest.approx((1e-3, 1e-3, 1e-3))
    assert inverse(0.0, 1e-3, 0.0, L1) == pytest.approx((S3 * 1e-3, 0.0, -S3 * 1e-3))


@settings(max_examples=50)
@given(poses)
def test_jacobian_equals_central_differences_of_inverse_kinematics(x):
    J = np.array(jacobian(x[2], L1))
    h = 1e-6
    num = np.zeros((3, 3))
    for j in range(3):
        dx = np.zeros(3)
        dx[j] = h
        num[:, j] = (np.array(inverse(*(np.array(x) + dx), L1)) - np.array(inverse(*(np.array(x) - dx), L1))) / (2 * h)
    assert np.allclose(J, num, atol=1e-9)


@given(poses, st.tuples(*[st.floats(-1, 1)] * 3))
def test_velocity_maps_and_force_maps_are_mutual_inverses(x, v):
    B = x[2]
    assert task_velocity(B, *joint_velocity(B, *v, L1), L1) == pytest.approx(v, abs=1e-9)
    assert transpose_times(B, *solve_transpose(B, *v, L1), L1) == pytest.approx(v, abs=1e-9)


def test_forward_kinematics_outside_its_domain_names_the_value():
    with pytest.raises(KinematicDomainError, match=r"2 q2 - q1 - q3\) = .* allowed is \|value\| < 1"):
        forward(0.0, 0.06, 0.0, L1)  # sqrt(3)/(2 L1) * 0.12 = 1.155
