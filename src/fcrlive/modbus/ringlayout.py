"""The governor-side ring buffer of controller samples: register layout and slot codec (pure, no I/O).

The contract is docs/buffered-acquisition.md; the simulated governor serves it (sim_device/ringbuffer.py)
and the daemon reads it (:mod:`fcrlive.daemon.buffered_source`); both build on this module, which is why
it lives with the rest of the Modbus codec. A register map opts in with (validated by
:mod:`fcrlive.modbus.mapfile`)::

    acquisition = "buffered"
    [buffer]
    header_address = 1000    # input registers: the header (HEADER_WORDS registers)
    slots_address = 1016     # first register of slot 0
    slots = 1024             # a power of two (the 32-bit counter wraps onto the same slot)
    fields = ["controller_output", "guide_vane", "control_error", "power", "excitation_applied", "grid_freq"]

Header (input registers from ``header_address``; 32-bit values in the map's word order):

| offset | type | meaning |
|---|---|---|
| 0 | uint32 | head: counter of the newest complete slot |
| 2 | uint32 | tail: counter of the oldest valid slot (the first after a (re)start, later head − slots + 1) |
| 4 | uint16 | epoch: changes at every (re)start of the buffer (power-up, reset, download) |
| 5 | uint16 | slot count N |
| 6 | uint16 | words per slot |
| 7 | uint32 | Tc, the controller sample time [µs] |

Slot k (registers ``slots_address + k·words``), holding controller sample n with ``k = n mod N``:
``counter`` uint32, one float32 per field, ``check`` uint16 = (counter & 0xFFFF) XOR 0x5A5A. The writer
writes ``check`` first (as the invalid marker of the new counter), then the values, then ``counter``
last; the reader accepts a slot only when counter and check agree, so an erased (all-zero) slot and a
slot torn by a concurrent write are both refused.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass

from fcrlive.modbus.registers import MAX_READ_REGISTERS

HEADER_WORDS = 9
CHECK_XOR = 0x5A5A
COUNTER_MOD = 1 << 32
DEFAULT_FIELDS = ("controller_output", "guide_vane", "control_error", "power", "excitation_applied",
                  "grid_freq")
"""c [%], a [%], ε [pu], u = electric power [MW], r = applied excitation [Hz], grid frequency [Hz]."""


def check_word(counter: int) -> int:
    """The slot's check word for ``counter`` (never equals an erased slot's 0 for counter 0)."""
    return (counter & 0xFFFF) ^ CHECK_XOR


@dataclass(frozen=True)
class BufferLayout:
    """Where the ring buffer lives in the input registers and what one slot holds."""

    header_address: int
    slots_address: int
    slots: int
    fields: tuple[str, ...] = DEFAULT_FIELDS

    def __post_init__(self):  # messages name the [buffer] key; the map loader prefixes "buffer: "
        if self.slots < 2 or self.slots & (self.slots - 1):
            raise ValueError(f"slots must be a power of two >= 2, not {self.slots}")
        if not self.fields or len(set(self.fields)) != len(self.fields):
            raise ValueError("fields must be a non-empty list of distinct names")
        if self.slot_words > MAX_READ_REGISTERS:
            raise ValueError(f"one slot ({self.slot_words} registers) exceeds one Modbus read (125)")
        if self.header_address + HEADER_WORDS > self.slots_address and self.header_address < self.end:
            raise ValueError("header and slots overlap")
        if self.end > 65536:
            raise ValueError(f"runs past register 65535 ({self.slots} slots from "
                             f"{self.slots_address})")

    @property
    def slot_words(self) -> int:
        """Registers per slot: counter (2) + one float32 per field (2 each) + check (1)."""
        return 3 + 2 * len(self.fields)

    @property
    def slots_per_read(self) -> int:
        """Whole slots in one FC4 request of at most 125 registers."""
        return MAX_READ_REGISTERS // self.slot_words

    @property
    def end(self) -> int:
        """One past the last slot register."""
        return self.slots_address + self.slots * self.slot_words

    def with_slots(self, slots: int) -> BufferLayout:
        return BufferLayout(self.header_address, self.slots_address, slots, self.fields)

    def slot_address(self, index: int) -> int:
        return self.slots_address + index * self.slot_words

    def as_dict(self) -> dict:
        return {"header_address": self.header_address, "slots_address": self.slots_address,
                "slots": self.slots, "fields": list(self.fields)}


# ---------------------------------------------------------------------------------------------------
# Codec (word order as in the register map; bytes in a register are big endian, the Modbus standard)

def _words(data: bytes, word_order: str) -> list[int]:
    w = [int.from_bytes(data[i:i + 2], "big") for i in range(0, len(data), 2)]
    if word_order == "little":  # swap the words of every 32-bit value
        for i in range(0, len(w) - 1, 2):
            w[i], w[i + 1] = w[i + 1], w[i]
    return w


def _u32(regs: Sequence[int], i: int, word_order: str) -> int:
    hi, lo = (regs[i], regs[i + 1]) if word_order == "big" else (regs[i + 1], regs[i])
    return ((hi & 0xFFFF) << 16) | (lo & 0xFFFF)


@dataclass(frozen=True)
class Header:
    head: int
    tail: int
    epoch: int
    slots: int
    slot_words: int
    tc_s: float


def encode_header(h: Header, word_order: str = "big") -> list[int]:
    regs = _words(struct.pack(">II", h.head % COUNTER_MOD, h.tail % COUNTER_MOD), word_order)
    regs += [h.epoch & 0xFFFF, h.slots, h.slot_words]
    regs += _words(struct.pack(">I", round(h.tc_s * 1e6)), word_order)
    return regs


def decode_header(regs: Sequence[int], word_order: str = "big") -> Header:
    if len(regs) < HEADER_WORDS:
        raise ValueError(f"buffer header needs {HEADER_WORDS} registers, got {len(regs)}")
    return Header(head=_u32(regs, 0, word_order), tail=_u32(regs, 2, word_order), epoch=regs[4],
                  slots=regs[5], slot_words=regs[6], tc_s=_u32(regs, 7, word_order) / 1e6)


def encode_slot(counter: int, values: Sequence[float], word_order: str = "big") -> list[int]:
    """Registers of one slot (counter mod 2^32, float32 values, check word)."""
    c = counter % COUNTER_MOD
    regs = _words(struct.pack(f">I{len(values)}f", c, *values), word_order)
    regs.append(check_word(c))
    return regs


def decode_slots(regs: Sequence[int], n_fields: int, word_order: str = "big"
                 ) -> list[tuple[int, tuple[float, ...]] | None]:
    """Slots read in one block: ``(counter mod 2^32, values)`` or None for an invalid/torn slot."""
    words = 3 + 2 * n_fields
    n = len(regs) // words
    regs = list(regs[:n * words])
    if word_order == "little":  # swap the two words of the counter and of every float
        for k in range(n):
            b = k * words
            for i in range(b, b + words - 1, 2):
                regs[i], regs[i + 1] = regs[i + 1], regs[i]
    data = struct.pack(f">{n * words}H", *(w & 0xFFFF for w in regs))
    out: list[tuple[int, tuple[float, ...]] | None] = []
    for c, *values, check in struct.iter_unpack(f">I{n_fields}fH", data):
        out.append((c, tuple(values)) if check == (c & 0xFFFF) ^ CHECK_XOR else None)
    return out


def counter_delta(c32: int, ref: int) -> int:
    """Signed distance from the unwrapped counter ``ref`` to the 32-bit counter ``c32`` (−2^31..2^31)."""
    d = (c32 - ref) % COUNTER_MOD
    return d - COUNTER_MOD if d >= COUNTER_MOD // 2 else d


def bandwidth(layout: BufferLayout, rate_hz: float, read_fraction: float = 0.75) -> dict[str, float]:
    """Requests/s and bytes/s on the wire to keep up with ``rate_hz`` controller samples, reading blocks
    of ``read_fraction`` × slots_per_read on average plus a header read per second (Modbus TCP: 7-byte
    MBAP + PDU; request 12 bytes, response 9 + 2·registers)."""
    per_read = max(1.0, math.floor(layout.slots_per_read * read_fraction))
    req = rate_hz / per_read + 1.0
    regs_per_s = rate_hz * layout.slot_words + HEADER_WORDS
    return {"requests_per_s": req, "bytes_per_s": req * (12 + 9) + 2 * regs_per_s,
            "slots_per_read": layout.slots_per_read}
