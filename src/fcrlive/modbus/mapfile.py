"""Register map files: the pydantic models and the one loader the daemon and the simulated governor share.

A map file (the format of ``sim_device/registers.toml``, documented in docs/config.md) has top-level
``unit_id``, ``word_order``, ``byte_order``, ``acquisition``, ``[[points]]`` and, for a device with a ring
buffer of controller samples, ``[buffer]`` (docs/buffered-acquisition.md). Validation refuses unknown keys,
a point name that could not be a signal name, a type, table or address outside the Modbus ranges, a
writable input register, a zero scale, non-finite scale/offset, a point name used twice, points sharing a
register, a ring buffer that is not a power of two slots, does not fit the register space or overlaps an
input point, and ``acquisition = "buffered"`` without a ``[buffer]``.
The first problem becomes ONE :class:`fcrlive.errors.ConfigError` line naming the file and the key, e.g.::

    registers.toml: points[3].address: must be between 0 and 65535 (got 70000)

Rules chosen where the daemon's and the simulator's validators used to disagree:

- ``unit_id`` is 0-255: on Modbus TCP it is one byte of the MBAP header that only a gateway to a serial
  line interprets; the MODBUS Messaging on TCP/IP Implementation Guide recommends 0xFF (255) for a device
  addressed directly by its IP address, so 248-255, reserved on a serial line, are valid here (pymodbus
  accepts 0-255 on both sides). 0-247 would refuse exactly the devices that follow that recommendation.
- A point name is a letter followed by up to 62 letters, digits or underscores: the daemon stores each
  point as an SQLite column and publishes it in MQTT payloads, so the simulator's maps obey the same rule.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from fcrlive.configerrors import decode_config_text, explain
from fcrlive.errors import ConfigError
from fcrlive.modbus.registers import TYPE_WORDS, RegisterMap, RegisterPoint, find_overlap
from fcrlive.modbus.ringlayout import DEFAULT_FIELDS, HEADER_WORDS, BufferLayout

PointName = Annotated[str, Field(pattern=r"^[A-Za-z][A-Za-z0-9_]{0,62}$")]
"""A point name: also a signal name, an SQLite column and part of MQTT payloads."""


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_default=True)


class PointModel(_Section):
    """One register-map point (same keys as ``sim_device/registers.toml``)."""

    name: PointName
    table: Literal["input", "holding"]
    address: int = Field(ge=0, le=65535)
    type: Literal["int16", "uint16", "int32", "uint32", "float32", "float64"]
    scale: float = Field(1.0, allow_inf_nan=False)
    offset: float = Field(0.0, allow_inf_nan=False)
    unit: str = ""
    writable: bool = False
    description: str = ""

    @model_validator(mode="after")
    def _check(self) -> PointModel:
        if self.address + TYPE_WORDS[self.type] > 65536:
            raise ValueError(f"{self.type} at address {self.address} runs past register 65535")
        if self.writable and self.table != "holding":
            raise ValueError("only holding registers can be writable")
        if self.scale == 0:
            raise ValueError("scale must not be 0")
        return self

    def to_point(self) -> RegisterPoint:
        return RegisterPoint(**self.model_dump())


def check_points(points: list[PointModel]) -> None:
    """ValueError when a name is used twice or two points share a register (naming both)."""
    seen: set[str] = set()
    for p in points:
        if p.name in seen:
            raise ValueError(f"duplicate point name {p.name!r}")
        seen.add(p.name)
    pair = find_overlap([p.to_point() for p in points])
    if pair:
        a, b = pair
        raise ValueError(
            f"points {a.name!r} ({a.table} {a.address}-{a.end - 1}) and {b.name!r} "
            f"({b.table} {b.address}-{b.end - 1}) overlap"
        )


class BufferModel(_Section):
    """The device's ring buffer of controller samples (``[buffer]``; docs/buffered-acquisition.md)."""

    header_address: int = Field(ge=0, le=65535, description="input register of the header")
    slots_address: int = Field(ge=0, le=65535, description="input register of slot 0")
    slots: int = Field(ge=2, le=32768, description="slot count, a power of two")
    fields: list[PointName] = Field(default_factory=lambda: list(DEFAULT_FIELDS), min_length=1,
                                    description="float32 values of one slot, after its counter")

    @field_validator("slots")
    @classmethod
    def _power_of_two(cls, n: int) -> int:
        if n & (n - 1):
            raise ValueError(f"must be a power of two (the 32-bit counter wraps onto the same slot), not {n}")
        return n

    @model_validator(mode="after")
    def _check(self) -> BufferModel:
        self.to_layout()  # distinct fields, one slot per read, header clear of the slots, below 65536
        return self

    def to_layout(self) -> BufferLayout:
        return BufferLayout(self.header_address, self.slots_address, self.slots, tuple(self.fields))


