"""Control laws: SC-DC (paper Section 4, Eq. 15-26), the APD-DC baseline (Eq. 38-39) and
PID-DC, a PID on e with modal gains and the same feedforward (a fair baseline).

Units: positions [m], velocities [m/s], motor forces [N]. The command u relates to
the motor force by K_T F = u (the closed-loop setting K_T u_1 = u_sc in the proof
of Theorem 1), so F = u / K_T. Gains are per motor (diagonal matrices of the paper).
"""

import math
from collections import namedtuple

from . import cmodel
from .errors import KinematicDomainError, ModelInputError, require_finite
from .laws import C_IDS
from .params import (ANTI_WINDUP_TIME, DEFAULT_MODAL_GAINS, GAIN_NAMES, MODAL_GAIN_NAMES, SERVO_STEP, ModelParams,
                     scdc_modal_image)

# the ``law`` setting of each law (tapmp.laws): SC-DC (Eq. 25), APD-DC (Eq. 38), PID-DC (modal PID on e)
SCDC, APDDC, PIDDC = (C_IDS[name] for name in ("sc-dc", "apd-dc", "pid-dc"))
VELOCITY_DIFFERENCE = 0  # velocity_source: backward difference of measured positions
VELOCITY_INPUT = 1       # velocity_source: the dq1..dq3 inputs
AW_OFF, AW_CLAMP, AW_BACK = 0, 1, 2  # anti_windup: off, conditional integration, back-calculation (TAPMP_AW_*)
# A communication point t is the sample instant t0 + k T_s if |t - t0 - k T_s| <= SAMPLE_TOLERANCE T_s
# (the C model's TAPMP_SAMPLE_TOLERANCE, which says why this width).
SAMPLE_TOLERANCE = cmodel.header_number("TAPMP_SAMPLE_TOLERANCE")
_INPUT_NAMES = ("X_d", "Z_d", "B_d", "dX_d", "dZ_d", "dB_d", "ddX_d", "ddZ_d", "ddB_d",
                "q1", "q2", "q3", "dq1", "dq2", "dq3")


class Gains(namedtuple("Gains", GAIN_NAMES)):
    """Per-motor gains; each field is (motor 1, motor 2, motor 3). The fields are the per-motor
    rows of the gains table (tapmp.settings.GAINS: Lambda_p, Lambda_v, b, D, K_T, with their units
    and meaning)."""

    __slots__ = ()

    def validated(self) -> "Gains":
        """Return self if every gain is within its range of the settings table (ModelInputError
        otherwise; the C model's generated tapmp_controller_settings_check, which every FMU runs too)."""
        _settings(self.per_motor())
        return self

    def per_motor(self) -> dict:
        """The gains by FMU variable name: Lambda_p1 .. K_T3."""
        return {f"{n}{i}": v for n, vs in zip(self._fields, self) for i, v in enumerate(vs, start=1)}

    @classmethod
    def from_preset(cls, preset: dict) -> "Gains":
        """Build from a preset dict as in tapmp.params.GAIN_PRESETS."""
        return cls(*(tuple(float(x) for x in preset[n]) for n in GAIN_NAMES))


class ModalGains(namedtuple("ModalGains", MODAL_GAIN_NAMES,
                            defaults=[DEFAULT_MODAL_GAINS[n] for n in MODAL_GAIN_NAMES])):
    """PID-DC gains per mode: common mode (1, 1, 1)/sqrt(3) (suffix _c) and the two
    differential modes (suffix _d), K = k_c Pi_c + k_d Pi_d. Units as Lambda (u scaled by
    K_T, F = u / K_T): kp [N/m], kv [N s/m], ki [N/(m s)]. Defaults: the modal image of
    the default SC-DC gains (tapmp.params.DEFAULT_MODAL_GAINS). The fields are the modal rows of
    the gains table (tapmp.settings.GAINS)."""

    __slots__ = ()

    def validated(self) -> "ModalGains":
        """Return self if every gain is within its range of the settings table (ModelInputError
        otherwise; the C model's generated tapmp_controller_settings_check, which every FMU runs too)."""
        _settings(self._asdict())
        return self

    @classmethod
    def matching_scdc(cls, g: "Gains") -> "ModalGains":
        """The gains with which PID-DC equals SC-DC with uniform gains g (see
        tapmp.params.scdc_modal_image); ValueError for non-uniform gains."""
        image = scdc_modal_image(g._asdict())
        return cls(*(image[n] for n in MODAL_GAIN_NAMES))


def _settings(values: dict):
    """The C model's tapmp_controller_settings with ``values`` (name -> value) filled by name from
    the settings table, the rest at their defaults; ModelInputError for the first setting outside
    its range (tapmp_controller_settings_check)."""
    from .models import CONTROLLER
    return cmodel.check_settings(CONTROLLER, values)


