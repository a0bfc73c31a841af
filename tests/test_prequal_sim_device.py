"""The simulated governor's applied-frequency mode over real Modbus TCP: a client selects a TR test profile,
starts it and reads back the applied frequency, the governor's input and the power; refusals and the
heartbeat abort. The device is an in-process SimGovernor on a free loopback port (as in
test_sim_device_modbus.py), the client a real pymodbus AsyncModbusTcpClient."""

from __future__ import annotations

import asyncio
import logging

import numpy as np
from pymodbus.client import AsyncModbusTcpClient

from fcrlive.plant.params import preset
from fcrlive.prequal import profiles as pf
from fcrlive.sim import SimConfig, simulate
from fcrlive.sim.realtime import RealtimeSimulator
from sim_device import SimGovernor, load_map
from sim_device.device import STATUS_TEST_PROFILE
from sim_device.profiles import PROFILES, STATE_ABORTED, STATE_FINISHED, STATE_RUNNING

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

PLANT = preset("paper-plant1")
MAP = load_map()
UNIT = MAP.unit_id
IN_START, IN_COUNT = MAP.span("input")


def device(samples: list, **kw) -> SimGovernor:
    # no noise: the governor's input is then exactly the applied frequency (y = f/f0 − 1), and the plant
    # rests in its steady state until a test starts
    sim = RealtimeSimulator(PLANT, seed=5, snr_db=None, load_noise_std=0.0)
    return SimGovernor(PLANT, simulator=sim, on_sample=samples.append, **kw)


async def connect(port: int) -> AsyncModbusTcpClient:
    client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=1.0, retries=0, reconnect_delay=0)
    assert await client.connect()
    return client


async def read_block(client) -> dict:
    rr = await client.read_input_registers(IN_START, count=IN_COUNT, device_id=UNIT)
    assert not rr.isError(), rr
    return MAP.decode_block("input", IN_START, rr.registers)


async def write_test(client, profile: int, command: int, period_s: float = 40.0, options: int = 0):
    """test_profile, test_command, test_period, test_options in one FC16 write (112-117)."""
    regs = (
        MAP.encode("test_profile", profile)
        + MAP.encode("test_command", command)
        + MAP.encode("test_period", period_s)
        + MAP.encode("test_options", options)
    )
    assert MAP.point("test_options").address == MAP.point("test_profile").address + 4
    return await client.write_registers(MAP.point("test_profile").address, regs, device_id=UNIT)


async def heartbeat(client, stop: asyncio.Event, every_s: float = 0.1):
    k = 0
    addr = MAP.point("heartbeat").address
    while not stop.is_set():
        k = (k + 1) & 0xFFFF
        await client.write_register(addr, k, device_id=UNIT)
        await asyncio.sleep(every_s)


async def wait_block(client, pred, timeout: float = 10.0) -> dict:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while loop.time() < end:
        v = await read_block(client)
        if pred(v):
            return v
        await asyncio.sleep(0.02)
    raise AssertionError(f"condition not reached; last block {v}")


