"""Buffered acquisition: every controller sample from the governor's ring buffer (Modbus TCP, FC4 blocks).

The contract and the reader's rules are docs/buffered-acquisition.md; the layout and slot codec are
:mod:`fcrlive.modbus.ringlayout`. ``acquisition = "buffered"`` in the register map selects this source
(:func:`fcrlive.daemon.service.make_source`); snapshot polling (:class:`ModbusSource`) stays the default
for devices without a buffer.

:class:`RingReader` is the reader's state machine over one coroutine ``read(address, count) -> registers``
(so the tests drive it by hand against the real simulated governor); :class:`BufferedModbusSource` runs
it on :class:`ModbusSource`'s connection handling (reconnect with backoff, watchdog) and yields one
:class:`Sample` per controller sample, in counter order, each counter once:

* OK / DECODE_ERROR (NaN or inf in a value) samples with ``seq`` = the unwrapped counter, ``t_device`` =
  counter × Tc and ``t_wall`` = when the governor produced it (the latest header read's head mapped to its
  arrival time, counters in between at the measured wall time per sample);
* one MISSING sample (NaN values) per lost counter: overrun (the reader fell more than N samples behind,
  a link down for longer than the buffer, a frozen device whose counter then jumped). Never interpolated;
* a restart of the governor (new epoch, counter back) is logged and counted; the reader continues with the
  new epoch's oldest sample, so what it produced since the restart is kept.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from dataclasses import dataclass

import numpy as np

from fcrlive.daemon.modbus_source import ModbusSource
from fcrlive.daemon.sample import COUNTER_NAME, DEVICE_TIME_NAME, Quality, Sample
from fcrlive.modbus.client import ModbusParams
from fcrlive.modbus.ringlayout import (
    HEADER_WORDS,
    BufferLayout,
    counter_delta,
    decode_header,
    decode_slots,
)

log = logging.getLogger("fcrlive.buffered")

PARALLEL_LINKS = 2
"""Further TCP connections used to read ahead while catching up (3 blocks = 24 samples per round trip)."""
MAX_MISSING_ROWS = 200_000
"""Lost samples stored as MISSING rows per gap at most; a longer gap is a jump in time (Window.gaps)."""


def buffered_signals(layout: BufferLayout) -> tuple[str, ...]:
    """Stored signals of a buffered source: the counter, the device time and the slot's fields."""
    return (COUNTER_NAME, DEVICE_TIME_NAME, *layout.fields)


class BufferProtocolError(Exception):
    """The device's header does not match the map's buffer layout."""


@dataclass
class RingStats:
    """What the reader did (the benchmark and the tests read it)."""

    requests: int = 0
    header_reads: int = 0
    samples: int = 0
    lost: int = 0
    gaps: int = 0
    duplicates: int = 0
    invalid_slots: int = 0
    restarts: int = 0
    catch_up_reads: int = 0


@dataclass(frozen=True)
class RingItem:
    """One controller sample (``values`` by field) or, with ``lost`` > 0, that many lost samples from
    ``counter`` on (``values`` None)."""

    counter: int
    """Unwrapped counter (the first lost one for a gap)."""
    t_wall: float
    values: tuple[float, ...] | None
    lost: int = 0
    age_s: float = math.nan
    """Wall seconds between the sample's production and its arrival."""


