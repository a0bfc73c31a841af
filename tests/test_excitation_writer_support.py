"""Helpers for the excitation tests: a simulated governor that logs every command it accepts, a grid-event
wrapper around the plant simulator, and polling of the device's ``excitation_applied`` input register."""

from __future__ import annotations

import asyncio
import time
from dataclasses import replace
from pathlib import Path

from fcrlive.excitation import GuardLimits, SafetyGuard, WhiteNoiseGenerator
from fcrlive.excitation.task import ExcitationTask
from fcrlive.excitation.writer import ExcitationWriter
from fcrlive.modbus.client import ModbusParams
from fcrlive.modbus.mapfile import load_register_map
from sim_device import SimGovernor

ROOT = Path(__file__).resolve().parents[1]
MAP_PATH = ROOT / "sim_device" / "registers.toml"
RMAP = load_register_map(MAP_PATH)
HEARTBEAT_TIMEOUT_S = 1.0
PERIOD_S = 0.05


class LoggedGovernor(SimGovernor):
    """SimGovernor that records every excitation command it receives (Modbus writes go through
    ``_command``): ``commands`` = [(monotonic time, offset_hz or None, enable or None, heartbeat or None)]."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self.commands: list[tuple[float, float | None, int | None, int | None]] = []

    def _command(self, offset_hz=None, enable=None, heartbeat=None):
        accepted = super()._command(offset_hz, enable, heartbeat)
        self.commands.append((time.monotonic(), offset_hz, enable, heartbeat))
        return accepted

    def commands_after(self, t: float):
        return [c for c in self.commands if c[0] > t]


class GridEventSimulator:
    """The plant simulator with a settable grid event: ``event_hz`` is added to the grid frequency the
    device reports (what the unit's frequency meter would see after a large generation trip elsewhere)."""

    def __init__(self, plant=None, seed: int = 0):
        from fcrlive.plant.params import preset
        from fcrlive.sim.realtime import RealtimeSimulator

        self.inner = RealtimeSimulator(plant or preset("paper-plant1"), seed=seed)
        self.dt = self.inner.dt
        self.event_hz = 0.0

    def reset(self) -> None:
        self.inner.reset()

    def step(self, r: float):
        s = self.inner.step(r)
        return replace(s, grid_freq_hz=s.grid_freq_hz + self.event_hz) if self.event_hz else s


def governor(**kw) -> LoggedGovernor:
    kw = {"speed": 1.0, "heartbeat_timeout_s": HEARTBEAT_TIMEOUT_S, **kw}
    return LoggedGovernor(**kw)


def make_task(port: int, *, holdoff_s: float = 1.0, seed: int = 1, period_s: float = PERIOD_S,
              amplitude_hz: float = 0.1, points=None, limits: dict | None = None, **kw) -> ExcitationTask:
    params = ModbusParams("127.0.0.1", port, RMAP, timeout_s=0.2, backoff_max_s=0.5)
    writer = ExcitationWriter(params, max_abs_hz=amplitude_hz, write_period_s=period_s, points=points)
    guard = SafetyGuard(GuardLimits(amplitude_hz=amplitude_hz, holdoff_s=holdoff_s, **(limits or {})))
    gen = WhiteNoiseGenerator(amplitude_hz=amplitude_hz, sample_time_s=period_s, seed=seed)
    return ExcitationTask(writer, guard, gen, period_s=period_s, **kw)


async def applied(dev: SimGovernor) -> float:
    """The device's ``excitation_applied`` input register [Hz], as a client reads it."""
    return (await dev.read_points("input"))["excitation_applied"]


async def wait_applied(dev: SimGovernor, pred, timeout_s: float, poll_s: float = 0.005) -> float:
    """Poll ``excitation_applied`` until ``pred(value)``; returns the time it took [s] (TimeoutError)."""
    t0 = time.monotonic()
    while True:
        v = await applied(dev)
        if pred(v):
            return time.monotonic() - t0
        if time.monotonic() - t0 > timeout_s:
            raise TimeoutError(f"excitation_applied still {v!r} after {timeout_s} s")
        await asyncio.sleep(poll_s)


async def wait_active(dev: SimGovernor, timeout_s: float = 5.0) -> None:
    """Until the device applies a non-zero excitation."""
    await wait_applied(dev, lambda v: v != 0.0, timeout_s)


async def wait_zero(dev: SimGovernor, timeout_s: float = HEARTBEAT_TIMEOUT_S) -> float:
    """Time until the device applies exactly zero [s]; fails beyond the heartbeat timeout."""
    return await wait_applied(dev, lambda v: v == 0.0, timeout_s)


async def stays_zero(dev: SimGovernor, seconds: float) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if await applied(dev) != 0.0:
            return False
        await asyncio.sleep(0.01)
    return True
