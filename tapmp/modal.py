"""The modal view of both control laws: SC-DC and APD-DC as PID gain matrices on e.

Written in the tracking error e = q_d - q (Eq. 15) [m], SC-DC (Eq. 22-25) is a PID
law with Laplacian coupling. With c = L e, L = 3 I - 1 1^T (Eq. 18 and 21: c_1 =
(e_1 - e_2) - (e_3 - e_1) = 2 e_1 - e_2 - e_3, and so on), the running integral
int(c) = L int(e) (L is constant), e_c = e + B L int(e) (Eq. 22), de_c = de + B L e
(Eq. 23) and n = de_c + D e_c (Eq. 24), Eq. 25 becomes

    u = K_T u_d + K_V de + K_P e + K_I int(e)
    K_V = Lambda_v
    K_P = Lambda_v D + (Lambda_v B + Lambda_p) L
    K_I = Lambda_v D B L

(all of Lambda_p, Lambda_v, B, D, K_T diagonal). APD-DC (Eq. 38 with Eq. 41) is the
diagonal case K_V = Lambda_v, K_P = Lambda_p, K_I = 0.

Modes: L has the eigenvalue 0 on the common mode v_c = (1, 1, 1)/sqrt(3) and 3 on the
plane orthogonal to it, spanned here by d_Z = (1, 0, -1)/sqrt(2) (q1 - q3: at fixed B it
moves Z, Eq. 2) and d_B = (1, -2, 1)/sqrt(6) (2 q2 - q1 - q3 alone sets B, Eq. 1). For
gains equal on the three motors the matrices are diagonal in this basis and

    common:        P = Lambda_v D,                        V = Lambda_v,  I = 0
    differential:  P = Lambda_v D + 3 (Lambda_v b + Lambda_p), V = Lambda_v, I = 3 Lambda_v D b.

For gains that differ per motor, V^T K V is not diagonal: the functions here report its
diagonal (the projected modal gains) and its largest off-diagonal entry (the coupling,
how much one mode's error drives another mode's command).

Units: the command u is in K_T-scaled newtons (u = K_T F, the paper's K_T u_1 = u_sc),
so K_P is in u/m, K_V in u s/m, K_I in u/(m s). ``force_view`` gives the same gains as
force on the motors, F = K_T^-1 u: K_P in N/m, K_V in N s/m, K_I in N/(m s).

Run ``tapmp modal`` to print the table of the gain presets (Markdown).
"""

from typing import NamedTuple

from .control import Gains
from .laws import LAPLACIAN, MODE_BASIS, Mat3, PIDMatrices, Vec3, apd_matrices, law_named, scdc_matrices  # noqa: F401
from .laws import LAWS as _LAWS, diag as _diag, mul as _mul
from .params import gain_preset

# (name, unit vector): an orthonormal basis of R^3, the eigenvectors of L (tapmp.laws.MODE_BASIS).
MODES: tuple[tuple[str, Vec3], ...] = tuple((f"{label} {words}", v) for label, words, v in MODE_BASIS)
LAWS = tuple(law.name for law in _LAWS if law.matrices)  # the laws written as PID matrices of Gains
ROUNDOFF = 1e-12  # relative size below which a projected entry is round-off


class ModeGains(NamedTuple):
    """Projected gains of one mode v: v^T K v, and its largest coupling to the other modes.

    P [u/m], V [u s/m], I [u/(m s)] (or N/m, N s/m, N/(m s) in the force view);
    coupling_P/V/I: max over the other modes w of |w^T K v| and |v^T K w| (0 when the
    matrix is diagonal in the modal basis, as for gains equal on all motors).
    """

    mode: str
    P: float
    V: float
    I: float
    coupling_P: float
    coupling_V: float
    coupling_I: float


def _apply(A: Mat3, x) -> Vec3:
    return tuple(A[i][0] * x[0] + A[i][1] * x[1] + A[i][2] * x[2] for i in range(3))


