"""Reference trajectory (paper Section 5.2 / 6.2)."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tapmp.errors import ModelInputError
from tapmp.trajectory import TrajectoryParams, reference

TP = TrajectoryParams()


def test_paper_circle_starts_at_home_moving_in_plus_x():
    r = reference(0.0, TP)
    assert r[:3] == pytest.approx((0.0, 0.0, 0.0), abs=1e-15)
    assert r[3] == pytest.approx(0.01 * 2 * math.pi * 0.4)            # 25.1 mm/s
    assert r[4] == pytest.approx(0.0, abs=1e-15)
    assert r[5] == pytest.approx(5 * math.pi / 180 * 2 * math.pi * 0.4)  # 0.219 rad/s


def test_circle_has_the_stated_centre_and_radius():
    for t in (0.1, 0.6, 1.3, 2.2):
        X, Z = reference(t, TP)[:2]
        assert math.hypot(X - 0.0, Z + 0.01) == pytest.approx(0.01, rel=1e-12)


@given(st.floats(0.0, 10.0))
def test_derivatives_are_the_analytic_ones(t):
    h = 1e-5
    rp, rm, r = reference(t + h, TP), reference(t - h, TP), reference(t, TP)
    for i in range(3):
        assert r[3 + i] == pytest.approx((rp[i] - rm[i]) / (2 * h), rel=1e-6, abs=1e-9)
        assert r[6 + i] == pytest.approx((rp[3 + i] - rm[3 + i]) / (2 * h), rel=1e-6, abs=1e-7)


def test_amplitude_beyond_the_kinematic_domain_is_refused():
    with pytest.raises(ModelInputError, match=r"B_amplitude = 2.0 is invalid: allowed is a number in \[0, 1.5\]"):
        TP._replace(B_amplitude=2.0).validated()
