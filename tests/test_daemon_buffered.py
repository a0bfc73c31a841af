"""Buffered acquisition (fcrlive.daemon.buffered_source) against the real simulated governor over Modbus
TCP: every controller sample once, in order; wrap-around of the counter; overrun of a slow reader as a gap
of the right length; link loss, device restart, duplicate reads and the fault injector's faults."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import math
import time

import pytest

from fcrlive.daemon.buffered_source import BufferedModbusSource, RingReader, buffered_signals
from fcrlive.daemon.sample import Quality
from fcrlive.modbus.client import ModbusParams
from fcrlive.modbus.ringlayout import COUNTER_MOD
from sim_device import SimGovernor
from sim_device.registers import load_map
from sim_device.ringbuffer import sample_values

RMAP = load_map()


def _params(gov: SimGovernor, **kw) -> ModbusParams:
    from dataclasses import replace

    return ModbusParams("127.0.0.1", gov.port, replace(RMAP, acquisition="buffered"), timeout_s=0.3,
                        backoff_min_s=0.05, backoff_max_s=0.2, **kw)


@contextlib.asynccontextmanager
async def _device_and_source(**kw):
    async with SimGovernor(port=0, **kw) as gov, BufferedModbusSource(_params(gov)) as src:
        yield gov, src


@contextlib.asynccontextmanager
async def _raw_reader(gov: SimGovernor):
    """A RingReader on a pymodbus client of its own: the governor's ring read directly, no source."""
    from pymodbus.client import AsyncModbusTcpClient

    client = AsyncModbusTcpClient("127.0.0.1", port=gov.port)
    await client.connect()

    async def read(addr, count):
        return (await client.read_input_registers(addr, count=count, device_id=1)).registers

    try:
        yield RingReader(gov.ring.layout, read)
    finally:
        client.close()


async def _collect(src: BufferedModbusSource, seconds: float, during=None) -> list:
    out = []

    async def run():
        async for s in src.samples():
            out.append(s)

    task = asyncio.create_task(run())
    try:
        if during is not None:
            await during()
        await asyncio.sleep(seconds)
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
    return out


def _check_values(samples, rec, first_counter=0):
    """Every OK sample carries the float32 values of the very controller sample the plant computed."""
    fields = RMAP.buffer.fields
    n = 0
    for s in samples:
        if s.quality != Quality.OK:
            continue
        v = sample_values(rec[s.seq - first_counter], s.values["excitation_applied"])
        assert [s.values[f] for f in fields] == pytest.approx([v[f] for f in fields], rel=1e-6, abs=1e-9)
        n += 1
    return n


