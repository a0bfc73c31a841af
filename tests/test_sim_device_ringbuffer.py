"""The simulated governor's ring buffer (sim_device/ringbuffer.py) read over real Modbus TCP: every
controller sample the plant computed is in it, in order, with its counter, at any speed."""

from __future__ import annotations

import asyncio

import pytest
from pymodbus.client import AsyncModbusTcpClient

from fcrlive.modbus.ringlayout import COUNTER_MOD, decode_header, decode_slots
from sim_device import SimGovernor
from sim_device.ringbuffer import sample_values


async def _read_ring(gov: SimGovernor):
    """Header and every slot, read in 8-slot blocks while the device is frozen (a consistent picture)."""
    lay = gov.ring.layout
    c = AsyncModbusTcpClient("127.0.0.1", port=gov.port)
    await c.connect()
    try:
        rr = await c.read_input_registers(lay.header_address, count=9, device_id=1)
        h = decode_header(rr.registers)
        slots = []
        for k in range(0, lay.slots, lay.slots_per_read):
            n = min(lay.slots_per_read, lay.slots - k)
            rr = await c.read_input_registers(lay.slot_address(k), count=n * lay.slot_words, device_id=1)
            slots += decode_slots(rr.registers, len(lay.fields))
    finally:
        c.close()
    return h, slots


@pytest.mark.parametrize("speed", [1.0, 60.0])
async def test_every_controller_sample_enters_the_ring(speed):
    rec = []
    async with SimGovernor(port=0, speed=speed, seed=4, on_sample=rec.append, buffer_slots=256) as gov:
        await asyncio.sleep(0.6)
        gov.faults.set(freeze=True)  # the ring stops; the plant runs on
        frozen_at = len(rec)
        h, slots = await _read_ring(gov)
        await asyncio.sleep(0.1)
        assert len(rec) > frozen_at  # the plant went on
        assert (await _read_ring(gov))[0] == h  # the header does not move while frozen
    lay = gov.ring.layout
    assert h.slots == 256 and h.slot_words == 15 and h.tc_s == pytest.approx(0.02)
    assert h.head == frozen_at - 1  # counter n = the n-th sample since start (0-based)
    assert h.tail == max(0, frozen_at - 256)
    want = range(h.tail, h.head + 1)
    got = {c: v for c, v in (s for s in slots if s is not None)}
    assert sorted(got) == list(want)  # every sample of the last N, none missing, none extra
    for c in want:
        v = sample_values(rec[c], 0.0)
        expect = [v[f] for f in lay.fields]
        assert got[c] == pytest.approx(expect, rel=1e-6, abs=1e-9), c  # float32 of the very sample


async def test_counter_wraps_at_2_32_onto_the_same_slot():
    start = COUNTER_MOD - 40
    async with SimGovernor(port=0, speed=10.0, seed=1, buffer_slots=64, buffer_counter_start=start) as gov:
        await asyncio.sleep(0.5)  # ~250 samples: past the wrap
        gov.faults.set(freeze=True)
        h, slots = await _read_ring(gov)
    assert h.head < 1000 and h.tail < h.head  # wrapped
    for k, s in enumerate(slots):
        assert s is not None and s[0] % 64 == k


async def test_restart_erases_the_ring_and_changes_the_epoch():
    async with SimGovernor(port=0, speed=10.0, seed=1, buffer_slots=64) as gov:
        await asyncio.sleep(0.3)
        h0, _ = await _read_ring(gov)
        await gov.faults.restart(0.05)
        await asyncio.sleep(0.02)
        gov.faults.set(freeze=True)
        h1, slots = await _read_ring(gov)
    assert h1.epoch != h0.epoch
    assert h1.tail == 0 and h1.head < 64  # counting again from 0
    valid = [s[0] for s in slots if s is not None]
    assert valid == list(range(0, h1.head + 1))  # erased slots read invalid, never as old data