def law_matrices(g: Gains, law: str) -> PIDMatrices:
    """PID matrices of ``law`` (one of LAWS: "sc-dc" or "apd-dc") for the gains g."""
    if law not in LAWS:
        raise ValueError(f"law = {law!r} is invalid: allowed are {', '.join(LAWS)}")
    return law_named(law).matrices(g)


def pid_command(e, de, int_e, u_d, m: PIDMatrices) -> Vec3:
    """u = K_T u_d + K_V de + K_P e + K_I int(e) for e [m], de [m/s], int(e) [m s], u_d [N]."""
    terms = (_apply(m.K_T, u_d), _apply(m.K_V, de), _apply(m.K_P, e), _apply(m.K_I, int_e))
    return tuple(sum(t[i] for t in terms) for i in range(3))


def force_view(m: PIDMatrices) -> PIDMatrices:
    """The same law as motor force F = K_T^-1 u: K_T becomes I, gains in N/m, N s/m, N/(m s)."""
    inv = _diag(tuple(1.0 / m.K_T[i][i] for i in range(3)))
    return PIDMatrices(_diag((1.0, 1.0, 1.0)), _mul(inv, m.K_V), _mul(inv, m.K_P), _mul(inv, m.K_I))


def _project(K: Mat3) -> Mat3:
    """W = V^T K V with V's columns the MODES (W[k][j] = v_k^T K v_j)."""
    vs = [v for _, v in MODES]
    return tuple(tuple(sum(vs[k][i] * K[i][j] * vs[l][j] for i in range(3) for j in range(3))
                       for l in range(3)) for k in range(3))


def modal_gains(m: PIDMatrices) -> list[ModeGains]:
    """Per-mode P, V, I gains of the PID matrices m (units of m) and their couplings.

    Entries of V^T K V below ROUNDOFF times the largest |entry| of K are round-off of the
    projection and reported as 0.
    """
    W = {}
    for k in ("P", "V", "I"):
        K = getattr(m, f"K_{k}")
        tol = ROUNDOFF * max(abs(x) for row in K for x in row)
        W[k] = tuple(tuple(x if abs(x) > tol else 0.0 for x in row) for row in _project(K))
    out = []
    for k, (name, _) in enumerate(MODES):
        coup = {x: max(max(abs(W[x][k][j]), abs(W[x][j][k])) for j in range(3) if j != k) for x in W}
        out.append(ModeGains(name, W["P"][k][k], W["V"][k][k], W["I"][k][k],
                             coup["P"], coup["V"], coup["I"]))
    return out


def _fmt(x: float) -> str:
    return "0" if x == 0.0 else f"{x:.4g}"


def modal_table(preset_names=("default", "paper_simulation", "paper_experiment")) -> str:
    """Markdown table of the per-mode gains of both laws for the named gain presets.

    Columns: P, V (= D of PID), I in u units (u = K_T F, the paper's numbers) and in the
    force view (divided by K_T: N/m, N s/m, N/(m s)), and the largest coupling to the
    other modes of P and I in the force view (0: the mode is exact). ValueError names
    an unknown preset.
    """
    lines = ["| preset | law | mode | P [u/m] | V [u s/m] | I [u/(m s)] | P/K_T [N/m] | V/K_T [N s/m] "
             "| I/K_T [N/(m s)] | coupling P, I [N/m, N/(m s)] |",
             "|---" * 10 + "|"]
    for name in preset_names:
        g = Gains.from_preset(gain_preset(name))
        for law in LAWS:
            m = law_matrices(g, law)
            for a, f in zip(modal_gains(m), modal_gains(force_view(m))):
                lines.append(f"| `{name}` | {law.upper()} | {a.mode} | {_fmt(a.P)} | {_fmt(a.V)} | {_fmt(a.I)} "
                             f"| {_fmt(f.P)} | {_fmt(f.V)} | {_fmt(f.I)} | {_fmt(f.coupling_P)}, "
                             f"{_fmt(f.coupling_I)} |")
    return "\n".join(lines)
