"""CAN source on python-can's in-process `virtual` interface, decoding with the sim_device DBC."""

from __future__ import annotations

import asyncio
import math
from pathlib import Path

import can
import pytest

from fcrlive.daemon.can_source import CanParams, CanSource, dbc_signal_names, load_dbc
from fcrlive.daemon.sample import Quality

ROOT = Path(__file__).resolve().parents[1]
DBC = ROOT / "sim_device" / "fcrlive_sim.dbc"


def test_dbc_signals_exclude_own_commands():
    names = dbc_signal_names(DBC)
    assert "power" in names and "sample_counter" in names and "device_time" in names
    assert "excitation_offset" not in names  # sent by FCRLIVE, not sampled


async def _frames(bus, db, counter, values):
    for name in ("GOV_Counter", "GOV_Time", "GOV_Speed", "GOV_Power", "GOV_Gate", "GOV_Excitation"):
        m = db.get_message_by_name(name)
        v = {s.name: values.get(s.name, 0.0) for s in m.signals} | {"sample_counter": counter}
        v = {k: val for k, val in v.items() if k in {s.name for s in m.signals}}
        bus.send(can.Message(arbitration_id=m.frame_id, data=m.encode(v, strict=False), is_extended_id=False))


async def test_bursts_quality_and_silence():
    db = load_dbc(DBC)
    tx = can.Bus(interface="virtual", channel="fcr-unit")
    got = []
    try:
        async with CanSource(CanParams("virtual", "fcr-unit", DBC, poll_hz=50.0, stale_after_s=0.2)) as src:
            async for s in src.samples():
                got.append(s)
                n = len(got)
                if n < 30:
                    await _frames(tx, db, n, {"power": 80.0 + n, "grid_freq": 50.01, "device_time": n * 0.02})
                elif n == 30:
                    await _frames(tx, db, n, {"power": math.nan, "device_time": n * 0.02})
                if n == 60:  # 30 silent ticks = 0.6 s > stale_after_s
                    break
    finally:
        tx.shutdown()
    assert [s.seq for s in got] == list(range(60))
    ok = [s for s in got if s.quality == Quality.OK]
    assert len(ok) >= 20
    s = ok[-1]
    assert s.values["power"] == 80.0 + s.values["sample_counter"] and s.t_device == pytest.approx(
        s.values["sample_counter"] * 0.02)
    assert any(s.quality == Quality.DECODE_ERROR for s in got[30:35])
    assert all(s.quality == Quality.COMM_ERROR for s in got[-10:])


async def test_sim_governor_over_virtual_can():
    sim_device = pytest.importorskip("sim_device")
    from tests_daemon_support import ToySimulator

    async with sim_device.SimGovernor(simulator=ToySimulator(), port=0, speed=1.0, can_channel="fcr-sim",
                                      can_interface="virtual") as gov:
        async with CanSource(CanParams("virtual", "fcr-sim", DBC, poll_hz=25.0)) as src:
            got = []
            async for s in src.samples():
                got.append(s)
                if len(got) == 5:  # an excitation command frame reaches the device
                    await src.send("GOV_ExcitationCmd", {"excitation_offset": 0.02, "excitation_enable": 1,
                                                         "heartbeat": 7})
                if len(got) == 30:
                    break
            await asyncio.sleep(0.1)
        assert gov.can.commands_received == 1
    good = [s for s in got if s.quality == Quality.OK]
    assert len(good) >= 20
    assert good[-1].values["grid_freq"] == pytest.approx(50.0, abs=0.2)
    counters = [s.values["sample_counter"] for s in good]
    assert counters == sorted(counters) and len(set(counters)) == len(counters)
