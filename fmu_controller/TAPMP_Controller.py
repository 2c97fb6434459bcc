"""FMI adapter of the SC-DC / APD-DC / PID-DC controller: maps FMU variables to
tapmp.control.ControllerModel."""

from fmu_common.slave import WARNING, TapmpSlave, as_float, is_number, require_state
from tapmp import cmodel, laws
from tapmp.control import ControllerModel, Gains, ModalGains
from tapmp.errors import ModelInputError
from tapmp.interface import CONTROLLER_VARS
from tapmp.params import GAIN_NAMES, ModelParams


class TAPMP_Controller(TapmpSlave):
    """Discrete-time SC-DC controller (Eq. 15-26) with the APD-DC baseline (Eq. 38-39) and
    the PID-DC baseline (modal PID on e, same feedforward).

    On doStep(t, h) at a sample instant t0 + k T_s it samples its inputs, computes the
    command and holds it; at any other communication point it keeps its outputs
    (tapmp.control.ControllerModel.communication_point)."""

    VARIABLES = CONTROLLER_VARS
    description = laws.controller_description()

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.model = None

    def _build(self):
        params = ModelParams(*(getattr(self, n) for n in ModelParams._fields))
        gains = Gains(*(tuple(getattr(self, f"{n}{i}") for i in (1, 2, 3)) for n in GAIN_NAMES))
        modal = ModalGains(*(getattr(self, n) for n in ModalGains._fields))
        return ControllerModel(params, gains, self.law, self.velocity_source, self.force_limit, modal,
                               self.T_s, self.time, self.anti_windup, self.anti_windup_time)

    def setup_model(self):
        self.model = self._build()

    def check_parameters(self):
        self._build()  # the model's own checks (Gains, ModalGains, law, velocity_source, force_limit)
        super().check_parameters()

    def check_hidden_state(self, hidden):
        def numbers(v):
            return isinstance(v, list) and len(v) == 3 and all(is_number(x) for x in v)
        if not (isinstance(hidden, list) and len(hidden) == 3 and numbers(hidden[0])
                and (hidden[1] is None or numbers(hidden[1])) and isinstance(hidden[2], list)
                and len(hidden[2]) == 3 and is_number(hidden[2][0])
                and (hidden[2][1] is None or is_number(hidden[2][1])) and isinstance(hidden[2][2], bool)):
            raise ModelInputError("controller state", hidden, "[integral (3 numbers), previous q (3 numbers or "
                                  "null), [t0, k_last (a number or null), warned (true or false)]]")
        integral, q_prev, (t0, k_last, warned) = hidden
        m = self._build()  # the settings as the C structs the check reads
        ffi, _ = cmodel.load()
        st = ffi.new("tapmp_controller_state *", {"integral": [as_float(v) for v in integral],
                                                   "q_prev": [as_float(v) for v in q_prev or (0, 0, 0)],
                                                   "has_q_prev": q_prev is not None})
        clock = ffi.new("tapmp_clock *", {"t0": as_float(t0), "T_s": self.T_s, "has_sample": k_last is not None,
                                          "k_last": 0.0 if k_last is None else as_float(k_last),
                                          "warned": warned})
        require_state("tapmp_controller_state_check", m._cp, m._cg, self.law, self.force_limit, st, clock, self.time)

    def initial_outputs(self):
        r = self.reals
        F, u, e, es = self.model.sample(self.time, self.T_s, r[_REF], r[_Q], r[_DQ], advance=False)
        self.publish_block(_OUTPUTS, (*F, *u, *e, *es))

    def step(self, t, h):
        if self.retune:  # new gains take effect at this sample; the loop state carries over
            old = self.model
            self.model = self._build()
            self._carry(old, self.model)
            self.retune = False
        r = self.reals
        out, warning = self.model.communication_point(t, h, r[_REF], r[_Q], r[_DQ])
        if warning:
            self.log(warning, WARNING, "logStatusWarning")
        if out is not None:  # else the outputs hold
            F, u, e, es = out
            self.publish_block(_OUTPUTS, (*F, *u, *e, *es))

    @staticmethod
    def _carry(old, new):
        """The loop state and the sample clock of ``old`` into ``new``."""
        new.integral, new.q_prev = old.integral, old.q_prev
        new.t0, new.k_last, new.warned = old.t0, old.k_last, old.warned

    def hidden_state(self):
        if self.model is None:
            return None
        m = self.model
        q_prev = None if m.q_prev is None else list(m.q_prev)
        return [list(m.integral), q_prev, [m.t0, m.k_last, m.warned]]

    def restore_hidden_state(self, hidden):
        if hidden is None:
            self.model = None
            return
        self.model = m = self._build()
        m.integral = [float(v) for v in hidden[0]]
        m.q_prev = None if hidden[1] is None else tuple(float(v) for v in hidden[1])
        t0, k_last, warned = hidden[2]
        m.t0, m.k_last, m.warned = float(t0), None if k_last is None else int(k_last), bool(warned)


_REF = TAPMP_Controller.block("X_d", 9)     # X_d, Z_d, B_d and their rates and accelerations
_Q = TAPMP_Controller.block("q1", 3)
_DQ = TAPMP_Controller.block("dq1", 3)
_OUTPUTS = TAPMP_Controller.block("F1", 12)  # F1..F3, u1..u3, e1..e3, es1..es3
