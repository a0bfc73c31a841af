"""Modbus source against a real loopback server: rate, quality flags, reconnect, watchdog, missed ticks."""

from __future__ import annotations

import itertools
import math
import statistics
import time
from pathlib import Path

import pytest

from fcrlive.daemon.modbus_source import ModbusSource
from fcrlive.daemon.sample import Quality
from fcrlive.modbus.client import ModbusParams
from fcrlive.modbus.mapfile import load_register_map
from fcrlive.modbus.registers import RegisterMap, RegisterPoint
from testsupport.modbus_server import RegisterServer

ROOT = Path(__file__).resolve().parents[1]

RMAP = RegisterMap(
    points=(RegisterPoint("sample_counter", "input", 0, "uint32"),
            RegisterPoint("device_time", "input", 2, "float64", unit="s"),
            RegisterPoint("power", "input", 6, "float32", unit="MW"),
            RegisterPoint("grid_freq", "input", 8, "int16", scale=0.001, offset=50.0, unit="Hz"),
            RegisterPoint("excitation_offset", "holding", 100, "float32", unit="Hz", writable=True)),
    unit_id=2, word_order="little", byte_order="little")


def _params(port, **kw):
    kw = {"poll_hz": 50.0, "timeout_s": 0.1, "backoff_max_s": 0.5, **kw}
    return ModbusParams("127.0.0.1", port, RMAP, **kw)


async def test_rate_values_and_quality_flags():
    async with RegisterServer(RMAP) as srv:
        await srv.set({"sample_counter": 1, "device_time": 0.02, "power": 81.25, "grid_freq": 49.987})
        got = []
        async with ModbusSource(_params(srv.port)) as src:
            await src.wait_connected(5)
            async for s in src.samples():
                got.append(s)
                n = len(got)
                if n % 2 == 0 and n < 60:  # the device produces a new value every other tick
                    await srv.set({"sample_counter": n, "device_time": n * 0.02})
                if n == 60:
                    await srv.set({"power": math.nan})
                if n == 70:
                    break
            await src.write("excitation_offset", 0.05)
            assert (await src.read_points("holding"))["excitation_offset"] == pytest.approx(0.05)
            with pytest.raises(ValueError):
                await src.write("power", 1.0)
    assert [s.seq for s in got] == list(range(70))
    ok = [s for s in got if s.quality == Quality.OK]
    assert ok[0].values["power"] == 81.25 and ok[0].values["grid_freq"] == pytest.approx(49.987)
    assert not math.isnan(ok[-1].t_device)
    q = [s.quality for s in got[:58]]
    assert q.count(Quality.STALE) >= 20 and q.count(Quality.OK) >= 20
    assert all(s.quality == Quality.DECODE_ERROR for s in got[61:])
    assert "power" in src.names and "excitation_offset" not in src.names  # holding: on demand only
    # the schedule is on absolute deadlines: median spacing is the period, nothing skipped
    dts = [b.t_wall - a.t_wall for a, b in itertools.pairwise(got)]
    assert statistics.median(dts) == pytest.approx(0.02, rel=0.25)
    assert src.stats.missed_ticks == 0 and 0 < statistics.median(s.latency_s for s in ok) < 0.05


async def test_server_restart_is_reconnected():
    async with RegisterServer(RMAP) as srv:
        await srv.set({"sample_counter": 1, "power": 10.0})
        qualities = []
        async with ModbusSource(_params(srv.port)) as src:
            await src.wait_connected(5)
            async for s in src.samples():
                qualities.append(s.quality)
                await srv.set({"sample_counter": len(qualities) + 1})
                if len(qualities) == 10:
                    await srv.stop()
                if len(qualities) == 60:  # ~1 s later, same port
                    await srv.start()
                if len(qualities) > 60 and s.quality == Quality.OK:
                    break
                if len(qualities) > 1000:
                    pytest.fail("never reconnected")
        assert src.stats.connects == 2 and src.stats.reconnects == 1
    assert Quality.COMM_ERROR in qualities[10:60]
    assert qualities[:10].count(Quality.OK) >= 8


async def test_watchdog_recreates_a_client_that_gets_no_answers():
    async with RegisterServer(RMAP) as srv:
        await srv.set({"sample_counter": 1})
        async with ModbusSource(_params(srv.port, watchdog_failures=3, poll_hz=20.0)) as src:
            await src.wait_connected(5)
            n = 0
            async for s in src.samples():
                n += 1
                await srv.set({"sample_counter": n + 1})
                if n == 3:
                    srv.hang = True  # connection stays open, no answers: only the watchdog helps
                if src.stats.watchdog_resets >= 1 and srv.hang:
                    srv.hang = False
                if src.stats.watchdog_resets >= 1 and s.quality == Quality.OK and n > 4:
                    break
                if n > 400:
                    pytest.fail("watchdog never recovered the link")
        assert src.stats.connects >= 2


async def test_missed_ticks_are_recorded_not_burst():
    async with RegisterServer(RMAP) as srv:
        await srv.set({"sample_counter": 1})
        got = []
        async with ModbusSource(_params(srv.port)) as src:
            await src.wait_connected(5)
            async for s in src.samples():
                got.append(s)
                if len(got) == 20:
                    time.sleep(0.25)  # a consumer that blocks the loop for 12.5 periods
                if len(got) >= 60:
                    break
    assert [s.seq for s in got] == list(range(len(got)))
    missing = [s for s in got if s.quality == Quality.MISSING]
    assert 8 <= len(missing) <= 14 and src.stats.missed_ticks == len(missing)
    assert all(math.isnan(s.values["power"]) for s in missing)
    # after the stall the poller resumes on the grid, no catch-up burst: the first read comes at once,
    # then one per deadline (a burst would make 13 reads at once)
    reads = [s.t_wall for s in got[20:] if s.quality != Quality.MISSING]
    assert sum(1 for t in reads if t - reads[1] < 0.1) <= 7  # 1 + 5 per 100 ms (+1 jitter); a burst: 13


async def test_against_sim_governor_and_its_register_map():
    sim_device = pytest.importorskip("sim_device")
    from tests_daemon_support import ToySimulator

    rmap = load_register_map(ROOT / "sim_device" / "registers.toml")
    gov = sim_device.SimGovernor(simulator=ToySimulator(), port=0, speed=1.0)
    async with gov, ModbusSource(ModbusParams("127.0.0.1", gov.port, rmap, poll_hz=25.0)) as src:
        await src.wait_connected(5)
        got = []
        async for s in src.samples():
            got.append(s)
            if len(got) == 40:
                break
    good = [s for s in got if s.quality == Quality.OK]
    assert len(good) >= 30
    assert good[-1].values["grid_freq"] == pytest.approx(50.0, abs=0.2)
    assert good[-1].t_device > good[0].t_device
    counters = [s.values["sample_counter"] for s in good]
    assert counters == sorted(counters)