async def test_every_sample_once_in_order_at_speed_20():
    rec = []
    async with _device_and_source(speed=20.0, seed=2, on_sample=rec.append) as (gov, src):
        n0, t0 = gov.ring.pushed, time.monotonic()
        got = await _collect(src, 2.0)
        produced_per_s = (gov.ring.pushed - n0) / (time.monotonic() - t0)  # < 1000 when the machine is busy
    assert src.names == buffered_signals(RMAP.buffer)
    seqs = [s.seq for s in got]
    assert len(got) > 200 and seqs == list(range(seqs[0], seqs[0] + len(seqs)))  # no gap, no repeat
    assert all(s.quality == Quality.OK for s in got) and src.reader.stats.lost == 0
    assert _check_values(got, rec) == len(got)
    assert all(s.t_device == pytest.approx(s.seq * 0.02) for s in got)
    t = [s.t_wall for s in got]
    assert all(b > a for a, b in itertools.pairwise(t))  # production times, strictly increasing
    # the measured wall time per sample is the device's (Tc / speed on an idle machine), within 30 %
    assert src.reader.wall_per_sample == pytest.approx(1.0 / produced_per_s, rel=0.3)
    # and the times are evenly spaced: no step a window would take for a gap (a step from the
    # clock map's reset happens only when the device's own clock jumped by seconds)
    dt = [b - a for a, b in itertools.pairwise(t)]
    steps = sum(d > 1.5 * sorted(dt)[len(dt) // 2] for d in dt)
    assert steps <= gov.slips, (steps, gov.slips)


async def test_counter_wraps_at_2_32():
    start = COUNTER_MOD - 300
    rec = []
    async with _device_and_source(speed=10.0, seed=1, on_sample=rec.append, buffer_slots=256,
                       buffer_counter_start=start) as (_gov, src):
        got = await _collect(src, 1.5)
    seqs = [s.seq for s in got]
    assert seqs[0] < COUNTER_MOD < seqs[-1], (seqs[0], seqs[-1])  # crossed the wrap
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    raw = [int(s.values["sample_counter"]) for s in got]
    assert raw == [q % COUNTER_MOD for q in seqs]  # the device's 32-bit counter wrapped to 0
    assert _check_values(got, rec, first_counter=start) == len(got)


async def test_slow_reader_overrun_is_a_gap_of_the_right_length():
    rec = []
    async with (
        SimGovernor(port=0, speed=5.0, seed=3, on_sample=rec.append, buffer_slots=64) as gov,
        _raw_reader(gov) as reader,
    ):
        items = []
        for _ in range(20):  # keep up for a while
            got, _more = await reader.poll()
            items += got
            await asyncio.sleep(0.02)
        before = reader.next
        await asyncio.sleep(1.0)  # 250 samples at 250/s: the 64-slot ring is overrun
        head_then = gov.ring.next - 1
        for _ in range(40):
            got, more = await reader.poll()
            items += got
            if not more:
                await asyncio.sleep(0.02)
    gaps = [it for it in items if it.lost]
    assert len(gaps) == 1
    gap = gaps[0]
    samples = [it for it in items if it.values is not None]
    before_gap = [it.counter for it in samples if it.counter < gap.counter]
    after_gap = [it.counter for it in samples if it.counter > gap.counter]
    # the gap is exactly the counters not delivered, and it covers what was overwritten
    assert gap.counter == before_gap[-1] + 1 == before
    assert after_gap[0] == gap.counter + gap.lost
    assert gap.lost >= head_then - 64 + 1 - before  # at least every overwritten sample
    assert reader.stats.lost == gap.lost
    counters = before_gap + list(range(gap.counter, gap.counter + gap.lost)) + after_gap
    assert counters == list(range(counters[0], counters[-1] + 1))  # delivered + lost = all, once
    for it in samples:  # delivered values are the device's, also right after the gap
        v = sample_values(rec[it.counter], 0.0)
        assert it.values == pytest.approx(tuple(v[f] for f in gov.ring.layout.fields), rel=1e-6, abs=1e-9)


async def test_duplicate_reads_emit_nothing_twice():
    async with SimGovernor(port=0, speed=5.0, seed=3) as gov, _raw_reader(gov) as reader:
        counters = []
        for _ in range(500):  # until samples flow (the first header reads measure the rate)
            got, _ = await reader.poll()
            counters += [it.counter for it in got if it.values is not None]
            if counters:
                break
            await asyncio.sleep(0.02)
        for i in range(30):
            if i in (10, 20):
                reader.rewind(5)  # a retried request: the same slots come back
            got, _ = await reader.poll()
            counters += [it.counter for it in got if it.values is not None]
            await asyncio.sleep(0.02)
    assert counters == list(range(counters[0], counters[0] + len(counters)))
    assert reader.stats.duplicates == 10 and reader.stats.lost == 0


async def test_link_loss_shorter_than_the_buffer_loses_nothing():
    rec = []
    async with _device_and_source(speed=5.0, seed=5, on_sample=rec.append, buffer_slots=1024) as (gov, src):

        async def faults():
            await asyncio.sleep(0.5)
            gov.faults.drop_connections()
            await asyncio.sleep(0.5)
            gov.faults.set(hang=True)  # requests time out: the watchdog rebuilds the client
            await asyncio.sleep(1.0)
            gov.faults.set(hang=False)
            await asyncio.sleep(0.3)
            gov.faults.set(exception="busy")
            await asyncio.sleep(0.3)
            gov.faults.set(exception=None)

        got = await _collect(src, 1.5, during=faults)
        behind = gov.ring.next - 1 - got[-1].seq
    seqs = [s.seq for s in got]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    assert src.reader.stats.lost == 0 and all(s.quality == Quality.OK for s in got)
    assert src.stats.connects >= 2  # it did lose the link
    assert _check_values(got, rec) == len(got)
    assert behind < 500  # and caught up after the faults (within 2 s of the head at 250 samples/s)


async def test_device_restart_mid_buffer_counts_a_restart_and_keeps_the_new_epoch():
    async with _device_and_source(speed=5.0, seed=5) as (gov, src):

        async def restart():
            await asyncio.sleep(0.8)
            await gov.faults.restart(0.3)

        got = await _collect(src, 1.5, during=restart)
    seqs = [s.seq for s in got]
    cut = next(i for i in range(1, len(seqs)) if seqs[i] != seqs[i - 1] + 1)
    assert src.reader.stats.restarts == 1
    assert seqs[cut] == 0  # the new epoch from its first sample: nothing after the restart is lost
    assert seqs[cut:] == list(range(0, len(seqs) - cut)) and seqs[:cut] == list(range(seqs[0], seqs[0] + cut))
    assert got[cut].t_device == 0.0 and got[cut].t_wall > got[cut - 1].t_wall


async def test_freeze_and_nan_faults():
    async with _device_and_source(speed=5.0, seed=6, buffer_slots=64) as (gov, src):
        frozen: dict[str, int] = {}

        async def faults():
            await asyncio.sleep(0.4)
            frozen["from"] = gov.ring.next
            gov.faults.set(freeze=True)
            await asyncio.sleep(0.5)
            gov.faults.set(freeze=False)
            frozen["to"] = gov.ring.next  # first counter after the freeze (the counter jumped)
            await asyncio.sleep(0.4)
            gov.faults.set(nan=True)
            await asyncio.sleep(0.3)
            gov.faults.set(nan=False)

        got = await _collect(src, 0.5, during=faults)
    seqs = [s.seq for s in got]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))  # lost samples are rows too
    missing = [s.seq for s in got if s.quality == Quality.MISSING]
    # never in the ring: exactly the samples computed while frozen
    assert missing == list(range(frozen["from"], frozen["to"]))
    assert all(math.isnan(s.values["power"]) for s in got if s.quality == Quality.MISSING)
    bad = [s for s in got if s.quality == Quality.DECODE_ERROR]
    assert len(bad) >= 5 and all(math.isnan(s.values["power"]) for s in bad)
    assert src.reader.stats.lost == len(missing)


