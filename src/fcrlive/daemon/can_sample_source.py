"""Every controller sample over CAN: one CAN FD frame per sample with a rolling counter (``GOV_Sample``).

The governor-side contract is docs/buffered-acquisition.md ("CAN"); the frame is in
``sim_device/fcrlive_sim.dbc``. ``[source.can] acquisition = "per_sample"`` selects this source instead of
the snapshot sampler (:mod:`fcrlive.daemon.can_source`). Every frame becomes one :class:`Sample`, in
counter order:

* ``seq`` = the unwrapped counter, ``t_device`` = counter × ``controller_tc_s``, ``t_wall`` = arrival
  (CAN delivers a frame within a millisecond or two of its controller cycle);
* a jump of the counter by k > 1 = k − 1 lost frames: one MISSING sample each (never interpolated);
* a frame with a counter already seen (a repeated frame) is dropped; a counter far back (more than
  ``RESTART_BACK`` samples) is a restart of the governor, counted, and the new run is taken as it comes.

The frame's signals are called ``seq_<field>``; the samples carry ``<field>`` (the same names as the
Modbus ring buffer's slots), plus ``sample_counter`` and ``device_time``.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path

from fcrlive.canbus import close_bus, open_bus_retrying
from fcrlive.daemon.can_source import load_dbc
from fcrlive.daemon.pacing import SourceStats
from fcrlive.daemon.sample import COUNTER_NAME, DEVICE_TIME_NAME, Quality, Sample
from fcrlive.modbus.ringlayout import counter_delta

log = logging.getLogger("fcrlive.can_sample")

SAMPLE_MESSAGE = "GOV_Sample"
COUNTER_SIGNAL = "seq_counter"
PREFIX = "seq_"
RESTART_BACK = 1000
"""A counter this many samples behind the last one is a restart, not a late frame."""
MAX_MISSING_ROWS = 200_000


def sample_fields(dbc: str | Path) -> tuple[str, ...]:
    """The per-sample frame's value fields (signal names without ``seq_``)."""
    m = load_dbc(dbc).get_message_by_name(SAMPLE_MESSAGE)
    return tuple(s.name[len(PREFIX):] for s in m.signals if s.name != COUNTER_SIGNAL)


def per_sample_signals(dbc: str | Path) -> tuple[str, ...]:
    """Stored signals of this source."""
    return (COUNTER_NAME, DEVICE_TIME_NAME, *sample_fields(dbc))


@dataclass
class CanSampleStats(SourceStats):
    frames: int = 0
    lost: int = 0
    gaps: int = 0
    duplicates: int = 0
    restarts: int = 0


class CanSampleSource:
    """``async with CanSampleSource(interface, channel, dbc, tc_s) as src: async for s in src.samples()``."""

    def __init__(self, interface: str, channel: str, dbc: str | Path, tc_s: float, bitrate: int | None = None,
                 backoff_max_s: float = 5.0):
        self.interface, self.channel, self.tc_s = interface, channel, float(tc_s)
        self.bitrate, self.backoff_max_s = bitrate, backoff_max_s
        self.msg = load_dbc(dbc).get_message_by_name(SAMPLE_MESSAGE)
        self.fields = sample_fields(dbc)
        self.names = (COUNTER_NAME, DEVICE_TIME_NAME, *self.fields)
        self.stats = CanSampleStats()
        self.bus = None
        self._notifier = None
        self._opener: asyncio.Task | None = None
        self._q: asyncio.Queue = asyncio.Queue()
        self._last: int | None = None  # unwrapped counter of the last sample emitted
        self._last_t = math.nan

    async def __aenter__(self) -> CanSampleSource:
        self._opener = asyncio.create_task(self._open_loop(), name="can-sample-open")
        return self

    async def __aexit__(self, *exc) -> None:
        if self._opener is not None:
            self._opener.cancel()
            await asyncio.gather(self._opener, return_exceptions=True)
        close_bus(self._notifier, self.bus)
        self._notifier = self.bus = None
        self.stats.connected = False

    async def _open_loop(self) -> None:
        self.bus, self._notifier = await open_bus_retrying(
            self.interface, self.channel, self.bitrate, self._on_message, self.stats, log,
            backoff_max_s=self.backoff_max_s, fd=self.interface == "socketcan",
        )

    def _on_message(self, msg) -> None:
        if msg.arbitration_id != self.msg.frame_id or msg.is_error_frame:
            return
        try:
            d = self.msg.decode(msg.data, decode_choices=False)
        except Exception:  # a malformed frame: counted as lost through the counter gap
            return
        self.stats.frames += 1
        self._q.put_nowait((time.time(), d))

    def _to_samples(self, t: float, d: dict) -> list[Sample]:
        c32 = int(d[COUNTER_SIGNAL])
        values = tuple(float(d[PREFIX + f]) for f in self.fields)
        if self._last is None:
            n = c32
        else:
            delta = counter_delta(c32, self._last)
            if delta <= 0 and -delta < RESTART_BACK:
                self.stats.duplicates += 1
                return []
            if delta <= 0:
                self.stats.restarts += 1
                log.warning("CAN per-sample frames: the governor restarted (counter %d after %d)", c32,
                            self._last & 0xFFFFFFFF)
                n = c32
            else:
                n = self._last + delta
        out: list[Sample] = []
        if self._last is not None and n > self._last + 1:
            lost = n - self._last - 1
            self.stats.lost += lost
            self.stats.gaps += 1
            nan = dict.fromkeys(self.names, math.nan)
            first = n - min(lost, MAX_MISSING_ROWS)
            # when they would have arrived: between the neighbours (times only, the values stay NaN)
            t0 = self._last_t if math.isfinite(self._last_t) else t
            out += [Sample(t0 + (t - t0) * (k - self._last) / (n - self._last), k * self.tc_s, k, nan,
                           Quality.MISSING, detail="lost") for k in range(first, n)]
        self._last, self._last_t = n, t
        vals = {COUNTER_NAME: float(c32), DEVICE_TIME_NAME: n * self.tc_s}
        vals.update(zip(self.fields, values, strict=True))
        q = Quality.OK if all(math.isfinite(v) for v in values) else Quality.DECODE_ERROR
        out.append(Sample(t, n * self.tc_s, n, vals, q))
        return out

    async def samples(self) -> AsyncIterator[Sample]:
        """Every frame's sample (and lost ones as MISSING), forever."""
        while True:
            t, d = await self._q.get()
            for s in self._to_samples(t, d):
                self.stats.samples[s.quality] += 1
                yield s
