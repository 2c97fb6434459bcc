"""FMI adapter of the reference trajectory: maps FMU variables to tapmp.trajectory."""

from fmu_common.slave import TapmpSlave
from tapmp import cmodel
from tapmp.interface import TRAJECTORY, TRAJECTORY_VARS
from tapmp.kinematics import inverse
from tapmp.trajectory import TrajectoryParams, reference


class TAPMP_Trajectory(TapmpSlave):
    """Reference of the paper (XZ circle and B sinusoid) or a point-to-point move (step,
    ramp, jerk-limited S-curve; parameter profile), analytic to 2nd order, plus motor
    references by inverse kinematics. After doStep(t, h) the outputs are the reference
    at t + h."""

    VARIABLES = TRAJECTORY_VARS
    description = ("TAPMP reference trajectory (paper Section 5.2 / 6.2): XZ circle and B sinusoid, or a "
                   "point-to-point step, ramp or jerk-limited S-curve")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.params = None

    def setup_model(self):
        self.params = TrajectoryParams(*(getattr(self, n) for n in TrajectoryParams._fields))
        cmodel.check_settings(TRAJECTORY, {**self.params._asdict(), "L_1": self.L_1})
        self.publish(self.time)

    def step(self, t, h):
        self.publish(t + h)

    def publish(self, t):
        ref = reference(t, self.params)
        self.publish_block(_OUTPUTS, (*ref, *inverse(ref[0], ref[1], ref[2], self.L_1)))

    def hidden_state(self):
        return None if self.params is None else True

    def restore_hidden_state(self, hidden):
        if hidden:
            self.params = TrajectoryParams(*(getattr(self, n) for n in TrajectoryParams._fields))


_OUTPUTS = TAPMP_Trajectory.block("X_d", 12)  # the reference (9 values), then q1_d..q3_d
