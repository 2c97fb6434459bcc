"""FMI adapter of the SC-DC / APD-DC controller: maps FMU variables to
tapmp.control.ControllerModel."""

from fmu_common.slave import TapmpSlave
from tapmp.control import ControllerModel, Gains
from tapmp.interface import CONTROLLER_VARS
from tapmp.params import GAIN_NAMES, ModelParams


class TAPMP_Controller(TapmpSlave):
    """Discrete-time SC-DC controller (Eq. 15-26) with the APD-DC baseline (Eq. 38-39).

    On doStep(t, h) it samples its inputs, computes the command and holds it."""

    VARIABLES = CONTROLLER_VARS
    description = ("SC-DC synchronization controller with dynamics compensation (law 0) and the "
                   "APD-DC baseline (law 1) for the TAPMP; outputs force commands F = u / K_T")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.model = None

    def _build(self):
        params = ModelParams(*(getattr(self, n) for n in ModelParams._fields))
        gains = Gains(*(tuple(getattr(self, f"{n}{i}") for i in (1, 2, 3)) for n in GAIN_NAMES))
        return ControllerModel(params, gains, self.law, self.velocity_source, self.force_limit)

    def setup_model(self):
        self.model = self._build()

    def _sample(self, t, h, advance):
        ref = (self.X_d, self.Z_d, self.B_d, self.dX_d, self.dZ_d, self.dB_d,
               self.ddX_d, self.ddZ_d, self.ddB_d)
        F, u, e, es = self.model.sample(t, h, ref, (self.q1, self.q2, self.q3),
                                        (self.dq1, self.dq2, self.dq3), advance)
        self.F1, self.F2, self.F3 = F
        self.u1, self.u2, self.u3 = u
        self.e1, self.e2, self.e3 = e
        self.es1, self.es2, self.es3 = es

    def initial_outputs(self):
        self._sample(self.time, 0.0, advance=False)

    def step(self, t, h):
        if self.retune:  # new gains take effect at this sample; the loop state carries over
            old = self.model
            self.model = self._build()
            self.model.integral, self.model.q_prev = old.integral, old.q_prev
            self.retune = False
        self._sample(t, h, advance=True)

    def hidden_state(self):
        if self.model is None:
            return None
        q_prev = None if self.model.q_prev is None else list(self.model.q_prev)
        return [list(self.model.integral), q_prev]

    def restore_hidden_state(self, hidden):
        if hidden is None:
            self.model = None
            return
        self.model = self._build()
        self.model.integral = [float(v) for v in hidden[0]]
        self.model.q_prev = None if hidden[1] is None else tuple(float(v) for v in hidden[1])
