"""The paper's Theorem 1 (Section 4.3) put to the test.

Theorem 1 claims that SC-DC (Eq. 25) drives the tracking and synchronization errors to zero
for any positive diagonal gains. Its proof does not hold:

* Eq. 27 only restates the control law with K_T u_1 = u_sc: the plant dynamics (Eq. 14) never
  enter the argument, so nothing in it depends on the masses, and no gain condition appears.
  Multiplying it by -n^T adds zero to Eq. 29, so -n^T K_T (u_d - u_1) equals
  n^T Lambda_v n + n^T Lambda_p c exactly and Eq. 32 is Eq. 29 written differently.
* The first line of Eq. 33 bounds that term by -lambda_min(K_T) k_t |n| |e|, which has the wrong
  sign: a Lipschitz bound gives |n^T K_T (u_d - u_1)| <= lambda_max(K_T) k_t |n| |e|, so the term
  may be positive, and Eq. 34's V' <= 0 does not follow. Along a growing mode V' > 0
  (``lyapunov_v``).
* Eq. 31, the identity that turns Eq. 30 into Eq. 32, holds only when Lambda_p and D are
  multiples of the identity (then S^T Lambda_p S = Lambda_p L); B may differ per motor, a
  per-motor D or Lambda_p breaks it; for the paper's own Eq. 40
  gains its two sides differ (``eq31_sides`` evaluates both from the definitions Eq. 18-24).

A counterexample with every gain positive is ``COUNTEREXAMPLE``: with exact dynamics
compensation the continuous-time error dynamics are M_q e'' = -K_T^-1 (K_V e' + K_P e +
K_I int(e)) (the modal form of tapmp.modal, M_q the joint-space mass matrix at B = 0), and
their eigenvalues have a positive real part (about +18.9 1/s) under SC-DC while APD-DC with
the same numbers (Eq. 41) is stable. ``tapmp check`` at a fine step agrees (docs/theorem1.md).

Run ``tapmp theorem1`` to print the eigenvalues and Eq. 31's sides.
"""

import numpy as np

from tapmp.control import Gains
from tapmp.dynamics import mass_matrix
from tapmp.kinematics import jacobian
from tapmp.modal import law_matrices
from tapmp.params import PAPER_MODEL, ModelParams

# Lambda_p [u/m], Lambda_v [u s/m], b [1/s], D [1/s], K_T: every one positive, equal on the motors.
COUNTEREXAMPLE = {"Lambda_p": (1.0,) * 3, "Lambda_v": (0.01,) * 3, "b": (100.0,) * 3, "D": (200.0,) * 3,
                  "K_T": (4.1e-5,) * 3}
# Eq. 18 and 21 as matrices: e_s = S e, c = L e with L = 3 I - 1 1^T.
S = np.array([[1.0, -1.0, 0.0], [0.0, 1.0, -1.0], [-1.0, 0.0, 1.0]])
L = np.array([[2.0, -1.0, -1.0], [-1.0, 2.0, -1.0], [-1.0, -1.0, 2.0]])


def joint_mass_matrix(p: ModelParams = PAPER_MODEL, B: float = 0.0) -> np.ndarray:
    """Joint-space mass matrix J^-T M J^-1 [kg] at rotation B [rad] (Eq. 4 and 12)."""
    J = np.array(jacobian(B, p.L_1))
    Ji = np.linalg.inv(J)
    return Ji.T @ np.array(mass_matrix(B, p)) @ Ji


