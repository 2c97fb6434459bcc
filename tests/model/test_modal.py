"""The modal view (tapmp.modal): SC-DC and APD-DC as PID matrices on e, and their modes."""

import math
import random

import pytest

from tapmp.control import Gains, sync_deviation
from tests.support.control_reference import apd_command, scdc_command, sync_errors
from tapmp.modal import (LAPLACIAN, MODES, apd_matrices, force_view, modal_gains, modal_table, pid_command,
                         scdc_matrices)
from tapmp.params import GAIN_PRESETS


def _random_gains(rng):
    return Gains(*(tuple(rng.uniform(lo, hi) for _ in range(3))
                   for lo, hi in ((0.0, 1e4), (1e-3, 200.0), (0.0, 60.0), (0.0, 1e3), (1e-6, 1e-3))))


def _mat_vec(K, x):
    return [sum(K[i][j] * x[j] for j in range(3)) for i in range(3)]


def test_c_is_the_laplacian_of_e():
    rng = random.Random(3)
    for _ in range(200):
        e = [rng.uniform(-1e-3, 1e-3) for _ in range(3)]
        c = sync_deviation(*sync_errors(*e))  # Eq. 18, Eq. 21
        assert c == pytest.approx(_mat_vec(LAPLACIAN, e), rel=0, abs=1e-18)


def test_scdc_equals_its_pid_form_on_random_states():
    """u = K_T u_d + K_V de + K_P e + K_I int(e) reproduces scdc_command (Eq. 22-25) to 1e-12
    of the largest term, on 2,000 random states with random per-motor (non-uniform) gains and
    the presets; c = L e and int(c) = L int(e) are fed to scdc_command."""
    rng = random.Random(14)
    presets = [Gains.from_preset(p) for p in GAIN_PRESETS.values()]
    worst = 0.0
    for k in range(2000):
        g = presets[k % len(presets)] if k < 300 else _random_gains(rng)
        e = [rng.uniform(-1e-4, 1e-4) for _ in range(3)]
        de = [rng.uniform(-1e-2, 1e-2) for _ in range(3)]
        int_e = [rng.uniform(-1e-5, 1e-5) for _ in range(3)]
        u_d = [rng.uniform(-100.0, 100.0) for _ in range(3)]
        c = _mat_vec(LAPLACIAN, e)
        int_c = _mat_vec(LAPLACIAN, int_e)
        u = scdc_command(e, de, c, int_c, u_d, g)
        m = scdc_matrices(g)
        u_pid = pid_command(e, de, int_e, u_d, m)
        for i in range(3):
            scale = max(abs(g.K_T[i] * u_d[i]), *(abs(sum(K[i][j] * x[j] for j in range(3)))
                                                  for K, x in ((m.K_V, de), (m.K_P, e), (m.K_I, int_e))))
            worst = max(worst, abs(u[i] - u_pid[i]) / scale)
    assert worst < 1e-12
    print(f"worst relative difference {worst:.3g}")


def test_apd_equals_its_pid_form():
    rng = random.Random(41)
    for _ in range(300):
        g = _random_gains(rng)
        e, de, u_d = ([rng.uniform(-1, 1) * s for _ in range(3)] for s in (1e-4, 1e-2, 100.0))
        assert pid_command(e, de, (0.0, 0.0, 0.0), u_d, apd_matrices(g)) == pytest.approx(
            apd_command(e, de, u_d, g), rel=1e-13, abs=0)


def test_modes_are_an_orthonormal_eigenbasis_of_l():
    vs = [v for _, v in MODES]
    for a in range(3):
        for b in range(3):
            assert sum(x * y for x, y in zip(vs[a], vs[b])) == pytest.approx(float(a == b), abs=1e-15)
    assert _mat_vec(LAPLACIAN, vs[0]) == pytest.approx([0, 0, 0], abs=1e-15)
    for v in vs[1:]:
        assert _mat_vec(LAPLACIAN, v) == pytest.approx([3 * x for x in v], abs=1e-15)


def test_uniform_preset_modal_gains_match_hand_derivation():
    """default: Lambda_v = 0.36, D = 900, Lambda_p = 300, b = 50, K_T = 4.1e-5 on all motors.
    Common P = Lambda_v D = 324; differential P = 324 + 3 (0.36 * 50 + 300) = 1278;
    differential I = 3 * 0.36 * 900 * 50 = 48600; V = 0.36; no coupling (exact modes)."""
    g = Gains.from_preset(GAIN_PRESETS["default"])
    common, dz, db = modal_gains(scdc_matrices(g))
    assert (common.P, common.V, common.I) == pytest.approx((324.0, 0.36, 0.0), rel=1e-13, abs=1e-9)
    for d in (dz, db):
        assert (d.P, d.V, d.I) == pytest.approx((1278.0, 0.36, 48600.0), rel=1e-13)
    for m in (common, dz, db):
        assert (m.coupling_P, m.coupling_V, m.coupling_I) == (0.0, 0.0, 0.0)
    for m in modal_gains(apd_matrices(g)):
        assert (m.P, m.V, m.I, m.coupling_P) == pytest.approx((300.0, 0.36, 0.0, 0.0), rel=1e-13, abs=1e-9)
    f_common, f_dz, _ = modal_gains(force_view(scdc_matrices(g)))
    assert f_common.P == pytest.approx(324.0 / 4.1e-5, rel=1e-13)   # 7.90e6 N/m
    assert f_dz.I == pytest.approx(48600.0 / 4.1e-5, rel=1e-13)


def test_non_uniform_gains_report_projection_and_coupling():
    """APD-DC with Eq. 41's k_p = diag(8000, 8000, 8850): common P = (8000 + 8000 + 8850) / 3;
    its coupling to the Z mode is |v_c^T K v_Z| = 850 / sqrt(6) (larger than to B: 850 / sqrt(18))."""
    g = Gains.from_preset(GAIN_PRESETS["paper_simulation"])
    common, dz, db = modal_gains(apd_matrices(g))
    assert common.P == pytest.approx(24850.0 / 3.0, rel=1e-13)
    assert dz.P == pytest.approx((8000.0 + 8850.0) / 2.0, rel=1e-13)
    assert db.P == pytest.approx((8000.0 + 4 * 8000.0 + 8850.0) / 6.0, rel=1e-13)
    assert common.coupling_P == pytest.approx(850.0 / math.sqrt(6.0), rel=1e-12)
    # SC-DC: K_I = Lambda_v D B L has K_I v_c = 0 (no integral on the common mode), but with
    # b differing per motor the differential integral drives the common command: v_c^T K_I v_B != 0.
    sc = modal_gains(scdc_matrices(g))
    assert sc[0].I == 0.0 and sc[0].coupling_I > 1e3


def test_modal_table_and_command(capsys):
    from orchestrator.cli import main
    text = modal_table(["default"])
    assert "| `default` | SC-DC | common (1,1,1)/sqrt3 | 324 | 0.36 | 0 | 7.902e+06 |" in text
    assert "| `default` | SC-DC | diff. Z (1,0,-1)/sqrt2 | 1278 | 0.36 | 4.86e+04 |" in text
    with pytest.raises(ValueError, match="'nope' is unknown"):
        modal_table(["nope"])
    assert main(["modal", "nope"]) == 2
    assert capsys.readouterr().err == ("error: preset = 'nope' is invalid: allowed are default, paper_simulation, "
                                       "paper_experiment\n")
    assert main(["modal", "default"]) == 0
    assert capsys.readouterr().out == modal_table(["default"]) + "\n"
