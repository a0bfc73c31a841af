"""The simulated governor: a Modbus TCP (and optionally CAN) device driven by the plant simulator.

``SimGovernor`` steps a real-time simulator (``fcrlive.sim.realtime.RealtimeSimulator`` or any object with
``dt``, ``step(r)`` and ``reset()``) on absolute wall-clock deadlines, ``speed`` simulated seconds per wall
second, in batches of whole controller samples. After each batch the latest sample is written into the
input-register block in one synchronous operation, so one FC4 read of the block is one consistent snapshot.
Every sample of a batch also enters the ring buffer of controller samples (``sim_device/ringbuffer.py``,
docs/buffered-acquisition.md), whatever the speed and the machine's load.

Device-side safety, as a real governor would be configured:
- the excitation offset is clamped to ±``excitation_limit_hz``; NaN/inf writes count as 0 (and are counted);
- it is ignored while ``excitation_enable`` = 0;
- it is reset to zero when the ``heartbeat`` register has not changed for ``heartbeat_timeout_s`` seconds of
  WALL time (a safety timer is wall-clock even when the simulation runs accelerated).
The offset acts on the frequency reference: the governor's control error becomes ε = r − y with
r = offset / f0. It is applied to whole batches (one controller sample at speed 1).
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import math
import socket
import time
from collections.abc import Callable
from typing import Any

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from fcrlive.errors import ConfigError, UserError
from fcrlive.modbus.registers import RegisterMap
from sim_device.can_io import CanLink
from sim_device.faults import FaultInjector
from sim_device.profiles import HOLDING_POINTS as TEST_POINTS
from sim_device.profiles import TestProfileRunner
from sim_device.registers import load_map
from sim_device.ringbuffer import slot_values

log = logging.getLogger("sim_device")

STATUS_FCR_N_ACTIVE = 1 << 0
STATUS_NORMAL_OPERATION = 1 << 1
STATUS_EXCITATION_ACCEPTED = 1 << 2
STATUS_HEARTBEAT_OK = 1 << 3
STATUS_TEST_PROFILE = 1 << 4

HEARTBEAT_AGE_CAP_S = 1e6
NAN_POINTS = ("speed", "grid_freq", "power", "mech_power", "controller_output", "guide_vane", "control_error")
REQUIRED_POINTS = (
    "sample_counter",
    "device_time",
    "status",
    "speed",
    "grid_freq",
    "power",
    "controller_output",
    "guide_vane",
    "excitation_applied",
    "excitation_offset",
    "excitation_enable",
    "heartbeat",
)
_BIT_FUNCTIONS = {1, 2, 5, 15}


async def _no_such_unit(*_args) -> ExcCodes:
    return ExcCodes.GATEWAY_NO_RESPONSE


class PortInUseError(UserError):
    """The TCP port cannot be bound."""


def check_bindable(host: str, port: int) -> None:
    """Raise PortInUseError (one line) when ``host:port`` cannot be bound for listening."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise PortInUseError(f"cannot resolve host {host!r}: {exc.strerror}") from None
    family, _, _, _, addr = infos[0]
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(addr)
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise PortInUseError(f"port {port} on {host} is already in use") from None
            raise PortInUseError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None