def sync_deviation(es1: float, es2: float, es3: float) -> tuple[float, float, float]:
    """Deviation c of the synchronization errors, Eq. 21 [m]. It sums to zero."""
    return es1 - es3, es2 - es1, es3 - es2


def sample_index(t: float, t0: float, T_s: float) -> int | None:
    """Index k of the sample instant t0 + k T_s [s] that the communication point t [s] falls
    on (within SAMPLE_TOLERANCE T_s), or None if t lies between sample instants."""
    ffi, lib = cmodel.load()
    k = ffi.new("double *")
    return int(k[0]) if lib.tapmp_sample_index(t, t0, T_s, k) else None


class ControllerModel:
    """The discrete-time controller: samples, computes and holds the command.

    It runs on its own clock: the sample instants t0 + k T_s. :meth:`communication_point`
    (a host's doStep(t, h)) samples only at a communication point t that falls on a sample
    instant not sampled yet, and holds the outputs otherwise; the time between two samples
    is (k - k_prev) T_s, whatever the host's step h.

    On each sample it uses q_d = IK(x_d), dq_d = J(x_d) xd_d, e = q_d - q (Eq. 15),
    e_s (Eq. 18), c (Eq. 21). The integral (of c for SC-DC, Eq. 22; of e for PID-DC;
    unused by APD-DC) is a right-rectangle sum I_k = I_{k-1} + dt x_k, so it includes
    the current sample. Joint velocity is the backward difference (q_k - q_{k-1}) / dt
    (velocity_source 0) or the dq inputs (1); the very first sample, which has no
    predecessor, takes the dq inputs. dt is the time between the two samples.
    """

    def __init__(self, params: ModelParams, gains: Gains, law: int = SCDC,
                 velocity_source: int = VELOCITY_DIFFERENCE, force_limit: float = 0.0,
                 modal: ModalGains = ModalGains(), T_s: float = SERVO_STEP, t0: float = 0.0,
                 anti_windup: int = AW_OFF, anti_windup_time: float = ANTI_WINDUP_TIME):
        """force_limit [N] (0 = none) clips the command and is where the anti-windup acts (anti_windup:
        AW_OFF, AW_CLAMP or AW_BACK with the tracking time anti_windup_time [s]; tapmp_model.h)."""
        self._s = _settings({**params._asdict(), **gains.per_motor(), **modal._asdict(), "law": law,
                             "velocity_source": velocity_source, "force_limit": force_limit, "T_s": T_s,
                             "anti_windup": anti_windup, "anti_windup_time": anti_windup_time})
        self.p, self.g, self.modal = params, gains, modal
        self.law = law
        self.velocity_source = velocity_source
        self.force_limit = force_limit
        self.anti_windup, self.anti_windup_time = anti_windup, anti_windup_time
        ffi, self._lib = cmodel.load()
        self._ffi = ffi
        self._cp = ffi.addressof(self._s, "p")  # members of self._s, which keeps them alive
        self._cg = ffi.addressof(self._s, "g")
        self._st = ffi.new("tapmp_controller_state *")
        self._out = ffi.new("double[12]")
        self._arg = ffi.new("double *")
        self._clock = ffi.new("tapmp_clock *", {"t0": t0, "T_s": T_s})
        self._k, self._steps, self._missed = ffi.new("double *"), ffi.new("double *"), ffi.new("double *")
        self._text = ffi.new("char[]", 1024)
        self.integral = [0.0, 0.0, 0.0]
        self.q_prev = None

    @property
    def T_s(self) -> float:
        """The sample period [s]."""
        return self._clock.T_s

    @property
    def t0(self) -> float:
        """The first sample instant [s]: the start time."""
        return self._clock.t0

    @t0.setter
    def t0(self, value: float):
        self._clock.t0 = value

    @property
    def k_last(self) -> int | None:
        """Index of the last sample instant t0 + k T_s sampled, None before the first."""
        return int(self._clock.k_last) if self._clock.has_sample else None

    @k_last.setter
    def k_last(self, value: int | None):
        self._clock.has_sample = value is not None
        self._clock.k_last = 0.0 if value is None else value

    @property
    def warned(self) -> bool:
        """The warning about skipped sample instants was given."""
        return bool(self._clock.warned)

    @warned.setter
    def warned(self, value: bool):
        self._clock.warned = bool(value)

    def communication_point(self, t: float, h: float, ref, q, dq_in):
        """A host's doStep(t, h) [s]: sample if t is a sample instant not sampled yet, else hold.

        Returns (outputs, warning): the new (F, u, e, e_s) of :meth:`sample`, or None when
        the outputs are held (t is no new sample instant); and, the first time the host's
        communication points skip a sample instant, the warning text (else None): naming the
        sample interval used when the next sample comes, or the instant missed when a
        communication point off the grid lies past it (one warning per instance). A step h that is not a finite number > 0 raises
        ModelInputError naming communicationStepSize.
        """
        if not (math.isfinite(h) and h > 0.0):
            raise ModelInputError("communicationStepSize", h, "a finite number > 0", t)
        lib, clock = self._lib, self._clock
        if not lib.tapmp_clock_at(clock, t, self._k, self._steps, self._missed):  # hold
            missed = self._missed[0]
            return None, None if math.isnan(missed) else self._warning(lib.tapmp_clock_missed_text, t, missed)
        steps = self._steps[0]
        out = self.sample(t, steps * self.T_s, ref, q, dq_in)
        skipped = lib.tapmp_clock_sampled(clock, self._k[0], steps)
        return out, self._warning(lib.tapmp_clock_skipped_text, t, steps) if skipped else None

    def next_event_time(self) -> float:
        """The next sample instant not sampled yet, t0 + k T_s [s]: the controller's next time event
        in FMI 3.0's Event Mode (nextEventTime), the start time t0 before the first sample."""
        clock = self._clock
        return clock.t0 + ((clock.k_last + 1.0) if clock.has_sample else 0.0) * clock.T_s

    def event(self, t: float, ref, q, dq_in):
        """The discrete update at an event at time t [s] (FMI 3.0 Event Mode,
        fmi3UpdateDiscreteStates): at a sample instant not sampled yet, sample the inputs and return
        the new (F, u, e, e_s) of :meth:`sample`, which belong to the instant t and are the outputs from
        t on; at any other time return None (the outputs hold). The host stops at every sample instant
        (:meth:`next_event_time`), so the interval since the previous sample is always one T_s on an
        unbroken run and no warning arises; the steps in between change nothing."""
        lib, clock = self._lib, self._clock
        if not lib.tapmp_clock_at(clock, t, self._k, self._steps, self._missed):
            return None
        steps = self._steps[0]
        out = self.sample(t, steps * self.T_s, ref, q, dq_in)
        lib.tapmp_clock_sampled(clock, self._k[0], steps)
        return out

    def _warning(self, text_function, t: float, x: float) -> str:
        """The text the C model writes for a warning of the clock (tapmp_clock_*_text)."""
        text_function(self._clock, t, x, self._text, len(self._text))
        return self._ffi.string(self._text).decode()

    def sample(self, t: float, h: float, ref, q, dq_in, advance: bool = True):
        """Compute the command from one sample of the inputs.

        ref: (X_d, Z_d, B_d, dX_d, dZ_d, dB_d, ddX_d, ddZ_d, ddB_d) [m, rad and rates];
        q, dq_in: measured motor positions [m] and rates [m/s]; h: time since the previous
        sample [s] ((k - k_prev) T_s when driven by :meth:`communication_point`).
        With advance=False (initialization) the state is left untouched and h unused.
        Returns (F, u, e, e_s) as four 3-tuples: F [N], u (command units, u = K_T F),
        e and e_s [m].
        """
        if not math.isfinite(sum(ref) + sum(q) + sum(dq_in)):  # one check on the fast path
            for name, v in zip(_INPUT_NAMES, (*ref, *q, *dq_in)):
                require_finite(name, v, t)
        st, out = self._st, self._out
        if type(ref) is not tuple:  # cffi takes tuples and lists for arrays (a host may give numpy arrays)
            ref, q, dq_in = tuple(ref), tuple(q), tuple(dq_in)
        st.integral = self.integral
        if self.q_prev is not None:
            st.q_prev = self.q_prev
        st.has_q_prev = self.q_prev is not None
        if not self._lib.tapmp_controller_sample(self._cp, self._cg, self.law, self.velocity_source,
                                                 self.force_limit, self.anti_windup, self.anti_windup_time, st, h,
                                                 ref, q, dq_in, advance, out, st, self._arg):
            raise KinematicDomainError(  # the text of kinematics.forward
                "sqrt(3)/(2 L1)*(2 q2 - q1 - q3)", self._arg[0],
                f"|value| < 1 (q = [{q[0]!r}, {q[1]!r}, {q[2]!r}] m, L1 = {self.p.L_1!r} m)")
        if advance:
            self.integral = list(st.integral)
            self.q_prev = tuple(st.q_prev)
        o = tuple(out)
        return o[0:3], o[3:6], o[6:9], o[9:12]
