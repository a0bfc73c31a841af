"""Every controller sample over CAN (fcrlive.daemon.can_sample_source): the CAN FD frame GOV_Sample with a
rolling counter, from the simulated governor on python-can's virtual bus, and lost/repeated frames."""

from __future__ import annotations

import asyncio
from pathlib import Path

import can
import pytest

from fcrlive.daemon.can_sample_source import CanSampleSource, per_sample_signals
from fcrlive.daemon.can_source import load_dbc
from fcrlive.daemon.sample import Quality
from fcrlive.modbus.ringlayout import COUNTER_MOD
from sim_device import SimGovernor
from sim_device.ringbuffer import sample_values

DBC = Path(__file__).resolve().parents[1] / "sim_device" / "fcrlive_sim.dbc"


async def _collect(src, n: int, timeout: float = 20.0) -> list:
    out = []

    async def run():
        async for s in src.samples():
            out.append(s)
            if len(out) >= n:
                return

    await asyncio.wait_for(run(), timeout)
    return out


async def test_every_sample_from_the_simulated_governor_over_can_fd():
    rec = []
    async with SimGovernor(port=0, speed=5.0, seed=2, on_sample=rec.append, can_channel="fcr-fd-1") as gov, \
            CanSampleSource("virtual", "fcr-fd-1", DBC, gov.dt) as src:
        got = await _collect(src, 600)
    assert src.names == per_sample_signals(DBC)
    seqs = [s.seq for s in got]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    assert all(s.quality == Quality.OK for s in got) and src.stats.lost == 0
    fields = src.fields
    for s in got:
        v = sample_values(rec[s.seq], s.values["excitation_applied"])
        assert [s.values[f] for f in fields] == pytest.approx([v[f] for f in fields], rel=1e-6, abs=1e-9)
        assert s.t_device == pytest.approx(s.seq * 0.02)


async def test_lost_repeated_and_wrapping_frames():
    m = load_dbc(DBC).get_message_by_name("GOV_Sample")
    tx = can.Bus(interface="virtual", channel="fcr-fd-2")
    start = COUNTER_MOD - 5
    counters = [start + k for k in range(10)] + [start + 13, start + 13, start + 14]  # 3 lost, 1 repeated

    try:
        async with CanSampleSource("virtual", "fcr-fd-2", DBC, 0.01) as src:
            await asyncio.sleep(0.2)  # the bus is opened in the background
            for c in counters:
                sig = {s.name: 1.0 for s in m.signals} | {"seq_counter": c % COUNTER_MOD}
                tx.send(can.Message(arbitration_id=m.frame_id, data=m.encode(sig, strict=False), is_fd=True,
                                    is_extended_id=False))
            got = await _collect(src, 15)
    finally:
        tx.shutdown()
    seqs = [s.seq for s in got]
    assert seqs == list(range(start, start + 15))  # unwrapped across 2^32
    missing = [s.seq for s in got if s.quality == Quality.MISSING]
    assert missing == [start + 10, start + 11, start + 12]
    assert src.stats.lost == 3 and src.stats.duplicates == 1 and src.stats.gaps == 1
    assert got[6].values["sample_counter"] == 1.0  # the raw 32-bit counter wrapped
