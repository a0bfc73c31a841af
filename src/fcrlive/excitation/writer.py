"""The Modbus link that writes the excitation to the governor: zero first, FC16, read-back, heartbeat.

:class:`ExcitationWriter` is the only code in fcrlive that writes a frequency-reference offset. It is
deliberately small and keeps these invariants by itself, whatever its caller does:

- **zero first**: on every new TCP connection (start-up and every reconnect) and after any failed write,
  the first write is offset 0.0 with enable 0, verified by read-back; whatever value the caller asked for
  at that moment is replaced by 0.0 (``WriteResult.forced_zero``). Only after that verified zero is the
  link *armed* and other values are written;
- **one atomic write**: offset (float32, two registers), enable and heartbeat are written together with
  one FC16 request when they are contiguous (addresses 100-103 of the simulated governor); otherwise in
  the safe order (offset first when going to zero, heartbeat and enable first otherwise);
- **read-back**: every write is followed by an FC3 read of the same registers, compared word for word; a
  device that holds something else (clamped, word order wrong, another master writing) raises
  :class:`ReadbackMismatch`, a fault that ends the excitation;
- **heartbeat**: every write changes the heartbeat register (+1 mod 2^16), so the device's watchdog sees
  the heartbeat exactly as long as writes keep coming: a stalled writer is zeroed by the device;
- **bounds**: a non-finite value or one beyond ``max_abs_hz`` is never sent (:class:`ExcitationFault`
  after writing zero); the device's own clamp (``excitation_limit``) must be at least ``max_abs_hz`` and
  its heartbeat timeout at least 4 write periods (checked on every connect).

Link errors (timeouts, refused connections, exception responses) never raise from :meth:`write` or
:meth:`read_measurements`: they return ``ok=False``/None, drop the link and reconnect with a bounded
backoff, so the caller (the task) keeps its loop, feeds "status unknown" to the guard and the hold-off
starts again.

It owns its own pymodbus client instead of sharing the daemon's ``ModbusSource``: ``ModbusSource.write``
writes one point per request (no offset+enable+heartbeat FC16), reconnects in a background task without
telling anyone (so "the first write after a reconnect is zero" could not be enforced from outside), and its
20-50 Hz poller's watchdog may recreate the client in the middle of a write/read-back pair. It receives
what it needs, a :class:`fcrlive.modbus.client.ModbusParams` (host/port/timeouts and the register map), and
uses the register codecs of :mod:`fcrlive.modbus.registers` and the bounded backoff of
:mod:`fcrlive.backoff`: it imports nothing from the daemon.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from fcrlive.backoff import backoff_delays
from fcrlive.errors import ConfigError
from fcrlive.modbus.client import ModbusParams, quiet_pymodbus
from fcrlive.modbus.registers import (
    ReadBlock,
    RegisterMap,
    RegisterPoint,
    decode_block,
    decode_point,
    encode_point,
    plan_reads,
)

log = logging.getLogger("fcrlive.excitation")

HEARTBEAT_MODULO = 1 << 16
MIN_HEARTBEAT_PERIODS = 4.0
"""The device's heartbeat timeout must cover at least this many write periods."""
APPLIED_TOLERANCE_HZ = 1e-6
"""A float32 of |r| ≤ 0.1 Hz is exact to 4e-9 Hz: anything further off is another value."""


class ExcitationFault(RuntimeError):
    """The excitation cannot be written safely: it must stop (after writing zero)."""


class ReadbackMismatch(ExcitationFault):
    """The device holds something else than what was written."""