def error_dynamics(gains: dict, law: str, p: ModelParams = PAPER_MODEL, B: float = 0.0) -> np.ndarray:
    """Continuous-time error dynamics x' = A x under exact dynamics compensation [1/s].

    ``law`` is "sc-dc" or "apd-dc"; ``gains`` maps Lambda_p, Lambda_v, b, D, K_T to three values
    each. States [int(e) (m s), e (m), e' (m/s)] when the law integrates, [e, e'] otherwise (APD-DC:
    the integral would only add three decoupled zero eigenvalues).
    """
    m = law_matrices(Gains.from_preset(gains), law)
    kt = np.array(m.K_T)
    KV, KP, KI = (np.linalg.solve(kt, np.array(k)) for k in (m.K_V, m.K_P, m.K_I))  # in N per m, m/s, m s
    Minv = np.linalg.inv(joint_mass_matrix(p, B))
    Z, I = np.zeros((3, 3)), np.eye(3)
    if not KI.any():
        return np.block([[Z, I], [-Minv @ KP, -Minv @ KV]])
    return np.block([[Z, I, Z], [Z, Z, I], [-Minv @ KI, -Minv @ KP, -Minv @ KV]])


def max_real_part(gains: dict, law: str, p: ModelParams = PAPER_MODEL) -> float:
    """Largest real part [1/s] of the error dynamics' eigenvalues: > 0 means the errors grow."""
    return float(np.linalg.eigvals(error_dynamics(gains, law, p)).real.max())


def eq31_sides(e, de, int_c, gains: dict) -> tuple[float, float]:
    """Left and right side of the paper's Eq. 31 for one state.

    e [m], de [m/s], int_c = int(c) [m s] (3-vectors); ``gains`` as in error_dynamics. Built
    from the definitions: e_s = S e (Eq. 18), c = L e (Eq. 21), e_c = e + B int(c) (Eq. 22),
    e_c' = e' + B c (Eq. 23), n = e_c' + D e_c (Eq. 24). Returns (n^T Lp c, the paper's right side).
    """
    e, de, int_c = (np.asarray(x, dtype=float) for x in (e, de, int_c))
    Lp, Bm, Dm = (np.diag(gains[k]) for k in ("Lambda_p", "b", "D"))
    es, des, c = S @ e, S @ de, L @ e
    n = de + Bm @ c + Dm @ (e + Bm @ int_c)
    lhs = n @ Lp @ c
    rhs = des @ Lp @ es + c @ Bm @ Lp @ c + es @ Dm @ Lp @ es + c @ Bm @ Lp @ Dm @ int_c
    return float(lhs), float(rhs)


def lyapunov_v(x, gains: dict) -> float:
    """The paper's V (Eq. 28) for an SC-DC error state x = [int(e), e, e'] (as error_dynamics):
    1/2 e_s^T Lambda_p e_s + 1/2 int(c)^T B Lambda_p D int(c), with e_s = S e and int(c) = L int(e)."""
    x = np.asarray(x, dtype=float)
    Lp, Bm, Dm = (np.diag(gains[k]) for k in ("Lambda_p", "b", "D"))
    es, ic = S @ x[3:6], L @ x[0:3]
    return float(0.5 * es @ Lp @ es + 0.5 * ic @ Bm @ Lp @ Dm @ ic)


def summary_lines() -> list[str]:
    """The counterexample's largest eigenvalue real part [1/s] for both laws, and both sides of
    Eq. 31 on one random state (seed 1) for the counterexample's and the paper's Eq. 40 gains
    (`tapmp theorem1`)."""
    lines = []
    for law in ("sc-dc", "apd-dc"):
        ev = np.linalg.eigvals(error_dynamics(COUNTEREXAMPLE, law))
        worst = sorted(ev, key=lambda z: -z.real)[0]
        lines.append(f"{law}: largest real part {worst.real:+.4g} 1/s (eigenvalue {worst.real:.4g} "
                     f"{worst.imag:+.4g}j), {'unstable' if worst.real > 0 else 'stable'}")
    from tapmp.params import GAIN_PRESETS
    rng = np.random.default_rng(1)
    state = [rng.normal(size=3) for _ in range(3)]
    for name, gains in (("the counterexample's uniform gains", COUNTEREXAMPLE),
                        ("the paper's Eq. 40 gains", GAIN_PRESETS["paper_simulation"])):
        lhs, rhs = eq31_sides(*state, gains)
        lines.append(f"Eq. 31 on a random state (seed 1), {name}: left side {lhs:.6g}, right side {rhs:.6g}")
    return lines
