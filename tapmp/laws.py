"""The control laws, one record each: every place that lists, names or treats laws reads LAWS.

A law is computed by the C model (tapmp/c/tapmp_model.c, tapmp_controller_sample: one branch per
law, chosen by the controller's integer setting ``law``, Law.c_id); the record holds what the
rest of the house needs to know about it: its name in scenarios, its label in figures, the gains
it reads (and a study may tune), its modal matrices (tapmp.modal), which integral states it keeps
(orchestrator.tool.stability) and its text in the controller FMU's description and documentation.
docs/architecture.md, "Adding a control law", says how to add one.

Also here, because the laws are written in them: the Laplacian L = 3 I - 1 1^T of the coupling
(Eq. 18, 21), its eigenvector basis (the modes, MODE_LABELS) and the 3x3 matrix arithmetic of
the laws' PID matrices. This module imports nothing from tapmp but the gains table.
"""

import math
from dataclasses import dataclass
from typing import Callable, NamedTuple

from .settings import GAIN_NAMES

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]

LAPLACIAN: Mat3 = ((2.0, -1.0, -1.0), (-1.0, 2.0, -1.0), (-1.0, -1.0, 2.0))  # L = 3 I - 1 1^T
_R3, _R2, _R6 = 1.0 / math.sqrt(3.0), 1.0 / math.sqrt(2.0), 1.0 / math.sqrt(6.0)
# (label, basis vector in words, unit vector): an orthonormal basis of R^3, the eigenvectors of L.
MODE_BASIS: tuple[tuple[str, str, Vec3], ...] = (
    ("common", "(1,1,1)/sqrt3", (_R3, _R3, _R3)),
    ("diff. Z", "(1,0,-1)/sqrt2", (_R2, 0.0, -_R2)),
    ("diff. B", "(1,-2,1)/sqrt6", (_R6, -2.0 * _R6, _R6)),
)
MODE_LABELS = tuple(label for label, _, _ in MODE_BASIS)  # the modes' names in tables and figures
_COMMON = [(1.0, 1.0, 1.0)]                         # the common mode's direction of the integral states
_DIFFERENTIAL = [(1.0, -1.0, 0.0), (1.0, 1.0, -2.0)]  # a basis of the two differential modes' directions


class PIDMatrices(NamedTuple):
    """u = K_T u_d + K_V de + K_P e + K_I int(e), 3x3 matrices (row = motor).

    Units as in tapmp.modal: K_T dimensionless (1 in the force view), K_V [u s/m],
    K_P [u/m], K_I [u/(m s)] with u = K_T F; in the force view u is replaced by F [N].
    """

    K_T: Mat3
    K_V: Mat3
    K_P: Mat3
    K_I: Mat3


def diag(v) -> Mat3:
    """The diagonal matrix of the three numbers v."""
    return tuple(tuple(float(v[i]) if i == j else 0.0 for j in range(3)) for i in range(3))


def mul(A: Mat3, B: Mat3) -> Mat3:
    """The matrix product A B."""
    return tuple(tuple(sum(A[i][k] * B[k][j] for k in range(3)) for j in range(3)) for i in range(3))


def add(A: Mat3, B: Mat3) -> Mat3:
    """The matrix sum A + B."""
    return tuple(tuple(A[i][j] + B[i][j] for j in range(3)) for i in range(3))


def scdc_matrices(g) -> PIDMatrices:
    """SC-DC (Eq. 22-25) as PID matrices on e (tapmp.modal's doc); g: tapmp.control.Gains."""
    g = g.validated()
    Lv, D, B, Lp = diag(g.Lambda_v), diag(g.D), diag(g.b), diag(g.Lambda_p)
    K_P = add(mul(Lv, D), mul(add(mul(Lv, B), Lp), LAPLACIAN))
    K_I = mul(mul(mul(Lv, D), B), LAPLACIAN)
    return PIDMatrices(diag(g.K_T), Lv, K_P, K_I)


def apd_matrices(g) -> PIDMatrices:
    """APD-DC (Eq. 38, k_p = Lambda_p, k_v = Lambda_v, K_T1 = K_T as Eq. 41): diagonal, K_I = 0."""
    g = g.validated()
    return PIDMatrices(diag(g.K_T), diag(g.Lambda_v), diag(g.Lambda_p), diag((0.0, 0.0, 0.0)))


def _no_integral(g, mg) -> tuple[list[int], list[Vec3]]:
    return [], []


def _scdc_integral(g, mg) -> tuple[list[int], list[Vec3]]:
    # the integral of c (Eq. 22) enters only through b; c sums to zero, so the sum of the integrals never changes
    # (the anti-windup keeps it: tapmp_model.c's unwind holds and corrects the three together)
    motors = [i for i in range(3) if g.b[i] != 0.0]
    return motors, (_COMMON if len(motors) == 3 else [])