async def test_fcrn_step_profile_runs_over_modbus():
    """Select fcrn-steps, start it, read it back: the applied frequency follows TR Table 3 in simulated
    time, the governor's input is that frequency, and the unit's power answers the steps."""
    samples: list = []
    dev = device(samples, speed=60.0, heartbeat_timeout_s=2.0)
    async with dev:
        client = await connect(dev.port)
        stop = asyncio.Event()
        hb = asyncio.create_task(heartbeat(client, stop))
        await asyncio.sleep(0.3)
        rr = await write_test(client, 1, 1)
        assert not rr.isError(), rr
        n0 = len(samples)
        v = await wait_block(client, lambda b: b["test_time"] > 45.0)
        assert v["test_state"] == STATE_RUNNING and v["status"] & STATUS_TEST_PROFILE
        assert abs(v["applied_freq"] - 49.95) < 1e-4  # the pre-step, 30-60 s
        p_pre = v["power"]
        v = await wait_block(client, lambda b: b["test_time"] > 400.0)  # step 1: 49.9 Hz from 360 s
        assert abs(v["applied_freq"] - 49.9) < 1e-4
        assert v["power"] - p_pre > 1.0  # lower frequency: more power (droop response under way)
        hold = await client.read_holding_registers(MAP.point("test_profile").address, count=5, device_id=UNIT)
        got = MAP.decode_block("holding", MAP.point("test_profile").address, hold.registers)
        assert got == {"test_profile": 1, "test_command": 1, "test_period": 40.0, "test_options": 0}
        stop.set()
        await hb
        client.close()
    # every controller sample of the test: the governor's input y is the profile's frequency at n·dt
    prof = pf.profile(PROFILES[1])
    ys = np.array([s.y for s in samples[n0:]])
    k = np.flatnonzero(np.abs(ys - (49.95 / 50.0 - 1.0)) < 1e-12)
    assert k.size > 0
    # align: the pre-step starts at 30 s of the profile
    start = n0 + k[0] - round(30.0 / dev.dt)
    run = samples[start:]
    t = np.arange(len(run)) * dev.dt
    t = t[t < prof.duration_s]
    np.testing.assert_allclose([s.y for s in run[: t.size]], prof.frequency(t) / 50.0 - 1.0, atol=1e-12)
    np.testing.assert_allclose([s.epsilon for s in run[: t.size]], 1.0 - prof.frequency(t) / 50.0, atol=1e-12)
    # and the device's response is the offline simulation of the same test (fcrlive simulate --tso-test)
    res = simulate(
        PLANT,
        SimConfig(
            duration_s=t.size * dev.dt, applied_freq_hz=prof.frequency(t), snr_db=None, load_noise_std=0.0
        ),
    )
    np.testing.assert_allclose([s.pe_mw for s in run[: t.size]], res.pe_mw, rtol=0, atol=1e-6)


async def test_profile_ends_and_is_aborted_by_heartbeat_loss_and_stop():
    samples: list = []
    # the heartbeat's timeout is wall time: at 0.5 s a busy 2-core machine (the simulator at 50× in this
    # process, two test workers) delayed the 0.1-s heartbeat past it and aborted the sine before its end
    dev = device(samples, speed=50.0, heartbeat_timeout_s=2.0)
    async with dev:
        client = await connect(dev.port)
        # refused: no live heartbeat yet, an unknown profile, a start without a profile
        assert (await write_test(client, 1, 1)).isError()
        stop = asyncio.Event()
        hb = asyncio.create_task(heartbeat(client, stop))
        await asyncio.sleep(0.3)
        assert (await write_test(client, 99, 1)).isError()
        assert (await write_test(client, 0, 1)).isError()
        assert (await write_test(client, 9, 1, period_s=-5.0)).isError()
        assert (await read_block(client))["test_state"] == 0
        # a 10-s sine around 50.3 Hz (FCR-D down, 20 periods): runs to its end, then back to grid
        assert not (await write_test(client, 11, 1, period_s=10.0)).isError()
        v = await wait_block(client, lambda b: b["test_state"] == STATE_RUNNING and b["test_time"] > 2.0)
        assert 50.19 < v["applied_freq"] < 50.41
        v = await wait_block(client, lambda b: b["test_state"] == STATE_FINISHED)
        assert v["applied_freq"] == 0.0 and not v["status"] & STATUS_TEST_PROFILE
        # stop command
        assert not (await write_test(client, 1, 1)).isError()
        await wait_block(client, lambda b: b["test_state"] == STATE_RUNNING)
        assert not (await write_test(client, 1, 0)).isError()
        v = await wait_block(client, lambda b: b["test_state"] == STATE_ABORTED)
        # heartbeat loss: the test is aborted, the governor is back on its measured frequency
        assert not (await write_test(client, 2, 1)).isError()
        await wait_block(client, lambda b: b["test_state"] == STATE_RUNNING)
        stop.set()
        await hb
        v = await wait_block(client, lambda b: b["test_state"] == STATE_ABORTED, timeout=8.0)
        n = len(samples)
        await asyncio.sleep(0.2)
        client.close()
    # after the abort the governor's input is its own speed signal again, not 49.x Hz
    tail = samples[n:]
    assert tail and all(abs(s.y) < 0.002 for s in tail)
