"""Pacing of the daemon's sources: ticks on absolute deadlines, and the counters each source keeps.

The Modbus and the CAN source both sample at ``poll_hz`` with :func:`paced_ticks` and count what happened
in a :class:`SourceStats` (read by the metrics collector).
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field

from fcrlive.daemon.sample import Quality, Sample, Ticker, empty_values


@dataclass
class SourceStats:
    """Counters of a source since start (read by the metrics collector)."""

    polls: int = 0
    samples: dict[Quality, int] = field(default_factory=lambda: dict.fromkeys(Quality, 0))
    missed_ticks: int = 0
    connects: int = 0
    connect_failures: int = 0
    watchdog_resets: int = 0
    connected: bool = False

    @property
    def reconnects(self) -> int:
        """Successful connects after the first one."""
        return max(0, self.connects - 1)


async def paced_ticks(poll_hz: float, stats: SourceStats, names) -> AsyncIterator[int | Sample]:
    """Ticks on absolute deadlines at ``poll_hz`` (both sources use it): for every tick that was skipped
    because the previous one overran, a MISSING :class:`Sample` (counted in ``stats``; no catch-up
    burst of reads), then the index of the current tick once its deadline has come: poll then."""
    loop = asyncio.get_running_loop()
    ticker = Ticker(loop.time(), 1.0 / poll_hz)
    while True:
        idx, skipped = ticker.advance(loop.time())
        if skipped:
            stats.missed_ticks += skipped
            offset = time.time() - loop.time()
            for k in range(idx - skipped, idx):
                stats.samples[Quality.MISSING] += 1
                yield Sample(ticker.deadline(k) + offset, math.nan, k, empty_values(names), Quality.MISSING)
        wait = ticker.deadline(idx) - loop.time()
        if wait > 0:
            await asyncio.sleep(wait)
        yield idx