async def test_little_word_order_device():
    """A governor that sends the low word of 32-bit values first: the map says so, the slots decode."""
    from dataclasses import replace

    rec = []
    async with SimGovernor(port=0, speed=5.0, seed=7, on_sample=rec.append, word_order="little") as gov:
        rmap = replace(gov.register_map, acquisition="buffered")
        assert rmap.word_order == "little"
        params = ModbusParams("127.0.0.1", gov.port, rmap, timeout_s=0.3, backoff_min_s=0.05)
        async with BufferedModbusSource(params) as src:
            await src.wait_connected(5)
            got = await _collect(src, 1.0)
    seqs = [s.seq for s in got]
    assert len(seqs) > 100 and seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    assert _check_values(got, rec) == len(got)


async def test_counter_going_back_without_a_new_epoch_is_a_restart():
    """A device whose epoch did not change (e.g. a PLC that does not implement it) but whose counter went
    back: treated as a restart, never as 4 billion lost samples."""
    async with SimGovernor(port=0, speed=5.0, seed=8, buffer_slots=256) as gov, _raw_reader(gov) as reader:
        items = []
        for _ in range(40):
            items += (await reader.poll())[0]
            await asyncio.sleep(0.02)
        epoch = gov.ring.epoch
        gov.ring.reset()  # counter back to 0, slots erased ...
        gov.ring.epoch = epoch  # ... but the same epoch
        for _ in range(60):
            items += (await reader.poll())[0]
            await asyncio.sleep(0.02)
    assert reader.stats.restarts == 1 and reader.stats.lost == 0
    counters = [it.counter for it in items if it.values is not None]
    cut = next(i for i in range(1, len(counters)) if counters[i] < counters[i - 1])
    assert counters[:cut] == list(range(counters[0], counters[0] + cut))
    assert counters[cut:] == list(range(len(counters) - cut))  # the new run from its first sample
