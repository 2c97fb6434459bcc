"""FMI adapter of the SC-DC / APD-DC / PID-DC controller: maps FMU variables to
tapmp.control.ControllerModel."""

import math

from fmu_common.slave import TapmpSlave
from tapmp.control import ControllerModel, Gains, ModalGains
from tapmp.interface import CONTROLLER_VARS
from tapmp.params import GAIN_NAMES, ModelParams


class TAPMP_Controller(TapmpSlave):
    """Discrete-time SC-DC controller (Eq. 15-26) with the APD-DC baseline (Eq. 38-39) and
    the PID-DC baseline (modal PID on e, same feedforward).

    On doStep(t, h) it samples its inputs, computes the command and holds it."""

    VARIABLES = CONTROLLER_VARS
    description = ("SC-DC synchronization controller with dynamics compensation (law 0), the "
                   "APD-DC baseline (law 1) and the modal PID-DC baseline (law 2) for the TAPMP; "
                   "outputs force commands F = u / K_T")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.model = None

    def _build(self):
        params = ModelParams(*(getattr(self, n) for n in ModelParams._fields))
        gains = Gains(*(tuple(getattr(self, f"{n}{i}") for i in (1, 2, 3)) for n in GAIN_NAMES))
        modal = ModalGains(*(getattr(self, n) for n in ModalGains._fields))
        return ControllerModel(params, gains, self.law, self.velocity_source, self.force_limit, modal)

    def setup_model(self):
        self.model = self._build()

    def check_parameters(self):
        self._build()  # the model's own checks (Gains, ModalGains, law, velocity_source, force_limit)
        super().check_parameters()

    def check_hidden_state(self, hidden):
        values = [] if hidden is None else list(hidden[0]) + list(hidden[1] or [])
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
            raise ValueError(f"FMU state: controller state {hidden!r} is invalid: allowed are finite numbers")

    def _sample(self, t, h, advance):
        r = self.reals
        F, u, e, es = self.model.sample(t, h, r[_REF], r[_Q], r[_DQ], advance)
        self.publish_block(_OUTPUTS, (*F, *u, *e, *es))

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


_REF = TAPMP_Controller.block("X_d", 9)     # X_d, Z_d, B_d and their rates and accelerations
_Q = TAPMP_Controller.block("q1", 3)
_DQ = TAPMP_Controller.block("dq1", 3)
_OUTPUTS = TAPMP_Controller.block("F1", 12)  # F1..F3, u1..u3, e1..e3, es1..es3
