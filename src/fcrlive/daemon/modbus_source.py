"""Modbus TCP source: polls a typed register map on absolute deadlines and yields :class:`Sample`.

Only moves data and schedules work; decoding and quality are the pure functions of
:mod:`fcrlive.modbus.registers` and :mod:`fcrlive.daemon.sample`; the parameters are
:class:`fcrlive.modbus.client.ModbusParams`, the tick schedule :func:`fcrlive.daemon.pacing.paced_ticks`.

Robustness, following what Telegraf / Home Assistant users complain about (libraries.md):

* our own connect loop with bounded exponential backoff (pymodbus never retries a failed first
  ``connect()``), running in the background so ticks keep coming as COMM_ERROR samples;
* short request timeout, 0-1 retries, no ``asyncio.wait_for`` around pymodbus calls;
* a watchdog that throws the client away and builds a new one after ``watchdog_failures``
  consecutive failed polls (a half-open TCP connection otherwise never recovers);
* pymodbus's per-timeout ERROR log lines are silenced; we log state changes once.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import AsyncIterator

from fcrlive.backoff import backoff_delays
from fcrlive.daemon.pacing import SourceStats, paced_ticks
from fcrlive.daemon.sample import (
    COUNTER_NAME,
    DEVICE_TIME_NAME,
    Quality,
    Sample,
    classify,
    empty_values,
)
from fcrlive.modbus.client import ModbusParams, quiet_pymodbus
from fcrlive.modbus.registers import decode_block, encode_point, plan_reads

log = logging.getLogger("fcrlive.modbus")


class ModbusSource:
    """Async context manager polling a Modbus TCP device.

    ``async with ModbusSource(params) as src: async for s in src.samples(): ...`` yields one
    sample per tick at ``poll_hz``. ``await src.write(name, value)`` writes a holding point.
    """

    def __init__(self, params: ModbusParams):
        quiet_pymodbus()
        self.p = params
        self.map = params.register_map
        sampled = [p for p in self.map.points if p.table in params.sample_tables]
        if not sampled:
            raise ValueError(f"register map has no points in tables {params.sample_tables}")
        self.names = tuple(p.name for p in sampled)
        self.read_blocks = plan_reads(sampled)
        self.stats = SourceStats()
        self._client = None
        self._connected = asyncio.Event()
        self._need_connect = asyncio.Event()
        self._connector: asyncio.Task | None = None
        self._fails = 0
        self._prev_counter: float | None = None

    async def __aenter__(self) -> ModbusSource:
        self._need_connect.set()
        self._connector = asyncio.create_task(self._connect_loop(), name="modbus-connect")
        return self

    async def __aexit__(self, *exc) -> None:
        if self._connector:
            self._connector.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._connector
        self._drop_client("closing")

    # -- connection -------------------------------------------------------------------------------

    def _drop_client(self, why: str) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None
            if self.stats.connected:
                log.log(logging.INFO if why == "closing" else logging.WARNING,
                        "modbus disconnected host=%s port=%d reason=%s", self.p.host, self.p.port, why)
        self.stats.connected = False
        self._connected.clear()

    async def _connect_loop(self) -> None:
        from pymodbus.client import AsyncModbusTcpClient

        delays = backoff_delays(self.p.backoff_min_s, self.p.backoff_max_s)
        while True:
            await self._need_connect.wait()
            # reconnect_delay=0: pymodbus must not reconnect behind our back; we own the loop
            client = AsyncModbusTcpClient(self.p.host, port=self.p.port, timeout=self.p.timeout_s,
                                          retries=self.p.retries, reconnect_delay=0, reconnect_delay_max=0)
            ok = False
            try:
                ok = await client.connect() and client.connected
            except OSError:
                ok = False
            if ok:
                self._client = client
                self._fails = 0
                self.stats.connects += 1
                self.stats.connected = True
                self._need_connect.clear()
                self._connected.set()
                delays = backoff_delays(self.p.backoff_min_s, self.p.backoff_max_s)
                log.info("modbus connected host=%s port=%d connects=%d", self.p.host, self.p.port,
                         self.stats.connects)
                continue
            client.close()
            self.stats.connect_failures += 1
            if self.stats.connect_failures in (1, 10) or self.stats.connect_failures % 100 == 0:
                log.warning("modbus connect failed host=%s port=%d failures=%d", self.p.host, self.p.port,
                            self.stats.connect_failures)
            await asyncio.sleep(next(delays))

    async def wait_connected(self, timeout: float | None = None) -> None:
        """Wait until the client is connected (TimeoutError after ``timeout`` s)."""
        await asyncio.wait_for(self._connected.wait(), timeout)

    # -- polling ----------------------------------------------------------------------------------

    async def _read_once(self, blocks=None) -> tuple[dict[str, float] | None, str]:
        """Read every block once; ``(values, "")`` or ``(None, reason)`` on a communication error."""
        from pymodbus.exceptions import ModbusException

        client = self._client
        if client is None or not client.connected:
            return None, "not connected"
        values: dict[str, float] = {}
        for b in self.read_blocks if blocks is None else blocks:
            fn = client.read_input_registers if b.table == "input" else client.read_holding_registers
            try:
                rr = await fn(b.address, count=b.count, device_id=self.map.unit_id)
            except (TimeoutError, ModbusException, OSError) as exc:
                return None, f"{type(exc).__name__}: {exc}"
            if rr.isError():
                return None, f"exception response {rr}"
            values.update(decode_block(b, rr.registers, self.map.word_order, self.map.byte_order))
        return values, ""

    def _after_failure(self, reason: str) -> None:
        self._fails += 1
        client = self._client
        if client is not None and (not client.connected or self._fails >= self.p.watchdog_failures):
            if client.connected:
                self.stats.watchdog_resets += 1
                log.warning("modbus watchdog: %d failed polls in a row, recreating the client reason=%s",
                            self._fails, reason)
            self._drop_client(reason)
            self._fails = 0
        if self._client is None:
            self._need_connect.set()

    async def samples(self) -> AsyncIterator[Sample]:
        """One sample per tick at ``poll_hz``, forever (cancel or break to stop)."""
        loop = asyncio.get_running_loop()
        async for idx in paced_ticks(self.p.poll_hz, self.stats, self.names):
            if isinstance(idx, Sample):
                yield idx
                continue
            t_req = loop.time()
            values, reason = await self._read_once()
            t_wall = time.time()
            self.stats.polls += 1
            if values is None:
                self._after_failure(reason)
                q = Quality.COMM_ERROR
                sample = Sample(t_wall, math.nan, idx, empty_values(self.names), q, detail=reason)
            else:
                self._fails = 0
                q = classify(values, self._prev_counter)
                self._prev_counter = values.get(COUNTER_NAME, self._prev_counter)
                sample = Sample(t_wall, values.get(DEVICE_TIME_NAME, math.nan), idx, values, q,
                                latency_s=loop.time() - t_req)
            self.stats.samples[q] += 1
            yield sample

    async def read_points(self, table: str = "holding") -> dict[str, float]:
        """Read every point of ``table`` once (engineering values); ConnectionError on failure."""
        values, reason = await self._read_once(plan_reads([p for p in self.map.points if p.table == table]))
        if values is None:
            raise ConnectionError(reason)
        return values

    # -- writing ----------------------------------------------------------------------------------

    async def write(self, name: str, value: float) -> None:
        """Write engineering ``value`` to the writable holding point ``name`` (FC6 or FC16).

        Raises KeyError for an unknown point, ValueError for a read-only one, ConnectionError when
        not connected or the device refuses.
        """
        from pymodbus.exceptions import ModbusException

        point = self.map.point(name)
        if not point.writable or point.table != "holding":
            raise ValueError(f"point {name!r} is not a writable holding register")
        client = self._client
        if client is None or not client.connected:
            raise ConnectionError("modbus not connected")
        regs = encode_point(point, value, self.map.word_order, self.map.byte_order)
        try:
            if len(regs) == 1:
                rr = await client.write_register(point.address, regs[0], device_id=self.map.unit_id)
            else:  # multi-register values must be written atomically with FC16
                rr = await client.write_registers(point.address, regs, device_id=self.map.unit_id)
        except (ModbusException, OSError) as exc:
            raise ConnectionError(f"write {name}: {exc}") from exc
        if rr.isError():
            raise ConnectionError(f"write {name}: exception response {rr}")
