"""The closed loop in plain Python (no FMI): trajectory -> controller -> plant.

It reproduces the orchestrator's master algorithm step for step, so the two can be
compared to round-off: the trajectory's outputs after doStep(t, h) are the reference
at t + h; the controller samples its inputs on doStep at its sample instants t0 + k T_s
(ControllerModel.communication_point) and holds its command; the plant integrates over
the step with the command it was given.

Orderings (per macro step k, t = t0 + k h):
* "gauss-seidel" (controller, plant, trajectory): the controller samples reference
  and measurement at t, the plant steps with the command just computed, then the
  trajectory advances. This is a sampled servo loop with no delay beyond the hold.
  (Stepping the trajectory first would hand the controller the reference of t + h
  against a measurement of t: a one-step lead that costs about v h = 3.6 um on
  motor 3 in the paper scenario, ten times the loop's own error.)
* "jacobi": every FMU steps on the values at t: the controller samples reference
  and measurement at t, the plant steps with the previous command (one extra step
  of delay in the feedback path).

:func:`simulate` is the readable reference, one call of the C model per model and step.
:func:`run` steps the same loop in C (tapmp/c/tapmp_loop.c: the same C functions called in
the same order) many steps per call and hands the communication points back in blocks of rows:
the same doubles, about a hundred times faster (tests/model/test_compiled_loop.py).
"""

import math

from .control import ControllerModel
from .interface import ORDERINGS
from .plant import PlantModel
from .trajectory import TrajectoryParams, _c_trajectory, reference

# The columns of the rows :func:`run` hands back, in their order (tapmp_loop.h, TAPMP_LOOP_COLUMNS).
COLUMNS = ("t", "X_d", "Z_d", "B_d", "dX_d", "dZ_d", "dB_d", "ddX_d", "ddZ_d", "ddB_d",
           "q_d1", "q_d2", "q_d3", "F1", "F2", "F3", "q1", "q2", "q3", "q1_true", "q2_true", "q3_true",
           "X", "Z", "B", "dX", "dZ", "dB")
BLOCK = 8192  # communication points per call of the C loop: 1.8 MB of rows, long enough to amortize the call


def simulate(plant: PlantModel, controller: ControllerModel, traj: TrajectoryParams,
             t0: float, n_steps: int, h: float, ordering: str = "gauss-seidel",
             record=None) -> None:
    """Run n_steps macro steps of size h [s] from t0 [s].

    ``record(t, ref, F, q_meas, q_true)`` is called at t0 and after every step with
    the values that hold at that communication point.
    """
    if ordering not in ORDERINGS:
        raise ValueError(f"ordering = {ordering!r} is invalid: allowed are {', '.join(ORDERINGS)}")
    ref = reference(t0, traj)
    q = plant.measured_positions()
    dq = plant.joint_velocities()
    F = controller.sample(t0, h, ref, q, dq, advance=False)[0]
    if record:
        record(t0, ref, F, q, plant.joint_positions())
    _steps(plant, controller, traj, t0, 0, n_steps, h, ordering == "gauss-seidel", F, ref, q, dq, record)


def _steps(plant, controller, traj, t0, k_from, k_to, h, gauss_seidel, F, ref, q, dq, record):
    """Steps k_from .. k_to - 1 of :func:`simulate`'s loop from the command F held and the
    reference ref, measurement q and rates dq at t0 + k_from h; returns (F, ref, q, dq) after them."""
    for k in range(k_from, k_to):
        t = t0 + k * h
        F_held = F
        sampled = controller.communication_point(t, h, ref, q, dq)[0]  # None: held
        if sampled is not None:
            F = sampled[0]
        plant.step(t, h, *(F if gauss_seidel else F_held))
        ref = reference(t + h, traj)
        q = plant.measured_positions()
        dq = plant.joint_velocities()
        if record:
            record(t0 + (k + 1) * h, ref, F, q, plant.joint_positions())
    return F, ref, q, dq