@dataclass(frozen=True)
class ExcitationPoints:
    """Names of the register-map points the excitation uses (``[excitation.points]``).

    Holding (written): ``offset`` (the frequency-reference offset [Hz], required), ``enable`` (1 = apply;
    optional), ``heartbeat`` (changed on every write; required: writing is not allowed on a device
    without a heartbeat watchdog). Holding (read on connect, optional): ``limit`` (the device's clamp
    [Hz]), ``heartbeat_timeout`` [s]. Input (read every tick): ``grid_freq`` [Hz] and ``status`` (bit 0
    FCR-N active, bit 1 normal operation) for the guard's interlocks, ``counter`` (a sample counter: an
    unchanged counter means the frequency is not new), ``applied`` (the offset the device applies [Hz],
    checked against what was written), ``fcrd`` (non-zero = FCR-D activated). Without an ``fcrd`` point
    FCR-D is taken as not active: it only activates outside ±0.1 Hz, which the band interlock
    (band_hz ≤ 0.1) already covers.
    """

    offset: str = "excitation_offset"
    enable: str | None = "excitation_enable"
    heartbeat: str = "heartbeat"
    limit: str | None = "excitation_limit"
    heartbeat_timeout: str | None = "heartbeat_timeout"
    grid_freq: str = "grid_freq"
    status: str = "status"
    counter: str | None = "sample_counter"
    applied: str | None = "excitation_applied"
    fcrd: str | None = None

    def check(self, rmap: RegisterMap) -> None:
        """ConfigError unless every named point exists in ``rmap`` in the right table."""
        def need(name: str | None, table: str, writable: bool, role: str) -> None:
            if name is None:
                return
            try:
                p = rmap.point(name)
            except KeyError:
                raise ConfigError(f"excitation: the register map has no point {name!r} ({role})") from None
            if p.table != table:
                raise ConfigError(f"excitation: point {name!r} ({role}) must be an {table} register")
            if writable and not p.writable:
                raise ConfigError(f"excitation: point {name!r} ({role}) must be writable")

        need(self.offset, "holding", True, "offset")
        need(self.enable, "holding", True, "enable")
        need(self.heartbeat, "holding", True, "heartbeat")
        need(self.limit, "holding", False, "device limit")
        need(self.heartbeat_timeout, "holding", False, "heartbeat timeout")
        for name, role in ((self.grid_freq, "grid frequency"), (self.status, "status word"),
                           (self.counter, "sample counter"), (self.applied, "applied excitation"),
                           (self.fcrd, "FCR-D active")):
            need(name, "input", False, role)
        if rmap.point(self.offset).type not in ("float32", "float64", "int16", "int32"):
            raise ConfigError(f"excitation: offset point {self.offset!r} must be signed")
        if rmap.point(self.heartbeat).type != "uint16":
            raise ConfigError(f"excitation: heartbeat point {self.heartbeat!r} must be a uint16")


@dataclass(frozen=True)
class Measurement:
    """One read of the device's input points (engineering values; None = point not configured)."""

    t_mono: float
    """time.monotonic() at arrival [s]."""
    grid_freq_hz: float
    status_word: int | None
    counter: int | None
    applied_hz: float | None
    fcrd_active: bool | None


@dataclass(frozen=True)
class WriteResult:
    """Outcome of one :meth:`ExcitationWriter.write`."""

    ok: bool
    """The write was acknowledged and read back equal."""
    written_hz: float | None
    """The offset now held by the device [Hz] (0.0 on a forced zero); None when unknown (link error)."""
    requested_hz: float
    forced_zero: bool = False
    """The link was not armed: zero was written instead of the request."""
    heartbeat: int | None = None
    error: str = ""


@dataclass
class WriterStats:
    """Counters since construction."""

    connects: int = 0
    connect_failures: int = 0
    writes: int = 0
    write_failures: int = 0
    forced_zero_writes: int = 0
    readback_checks: int = 0
    reads: int = 0
    read_failures: int = 0
    max_abs_written_hz: float = 0.0
    errors: dict[str, int] = field(default_factory=dict)


def _f32(x: float) -> float:
    import struct

    return struct.unpack(">f", struct.pack(">f", x))[0]


