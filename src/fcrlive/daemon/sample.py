"""The sampler's output: one :class:`Sample` per tick, with a quality flag (pure parts, no I/O).

Every source (Modbus, CAN) emits exactly one sample per scheduled tick, so the stored time series
is on a regular grid and gaps are explicit: a tick the poller could not serve (it was still busy
with an earlier read) becomes a ``MISSING`` sample with NaN values, a failed read a ``COMM_ERROR``
sample. Identification code then sees NaN/quality instead of silently irregular time.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import IntEnum


class Quality(IntEnum):
    """Per-sample quality; stored as a small integer in SQLite (values are part of the file format)."""

    OK = 0
    STALE = 1
    """the device did not produce a new value (``sample_counter`` unchanged, CAN signal too old)"""
    MISSING = 2
    """the tick was skipped because the previous read overran its period"""
    DECODE_ERROR = 3
    """a value decoded to NaN/inf or could not be decoded"""
    COMM_ERROR = 4
    """no answer (timeout, connection down, exception response)"""


@dataclass(frozen=True)
class Sample:
    """One sample of all signals.

    ``t_wall``: UNIX time of arrival of the (last) response [s]; for MISSING samples the scheduled
    tick time. ``t_device``: the device's own clock [s] when the map has ``device_time``, else NaN.
    ``seq``: tick index since the source started (consecutive; a jump never happens, skipped ticks
    are MISSING samples). ``values``: engineering values by signal name (NaN when unavailable).
    ``latency_s``: request-to-response time of the poll [s] (NaN when no read was made).
    """

    t_wall: float
    t_device: float
    seq: int
    values: Mapping[str, float]
    quality: Quality
    latency_s: float = math.nan
    detail: str = field(default="", compare=False)


COUNTER_NAME = "sample_counter"
DEVICE_TIME_NAME = "device_time"


def classify(values: Mapping[str, float], previous_counter: float | None) -> Quality:
    """Quality of a successfully read sample: DECODE_ERROR on NaN/inf, STALE when the device's
    ``sample_counter`` did not advance since ``previous_counter``, else OK."""
    if any(not math.isfinite(v) for v in values.values()):
        return Quality.DECODE_ERROR
    counter = values.get(COUNTER_NAME)
    if counter is not None and previous_counter is not None and counter == previous_counter:
        return Quality.STALE
    return Quality.OK


def empty_values(names) -> dict[str, float]:
    """All-NaN values for ``names`` (MISSING / COMM_ERROR samples)."""
    return dict.fromkeys(names, math.nan)


@dataclass
class Ticker:
    """Absolute-deadline schedule at ``period`` s from ``t0`` (loop.time() units).

    ``next_tick(now)`` returns the index of the tick to serve now and how many ticks were skipped
    since the previous one: when a read overran, the missed ticks are skipped, never served in a
    burst (a burst would sample the same device state several times).
    """

    t0: float
    period: float
    index: int = -1

    def deadline(self, index: int) -> float:
        """Scheduled time of tick ``index``."""
        return self.t0 + index * self.period

    def advance(self, now: float) -> tuple[int, int]:
        """``(tick index to serve, number of skipped ticks)`` given the current time ``now``.

        The tick served is the latest whose deadline has passed (or the next one when none has).
        """
        due = max(self.index + 1, math.floor((now - self.t0) / self.period + 1e-9))
        skipped = due - self.index - 1
        self.index = due
        return due, skipped