class SimGovernor:
    """A simulated hydro governor serving Modbus TCP (and CAN). Async context manager.

    ``plant`` is a :class:`fcrlive.plant.params.Plant` (the simulator is built from it), or pass
    ``simulator=`` any object with ``dt``, ``step(r) -> sample`` and ``reset()``; ``plant`` then only feeds
    :meth:`truth` and the nameplate registers.
    """

    def __init__(
        self,
        plant: Any = None,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        speed: float = 1.0,
        seed: int = 0,
        snr_db: float = 12.0,
        word_order: str = "big",
        unit_id: int | None = None,
        excitation_limit_hz: float = 0.1,
        heartbeat_timeout_s: float = 2.0,
        can_channel: str | None = None,
        can_interface: str = "virtual",
        can_kwargs: dict | None = None,
        register_map: RegisterMap | None = None,
        simulator: Any = None,
        min_tick_s: float = 0.01,
        max_lag_s: float = 0.5,
        on_sample: Callable[[Any], None] | None = None,
        sim_kwargs: dict | None = None,
        buffer_slots: int | None = None,
        buffer_counter_start: int = 0,
    ):
        if not (isinstance(speed, int | float) and math.isfinite(speed) and speed > 0):
            raise ConfigError(f"speed must be a positive number, not {speed!r}")
        if not (math.isfinite(excitation_limit_hz) and excitation_limit_hz >= 0):
            raise ConfigError(f"excitation limit must be >= 0 Hz, not {excitation_limit_hz!r}")
        if not (math.isfinite(heartbeat_timeout_s) and heartbeat_timeout_s > 0):
            raise ConfigError(f"heartbeat timeout must be > 0 s, not {heartbeat_timeout_s!r}")
        if not 0 <= int(port) <= 65535:
            raise ConfigError(f"port must be 0..65535, not {port!r}")
        if plant is None and simulator is None:
            from fcrlive.plant.params import preset

            plant = preset("paper-plant1")
        self.plant = plant
        self.host = host
        self.port = int(port)
        self.speed = float(speed)
        self.seed = seed
        self.snr_db = snr_db
        self.excitation_limit_hz = float(excitation_limit_hz)
        self.heartbeat_timeout_s = float(heartbeat_timeout_s)
        rmap = register_map or load_map()
        rmap = rmap.with_word_order(word_order)  # type: ignore[arg-type]
        if unit_id is not None:
            if not 0 <= unit_id <= 247:
                raise ConfigError(f"unit id must be 0..247, not {unit_id}")
            from dataclasses import replace

            rmap = replace(rmap, unit_id=unit_id)
        missing = [n for n in REQUIRED_POINTS if n not in rmap]
        if missing:
            raise ConfigError(f"register map lacks point(s) {', '.join(missing)}")
        self.register_map: RegisterMap = rmap
        self._sim = simulator if simulator is not None else self._make_simulator(sim_kwargs or {})
        self.dt = float(self._sim.dt)
        self.f0 = float(plant.grid.f0) if plant is not None else 50.0
        self.rated_mw = float(plant.unit.rated_mw) if plant is not None else float("nan")
        self.min_tick_s = float(min_tick_s)
        self.max_lag_s = float(max_lag_s)
        self.on_sample = on_sample
        self.faults = FaultInjector(self)
        self.can_channel = can_channel
        self.can_interface = can_interface
        self.can_kwargs = dict(can_kwargs or {})
        self.can: CanLink | None = None
        self.ring = self._make_ring(buffer_slots, buffer_counter_start)

        self._server: ModbusTcpServer | None = None
        self._clock_task: asyncio.Task | None = None
        self._internal = False
        self._running = False
        self._reset_state()
        # counters that survive a restart (not device state: test/benchmark instrumentation)
        self.requests = 0
        self.slips = 0
        self.error: BaseException | None = None

    # ------------------------------------------------------------------ construction helpers
    def _make_simulator(self, kwargs: dict) -> Any:
        try:
            from fcrlive.sim.realtime import RealtimeSimulator
        except ImportError as exc:
            raise UserError(f"the plant simulator is not available: {exc}") from None

        return RealtimeSimulator(self.plant, seed=self.seed, snr_db=self.snr_db, **kwargs)

    def _make_ring(self, slots: int | None, counter_start: int):
        """The ring buffer of every controller sample, when the map has a ``[buffer]`` (ringbuffer.py)."""
        layout = self.register_map.buffer
        if layout is None:
            return None
        from sim_device.ringbuffer import SLOT_FIELDS, RingBuffer, slots_for

        unknown = [f for f in layout.fields if f not in SLOT_FIELDS]
        if unknown:
            raise ConfigError(f"buffer fields {', '.join(unknown)}: the simulator has only "
                              f"{', '.join(SLOT_FIELDS)}")

        n = slots if slots is not None else slots_for(self.speed, self.dt, layout.slots)
        try:
            layout = layout.with_slots(int(n))
        except ValueError as exc:
            raise ConfigError(f"buffer: {exc}") from None
        return RingBuffer(layout, self.dt, self.register_map.word_order, counter_start,
                          on_sample=self._can_sample)

    def _can_sample(self, counter: int, values: tuple[float, ...]) -> None:
        if self.can is not None:
            self.can.send_sample(counter, self.ring.layout.fields, values)

    def _reset_state(self) -> None:
        self.sample_counter = 0
        self.last_sample: Any = None
        self._offset_hz = 0.0
        self._enable = False
        self._hb_value = 0
        self._hb_last: float | None = None
        self.nonfinite_writes = 0
        self.clamped_writes = 0
        self.heartbeat_timeouts = 0
        self._applied_hz = 0.0
        self._published: dict[str, float] | None = None
        # TR test profiles in the applied-frequency mode (sim_device/profiles.py)
        self.test_profile = TestProfileRunner(self.dt, self.f0)

    def _build_simdevice(self) -> list[SimDevice]:
        m = self.register_map
        nameplate = {
            "excitation_limit": self.excitation_limit_hz,
            "heartbeat_timeout": self.heartbeat_timeout_s,
            "rated_power": self.rated_mw,
            "nominal_freq": self.f0,
            "test_period": self.test_profile.period_s,
        }
        holding = [
            SimData(
                address=p.address,
                values=m.encode(p, nameplate.get(p.name, 0)),
                datatype=DataType.REGISTERS,
                readonly=not p.writable,
            )
            for p in m.table("holding")
        ]
        inputs = [
            SimData(address=p.address, values=m.encode(p, 0), datatype=DataType.REGISTERS)
            for p in m.table("input")
        ]
        if self.ring is not None:
            lo, count = self.ring.span()
            inputs.append(SimData(address=lo, count=count, values=0, datatype=DataType.REGISTERS))
        # pymodbus needs a non-empty coil and discrete-input block in non-shared mode; the action
        # hook refuses every bit function (ILLEGAL_FUNCTION): this device has no coils.
        bits = [SimData(address=0, values=[False] * 16, datatype=DataType.BITS)]
        devices = [SimDevice(id=m.unit_id, simdata=(bits, list(bits), holding, inputs), action=self._action)]
        if m.unit_id != 0:
            # Any other unit id: answered with exception 11 (gateway target failed to respond), as a
            # Modbus TCP gateway with nothing behind that id would (pymodbus: id 0 = "all other ids").
            whole = [SimData(address=0, count=65536, values=0, datatype=DataType.REGISTERS)]
            other = SimDevice(id=0, simdata=(bits, list(bits), whole, list(whole)), action=_no_such_unit)
            devices.append(other)
        return devices

    # ------------------------------------------------------------------ lifecycle
    async def __aenter__(self) -> SimGovernor:
        await self.start()
        return self

    async def __aexit__(self, *exc_info) -> None:
        await self.stop()

    async def start(self) -> None:
        """Bind, publish the first sample, start the clock (and CAN)."""
        if self._running:
            return
        loop = asyncio.get_running_loop()
        await self._start_server()
        if self.can_channel:
            self.can = CanLink(
                self.can_channel, self.can_interface, on_command=self._can_command, bus_kwargs=self.can_kwargs
            )
            try:
                self.can.open(loop)
            except BaseException:
                await self._stop_server()
                raise
        self._running = True
        await self._first_sample()
        self._clock_task = asyncio.create_task(self._clock(), name="sim_device clock")

    async def stop(self) -> None:
        self._running = False
        await self._stop_clock()
        await self._stop_server()
        if self.can is not None:
            self.can.close()
            self.can = None

    async def _start_server(self) -> None:
        check_bindable(self.host, self.port)
        server = ModbusTcpServer(
            self._build_simdevice(),
            address=(self.host, self.port),
            trace_pdu=self._trace_pdu,
        )
        try:
            await server.serve_forever(background=True)
        except RuntimeError:
            raise PortInUseError(f"cannot listen on {self.host}:{self.port}") from None
        self._server = server
        if self.ring is not None:
            start, _count, regs, _flags = server.context.devices[self.register_map.unit_id].block["i"]
            self.ring.attach(regs, start)
        sockets = getattr(server.transport, "sockets", None) or []
        if sockets:
            self.port = sockets[0].getsockname()[1]
        log.info("Modbus TCP listening on %s:%d (unit %d)", self.host, self.port, self.register_map.unit_id)

    async def _stop_server(self) -> None:
        if self._server is not None:
            server, self._server = self._server, None
            await server.shutdown()

    async def _stop_clock(self) -> None:
        if self._clock_task is not None:
            task, self._clock_task = self._clock_task, None
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    async def _first_sample(self) -> None:
        self._advance(1)
        await self._publish()

    async def _restart(self, downtime_s: float) -> None:
        log.info("restart: closing, down for %.3f s", downtime_s)
        await self._stop_clock()
        await self._stop_server()
        self._sim.reset()
        self._reset_state()
        if self.ring is not None:
            self.ring.reset()
        await asyncio.sleep(max(0.0, downtime_s))
        await self._start_server()
        if self._running:
            await self._first_sample()
            self._clock_task = asyncio.create_task(self._clock(), name="sim_device clock")
        log.info("restart: back on %s:%d", self.host, self.port)

    # ------------------------------------------------------------------ clock
    async def _clock(self) -> None:
        """Step the plant on absolute deadlines: a batch of ``tick_steps`` samples every ≥ min_tick_s.

        Behind schedule it catches up in chunks of at most 4 ticks, serving requests in between; more
        than ``max_lag_s`` behind (CPU starved) it drops the backlog and re-anchors (a "slip", counted
        in ``slips`` and logged): the device clock then runs slow, visibly in device_time.
        """
        loop = asyncio.get_running_loop()
        period = self.dt / self.speed  # wall seconds per controller sample
        tick_steps = max(1, math.ceil(self.min_tick_s / period - 1e-9))
        chunk = 4 * tick_steps
        lag_steps = max(chunk, int(self.max_lag_s / period))
        anchor, base = loop.time(), self.sample_counter
        try:
            while True:
                due = base + int((loop.time() - anchor) / period)
                n = due - self.sample_counter
                if n > lag_steps:
                    self.slips += 1
                    if self.slips in (1, 10) or self.slips % 100 == 0:
                        log.warning(
                            "simulation more than %.2f s behind the wall clock: slipped (%d so far)",
                            self.max_lag_s,
                            self.slips,
                        )
                    anchor, base = loop.time() - tick_steps * period, self.sample_counter
                    n, due = tick_steps, base + tick_steps
                n = min(n, chunk)
                if n > 0:
                    self._advance(n)
                self._safety_check()
                if n > 0 or self._published is None:
                    await self._publish()
                if due > self.sample_counter:
                    # Still behind: give pending requests a moment (pymodbus answers a request over a
                    # few loop iterations; sleep(0) would let the next chunk run after each of them).
                    await asyncio.sleep(0.002)
                    continue
                next_due = base + ((self.sample_counter - base) // tick_steps + 1) * tick_steps
                await asyncio.sleep(max(0.0, anchor + (next_due - base) * period - loop.time()))
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # keep serving the last snapshot; make the failure visible
            self.error = exc
            log.exception("simulation stopped")

    def _advance(self, n: int) -> None:
        """Run n controller samples with the excitation applied now."""
        self._applied_hz = self._applied_offset()
        r = self._applied_hz / self.f0
        step = self._sim.step
        cb = self.on_sample
        tp = self.test_profile
        ring = self.ring
        if ring is not None and self.faults.state.freeze:  # the controller counts on, the ring stands still
            ring.skip(n)
            ring = None
        if ring is not None:
            values = slot_values(ring.layout.fields, frozenset(NAN_POINTS) if self.faults.state.nan else
                                 frozenset())
        applied = self._applied_hz
        s = None
        for _ in range(n):
            app = tp.next_applied_hz() if tp.active else None
            s = step(r) if app is None else step(r, applied_hz=app)
            if cb is not None:
                cb(s)
            if ring is not None:  # every controller sample, not only the last of the batch
                ring.push(values(s, applied))
        if ring is not None:
            ring.commit()
        self.sample_counter += n
        self.last_sample = s

    # ------------------------------------------------------------------ safety
    def heartbeat_ok(self, now: float | None = None) -> bool:
        if self._hb_last is None:
            return False
        return ((now if now is not None else time.monotonic()) - self._hb_last) <= self.heartbeat_timeout_s

    def _applied_offset(self) -> float:
        return self._offset_hz if (self._enable and self.heartbeat_ok()) else 0.0

    def _safety_check(self) -> None:
        self.test_profile.check_heartbeat(self.heartbeat_ok())
        if self._offset_hz != 0.0 and not self.heartbeat_ok():
            log.warning("heartbeat lost for > %.3f s: excitation offset reset to 0", self.heartbeat_timeout_s)
            self._offset_hz = 0.0
            self.heartbeat_timeouts += 1
            self._write_holding({"excitation_offset": 0.0})

    def _command(
        self, offset_hz: float | None = None, enable: int | None = None, heartbeat: int | None = None
    ) -> float | None:
        """Apply one command (Modbus write or CAN frame); returns the accepted offset if one was given."""
        if heartbeat is not None and heartbeat != self._hb_value:
            self._hb_value = heartbeat
            self._hb_last = time.monotonic()
        if enable is not None:
            self._enable = bool(enable)
        if offset_hz is None:
            return None
        if not math.isfinite(offset_hz):
            self.nonfinite_writes += 1
            offset_hz = 0.0
        if abs(offset_hz) > self.excitation_limit_hz:
            self.clamped_writes += 1
            offset_hz = math.copysign(self.excitation_limit_hz, offset_hz)
        self._offset_hz = float(offset_hz)
        return self._offset_hz

    def _can_command(self, offset_hz: float, enable: int, heartbeat: int) -> None:
        accepted = self._command(offset_hz, 1 if enable else 0, heartbeat & 0xFFFF)
        self._write_holding(
            {"excitation_offset": accepted, "excitation_enable": self._enable, "heartbeat": self._hb_value}
        )

    # ------------------------------------------------------------------ registers
    def snapshot_values(self) -> dict[str, float]:
        """Engineering values of the current sample, keyed by point name (what is published)."""
        s = self.last_sample
        now = time.monotonic()
        hb_ok = self.heartbeat_ok(now)
        status = STATUS_FCR_N_ACTIVE | STATUS_NORMAL_OPERATION
        if hb_ok:
            status |= STATUS_HEARTBEAT_OK
            if self._enable:
                status |= STATUS_EXCITATION_ACCEPTED
        age = HEARTBEAT_AGE_CAP_S if self._hb_last is None else min(now - self._hb_last, HEARTBEAT_AGE_CAP_S)
        n = self.sample_counter - 1  # index of the published sample: 0 = the first after (re)start
        if self.test_profile.active:
            status |= STATUS_TEST_PROFILE
        v = {
            **self.test_profile.values(),
            "sample_counter": n & 0xFFFFFFFF,
            "device_time": n * self.dt,
            "status": status,
            "nonfinite_writes": self.nonfinite_writes & 0xFFFF,
            "clamped_writes": self.clamped_writes & 0xFFFF,
            "heartbeat_age": age,
            "speed": s.speed_pu,
            "grid_freq": s.grid_freq_hz,
            "power": s.pe_mw,
            "mech_power": s.pm_mw,
            "controller_output": 100.0 * s.c,
            "guide_vane": 100.0 * s.a,
            "excitation_applied": self._applied_hz,
            "control_error": s.epsilon,
        }
        if self.faults.state.nan:
            for name in NAN_POINTS:
                v[name] = math.nan
        return v

    async def _publish(self) -> None:
        if self.last_sample is None or self._server is None:
            return
        if self.faults.state.freeze and self._published is not None:
            values = self._published
        else:
            values = self.snapshot_values()
            m = self.register_map
            start, regs = m.encode_block("input", values)
            self._internal = True
            try:  # no suspension point inside: atomic with respect to client requests
                await self._server.async_setValues(m.unit_id, 4, start, regs)
            finally:
                self._internal = False
            self._published = values
        if self.can is not None:
            self.can.send_snapshot(values)

    def _write_holding(self, values: dict[str, float | None]) -> None:
        """Internal update of holding registers (safety resets, CAN commands): synchronous."""
        if self._server is None:
            return
        m = self.register_map
        block = self._holding_block()
        if block is None:
            return
        start, regs = block
        for name, val in values.items():
            if val is None or name not in m:
                continue
            p = m.point(name)
            regs[p.address - start : p.end - start] = m.encode(p, float(val))

    def _holding_block(self) -> tuple[int, list[int]] | None:
        # The runtime register list of the holding table (pymodbus 3.16 SimRuntime: block "h" =
        # (start, count, registers, flags)). Written in place: synchronous, so atomic for clients.
        try:
            runtime = self._server.context.devices[self.register_map.unit_id]  # type: ignore[union-attr]
            start, _count, regs, _flags = runtime.block["h"]
        except (AttributeError, KeyError):  # pragma: no cover - pymodbus internals changed
            log.error("cannot reach the holding registers of the pymodbus datastore")
            return None
        return start, regs

    async def read_points(self, table: str = "input") -> dict[str, float | int]:
        """Decode the device's own registers (for tests and the CLI), as a client would read them."""
        m = self.register_map
        start, count = m.span(table)  # type: ignore[arg-type]
        fc = 4 if table == "input" else 3
        self._internal = True
        try:
            regs = await self._server.context.async_getValues(m.unit_id, fc, start, count)  # type: ignore
        finally:
            self._internal = False
        return m.decode_block(table, start, list(regs))  # type: ignore[arg-type]

    # ------------------------------------------------------------------ pymodbus hooks
    def _trace_pdu(self, sending: bool, pdu):
        if not sending and self.faults.state.hang:
            return None  # swallowed: the request is never answered
        return pdu

    async def _action(
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        current_registers: list[int],
        set_values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        if self._internal or (function_code == 4 and set_values is not None):
            return None  # our own publish / read-back
        self.requests += 1
        st = self.faults.state
        if st.delay_ms > 0:
            await asyncio.sleep(st.delay_ms / 1000.0)
        if st.exception is not None:
            return st.exception
        if function_code in _BIT_FUNCTIONS:
            return ExcCodes.ILLEGAL_FUNCTION
        if set_values is None:
            return None
        return self._modbus_write(address, set_values)  # type: ignore[arg-type]

    def _modbus_write(self, address: int, values: list[int]) -> ExcCodes | None:
        m = self.register_map
        end = address + len(values)
        touched = [p for p in m.table("holding") if p.address < end and p.end > address]
        for p in touched:
            if not p.writable or p.address < address or p.end > end:
                return ExcCodes.ILLEGAL_ADDRESS  # read-only point, or only part of a multi-register point
        new = {p.name: m.decode(p, values[p.address - address : p.end - address]) for p in touched}
        if any(k in new for k in TEST_POINTS):
            refused = self.test_profile.write(new, self.heartbeat_ok())
            if refused is not None:
                return refused
        enable = new.get("excitation_enable")
        if enable is not None and enable not in (0, 1):
            return ExcCodes.ILLEGAL_VALUE
        accepted = self._command(new.get("excitation_offset"), enable, new.get("heartbeat"))
        if accepted is not None:  # the register holds the accepted (clamped, NaN -> 0) value
            p = m.point("excitation_offset")
            values[p.address - address : p.end - address] = m.encode(p, accepted)
        return None

    # ------------------------------------------------------------------ faults
    def _on_faults_changed(self) -> None:
        log.info("faults now: %s", self.faults.as_dict())

    def _drop_connections(self) -> int:
        if self._server is None:
            return 0
        conns = list(self._server.active_connections.values())
        for c in conns:
            transport = getattr(c, "transport", None)
            if transport is not None:
                transport.abort()
        log.info("dropped %d connection(s)", len(conns))
        return len(conns)

    @property
    def connections(self) -> int:
        return 0 if self._server is None else len(self._server.active_connections)

    # ------------------------------------------------------------------ truth
    def truth(self, analytic: bool = False) -> dict[str, Any]:
        """What the identification should find, from the plant parameters (for tests and the demo).

        ``analytic=True`` adds the peaks of the analytic S and G_1 (continuous time, from
        :func:`fcrlive.plant.transfer.analytic`; imports python-control, about a second the first time).
        """
        t: dict[str, Any] = {
            "dt": self.dt,
            "speed": self.speed,
            "f0": self.f0,
            "rated_mw": self.rated_mw,
            "excitation_limit_hz": self.excitation_limit_hz,
            "heartbeat_timeout_s": self.heartbeat_timeout_s,
        }
        p = self.plant
        if p is None:
            return t
        u = p.unit
        rho = u.governor.droop
        t.update(
            droop=rho,
            H=u.swing.H,
            Kd=u.swing.Kd,
            Pm0=u.turbine.Pm0,
            At=u.turbine.At,
            droop_placement=u.governor.droop_placement,
            droop_signal=u.governor.droop_signal,
            # any governor with integral action: G_1(0) = 1/(Kd + At/ρ) (plant-model.md)
            g1_static=1.0 / (u.swing.Kd + u.turbine.At / rho),
            # steady state: ΔPm = At·(Δr − Δy)/ρ·rated, i.e. MW per Hz of (offset − Δf)
            static_mw_per_hz=u.turbine.At * self.rated_mw / (self.f0 * rho),
        )
        if analytic:
            try:
                from fcrlive.plant import transfer
            except ImportError:  # pragma: no cover - only if the analytic module is missing
                return t
            tfs = transfer.analytic(p)
            s_pk, g1_pk = transfer.peak(tfs.S), transfer.peak(tfs.G_1)
            t.update(
                g1_static=transfer.static_gain(tfs.G_1),
                max_S=s_pk.value,
                max_S_omega_rad_s=s_pk.omega_rad_s,
                max_G1=g1_pk.value,
                max_G1_omega_rad_s=g1_pk.omega_rad_s,
            )
        return t
