"""Typed Modbus register maps: points, grouped reads and decoding (pure functions, no I/O).

A register map is what Telegraf / Home Assistant users write: per point a table (input = FC4,
holding = FC3), a start address, a type (int16 … float64), ``value = raw·scale + offset`` and the
device's word and byte order. The map file format is the one of ``sim_device/registers.toml``
(read and validated by :mod:`fcrlive.modbus.mapfile`)::

    unit_id = 1
    word_order = "big"    # "big": most significant 16-bit word first
    byte_order = "big"    # bytes within a register
    [[points]]
    name = "speed"; table = "input"; address = 0; type = "float32"
    scale = 1.0; offset = 0.0; unit = "pu"; writable = false; description = "..."

Reads are grouped into contiguous blocks per table (at most 125 registers, the Modbus limit for
FC3/FC4) so one request fetches many points. The daemon's poller and the excitation writer use the
per-block codec (:func:`decode_block`, :func:`encode_point`); a device serving the map (the simulated
governor) uses the whole-table one (:meth:`RegisterMap.encode_block`, :meth:`RegisterMap.decode_block`).
"""

from __future__ import annotations

import itertools
import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Literal

from fcrlive.errors import ConfigError

if TYPE_CHECKING:  # ringlayout takes MAX_READ_REGISTERS from here
    from fcrlive.modbus.ringlayout import BufferLayout

Table = Literal["input", "holding"]
RegType = Literal["int16", "uint16", "int32", "uint32", "float32", "float64"]
Order = Literal["big", "little"]

MAX_READ_REGISTERS = 125
"""Largest register count of one FC3/FC4 request (Modbus application protocol §6.3/6.4)."""

TYPE_WORDS: dict[str, int] = {
    "int16": 1, "uint16": 1, "int32": 2, "uint32": 2, "float32": 2, "float64": 4,
}
"""Number of 16-bit registers per type."""

_STRUCT_CODE: dict[str, str] = {
    "int16": "h", "uint16": "H", "int32": "i", "uint32": "I", "float32": "f", "float64": "d",
}


@dataclass(frozen=True)
class RegisterPoint:
    """One typed value in the device's register space.

    ``value = raw·scale + offset`` in ``unit``; ``address`` is the first register (0-based, as sent
    on the wire).
    """

    name: str
    table: Table
    address: int
    type: RegType
    scale: float = 1.0
    offset: float = 0.0
    unit: str = ""
    writable: bool = False
    description: str = ""

    @property
    def words(self) -> int:
        """Number of registers the point occupies."""
        return TYPE_WORDS[self.type]

    @property
    def end(self) -> int:
        """One past the last register of the point."""
        return self.address + self.words