def _pid_integral(g, mg) -> tuple[list[int], list[Vec3]]:
    # a mode whose integral gain is 0 is summed but never fed back
    if mg.ki_c == 0.0 and mg.ki_d == 0.0:
        return [], []
    return [0, 1, 2], (_COMMON if mg.ki_c == 0.0 else []) + (_DIFFERENTIAL if mg.ki_d == 0.0 else [])


@dataclass(frozen=True)
class Law:
    """One control law. ``gains``: (name shown, gain setting) of the gains it reads, in the order a
    text lists them; the per-motor ones (tapmp.settings.GAIN_NAMES) are its tunable gains."""

    name: str            # as a scenario's ``law`` spells it
    c_id: int            # the controller's ``law`` setting: the C model's branch
    c_name: str          # the C model's constant of c_id (tapmp_model.h)
    label: str           # legend label of its runs in figures
    where: str           # where it is defined, for the ``law`` setting's description: "Eq. 25"
    summary: str         # the controller FMU's description of it
    gains: tuple[tuple[str, str], ...]
    integrates: str      # the integrated signal ("c", "e"), "" for none
    # (g, mg) -> (motors whose integral state is fed back, integral directions with a structural
    # eigenvalue 1 among them); g: Gains, mg: ModalGains
    integral: Callable = _no_integral
    matrices: Callable | None = None  # Gains -> PIDMatrices (tapmp.modal), None if not built from Gains
    equation: tuple[str, str] | None = None  # a row of the controller's documentation (title, text)

    @property
    def title(self) -> str:
        """The law's short name in texts: "SC-DC"."""
        return self.name.upper()

    @property
    def tunable(self) -> tuple[str, ...]:
        """The per-motor gains it reads (K_T aside: F = u / K_T, only Lambda / K_T matters)."""
        return tuple(s for _, s in self.gains if s in GAIN_NAMES and s != "K_T")


LAWS: tuple[Law, ...] = (
    Law("sc-dc", 0, "TAPMP_SCDC", "SC-DC (proposed)", "Eq. 25",
        "SC-DC synchronization controller with dynamics compensation",
        (("Lambda_p", "Lambda_p"), ("Lambda_v", "Lambda_v"), ("b", "b"), ("D", "D")), "c",
        _scdc_integral, scdc_matrices),
    Law("apd-dc", 1, "TAPMP_APDDC", "APD-DC", "Eq. 38", "the APD-DC baseline",
        (("k_p", "Lambda_p"), ("k_v", "Lambda_v")), "", _no_integral, apd_matrices,
        ("APD-DC (Eq. 38, law = 1)", "u = K_T u_d + Lambda_v de + Lambda_p e")),
    Law("pid-dc", 2, "TAPMP_PIDDC", "PID-DC", "modal PID on e", "the modal PID-DC baseline",
        tuple((n, n) for n in ("kp_c", "kp_d", "kv_c", "kv_d", "ki_c", "ki_d")), "e", _pid_integral),
)
BY_NAME = {law.name: law for law in LAWS}
BY_ID = {law.c_id: law for law in LAWS}
C_IDS = {law.name: law.c_id for law in LAWS}  # a scenario's law -> the controller's ``law`` setting
C_RANGE = (min(BY_ID), max(BY_ID))            # the ``law`` setting's range (ids without gaps: a test)


def _listed(items: list[str], last: str) -> str:
    return ", ".join(items[:-1]) + f" {last} " + items[-1] if len(items) > 1 else items[0]


def choices_text() -> str:
    """The ``law`` setting's allowed values in words: "0 (SC-DC), 1 (APD-DC) or 2 (PID-DC)"."""
    return _listed([f"{law.c_id} ({law.title})" for law in LAWS], "or")


def setting_description() -> str:
    """The ``law`` FMU variable's description: "control law: 0 = SC-DC (Eq. 25), ...\""""
    return "control law: " + ", ".join(f"{law.c_id} = {law.title} ({law.where})" for law in LAWS)


def controller_description() -> str:
    """The controller FMU's description: each law's summary with its ``law`` value."""
    return (_listed([f"{law.summary} (law {law.c_id})" for law in LAWS], "and")
            + " for the TAPMP; outputs force commands F = u / K_T")


def equation_rows() -> list[tuple[str, str]]:
    """The rows (title, equation) of the laws whose equation the controller's documentation lists
    as a record gives it (SC-DC's, written with the gains' values, is the builder's own)."""
    return [law.equation for law in LAWS if law.equation]


def law_named(name: str) -> Law:
    """The record of the law ``name``; ValueError lists the known names."""
    try:
        return BY_NAME[name]
    except KeyError:
        raise ValueError(f"law = {name!r} is invalid: allowed are {', '.join(BY_NAME)}") from None
