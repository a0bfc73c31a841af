"""Running statistics of the raw signals between two ``live`` publications (pure, no I/O)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from fcrlive.daemon.payloads import LiveStatsPayload, SignalStats
from fcrlive.daemon.sample import Quality, Sample


@dataclass
class _Welford:
    n: int = 0
    mean: float = 0.0
    m2: float = 0.0
    lo: float = math.inf
    hi: float = -math.inf

    def add(self, x: float) -> None:
        self.n += 1
        d = x - self.mean
        self.mean += d / self.n
        self.m2 += d * (x - self.mean)
        self.lo = min(self.lo, x)
        self.hi = max(self.hi, x)

    def stats(self) -> SignalStats:
        if self.n == 0:
            return SignalStats(mean=None, std=None, min=None, max=None)
        std = math.sqrt(self.m2 / (self.n - 1)) if self.n > 1 else 0.0
        return SignalStats(mean=self.mean, std=std, min=self.lo, max=self.hi)


@dataclass
class LiveStats:
    """Accumulates samples; :meth:`snapshot` returns the payload and starts a new interval.

    Mean/std/min/max use OK samples only; ``signals`` restricts which signals are reported
    (None: all seen).
    """

    t_start: float
    signals: tuple[str, ...] | None = None
    samples: int = 0
    missed: int = 0
    counts: dict[str, int] = field(default_factory=lambda: {q.name.lower(): 0 for q in Quality})
    _acc: dict[str, _Welford] = field(default_factory=dict)

    def add(self, s: Sample) -> None:
        """Count ``s`` and fold its values into the running statistics."""
        self.samples += 1
        self.counts[s.quality.name.lower()] += 1
        if s.quality == Quality.MISSING:
            self.missed += 1
        if s.quality != Quality.OK:
            return
        for name, v in s.values.items():
            if (self.signals is None or name in self.signals) and math.isfinite(v):
                self._acc.setdefault(name, _Welford()).add(v)

    def snapshot(self, t: float) -> LiveStatsPayload:
        """Statistics of [t_start, t]; resets the accumulator to start at ``t``."""
        dt = max(t - self.t_start, 1e-9)
        names = self.signals if self.signals is not None else tuple(self._acc)
        p = LiveStatsPayload(
            t=t, interval_s=dt, samples=self.samples, rate_hz=(self.samples - self.missed) / dt,
            quality=dict(self.counts), missed_ticks=self.missed,
            signals={n: self._acc.get(n, _Welford()).stats() for n in names},
        )
        self.t_start, self.samples, self.missed = t, 0, 0
        self.counts = {q.name.lower(): 0 for q in Quality}
        self._acc = {}
        return p