class RegisterMapModel(_Section):
    """A register map file (``sim_device/registers.toml`` format)."""

    unit_id: int = Field(1, ge=0, le=255)
    word_order: Literal["big", "little"] = "big"
    byte_order: Literal["big", "little"] = "big"
    acquisition: Literal["polled", "buffered"] = Field(
        "polled", description="polled: snapshots of the input points; buffered: every controller sample "
        "from the ring buffer")
    points: list[PointModel]
    buffer: BufferModel | None = None

    @field_validator("points")
    @classmethod
    def _some(cls, points: list[PointModel]) -> list[PointModel]:
        if not points:
            raise ValueError("no [[points]] defined")
        return points

    @model_validator(mode="after")
    def _check(self) -> RegisterMapModel:
        check_points(self.points)
        if self.acquisition == "buffered" and self.buffer is None:
            raise ValueError('acquisition = "buffered" needs a [buffer] table')
        if self.buffer is not None:
            b = self.buffer.to_layout()
            ranges = ((b.header_address, b.header_address + HEADER_WORDS), (b.slots_address, b.end))
            for p in self.points:
                if p.table == "input" and any(p.address < hi and lo < p.address + TYPE_WORDS[p.type]
                                              for lo, hi in ranges):
                    raise ValueError(f"point {p.name!r} (input {p.address}) lies inside the ring buffer "
                                     f"(input {b.header_address}-{b.header_address + HEADER_WORDS - 1}, "
                                     f"{b.slots_address}-{b.end - 1})")
        return self

    def to_map(self, unit_id: int | None = None) -> RegisterMap:
        """The plain frozen map used by the source."""
        return RegisterMap(
            points=tuple(p.to_point() for p in self.points),
            unit_id=self.unit_id if unit_id is None else unit_id,
            word_order=self.word_order,
            byte_order=self.byte_order,
            acquisition=self.acquisition,
            buffer=None if self.buffer is None else self.buffer.to_layout(),
        )


def parse_register_map(data: object, where: str = "register map", unit_id: int | None = None) -> RegisterMap:
    """Validate a parsed TOML document into a :class:`RegisterMap`; ConfigError naming ``where`` and the key.

    ``unit_id`` (not None) overrides the document's.
    """
    try:
        model = RegisterMapModel.model_validate(data)
    except ValidationError as exc:
        key, msg = explain(exc, RegisterMapModel)
        raise ConfigError(msg, where=f"{where}: {key}" if key else where) from None
    return model.to_map(unit_id)


def load_register_map(path: str | Path, unit_id: int | None = None) -> RegisterMap:
    """Read and validate a register map file; errors name the file and the key in it."""
    p = Path(path)
    try:
        text = decode_config_text(p.read_bytes(), str(p))
    except OSError as exc:
        raise ConfigError(f"cannot read register map: {exc.strerror or exc}", str(p)) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"invalid TOML: {exc}", str(p)) from None
    return parse_register_map(data, str(p), unit_id)