class ExcitationWriter:
    """The write link to one governor (module docstring). Async context manager.

    ``params``: host, port, register map, request timeout and retries, backoff cap (a ``ModbusParams``;
    its polling fields are not used). ``max_abs_hz``: the largest |offset| this writer
    will ever send (the guard's amplitude). ``write_period_s``: how often the caller writes (checked
    against the device's heartbeat timeout).
    """

    def __init__(self, params: ModbusParams, *, max_abs_hz: float, write_period_s: float,
                 points: ExcitationPoints | None = None, backoff_min_s: float = 0.05):
        quiet_pymodbus()
        if not (math.isfinite(max_abs_hz) and 0.0 < max_abs_hz <= 0.1):
            raise ConfigError(f"excitation writer: max_abs_hz = {max_abs_hz!r} must be in (0, 0.1]")
        if not (math.isfinite(write_period_s) and write_period_s > 0):
            raise ConfigError(f"excitation writer: write_period_s = {write_period_s!r} must be > 0")
        self.p = params
        self.map = params.register_map
        self.points = points or ExcitationPoints()
        self.points.check(self.map)
        self.max_abs_hz = float(max_abs_hz)
        self.write_period_s = float(write_period_s)
        self.backoff_min_s = backoff_min_s
        pts = self.points
        self._offset = self.map.point(pts.offset)
        self._write_points: tuple[RegisterPoint, ...] = tuple(
            self.map.point(n) for n in (pts.offset, pts.enable, pts.heartbeat) if n is not None)
        # FC16 carries at most 123 registers; contiguous points share one request
        self._write_blocks = plan_reads(self._write_points, max_count=123)
        needed = {n for n in (pts.grid_freq, pts.status, pts.counter, pts.applied, pts.fcrd) if n}
        # plan over ALL input points so that a read spans defined registers only, then keep the blocks
        # that hold a needed point (the simulated governor: one FC4 of 0-21)
        inputs = [p for p in self.map.points if p.table == "input"]
        self._read_blocks = tuple(self._trim(b, needed) for b in plan_reads(inputs)
                                  if any(p.name in needed for p in b.points))
        info = [self.map.point(n) for n in (pts.limit, pts.heartbeat_timeout, pts.heartbeat) if n]
        self._info_blocks = plan_reads(info)
        self.stats = WriterStats()
        self._client: Any = None
        self._armed = False
        self._hb: int | None = None
        self._delays = backoff_delays(backoff_min_s, params.backoff_max_s)
        self._next_connect = 0.0
        self.device_limit_hz: float | None = None
        self.device_heartbeat_timeout_s: float | None = None
        self.last_error = ""

    @staticmethod
    def _trim(b: ReadBlock, needed: set[str]) -> ReadBlock:
        """The part of ``b`` from its first to its last needed point."""
        first = min(p.address for p in b.points if p.name in needed)
        last = max(p.end for p in b.points if p.name in needed)
        return ReadBlock(b.table, first, last - first,
                         tuple(p for p in b.points if p.address >= first and p.end <= last))

    # ---- lifecycle ----------------------------------------------------------------------------------------

    async def __aenter__(self) -> ExcitationWriter:
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._drop("closing")

    @property
    def connected(self) -> bool:
        return self._client is not None and self._client.connected

    @property
    def armed(self) -> bool:
        """A verified zero was written on the current connection and nothing failed since."""
        return self._armed and self.connected

    def _drop(self, why: str) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None
            if why != "closing":
                log.warning("excitation link dropped host=%s port=%d reason=%s", self.p.host, self.p.port,
                            why)
        self._armed = False

    def _note(self, kind: str, msg: str) -> None:
        self.stats.errors[kind] = self.stats.errors.get(kind, 0) + 1
        self.last_error = msg

    async def _ensure_client(self) -> bool:
        """Connected (connecting now if the backoff allows); False when not connected."""
        if self._client is not None:
            if self._client.connected:
                return True
            self._drop("connection lost")
        now = time.monotonic()
        if now < self._next_connect:
            return False
        from pymodbus.client import AsyncModbusTcpClient

        client = AsyncModbusTcpClient(self.p.host, port=self.p.port, timeout=self.p.timeout_s,
                                      retries=self.p.retries, reconnect_delay=0, reconnect_delay_max=0)
        try:
            ok = await client.connect() and client.connected
        except OSError:
            ok = False
        if not ok:
            client.close()
            self.stats.connect_failures += 1
            self._next_connect = time.monotonic() + next(self._delays)
            if self.stats.connect_failures in (1, 10) or self.stats.connect_failures % 100 == 0:
                log.warning("excitation link: connect failed host=%s port=%d failures=%d", self.p.host,
                            self.p.port, self.stats.connect_failures)
            return False
        self._client = client
        self._armed = False
        self._delays = backoff_delays(self.backoff_min_s, self.p.backoff_max_s)
        self._next_connect = 0.0
        self.stats.connects += 1
        log.info("excitation link connected host=%s port=%d connects=%d", self.p.host, self.p.port,
                 self.stats.connects)
        return True

    # ---- low-level requests (return an error string, never raise on link errors) -------------------------

    async def _read(self, block: ReadBlock) -> tuple[list[int] | None, str]:
        from pymodbus.exceptions import ModbusException

        client = self._client
        if client is None:
            return None, "not connected"
        fn = client.read_input_registers if block.table == "input" else client.read_holding_registers
        try:
            rr = await fn(block.address, count=block.count, device_id=self.map.unit_id)
        except (TimeoutError, ModbusException, OSError) as exc:
            self._drop(f"{type(exc).__name__}: {exc}")
            return None, f"{type(exc).__name__}: {exc}"
        if rr.isError():
            return None, f"exception response {rr}"
        regs = list(rr.registers)
        if len(regs) != block.count:
            return None, f"short read ({len(regs)} of {block.count} registers)"
        return regs, ""

    async def _write_block(self, address: int, regs: list[int]) -> str:
        from pymodbus.exceptions import ModbusException

        client = self._client
        if client is None:
            return "not connected"
        try:
            if len(regs) == 1:
                rr = await client.write_register(address, regs[0], device_id=self.map.unit_id)
            else:  # multi-register values atomically: FC16
                rr = await client.write_registers(address, regs, device_id=self.map.unit_id)
        except (TimeoutError, ModbusException, OSError) as exc:
            self._drop(f"{type(exc).__name__}: {exc}")
            return f"{type(exc).__name__}: {exc}"
        if rr.isError():
            return f"exception response {rr}"
        return ""

    # ---- arming -----------------------------------------------------------------------------------------

    async def _read_info(self) -> str:
        """Device limit, heartbeat timeout and current heartbeat; raises ExcitationFault when unsafe."""
        values: dict[str, float] = {}
        for b in self._info_blocks:
            regs, err = await self._read(b)
            if regs is None:
                return err
            values.update(decode_block(b, regs, self.map.word_order, self.map.byte_order))
        pts = self.points
        if pts.limit is not None:
            lim = values[pts.limit]
            self.device_limit_hz = lim
            if not (math.isfinite(lim) and lim >= self.max_abs_hz * (1 - 1e-6)):
                raise ExcitationFault(
                    f"the device clamps the excitation at {lim!r} Hz, below the guard's amplitude "
                    f"{self.max_abs_hz!r} Hz: every larger write would read back clamped; lower amplitude_hz")
        if pts.heartbeat_timeout is not None:
            hbt = values[pts.heartbeat_timeout]
            self.device_heartbeat_timeout_s = hbt
            if not (math.isfinite(hbt) and hbt > 0):
                raise ExcitationFault(f"the device reports a heartbeat timeout of {hbt!r} s: no watchdog")
            if hbt < MIN_HEARTBEAT_PERIODS * self.write_period_s:
                raise ExcitationFault(
                    f"the device's heartbeat timeout {hbt!r} s is shorter than {MIN_HEARTBEAT_PERIODS:g} "
                    f"write periods of {self.write_period_s!r} s")
        hb = values.get(pts.heartbeat)
        # continue from what the device holds, so that the next heartbeat is a change for it
        self._hb = int(hb) if hb is not None and math.isfinite(hb) else (self._hb or 0)
        return ""

    def _next_heartbeat(self) -> int:
        self._hb = ((self._hb or 0) + 1) % HEARTBEAT_MODULO
        return self._hb

    def _image(self, value_hz: float, heartbeat: int) -> dict[str, list[int]]:
        pts = self.points
        wo, bo = self.map.word_order, self.map.byte_order
        img = {pts.offset: encode_point(self._offset, value_hz, wo, bo),
               pts.heartbeat: encode_point(self.map.point(pts.heartbeat), heartbeat, wo, bo)}
        if pts.enable is not None:
            img[pts.enable] = encode_point(self.map.point(pts.enable), 1 if value_hz != 0.0 else 0, wo, bo)
        return img

    async def _send(self, value_hz: float) -> tuple[str, int]:
        """Write ``value_hz`` (with enable and a new heartbeat) and read it back; ('' , hb) when equal.

        Raises ReadbackMismatch when the device acknowledged the write but holds something else.
        """
        hb = self._next_heartbeat()
        img = self._image(value_hz, hb)
        blocks = list(self._write_blocks)
        offset_first = value_hz == 0.0
        blocks.sort(key=lambda b: (self._offset in b.points) != offset_first)
        for b in blocks:
            regs: list[int] = []
            for p in sorted(b.points, key=lambda p: p.address):
                regs += img[p.name]
            err = await self._write_block(b.address, regs)
            if err:
                return f"write: {err}", hb
            back, err = await self._read(ReadBlock("holding", b.address, len(regs), b.points))
            if back is None:
                return f"read-back: {err}", hb
            self.stats.readback_checks += 1
            if back != regs:
                got = {p.name: decode_point(p, back[p.address - b.address:p.end - b.address],
                                            self.map.word_order, self.map.byte_order) for p in b.points}
                raise ReadbackMismatch(f"wrote {value_hz!r} Hz (heartbeat {hb}) but the device holds {got}")
        return "", hb

    # ---- the API ----------------------------------------------------------------------------------------

    async def write(self, value_hz: float) -> WriteResult:
        """Write the guard's ``value_hz`` [Hz] (module docstring: zero first, read-back, heartbeat).

        Returns ``ok=False`` on a link error (the link is then disarmed: the next write is zero). Raises
        ExcitationFault for a value out of bounds (after writing zero) or a read-back mismatch.
        """
        v = float(value_hz)
        if not math.isfinite(v) or abs(v) > self.max_abs_hz:
            await self.zero(deadline_s=1.0)
            raise ExcitationFault(f"refused to write {value_hz!r} Hz (bound ±{self.max_abs_hz!r} Hz)")
        v += 0.0  # −0.0 → 0.0
        if not await self._ensure_client():
            self.stats.write_failures += 1
            self._note("not_connected", "not connected")
            return WriteResult(False, None, v, error="not connected")
        forced = not self._armed
        if forced:
            try:
                err = await self._read_info()
            except ExcitationFault:  # unsafe to drive: still leave a zero behind on this connection
                await self._best_effort_zero()
                raise
            if err:
                self.stats.write_failures += 1
                self._note("info", err)
                self._armed = False
                return WriteResult(False, None, v, forced_zero=True, error=err)
        target = 0.0 if forced else v
        err, hb = await self._send(target)
        self.stats.writes += 1
        if err:
            self.stats.write_failures += 1
            self._note("write", err)
            self._armed = False
            return WriteResult(False, None, v, forced_zero=forced, heartbeat=hb, error=err)
        if forced:
            self.stats.forced_zero_writes += 1
            self._armed = True
            log.info("excitation link armed: zero written and read back (heartbeat %d)", hb)
        self.stats.max_abs_written_hz = max(self.stats.max_abs_written_hz, abs(target))
        return WriteResult(True, target, v, forced_zero=forced, heartbeat=hb)

    async def zero(self, deadline_s: float = 1.0) -> bool:
        """Best effort: write 0.0 (enable 0) and read it back, reconnecting if needed, for up to
        ``deadline_s`` [s]. True when the device acknowledged and holds zero. Never raises for link errors;
        on the first contact with a device that is unsafe to drive (clamp below the amplitude, heartbeat
        timeout too short) it writes the zero and then raises ExcitationFault."""
        end = time.monotonic() + deadline_s
        unsafe: ExcitationFault | None = None
        while True:
            self._next_connect = min(self._next_connect, time.monotonic())  # no backoff on the way out
            if await self._ensure_client():
                try:
                    if self._hb is None:  # first contact: device checks (an unsafe device still gets zero)
                        try:
                            await self._read_info()
                        except ExcitationFault as exc:
                            unsafe = exc
                    err, _ = await self._send(0.0)
                except ExcitationFault as exc:  # a mismatch on a zero write: report, keep trying
                    err = str(exc)
                if not err:
                    if unsafe is not None:
                        self._armed = False
                        raise unsafe
                    self._armed = True
                    return True
                self._note("zero", err)
            if time.monotonic() + 0.05 >= end:
                log.critical("excitation: could not write zero (%s); the device's heartbeat watchdog must "
                             "reset the offset", self.last_error)
                return False
            await asyncio.sleep(0.05)

    async def _best_effort_zero(self) -> None:
        with contextlib.suppress(ExcitationFault):
            err, _ = await self._send(0.0)
            if err:
                self._note("zero", err)
        self._armed = False

    async def read_measurements(self) -> Measurement | None:
        """Read the input points the guard needs; None on a link error (the link is then disarmed)."""
        if not await self._ensure_client():
            self.stats.read_failures += 1
            return None
        values: dict[str, float] = {}
        for b in self._read_blocks:
            regs, err = await self._read(b)
            if regs is None:
                self.stats.read_failures += 1
                self._note("read", err)
                self._armed = False
                return None
            values.update(decode_block(b, regs, self.map.word_order, self.map.byte_order))
        self.stats.reads += 1
        pts = self.points

        def as_int(name: str | None) -> int | None:
            if name is None:
                return None
            x = values[name]
            return int(x) if math.isfinite(x) and x == int(x) else None

        fcrd: bool | None = False
        if pts.fcrd is not None:
            x = values[pts.fcrd]
            fcrd = bool(x) if math.isfinite(x) else None
        return Measurement(
            t_mono=time.monotonic(), grid_freq_hz=values[pts.grid_freq], status_word=as_int(pts.status),
            counter=as_int(pts.counter), applied_hz=values[pts.applied] if pts.applied else None,
            fcrd_active=fcrd)

    async def read_applied(self) -> float | None:
        """The device's applied excitation [Hz] (None without an ``applied`` point or on a link error)."""
        m = await self.read_measurements() if self.points.applied else None
        return m.applied_hz if m is not None else None


def matches_any(applied_hz: float, written: Sequence[float]) -> bool:
    """``applied_hz`` equals (as float32) one of the ``written`` values."""
    return any(abs(applied_hz - _f32(w)) <= APPLIED_TOLERANCE_HZ for w in written)
