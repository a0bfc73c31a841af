"""The simulated governor's ring buffer of controller samples (docs/buffered-acquisition.md).

Every controller sample the plant simulator computes goes into the ring, at any speed and load: the
device steps the plant in batches (one sample at speed 1, many when accelerated or behind), and
:meth:`RingBuffer.push` is called for each sample of a batch, not only for the last one the snapshot
registers show. A slot is written in one slice assignment straight into the pymodbus register list of
the input table; the header (head, tail) is updated once per batch by :meth:`RingBuffer.commit`. A batch
runs synchronously on the event loop, so a client request is served either before or after it, never in
the middle: the simulator needs no write order (a real PLC gets the same from the documented one: check
word, values, counter last).
"""

from __future__ import annotations

import math
import secrets
import struct
from collections.abc import Callable
from typing import Any

from fcrlive.modbus.ringlayout import (
    COUNTER_MOD,
    HEADER_WORDS,
    BufferLayout,
    Header,
    check_word,
    encode_header,
)

MAX_SLOTS = 4096
"""Largest ring the reference layout can hold below register 65536 (15-register slots from 1016)."""


def sample_values(s: Any, applied_hz: float) -> dict[str, float]:
    """The values of one controller sample (``fcrlive.sim.realtime.StepSample``) by register-map name."""
    return {
        "speed": s.speed_pu, "grid_freq": s.grid_freq_hz, "power": s.pe_mw, "mech_power": s.pm_mw,
        "controller_output": 100.0 * s.c, "guide_vane": 100.0 * s.a, "excitation_applied": applied_hz,
        "control_error": s.epsilon,
    }


_GETTERS: dict[str, Callable[[Any, float], float]] = {
    "speed": lambda s, r: s.speed_pu, "grid_freq": lambda s, r: s.grid_freq_hz, "power": lambda s, r: s.pe_mw,
    "mech_power": lambda s, r: s.pm_mw, "controller_output": lambda s, r: 100.0 * s.c,
    "guide_vane": lambda s, r: 100.0 * s.a, "excitation_applied": lambda s, r: r,
    "control_error": lambda s, r: s.epsilon,
}

SLOT_FIELDS = tuple(_GETTERS)
"""The values the simulator can put into a slot (register-map names)."""


def slot_values(fields: tuple[str, ...], nan_fields: frozenset[str] = frozenset()
                ) -> Callable[[Any, float], tuple[float, ...]]:
    """``f(sample, applied_hz) -> values in field order`` (the fields of :func:`sample_values`; those in
    ``nan_fields`` read NaN: the ``nan`` fault)."""
    nan = math.nan
    getters = [(lambda s, r: nan) if f in nan_fields else _GETTERS[f] for f in fields]
    return lambda s, r: tuple([g(s, r) for g in getters])


def slots_for(speed: float, tc_s: float, minimum: int, wall_s: float = 4.0) -> int:
    """Slots (a power of two, ≤ MAX_SLOTS) holding at least ``minimum`` slots and ``wall_s`` seconds of
    WALL time at ``speed``: an accelerated simulator fills the ring ``speed`` times faster than a real
    governor, and a reader needs the same wall-clock slack as against a real one."""
    need = max(minimum, math.ceil(wall_s * speed / tc_s))
    n = 1 << max(1, (need - 1).bit_length())
    return min(n, MAX_SLOTS)


class RingBuffer:
    """The ring in the device's input registers. ``attach`` it to the register list after the server
    is built; ``push`` every controller sample; ``commit`` after each batch."""

    def __init__(self, layout: BufferLayout, tc_s: float, word_order: str = "big", counter_start: int = 0,
                 on_sample: Callable[[int, tuple[float, ...]], None] | None = None):
        self.layout = layout
        self.tc_s = float(tc_s)
        self.word_order = word_order
        self.counter_start = int(counter_start) % COUNTER_MOD
        self.on_sample = on_sample
        """Called with (counter, values) for every sample pushed (the CAN per-sample frame)."""
        self.epoch = secrets.randbelow(1 << 16)
        self._regs: list[int] | None = None
        self._base = 0
        n = len(layout.fields)
        self._pack = struct.Struct(f">I{n}fH").pack
        self._words = struct.Struct(f">{3 + 2 * n}H").unpack
        self._little = word_order == "little"
        self.pushed = 0
        """Samples pushed since the last reset (instrumentation)."""
        self.reset()

    # ------------------------------------------------------------------ registers
    def span(self) -> tuple[int, int]:
        """(first register, count) the device must serve: the header through the last slot."""
        return self.layout.header_address, self.layout.end - self.layout.header_address

    def attach(self, registers: list[int], start: int) -> None:
        """Write into ``registers`` (the input table's register list, index 0 = address ``start``)."""
        self._regs = registers
        self._base = start
        lo, n = self.span()
        registers[lo - start:lo - start + n] = [0] * n
        self.commit()

    def reset(self) -> None:
        """A (re)start: new epoch, counter back to ``counter_start``, every slot erased (reads invalid)."""
        self.epoch = (self.epoch + 1) & 0xFFFF
        self.next = self.counter_start  # unwrapped counter of the next sample
        self.first_valid = self.counter_start
        self.pushed = 0
        if self._regs is not None:
            lo, n = self.span()
            self._regs[lo - self._base:lo - self._base + n] = [0] * n
            self.commit()

    # ------------------------------------------------------------------ writing
    def push(self, values: tuple[float, ...]) -> None:
        """Store one controller sample (values in ``layout.fields`` order) in slot ``counter mod N``."""
        c = self.next % COUNTER_MOD
        self.next += 1
        self.pushed += 1
        if self.on_sample is not None:
            self.on_sample(c, values)
        regs = self._regs
        if regs is None:
            return
        lay = self.layout
        a = lay.slots_address + (c % lay.slots) * lay.slot_words - self._base
        words = self._words(self._pack(c, *values, check_word(c)))
        if self._little:  # swap the two words of the counter and of every float, not the check
            words = list(words)
            for i in range(0, len(words) - 1, 2):
                words[i], words[i + 1] = words[i + 1], words[i]
        regs[a:a + lay.slot_words] = words

    def skip(self, n: int) -> None:
        """``n`` controller samples that never enter the ring (a frozen buffer): the counter jumps."""
        self.next += n
        self.first_valid = self.next  # the slots still hold the previous lap: not valid for these counters

    def commit(self) -> None:
        """Publish head and tail in the header (after a batch of pushes)."""
        if self._regs is None:
            return
        head = self.next - 1
        tail = max(self.first_valid, self.next - self.layout.slots)
        h = Header(head=head % COUNTER_MOD, tail=tail % COUNTER_MOD, epoch=self.epoch,
                   slots=self.layout.slots, slot_words=self.layout.slot_words, tc_s=self.tc_s)
        a = self.layout.header_address - self._base
        self._regs[a:a + HEADER_WORDS] = encode_header(h, self.word_order)
