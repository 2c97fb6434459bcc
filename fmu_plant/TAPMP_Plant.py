"""FMI adapter of the TAPMP plant: maps FMU variables to tapmp.plant.PlantModel."""

from fmu_common.slave import TapmpSlave
from tapmp.interface import PLANT_VARS
from tapmp.params import ModelParams
from tapmp.plant import PlantConfig, PlantModel


class TAPMP_Plant(TapmpSlave):
    """TAPMP plant: task-space rigid-body dynamics (Eq. 11) with RK4, friction,
    force saturation, mutual pulling of adjacent movers and encoder quantization."""

    VARIABLES = PLANT_VARS
    description = ("Three-axis parallel motion platform (Zhou, Gao, Zhang, Actuators 2024, 13, 166): "
                   "motor forces in, encoder positions and platform pose out")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.model = None

    def setup_model(self):
        params = ModelParams(*(getattr(self, n) for n in ModelParams._fields))
        config = PlantConfig(*(getattr(self, n) for n in PlantConfig._fields))
        self.model = PlantModel(params, config, (self.X0, self.Z0, self.B0),
                                (self.dX0, self.dZ0, self.dB0))
        self.publish()

    def step(self, t, h):
        self.model.step(t, h, self.F1, self.F2, self.F3)
        self.publish()

    def publish(self):
        m = self.model
        self.q1, self.q2, self.q3 = m.measured_positions()
        self.q1_true, self.q2_true, self.q3_true = m.joint_positions()
        self.dq1, self.dq2, self.dq3 = m.joint_velocities()
        self.X, self.Z, self.B, self.dX, self.dZ, self.dB = m.state

    def hidden_state(self):
        return None if self.model is None else list(self.model.state)

    def restore_hidden_state(self, hidden):
        if hidden is None:
            self.model = None
            return
        self.setup_model()
        self.model.state = [float(v) for v in hidden]
        self.publish()
