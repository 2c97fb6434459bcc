"""FMI adapter of the TAPMP plant: maps FMU variables to tapmp.plant.PlantModel."""

import math

from fmu_common.slave import TapmpSlave, as_float, is_number, require_state
from tapmp.errors import ModelInputError
from tapmp.interface import PLANT_VARS
from tapmp.params import ModelParams
from tapmp.plant import PlantConfig, PlantModel


class TAPMP_Plant(TapmpSlave):
    """TAPMP plant: task-space rigid-body dynamics (Eq. 11) with RK4, friction,
    force saturation, mutual pulling and magnetic attraction of adjacent movers, force
    ripple (cogging) and encoder quantization (docs/disturbances.md), and an optional flexible
    mode of the platform in Z (docs/native-fmus.md)."""

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
        F1, F2, F3 = self.reals[_FORCES]
        self.model.step(t, h, F1, F2, F3)
        self.publish()

    def publish(self):
        self.publish_block(_OUTPUTS, self.model.outputs())

    def check_hidden_state(self, hidden):
        if not (isinstance(hidden, list) and len(hidden) == 9 and all(is_number(v) for v in hidden)):
            raise ModelInputError("plant state", hidden, "9 numbers (X, Z, B, dX, dZ, dB, the sample count and the "
                                  "flexible mode's z_f, dz_f)")
        values = [as_float(v) for v in hidden]
        require_state("tapmp_plant_state_check", values[:6], values[6], list(self.reals[_STATE_OUTPUTS]))
        for name, v in zip(("plant state z_f", "plant state dz_f"), values[7:]):
            if not math.isfinite(v):
                raise ModelInputError(name, v, "a finite number")

    def hidden_state(self):
        return None if self.model is None else [*self.model.state, self.model.sample, *self.model.flex]

    def restore_hidden_state(self, hidden):
        if hidden is None:
            self.model = None
            return
        self.setup_model()
        self.model.state = [float(v) for v in hidden[:6]]
        self.model.sample = float(hidden[6])
        self.model.flex = [float(v) for v in hidden[7:9]]
        self.publish()


_FORCES = TAPMP_Plant.block("F1", 3)
# q1..q3 (measured), q1_true..q3_true, dq1..dq3, X, Z, B, dX, dZ, dB, in table order
_OUTPUTS = TAPMP_Plant.block("q1", 15)
_STATE_OUTPUTS = TAPMP_Plant.block("X", 6)  # X, Z, B, dX, dZ, dB: the state itself