def run(plant: PlantModel, controller: ControllerModel, traj: TrajectoryParams,
        t0: float, n_steps: int, h: float, ordering: str = "gauss-seidel", record_rows=None,
        L1_ref: float | None = None, block: int = BLOCK) -> None:
    """:func:`simulate` stepped in C: the same n_steps macro steps of size h [s] from t0 [s],
    the same doubles, the same errors (a failing step is replayed by :func:`simulate`'s own code,
    which raises what it raises), the models left in the same state.

    ``record_rows(rows)`` gets the communication points as numpy arrays of shape (n, 28), the
    columns of :data:`COLUMNS` (t [s], the reference, q_d [m] of the reference with the platform
    width L1_ref [m] (the trajectory's; default: the plant's L_1), F [N], the measured and the
    true positions [m], the plant state): first the row at t0, then up to ``block`` rows per call.
    It may raise to stop the run (the models then hold the state after that block).
    """
    import numpy as np
    from . import cmodel
    if ordering not in ORDERINGS:
        raise ValueError(f"ordering = {ordering!r} is invalid: allowed are {', '.join(ORDERINGS)}")
    if not (isinstance(block, int) and block >= 1):
        raise ValueError(f"block = {block!r} is invalid: allowed is an integer >= 1")
    L1 = plant.p.L_1 if L1_ref is None else L1_ref
    gauss_seidel = ordering == "gauss-seidel"
    ffi, lib = cmodel.load()
    ref = reference(t0, traj)
    q = plant.measured_positions()
    dq = plant.joint_velocities()
    F = controller.sample(t0, h, ref, q, dq, advance=False)[0]
    if record_rows:
        record_rows(np.array([(t0, *ref, *_inverse(lib, ffi, ref, L1), *F, *q, *plant.joint_positions(),
                              *plant.state)]))
    if not (math.isfinite(h) and h > 0.0):  # communication_point refuses it: let the reference say so
        return _steps_python(plant, controller, traj, t0, 0, n_steps, h, gauss_seidel, F, ref, q, dq,
                             record_rows, L1, lib, ffi)
    pt = ffi.new("tapmp_loop_point *", {"F": F, "ref": ref, "q": q, "dq": dq})
    st = ffi.new("tapmp_controller_state *", {"integral": controller.integral})
    if controller.q_prev is not None:
        st.q_prev, st.has_q_prev = controller.q_prev, 1
    buf = np.empty((min(block, max(n_steps, 1)), len(COLUMNS)))
    rows = ffi.cast("double *", ffi.from_buffer(buf))
    error = ffi.new("int *")
    pl, tp = plant._pl, _c_trajectory(traj)
    k = 0
    while k < n_steps:
        pl.s, pl.sample = plant.state + plant.flex, plant.sample
        n = min(len(buf), n_steps - k)
        done = lib.tapmp_loop_run(pl, controller._cp, controller._cg, controller.law, controller.velocity_source,
                                  controller.force_limit, controller.anti_windup,
                                  controller.anti_windup_time, st, controller._clock, tp, L1, t0, k, n, h,
                                  gauss_seidel, pt, rows, error)
        plant.state, plant.flex, plant.sample = list(pl.s)[:6], list(pl.s)[6:], pl.sample
        controller.integral = list(st.integral)
        controller.q_prev = tuple(st.q_prev) if st.has_q_prev else None
        k += done
        if done and record_rows:
            record_rows(buf[:done].copy())
        if error[0]:  # replay the failing step in Python: it raises the reference's error
            F, ref, q, dq = tuple(pt.F), tuple(pt.ref), tuple(pt.q), tuple(pt.dq)
            F, ref, q, dq = _steps_python(plant, controller, traj, t0, k, k + 1, h, gauss_seidel, F, ref, q, dq,
                                          record_rows, L1, lib, ffi)
            pt.F, pt.ref, pt.q, pt.dq = F, ref, q, dq
            st.integral = controller.integral
            if controller.q_prev is not None:
                st.q_prev, st.has_q_prev = controller.q_prev, 1
            k += 1


def _inverse(lib, ffi, ref, L1):
    """q_d [m] of the reference's pose (tapmp_inverse)."""
    q_d = ffi.new("double[3]")
    lib.tapmp_inverse(ref[0], ref[1], ref[2], L1, q_d)
    return tuple(q_d)


def _steps_python(plant, controller, traj, t0, k_from, k_to, h, gauss_seidel, F, ref, q, dq, record_rows, L1,
                  lib, ffi):
    """:func:`_steps` with its communication points handed to ``record_rows`` as rows of :data:`COLUMNS`."""
    import numpy as np

    def record(t, ref, F, q, q_true):
        record_rows(np.array([(t, *ref, *_inverse(lib, ffi, ref, L1), *F, *q, *q_true, *plant.state)]))

    return _steps(plant, controller, traj, t0, k_from, k_to, h, gauss_seidel, F, ref, q, dq,
                  record if record_rows else None)
