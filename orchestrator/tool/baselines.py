"""The runs of `tapmp compare`: SC-DC, the paper's APD-DC and the fair baselines.

Written in the tracking error e [m], SC-DC (Eq. 22-25) is a PID on e with Laplacian
coupling (tapmp.modal): on the common mode (1, 1, 1)/sqrt(3) its proportional gain is
Lambda_v D, on the two differential modes Lambda_v D + 3 (Lambda_v b + Lambda_p), its
derivative gain is Lambda_v on every mode and it integrates only the differential modes
(3 Lambda_v D b). The paper's APD-DC (Eq. 38 with Eq. 41, k_p = Lambda_p) has other gains
on every mode, so SC-DC vs APD-DC mixes "other gains" with "synchronization structure".
The baselines here take the structure apart, one change per run:

    run name               law     what it changes against SC-DC
    apd-dc                 APD-DC  the paper's baseline, k_p = Lambda_p, k_v = Lambda_v (Eq. 41)
    apd-dc-matched         APD-DC  k_p = Lambda_v D: SC-DC's common-mode P on every mode
    apd-dc-diff-stiffness  APD-DC  k_p = Lambda_v D + 3 (Lambda_v b + Lambda_p): SC-DC's
                                   differential-mode P on every mode
    apd-dc-mode-matched    PID-DC  SC-DC's P and D per mode, no integral (ki_c = ki_d = 0)
    apd-dc-ms-matched      PID-DC  SC-DC's D per mode, no integral, P per mode tuned to SC-DC's
                                   peak sensitivity Ms (orchestrator.tool.robustness)
    pid-dc-mode-matched    PID-DC  SC-DC's P, D and I per mode (equals SC-DC for uniform gains)
    pid-dc-full            PID-DC  SC-DC's P, D and differential I per mode, plus the same integral
                                   gain on the common mode (ki_c = ki_d, not tuned): the ordinary
                                   PID that integrates every mode
    sc-dc-b0               SC-DC   b = 0 (no integral of c, differential P down by 3 Lambda_v b)
    sc-dc-lp0              SC-DC   Lambda_p = 0 (differential P down by 3 Lambda_p)

Gains that differ between motors (e.g. the paper_experiment preset, Eq. 42): SC-DC is then
not exactly a modal PID (the modes of L are not the modes of the law). The PID-DC rows then
take the projected modal gains of tapmp.modal (v^T K v per mode; the differential gain is
the mean of the two differential modes) and drop the cross-mode coupling, which
`modal_note` reports; the APD-DC differential stiffness is computed per motor from that
motor's gains.
"""

from typing import NamedTuple

from tapmp.control import Gains, ModalGains
from tapmp.laws import law_named
from tapmp.modal import modal_gains, scdc_matrices
from tapmp.params import scdc_mode_gains

from .robustness import ms_matched
from .scenario import model_tuple


class Baseline(NamedTuple):
    """One run of `tapmp compare`: folder name, table label and what it isolates."""

    name: str
    label: str
    isolates: str


BASELINES = (
    Baseline("sc-dc", "SC-DC (proposed)", "the law under test (Eq. 22-25)"),
    Baseline("apd-dc", "APD-DC (k_p = Lambda_p, Eq. 41)",
             "the paper's baseline: other P on every mode, no integral, no coupling"),
    Baseline("apd-dc-matched", "APD-DC, common-mode stiffness (k_p = Lambda_v D)",
             "SC-DC's common-mode P and D on all modes: differential modes softer than SC-DC's, no integral"),
    Baseline("apd-dc-diff-stiffness", "APD-DC, differential-mode stiffness (k_p = Lambda_v D + 3 (Lambda_v b + Lambda_p))",
             "SC-DC's differential-mode P and D on all modes, no integral: what stiffness alone gives"),
    Baseline("apd-dc-mode-matched", "APD-DC mode-matched (PID-DC, SC-DC's P and D per mode, ki = 0)",
             "SC-DC's P and D mode by mode without the integral: what the integral on c adds"),
    Baseline("apd-dc-ms-matched", "APD-DC robustness-matched (PID-DC, ki = 0, P per mode for SC-DC's Ms)",
             "a PD at SC-DC's robustness: the same peak sensitivity Ms per mode, so a difference is not "
             "bought with a smaller stability margin"),
    Baseline("pid-dc-mode-matched", "PID-DC mode-matched (SC-DC's P, D and I per mode)",
             "SC-DC as a modal PID; for uniform gains the same law (a check of the identity)"),
    Baseline("pid-dc-full", "PID-DC full integral (SC-DC's P and D per mode, ki_c = ki_d)",
             "SC-DC's modal PID with an integral on the common mode too (ki_c = ki_d, not tuned): what the "
             "integral SC-DC leaves out of the common mode gives"),
    Baseline("sc-dc-b0", "SC-DC ablation, b = 0",
             "SC-DC without the coupling b: no integral of c, differential P lower by 3 Lambda_v b"),
    Baseline("sc-dc-lp0", "SC-DC ablation, Lambda_p = 0",
             "SC-DC without the Lambda_p c term: differential P lower by 3 Lambda_p"),
)
BY_NAME = {b.name: b for b in BASELINES}