class RingReader:
    """The reader of docs/buffered-acquisition.md over ``read(address, count)`` (Modbus FC4)."""

    def __init__(self, layout: BufferLayout, read: Callable[[int, int], Awaitable[Sequence[int]]],
                 word_order: str = "big", header_every_s: float = 1.0,
                 clock: Callable[[], float] = time.time,
                 parallel: Sequence[Callable[[int, int], Awaitable[Sequence[int]]]] = ()):
        self.layout = layout
        self._read = read
        self._parallel = tuple(parallel)
        """Further links to the same device, used only to read ahead while behind."""
        self._behind = False
        self.word_order = word_order
        self.header_every_s = header_every_s
        self.clock = clock
        self.stats = RingStats()
        self.slots = layout.slots
        self.tc_s = math.nan
        self.epoch: int | None = None
        self.next: int | None = None
        """Unwrapped counter of the next sample wanted."""
        self.last_emitted: int | None = None
        self.wall_per_sample = math.nan
        """Measured wall seconds per controller sample (Tc at speed 1; Tc/speed for a simulator)."""
        self._clock_map: tuple[float, int, float] | None = None  # t(n) = t_a + (n − n_a)·slope
        self._last_header_wall = -math.inf
        self._last_t = -math.inf
        self._last_progress = -math.inf

    # ------------------------------------------------------------------ reading
    async def read(self, address: int, count: int) -> Sequence[int]:
        self.stats.requests += 1
        return await self._read(address, count)

    def rewind(self, n: int) -> None:
        """Read the last ``n`` slots again (what a retried request does); nothing is emitted twice."""
        if self.next is not None:
            self.next -= n

    def reset(self) -> None:
        """Forget the position (a new connection to a possibly different device): sync again."""
        self._last_header_wall = -math.inf

    async def poll(self) -> tuple[list[RingItem], bool]:
        """One block read (and a header read when due). ``(items, more)``: ``more`` when the block came
        back full, i.e. more samples are probably waiting (read again at once)."""
        items: list[RingItem] = []
        now = self.clock()
        every = self.header_every_s if getattr(self, "_rate_measured", False) else 0.2
        # no new sample for a while although some were due: the counter may have jumped (a frozen or
        # restarted buffer, whose slots still hold the previous lap): ask the header now
        stalled = now - self._last_progress > max(0.1, 4.0 * self.due_in_s()) and \
            now - self._last_header_wall > max(0.1, 4.0 * self.due_in_s())
        if self.next is None or now - self._last_header_wall >= every or stalled:
            await self._header(items)
        if self.next is None or not getattr(self, "_rate_measured", False):
            return items, False  # the first header reads measure the rate: times need it
        lay = self.layout
        # behind (the last poll came back full): read several blocks at once over the parallel links, so
        # a slow round trip (a loaded machine, a far gateway) does not cap the throughput
        k = 1
        if self._behind and self._parallel:  # as many blocks as the estimated backlog fills
            backlog = self._head_estimate(now) - self.next + 1
            k = max(1, min(1 + len(self._parallel), math.ceil(backlog / lay.slots_per_read)))
        blocks: list[tuple[int, int]] = []
        pos = self.next
        for _ in range(k):
            idx = pos % self.slots
            n = min(lay.slots_per_read, self.slots - idx)
            blocks.append((pos, n))
            pos += n
        reads = [self.read(lay.slot_address(p % self.slots), n * lay.slot_words) if i == 0 else
                 self._read_parallel(i - 1, lay.slot_address(p % self.slots), n * lay.slot_words)
                 for i, (p, n) in enumerate(blocks)]
        results = await asyncio.gather(*reads, return_exceptions=True)
        if isinstance(results[0], BaseException):
            raise results[0]
        arrival = self.clock()
        got = 0
        full = True
        for (start, n), regs in zip(blocks, results, strict=True):
            if isinstance(regs, BaseException) or not full or start != self.next:
                break
            got_block = 0
            for s in decode_slots(regs, len(lay.fields), self.word_order):
                if s is None:  # being written, or erased by a restart and not yet written again
                    self.stats.invalid_slots += 1
                    break
                c32, values = s
                d = counter_delta(c32, self.next)
                if d < 0:  # the previous lap: not written yet, we are at the head
                    break
                if d > 0:  # overwritten: we fell more than N samples behind
                    await self._header(items)
                    break
                self._emit(items, self.next, values, arrival)
                self.next += 1
                got_block += 1
            got += got_block
            full = got_block == n
        if got:
            self._last_progress = arrival
        more = full
        self._behind = more
        if more:
            self.stats.catch_up_reads += 1
        return items, more

    def _head_estimate(self, now: float) -> float:
        """The device's head now, from the last header read and the measured rate."""
        if self._clock_map is None or not math.isfinite(self.wall_per_sample):
            return float(self.next or 0)
        t_a, n_a, slope = self._clock_map
        return n_a + (now - t_a) / slope

    async def _read_parallel(self, i: int, address: int, count: int) -> Sequence[int]:
        self.stats.requests += 1
        return await self._parallel[i](address, count)

    def due_in_s(self, fraction: float = 0.75) -> float:
        """Wall seconds until about ``fraction`` of a block of new samples is waiting."""
        w = self.wall_per_sample if math.isfinite(self.wall_per_sample) else (self.tc_s or 0.02)
        return fraction * self.layout.slots_per_read * w

    # ------------------------------------------------------------------ internals
    def _time_of(self, counter: int) -> float:
        if self._clock_map is None:
            return self.clock()
        t_a, n_a, slope = self._clock_map
        return t_a + (counter - n_a) * slope

    def _steer_clock(self, wall: float, head: int, hard: bool = False) -> None:
        """Map counters to wall time: the head was produced at about ``wall``. The map stays continuous
        (no steps between neighbouring samples, which a window would take for gaps); an error is
        absorbed by the slope over the next ~5 s, a large one (> 2 s: a restart, a stall) by a reset."""
        b = self.wall_per_sample if math.isfinite(self.wall_per_sample) else self.tc_s
        if self._clock_map is None or hard:
            self._clock_map = (wall, head, b)
            return
        err = wall - self._time_of(head)
        if abs(err) > 2.0:
            self._clock_map = (wall, head, b)
            return
        n_a = self.last_emitted if self.last_emitted is not None else head
        span = max(1.0, 5.0 / b)
        slope = min(max(b + err / span, 0.75 * b), 1.25 * b)  # neighbours stay < 1.5 periods apart
        self._clock_map = (self._time_of(n_a), n_a, slope)

    def _emit(self, items: list[RingItem], counter: int, values: tuple[float, ...], arrival: float) -> None:
        if self.last_emitted is not None and counter <= self.last_emitted:
            self.stats.duplicates += 1
            return
        t = max(self._time_of(counter), self._last_t + 1e-6)
        self._last_t = t
        self.last_emitted = counter
        self.stats.samples += 1
        items.append(RingItem(counter, t, values, age_s=arrival - t))

    def _lose(self, items: list[RingItem], first: int, count: int) -> None:
        if count <= 0:
            return
        self.stats.lost += count
        self.stats.gaps += 1
        t = max(self._time_of(first), self._last_t + 1e-6)
        items.append(RingItem(first, t, None, lost=count))
        self._last_t = max(self._last_t, self._time_of(first + count - 1))
        self.last_emitted = first + count - 1
        log.warning("buffered acquisition: %d controller sample(s) lost from counter %d (%d lost so far)",
                    count, first, self.stats.lost)

    async def _header(self, items: list[RingItem]) -> None:
        lay = self.layout
        t_req = self.clock()
        regs = await self.read(lay.header_address, HEADER_WORDS)
        wall = 0.5 * (t_req + self.clock())
        self.stats.header_reads += 1
        self._last_header_wall = wall
        h = decode_header(regs, self.word_order)
        if h.slot_words != lay.slot_words or h.slots < 2 or h.slots & (h.slots - 1) or not h.tc_s > 0:
            raise BufferProtocolError(
                f"the device's buffer header (slots {h.slots}, {h.slot_words} registers per slot, Tc "
                f"{h.tc_s} s) does not match the map ({lay.slot_words} registers per slot)")
        if self.slots != h.slots and self.epoch is not None:
            log.info("buffered acquisition: the device reports %d slots", h.slots)
        self.slots, self.tc_s = h.slots, h.tc_s
        if self.epoch is None or h.epoch != self.epoch or self.next is None:
            self._start_epoch(h, wall, restart=self.epoch is not None)
            return
        head = self.next + counter_delta(h.head, self.next)
        tail = self.next + counter_delta(h.tail, self.next)
        if head < self.next - 1:  # the counter went back without a new epoch: a restart all the same
            self._start_epoch(h, wall, restart=True)
            return
        self._measure_rate(wall, head)
        if self.next < tail:  # overrun: skip to the oldest valid slot, the rest is lost; a reader that
            # fell behind by a whole ring also leaves N/8 slots of margin, so it does not overrun at once
            new = min(head + 1, max(tail, head + 1 - (self.slots - self.slots // 8)))
            lost = new - self.next
            first = self.next
            self.next = new
            self._lose(items, first, min(lost, MAX_MISSING_ROWS) if lost > 0 else 0)
            if lost > MAX_MISSING_ROWS:
                self.stats.lost += lost - MAX_MISSING_ROWS

    def _start_epoch(self, h, wall: float, restart: bool) -> None:
        if restart:
            self.stats.restarts += 1
            log.warning("buffered acquisition: the governor restarted (epoch %s -> %d); continuing from "
                        "its oldest sample", self.epoch, h.epoch)
        self.epoch = h.epoch
        empty = counter_delta(h.head, h.tail) < 0
        # unwrapped counters of a new epoch start at the device's own values
        head = h.head if not empty else h.tail - 1
        self.next = h.tail if (restart or empty) else head
        self.last_emitted = self.next - 1
        if not math.isfinite(self.wall_per_sample):
            self.wall_per_sample = h.tc_s
        self._rate_ref = (wall, head)
        self._steer_clock(wall, head, hard=True)

    def _measure_rate(self, wall: float, head: int) -> None:
        w0, h0 = getattr(self, "_rate_ref", (wall, head))
        measured = getattr(self, "_rate_measured", False)
        if head > h0 and wall - w0 >= (0.5 if measured else 0.15):
            b = (wall - w0) / (head - h0)
            old = self.wall_per_sample
            if not measured or not math.isfinite(old):  # the first measurement replaces the Tc guess
                self.wall_per_sample = b
                self._rate_measured = True
            else:  # smooth, and bounded: a frozen device's counter jump must not wreck the estimate
                self.wall_per_sample = 0.5 * old + 0.5 * min(max(b, 0.5 * old), 2.0 * old)
            self._rate_ref = (wall, head)
        elif head == h0:
            self._rate_ref = (wall, head)
        self._steer_clock(wall, head)


class BufferedModbusSource(ModbusSource):
    """``async with BufferedModbusSource(params) as src: async for s in src.samples()`` — every controller
    sample of the map's ring buffer (module docstring); ``write``/``read_points`` as :class:`ModbusSource`."""

    def __init__(self, params: ModbusParams, parallel_links: int = PARALLEL_LINKS):
        super().__init__(params)
        layout = self.map.buffer
        if layout is None:
            raise ValueError("the register map has no [buffer]: buffered acquisition is not possible")
        self.layout = layout
        self.names = buffered_signals(layout)
        self._extra: list = [None] * parallel_links
        self.reader = RingReader(layout, self._read_regs, self.map.word_order,
                                 parallel=[self._extra_reader(i) for i in range(parallel_links)])
        self._client_seen = None

    async def __aexit__(self, *exc) -> None:
        for i, c in enumerate(self._extra):
            if c is not None:
                c.close()
                self._extra[i] = None
        await super().__aexit__(*exc)

    def _extra_reader(self, i: int):
        """A further connection to the device, read only while catching up (opened when first needed;
        a failure closes it and costs only the read-ahead)."""

        async def read(address: int, count: int) -> list[int]:
            from pymodbus.client import AsyncModbusTcpClient
            from pymodbus.exceptions import ModbusException

            c = self._extra[i]
            if c is None or not c.connected:
                if c is not None:
                    c.close()
                c = AsyncModbusTcpClient(self.p.host, port=self.p.port, timeout=self.p.timeout_s, retries=0,
                                         reconnect_delay=0, reconnect_delay_max=0)
                self._extra[i] = c
                if not await c.connect():
                    c.close()
                    self._extra[i] = None
                    raise ConnectionError("read-ahead link: connect failed")
            try:
                rr = await c.read_input_registers(address, count=count, device_id=self.map.unit_id)
            except (TimeoutError, ModbusException, OSError) as exc:
                c.close()
                self._extra[i] = None
                raise ConnectionError(f"read-ahead link: {exc}") from None
            if rr.isError():
                raise ConnectionError(f"read-ahead link: exception response {rr}")
            return list(rr.registers)

        return read

    async def _read_regs(self, address: int, count: int) -> list[int]:
        from pymodbus.exceptions import ModbusException

        client = self._client
        if client is None or not client.connected:
            raise ConnectionError("not connected")
        try:
            rr = await client.read_input_registers(address, count=count, device_id=self.map.unit_id)
        except (TimeoutError, ModbusException, OSError) as exc:
            raise ConnectionError(f"{type(exc).__name__}: {exc}") from None
        if rr.isError():
            raise ConnectionError(f"exception response {rr}")
        return list(rr.registers)

    def _sample(self, it: RingItem) -> Sample:
        c = it.counter
        tc = self.reader.tc_s
        vals = {COUNTER_NAME: float(c & 0xFFFFFFFF), DEVICE_TIME_NAME: c * tc}
        vals.update(zip(self.layout.fields, it.values, strict=True))
        q = Quality.OK if all(math.isfinite(v) for v in it.values) else Quality.DECODE_ERROR
        return Sample(it.t_wall, c * tc, c, vals, q, latency_s=it.age_s)

    def _missing(self, it: RingItem) -> list[Sample]:
        tc, w = self.reader.tc_s, self.reader.wall_per_sample
        w = w if math.isfinite(w) else tc
        nan = dict.fromkeys(self.names, math.nan)
        return [Sample(it.t_wall + k * w, (it.counter + k) * tc, it.counter + k, nan, Quality.MISSING,
                       detail="lost") for k in range(it.lost)]

    async def samples(self) -> AsyncIterator[Sample]:
        """Every controller sample, forever (cancel or break to stop); paced to keep up."""
        while True:
            if self._client is None or not self._client.connected:
                try:
                    await asyncio.wait_for(self._connected.wait(), 0.5)
                except TimeoutError:
                    continue
            if self._client is not self._client_seen:  # a new connection: check the epoch first
                self._client_seen = self._client
                self.reader.reset()
            try:
                items, more = await self.reader.poll()
            except ConnectionError as exc:
                self.stats.polls += 1
                self._after_failure(str(exc))
                await asyncio.sleep(0.05)
                continue
            except BufferProtocolError as exc:
                log.error("buffered acquisition: %s", exc)
                self._after_failure(str(exc))
                await asyncio.sleep(1.0)
                continue
            self.stats.polls += 1
            self._fails = 0
            for it in items:
                batch = [self._sample(it)] if it.values is not None else self._missing(it)
                for s in batch:
                    self.stats.samples[s.quality] += 1
                    yield s
            await asyncio.sleep(0 if more else max(0.002, min(0.25, self.reader.due_in_s())))


def expected_samples(w, t1: float, t2: float) -> int:
    """Samples a buffered window [t1, t2] should hold: its span over the median spacing of the rows
    (lost samples are rows too; a stretch with no rows at all counts as missing)."""
    if len(w) < 2:
        return max(1, len(w))
    dt = np.diff(np.asarray(w.t, dtype=float))
    dt = dt[dt > 0]
    if dt.size == 0:
        return len(w)
    return max(len(w), round((t2 - t1) / float(np.median(dt))))
