"""The simulated governor's register map: a thin layer over :mod:`fcrlive.daemon.registers`.

The map is a TOML file (``registers.toml`` beside this module, documented in REGISTERS.md) with
``unit_id``, ``word_order``, ``byte_order`` and a list of ``[[points]]``, the format the fcrlive daemon
reads. Points, the overlap check and the value codec (type, scale/offset, word and byte order) are the
daemon's; this module adds the simulator's side: strict validation with ConfigError messages, whole-table
encode/decode for the register blocks it serves, and writing a map back as TOML.
"""

from __future__ import annotations

import math
import struct
import tomllib
from dataclasses import replace
from pathlib import Path

from fcrlive.daemon.registers import (
    TYPE_WORDS,
    Order,
    Table,
    decode_raw,
    encode_raw,
    find_overlap,
    register_map_from_dict,
)
from fcrlive.daemon.registers import RegisterMap as _DaemonRegisterMap
from fcrlive.daemon.registers import RegisterPoint as Point
from fcrlive.errors import ConfigError

__all__ = ["DEFAULT_MAP_PATH", "Point", "RegisterMap", "load_map", "parse_map"]

DEFAULT_MAP_PATH = Path(__file__).with_name("registers.toml")

_POINT_KEYS = {"name", "table", "address", "type", "scale", "offset", "unit", "writable", "description"}


class RegisterMap(_DaemonRegisterMap):
    """A validated register map (immutable): the daemon's map plus the simulator's helpers."""

    # ------------------------------------------------------------------ look-up
    def point(self, name: str) -> Point:
        try:
            return super().point(name)
        except KeyError:
            raise KeyError(f"no point named {name!r} in the register map") from None

    def __contains__(self, name: object) -> bool:
        return name in self.names

    def table(self, table: Table) -> tuple[Point, ...]:
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
    def encode(self, point: Point | str, value: float) -> list[int]:
        """Engineering value -> registers (scale/offset, type, word and byte order)."""
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

    def decode(self, point: Point | str, regs: list[int]) -> float | int:
        """Registers (exactly ``point.words`` of them) -> engineering value."""
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
        """The map in the registers.toml format (round-trips through :func:`parse_map`)."""
        lines = [
            f"unit_id = {self.unit_id}",
            f'word_order = "{self.word_order}"',
            f'byte_order = "{self.byte_order}"',
        ]
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


def _check_point(rp: object, where: str, i: int) -> dict:
    """Raw ``points[i]`` -> the keyword arguments of a :class:`Point` (ConfigError if invalid)."""
    pw = f"{where}: points[{i}]"
    if not isinstance(rp, dict):
        raise ConfigError("each point must be a table", pw)
    bad = set(rp) - _POINT_KEYS
    if bad:
        raise ConfigError(f"unknown key(s) {', '.join(sorted(bad))}", pw)
    for key in ("name", "table", "address", "type"):
        if key not in rp:
            raise ConfigError(f"missing key {key!r}", pw)
    name = rp["name"]
    if not isinstance(name, str) or not name:
        raise ConfigError("name must be a non-empty string", pw)
    pw = f"{where}: point {name!r}"
    if rp["table"] not in ("input", "holding"):
        raise ConfigError(f"table must be 'input' or 'holding', not {rp['table']!r}", pw)
    if rp["type"] not in TYPE_WORDS:
        raise ConfigError(f"type must be one of {', '.join(TYPE_WORDS)}, not {rp['type']!r}", pw)
    addr = rp["address"]
    if not isinstance(addr, int) or isinstance(addr, bool) or not 0 <= addr <= 65535:
        raise ConfigError(f"address must be an integer 0..65535, not {addr!r}", pw)
    scale = rp.get("scale", 1.0)
    offset = rp.get("offset", 0.0)
    for key, val in (("scale", scale), ("offset", offset)):
        if not isinstance(val, int | float) or isinstance(val, bool) or not math.isfinite(val):
            raise ConfigError(f"{key} must be a finite number, not {val!r}", pw)
    if scale == 0:
        raise ConfigError("scale must not be 0", pw)
    writable = rp.get("writable", False)
    if not isinstance(writable, bool):
        raise ConfigError("writable must be true or false", pw)
    if writable and rp["table"] == "input":
        raise ConfigError("input registers cannot be writable", pw)
    if addr + TYPE_WORDS[rp["type"]] > 65536:
        raise ConfigError("point runs past address 65535", pw)
    return {
        "name": name, "table": rp["table"], "address": addr, "type": rp["type"],
        "scale": float(scale), "offset": float(offset), "unit": str(rp.get("unit", "")),
        "writable": writable, "description": str(rp.get("description", "")),
    }


def parse_map(data: dict, where: str = "register map") -> RegisterMap:
    """Validate a parsed TOML document into a :class:`RegisterMap` (ConfigError on any problem)."""
    unknown = set(data) - {"unit_id", "word_order", "byte_order", "points"}
    if unknown:
        raise ConfigError(f"unknown top-level key(s) {', '.join(sorted(unknown))}", where)
    unit_id = data.get("unit_id", 1)
    if not isinstance(unit_id, int) or not 0 <= unit_id <= 247:
        raise ConfigError(f"unit_id must be an integer 0..247, not {unit_id!r}", where)
    orders = {}
    for key in ("word_order", "byte_order"):
        val = data.get(key, "big")
        if val not in ("big", "little"):
            raise ConfigError(f"{key} must be 'big' or 'little', not {val!r}", where)
        orders[key] = val
    raw_points = data.get("points")
    if not isinstance(raw_points, list) or not raw_points:
        raise ConfigError("no [[points]] defined", where)
    points = [_check_point(rp, where, i) for i, rp in enumerate(raw_points)]
    names = [p["name"] for p in points]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ConfigError(f"duplicate point name(s) {', '.join(dup)}", where)
    rmap = register_map_from_dict({"unit_id": unit_id, **orders, "points": points})
    pair = find_overlap(rmap.points)
    if pair:
        a, b = pair
        raise ConfigError(f"points {a.name!r} and {b.name!r} overlap in the {a.table} table", where)
    return RegisterMap(**vars(rmap))


def load_map(path: str | Path | None = None) -> RegisterMap:
    """Load and validate a register map; ``None`` loads the one shipped with sim_device."""
    p = Path(path) if path is not None else DEFAULT_MAP_PATH
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot read register map: {exc.strerror or exc}", str(p)) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"invalid TOML: {exc}", str(p)) from None
    return parse_map(data, str(p))