def scdc_modal(g: Gains) -> tuple[ModalGains, str]:
    """(PID-DC gains per mode equal to SC-DC's, note) for the SC-DC gains g.

    Gains in u units like Lambda (F = u / K_T): kp [N/m], kv [N s/m], ki [N/(m s)].
    Uniform gains: ModalGains.matching_scdc, exact, note "exact". Otherwise the projected
    modal gains of tapmp.modal (common mode; mean of the two differential modes) and a
    note naming the largest cross-mode coupling of P and I that PID-DC leaves out.
    """
    try:
        return ModalGains.matching_scdc(g), "exact (uniform gains: PID-DC equals SC-DC)"
    except ValueError:
        pass
    common, dz, db = modal_gains(scdc_matrices(g))
    mg = ModalGains(kp_c=common.P, kv_c=common.V, ki_c=max(common.I, 0.0),
                    kp_d=(dz.P + db.P) / 2.0, kv_d=(dz.V + db.V) / 2.0, ki_d=max((dz.I + db.I) / 2.0, 0.0))
    cp = max(m.coupling_P for m in (common, dz, db))
    ci = max(m.coupling_I for m in (common, dz, db))
    return mg.validated(), (f"projected (gains differ between motors: per-mode P, D, I of V^T K V, the "
                            f"differential gain the mean of the two differential modes; left out: coupling "
                            f"up to {cp:.4g} u/m in P and {ci:.4g} u/(m s) in I)")


def full_integral(mg: ModalGains) -> ModalGains:
    """SC-DC's modal gains ``mg`` with the common mode integrated as the differential modes are:
    ki_c = ki_d [N/(m s)] (the same integral gain on every mode; not tuned)."""
    return mg._replace(ki_c=mg.ki_d)


def differential_stiffness(g: Gains) -> list[float]:
    """SC-DC's differential-mode proportional gain per motor, Lambda_v D + 3 (Lambda_v b + Lambda_p)
    [u/m, like Lambda_p], from each motor's own gains (tapmp.modal, eigenvalue 3 of L)."""
    return [scdc_mode_gains(*motor)["kp_d"] for motor in zip(g.Lambda_p, g.Lambda_v, g.b, g.D)]


def compare_runs(scenario) -> dict:
    """{run name: Scenario} for `tapmp compare`, in the order of BASELINES.

    Every run is the scenario with one change: the law and gains of its Baseline (module
    doc). The gains follow the scenario's preset and [gain_overrides]; the PID-DC rows put
    their modal gains (scdc_modal) into the [controller] table.
    """
    g = scenario.gain_values()
    ov = scenario.gain_overrides
    mg, _ = scdc_modal(g)
    no_integral = mg._replace(ki_c=0.0, ki_d=0.0)
    ctrl = scenario.controller

    def pid(gains: ModalGains):
        return scenario.with_changes(law="pid-dc", controller={**ctrl, **gains._asdict()})

    return {
        "sc-dc": scenario.with_changes(law="sc-dc"),
        "apd-dc": scenario.with_changes(law="apd-dc"),
        "apd-dc-matched": scenario.with_changes(
            law="apd-dc", gain_overrides=dict(ov, Lambda_p=[v * d for v, d in zip(g.Lambda_v, g.D)])),
        "apd-dc-diff-stiffness": scenario.with_changes(
            law="apd-dc", gain_overrides=dict(ov, Lambda_p=differential_stiffness(g))),
        "apd-dc-mode-matched": pid(no_integral),
        "apd-dc-ms-matched": pid(robustness_matched(scenario).gains),
        "pid-dc-mode-matched": pid(mg),
        "pid-dc-full": pid(full_integral(mg)),
        "sc-dc-b0": scenario.with_changes(law="sc-dc", gain_overrides=dict(ov, b=[0.0, 0.0, 0.0])),
        "sc-dc-lp0": scenario.with_changes(law="sc-dc", gain_overrides=dict(ov, Lambda_p=[0.0, 0.0, 0.0])),
    }


def robustness_matched(scenario):
    """orchestrator.tool.robustness.Matched for the scenario's SC-DC and its mode-matched PD."""
    mg, _ = scdc_modal(scenario.gain_values())
    pd = scenario.with_changes(law="pid-dc", controller={**scenario.controller,
                                                         **mg._replace(ki_c=0.0, ki_d=0.0)._asdict()})
    return ms_matched(scenario.with_changes(law="sc-dc"), pd)


def run_gains_text(sc) -> str:
    """The gains a compare run uses, in words: the gains its law reads (tapmp.laws.Law.gains) by the
    names the law gives them (Lambda_p etc. per motor, one value if equal on all; PID-DC: its modal
    gains)."""
    values = {**sc.gain_values()._asdict(), **model_tuple(ModalGains, sc.controller)._asdict()}

    def text(v):
        if not isinstance(v, tuple):
            return f"{v:.4g}"
        return "/".join(f"{x:.4g}" for x in v) if len(set(v)) > 1 else f"{v[0]:.4g}"

    return ", ".join(f"{shown} = {text(values[setting])}" for shown, setting in law_named(sc.law).gains)