@dataclass(frozen=True)
class RegisterMap:
    """A device's points and its word/byte order; ``unit_id`` is the Modbus device id.

    Build one from a file with :func:`fcrlive.modbus.mapfile.load_register_map` (validated: names,
    tables, overlaps); the constructor itself does not check.
    """

    points: tuple[RegisterPoint, ...]
    unit_id: int = 1
    word_order: Order = "big"
    byte_order: Order = "big"
    acquisition: Literal["polled", "buffered"] = "polled"
    """"buffered": read the device's ring buffer of controller samples (docs/buffered-acquisition.md)."""
    buffer: BufferLayout | None = None
    """The ring buffer's layout when the device has one (``[buffer]`` of the map file)."""

    # ------------------------------------------------------------------ look-up
    def point(self, name: str) -> RegisterPoint:
        """The point called ``name`` (KeyError if absent)."""
        for p in self.points:
            if p.name == name:
                return p
        raise KeyError(f"no point named {name!r} in the register map")

    def __contains__(self, name: object) -> bool:
        return name in self.names

    @property
    def names(self) -> tuple[str, ...]:
        """Point names in map order."""
        return tuple(p.name for p in self.points)

    def table(self, table: Table) -> tuple[RegisterPoint, ...]:
        """Points of one table, by address."""
        return tuple(sorted((p for p in self.points if p.table == table), key=lambda p: p.address))

    def span(self, table: Table) -> tuple[int, int]:
        """(first address, register count) covering every point of ``table``."""
        pts = self.table(table)
        if not pts:
            raise KeyError(f"no points in table {table!r}")
        start = pts[0].address
        return start, max(p.end for p in pts) - start

    def with_word_order(self, word_order: Order) -> RegisterMap:
        if word_order not in ("big", "little"):
            raise ConfigError(f"word_order must be 'big' or 'little', not {word_order!r}")
        return replace(self, word_order=word_order)

    # ----------------------------------------------------------- conversions
    def encode(self, point: RegisterPoint | str, value: float) -> list[int]:
        """Engineering value -> registers (scale/offset, type, word and byte order).

        ValueError (naming the point) for a non-finite value of an integer type or one out of its range.
        """
        p = self.point(point) if isinstance(point, str) else point
        raw: float | int = (value - p.offset) / p.scale if (p.scale != 1.0 or p.offset != 0.0) else value
        if p.type.startswith("float"):
            return encode_raw(float(raw), p.type, self.word_order, self.byte_order)
        if not math.isfinite(raw):
            raise ValueError(f"{p.name}: cannot encode {value!r} as {p.type}")
        try:
            return encode_raw(raw, p.type, self.word_order, self.byte_order)
        except struct.error:
            raise ValueError(f"{p.name}: {value!r} out of range for {p.type}") from None

    def decode(self, point: RegisterPoint | str, regs: list[int]) -> float | int:
        """Registers (exactly ``point.words`` of them) -> engineering value (the raw int when unscaled)."""
        p = self.point(point) if isinstance(point, str) else point
        if len(regs) != p.words:
            raise ValueError(f"{p.name}: expected {p.words} registers, got {len(regs)}")
        raw = decode_raw(regs, p.type, self.word_order, self.byte_order)
        if p.scale == 1.0 and p.offset == 0.0:
            return raw
        return raw * p.scale + p.offset

    def decode_block(self, table: Table, start: int, regs: list[int]) -> dict[str, float | int]:
        """Decode every point of ``table`` lying wholly inside ``regs`` read from address ``start``."""
        out: dict[str, float | int] = {}
        stop = start + len(regs)
        for p in self.table(table):
            if p.address >= start and p.end <= stop:
                out[p.name] = self.decode(p, regs[p.address - start : p.end - start])
        return out

    def encode_block(self, table: Table, values: dict[str, float]) -> tuple[int, list[int]]:
        """(start, registers) of the whole ``table`` span, gaps zero; points missing from ``values`` are 0."""
        start, count = self.span(table)
        regs = [0] * count
        for p in self.table(table):
            regs[p.address - start : p.end - start] = self.encode(p, values.get(p.name, 0))
        return start, regs

    # -------------------------------------------------------------- writing
    def to_toml(self) -> str:
        """The map in the registers.toml format (round-trips through the map file loader)."""
        lines = [
            f"unit_id = {self.unit_id}",
            f'word_order = "{self.word_order}"',
            f'byte_order = "{self.byte_order}"',
            f'acquisition = "{self.acquisition}"',
        ]
        if self.buffer is not None:
            b = self.buffer
            lines += ["", "[buffer]", f"header_address = {b.header_address}",
                      f"slots_address = {b.slots_address}", f"slots = {b.slots}",
                      "fields = [" + ", ".join(_q(f) for f in b.fields) + "]"]
        for p in self.points:
            lines += [
                "",
                "[[points]]",
                f"name = {_q(p.name)}",
                f"table = {_q(p.table)}",
                f"address = {p.address}",
                f"type = {_q(p.type)}",
                f"scale = {float(p.scale)!r}",
                f"offset = {float(p.offset)!r}",
                f"unit = {_q(p.unit)}",
                f"writable = {'true' if p.writable else 'false'}",
                f"description = {_q(p.description)}",
            ]
        return "\n".join(lines) + "\n"


