"""The stability verdict's band around rho = 1: stable below 1 - 1e-6,
unstable above 1 + 1e-6, marginal between, pinned at 1 - 2e-6, 1 and 1 + 2e-6 and at the edges."""

import pytest

from orchestrator.tool.stability import MARGIN, verdict_for


def test_the_margin_is_one_in_a_million():
    assert MARGIN == 1e-6


@pytest.mark.parametrize("rho, verdict", [
    (1.0 - 2e-6, "stable"),
    (1.0, "marginal"),
    (1.0 + 2e-6, "unstable"),
    (1.0 - 0.5e-6, "marginal"),   # inside the band, both sides
    (1.0 + 0.5e-6, "marginal"),
    (0.996172, "stable"),         # the default gains (README table)
    (39.2, "unstable"),           # Eq. 40 gains, gauss-seidel
    (float("inf"), "unstable"),
])
def test_the_verdict_at_and_around_one(rho, verdict):
    assert verdict_for(rho) == verdict
