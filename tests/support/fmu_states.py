"""Serialized FMU states of the TAPMP runtime (fmu_common/c/fmu_state.c, serial_layout), read and
edited field by field, to craft the states a hostile or careless host may hand back.

The layout (format 2, magic TAPMPST2), in the native byte order: 8 bytes magic, 32 bytes model
identifier, the ints n_vars, n_hidden, mode, failed, retune, has_model, me_continuous (Model Exchange's
Continuous-Time Mode), clock_active (a tick of the input clock in this event), the doubles time and
me_floor (Model Exchange's last accepted time), the doubles reals[n_vars], the ints
ints[n_vars], the doubles hidden[n_hidden] (8-byte aligned) and 1024 bytes of the first error.
The native models' hidden values are numbers (the plant: X, Z, B, dX, dZ, dB, sample count; the
controller: integral 1-3, previous q 1-3, has previous q, t0, k_last, has sample, warned); the
pythonfmu family's are the character codes of its JSON text.
"""

import json
import struct

HEADER = ("mode", "failed", "retune", "has_model", "me_continuous", "clock_active")
NATIVE_HIDDEN = {
    "TAPMP_Plant": ("X", "Z", "B", "dX", "dZ", "dB", "sample"),
    "TAPMP_Controller": ("integral1", "integral2", "integral3", "q_prev1", "q_prev2", "q_prev3", "has_q_prev",
                         "t0", "k_last", "has_sample", "warned"),
}


class SerializedState:
    """The bytes of one serialized state, with its fields as properties to read and change."""

    def __init__(self, data: bytes):
        self.data = bytearray(data)
        self.n_vars, self.n_hidden = struct.unpack_from("=ii", self.data, 40)
        self.reals_at = 88
        self.hidden_at = (88 + 12 * self.n_vars + 7) // 8 * 8
        assert (self.hidden_at + 8 * self.n_hidden + 1024 + 7) // 8 * 8 == len(self.data), "not the runtime's layout"

    def __bytes__(self) -> bytes:
        return bytes(self.data)

    def header(self, name: str) -> int:
        return struct.unpack_from("=i", self.data, 48 + 4 * HEADER.index(name))[0]

    def set_header(self, name: str, value: int) -> None:
        struct.pack_into("=i", self.data, 48 + 4 * HEADER.index(name), value)

    def real(self, vr: int) -> float:
        return struct.unpack_from("=d", self.data, self.reals_at + 8 * vr)[0]

    def hidden(self) -> list[float]:
        return list(struct.unpack_from(f"={self.n_hidden}d", self.data, self.hidden_at))

    def set_hidden(self, values) -> None:
        struct.pack_into(f"={self.n_hidden}d", self.data, self.hidden_at, *values)

    def json(self):
        """The pythonfmu family's hidden state (its JSON text, decoded)."""
        codes = self.hidden()
        return json.loads(bytes(int(c) for c in codes[:codes.index(0.0)] if c).decode())

    def set_json(self, value) -> None:
        text = json.dumps(value).encode()
        assert len(text) <= self.n_hidden
        self.set_hidden([float(c) for c in text] + [0.0] * (self.n_hidden - len(text)))