def _q(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


@dataclass(frozen=True)
class ReadBlock:
    """One FC3/FC4 request: ``count`` registers from ``address`` covering ``points``."""

    table: Table
    address: int
    count: int
    points: tuple[RegisterPoint, ...]


def find_overlap(points: Sequence[RegisterPoint]) -> tuple[RegisterPoint, RegisterPoint] | None:
    """The first pair of points sharing a register in the same table, or None."""
    for table in ("input", "holding"):
        ps = sorted((p for p in points if p.table == table), key=lambda p: p.address)
        for a, b in itertools.pairwise(ps):
            if b.address < a.end:
                return a, b
    return None


def plan_reads(points: Sequence[RegisterPoint], max_count: int = MAX_READ_REGISTERS,
               max_gap: int = 0) -> tuple[ReadBlock, ...]:
    """Group points into contiguous read blocks per table.

    Points whose registers are adjacent (or separated by at most ``max_gap`` unused registers)
    share a block as long as the block stays within ``max_count`` registers. ``max_gap`` defaults
    to 0 because many devices answer an exception for undefined addresses inside a request.
    """
    blocks: list[ReadBlock] = []
    for table in ("input", "holding"):
        ps = sorted((p for p in points if p.table == table), key=lambda p: p.address)
        cur: list[RegisterPoint] = []
        start = end = 0
        for p in ps:
            if cur and p.address - end <= max_gap and p.end - start <= max_count:
                cur.append(p)
                end = max(end, p.end)
                continue
            if cur:
                blocks.append(ReadBlock(table, start, end - start, tuple(cur)))
            cur, start, end = [p], p.address, p.end
        if cur:
            blocks.append(ReadBlock(table, start, end - start, tuple(cur)))
    return tuple(blocks)


def _swap_bytes(word: int) -> int:
    return ((word & 0xFF) << 8) | (word >> 8)


def decode_raw(registers: Sequence[int], type_: RegType, word_order: Order = "big",
               byte_order: Order = "big") -> int | float:
    """Decode the registers of one point into its raw (unscaled) value.

    ``word_order`` "big" means the most significant register comes first; ``byte_order`` "little"
    means the two bytes inside every register are swapped (the "byte-swapped" devices).
    """
    n = TYPE_WORDS[type_]
    if len(registers) != n:
        raise ValueError(f"{type_} needs {n} registers, got {len(registers)}")
    words = list(registers) if word_order == "big" else list(reversed(registers))
    if byte_order == "little":
        words = [_swap_bytes(w) for w in words]
    data = b"".join(int(w & 0xFFFF).to_bytes(2, "big") for w in words)
    return struct.unpack(">" + _STRUCT_CODE[type_], data)[0]


def encode_raw(value: int | float, type_: RegType, word_order: Order = "big",
               byte_order: Order = "big") -> list[int]:
    """Inverse of :func:`decode_raw`: the registers holding raw ``value``."""
    code = _STRUCT_CODE[type_]
    if code in "hHiI":
        value = round(value)
    data = struct.pack(">" + code, value)
    words = [int.from_bytes(data[i:i + 2], "big") for i in range(0, len(data), 2)]
    if byte_order == "little":
        words = [_swap_bytes(w) for w in words]
    return words if word_order == "big" else list(reversed(words))


def decode_point(point: RegisterPoint, registers: Sequence[int], word_order: Order = "big",
                 byte_order: Order = "big") -> float:
    """Engineering value of ``point``: ``raw·scale + offset`` as a float (may be NaN/inf for floats)."""
    raw = decode_raw(registers, point.type, word_order, byte_order)
    return float(raw) * point.scale + point.offset


def encode_point(point: RegisterPoint, value: float, word_order: Order = "big",
                 byte_order: Order = "big") -> list[int]:
    """Registers to write for engineering ``value`` of ``point`` (inverse of the scaling)."""
    raw = (value - point.offset) / point.scale if point.scale else value
    return encode_raw(raw, point.type, word_order, byte_order)


def decode_block(block: ReadBlock, registers: Sequence[int], word_order: Order = "big",
                 byte_order: Order = "big") -> dict[str, float]:
    """Decode every point of ``block`` from the registers read for it.

    A point that cannot be decoded (short read) comes back as NaN so the caller can flag it.
    """
    out: dict[str, float] = {}
    for p in block.points:
        i = p.address - block.address
        regs = registers[i:i + p.words]
        try:
            out[p.name] = decode_point(p, regs, word_order, byte_order)
        except (ValueError, struct.error):
            out[p.name] = math.nan
    return out

