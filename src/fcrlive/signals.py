"""The paper's sampled signals (:class:`PlantSignals`) and the conditioning every data source shares:
the sample interval, gaps, segments, filling and resampling.

Pure: numpy arrays in, frozen dataclasses out, no I/O. The sources are the TSO CSV reader
(:mod:`fcrlive.tso.csvlog`, whose log-to-signals mapping is :mod:`fcrlive.tso.signals`), the daemon's
window store (:mod:`fcrlive.daemon.store`) and its identification plug-in
(:mod:`fcrlive.daemon.identify_plugin`).

**The gap rule**, one for every source: an interval between two consecutive samples is a gap when it is
longer than ``GAP_FACTOR`` = 1.5 times the nominal (median) sample interval. 1.5 is halfway between one
interval (nothing missing) and two (one sample missing), so the first missing sample is caught while
timing jitter of up to half an interval is not taken for a loss; a source that wants the regular
intervals tighter than that checks it itself (the CSV reader refuses intervals off the median by more
than its jitter tolerance). What happens at a gap is the caller's choice, ``max_fill``: gaps of at most
that many missing samples are filled by linear interpolation, longer ones split the data into segments
that no filter may run across. The CSV reader fills up to 3 samples (on the sampling grid); the
daemon's identification fills 1 (its former "2.5 intervals" split is exactly this rule with one sample
filled); the store reports every gap in the window's data quality. Time that does not advance (a
device's clock set back by a restart) always splits.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

GAP_FACTOR = 1.5
"""An interval longer than this many nominal (median) intervals is a gap (module docstring)."""

EXCITATION_THRESHOLD_HZ = 1e-3
"""Peak-to-peak of the excitation (GridFreq − ApplFreqSig in a log, the written or applied excitation
in a daemon window) [Hz] above which the data count as excited (r ≠ 0)."""


def is_excited(excitation_hz: np.ndarray, threshold_hz: float = EXCITATION_THRESHOLD_HZ) -> bool:
    """True when the excitation [Hz] varies by more than ``threshold_hz`` peak to peak."""
    return bool(np.ptp(excitation_hz) > threshold_hz)


@dataclass(frozen=True, eq=False)
class PlantSignals:
    """The paper's sampled signals (Fig. 1) from one source (a log, a daemon window, a simulation), in pu
    on the machine base (frequency in pu of f0)."""

    t: np.ndarray
    """Time since the first sample [s]."""
    Ts: float
    """Nominal sample interval [s]."""
    u: np.ndarray
    """Electrical power deviation ΔPe [pu machine base]."""
    y: np.ndarray
    """Measured frequency deviation [pu of f0] (not detrended)."""
    r: np.ndarray
    """Excitation [pu of f0]: in a log (GridFreq − ApplFreqSig)/f0; zeros when there is none."""
    epsilon: np.ndarray
    """Control error r − y [pu of f0]."""
    c: np.ndarray | None
    """Controller output [pu], None if not measured (ContOutSig in a log)."""
    a: np.ndarray | None
    """Guide-vane position [pu], None if not measured (GuideVane in a log)."""
    rated_mw: float
    f0: float
    """Nominal frequency [Hz]."""
    p0_mw: float
    """Power subtracted from the measured power (InsAcPow in a log) to form u [MW]."""
    has_excitation: bool
    """True when the excitation varies by more than ``EXCITATION_THRESHOLD_HZ`` peak to peak (in a log:
    ApplFreqSig is logged and differs from GridFreq)."""
    filled: np.ndarray
    """True for samples interpolated across a short gap."""
    segments: tuple[tuple[int, int], ...]
    """Half-open gap-free index ranges; identification must not run a filter across a boundary."""
    period_s: float | None = None
    """Sine-test period [s] of the source log, None for operation logs."""
    sources: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()

    @property
    def valid(self) -> np.ndarray:
        """True for measured samples (not filled)."""
        return ~self.filled

    def __len__(self) -> int:
        return int(self.t.shape[0])


# --- sample interval and gaps -----------------------------------------------------------------------


def median_interval(t: np.ndarray) -> float:
    """Nominal sample interval: the median of the intervals that advance [unit of ``t``]; NaN if none."""
    dt = np.diff(t)
    pos = dt[dt > 0]
    return float(np.median(pos)) if pos.size else math.nan


def is_gap(dt: np.ndarray, ts: float) -> np.ndarray:
    """Mask of the intervals ``dt`` that are gaps under the gap rule (``dt > GAP_FACTOR·ts``)."""
    return dt > GAP_FACTOR * ts


def segments_between(breaks: np.ndarray, n: int) -> tuple[tuple[int, int], ...]:
    """Half-open index ranges of ``n`` samples split after each interval index in ``breaks``."""
    bounds = [0, *(int(i) + 1 for i in breaks), n]
    return tuple(pairwise(bounds))


@dataclass(frozen=True, eq=False)
class Gaps:
    """The gaps of a time axis under the gap rule, and which of them are filled or split."""

    ts: float
    """Nominal sample interval [unit of the time axis]."""
    index: np.ndarray
    """Interval index i of each gap (between samples i and i + 1)."""
    missing: np.ndarray
    """Samples missing in each gap at the nominal interval."""
    filled: np.ndarray
    """Per gap: short enough (and on the grid, when asked) to be filled by interpolation."""
    breaks: np.ndarray
    """Interval indices where the data are split: unfilled gaps and time that does not advance."""
    n: int
    """Samples on the time axis."""

    @property
    def segments(self) -> tuple[tuple[int, int], ...]:
        """Half-open gap-free index ranges of the samples (before any filling)."""
        return segments_between(self.breaks, self.n)


def find_gaps(
    t: np.ndarray, *, ts: float | None = None, max_fill: int = 0, tol: float | None = None
) -> Gaps:
    """The gaps of the time axis ``t`` (any unit; int64 microseconds or float seconds).

    ``ts``: nominal interval, default :func:`median_interval`. ``max_fill``: gaps of at most this many
    missing samples are filled. ``tol``: when given, a gap is filled only if its length is a whole number
    of intervals within ``tol`` (a logger on a grid that lost samples); None for sources whose samples
    have arrival jitter and are resampled anyway.
    """
    dt = np.diff(t).astype(np.float64)
    if ts is None:
        ts = median_interval(t)
    index = np.flatnonzero(is_gap(dt, ts))
    k = np.rint(dt[index] / ts).astype(np.int64)
    missing = k - 1
    filled = missing <= max_fill
    if tol is not None:
        filled &= np.abs(dt[index] - k * ts) <= tol
    split = np.zeros(dt.shape, dtype=bool)
    split[index[~filled]] = True
    split |= dt <= 0
    return Gaps(
        ts=float(ts), index=index, missing=missing, filled=filled, breaks=np.flatnonzero(split),
        n=int(np.shape(t)[0]),
    )


# --- filling and resampling -------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Filled:
    """Samples with the short gaps filled: the measured samples unchanged, interpolated ones between."""

    t: np.ndarray
    columns: dict[str, np.ndarray]
    filled: np.ndarray
    """True for the interpolated samples."""
    source: np.ndarray
    """Index of the measured sample at or before each sample (the input's row)."""
    segments: tuple[tuple[int, int], ...]
    """Half-open gap-free ranges of the output, split at the gaps that were not filled."""


def fill_gaps(t: np.ndarray, columns: Mapping[str, np.ndarray], gaps: Gaps) -> Filled:
    """Insert the missing samples of every filled gap of ``gaps`` by linear interpolation in ``t`` and the
    float columns; other columns (identifiers) hold the previous value."""
    n = gaps.n
    fills = [(int(i), int(m) + 1) for i, m, f in zip(gaps.index, gaps.missing, gaps.filled) if f]
    if not fills:
        return Filled(
            t=t, columns=dict(columns), filled=np.zeros(n, dtype=bool), source=np.arange(n),
            segments=gaps.segments,
        )
    # q: each output sample as a fractional index into the input (k sub-intervals per filled gap)
    pieces: list[np.ndarray] = []
    prev = 0
    for i, k in fills:
        pieces.append(np.arange(prev, i + 1, dtype=np.float64))
        pieces.append(i + np.arange(1, k, dtype=np.float64) / k)
        prev = i + 1
    pieces.append(np.arange(prev, n, dtype=np.float64))
    q = np.concatenate(pieces)
    idx = np.arange(n, dtype=np.float64)
    source = np.floor(q).astype(np.int64)
    out = {
        name: np.interp(q, idx, col) if col.dtype.kind == "f" else col[source]
        for name, col in columns.items()
    }
    new_index = np.searchsorted(q, np.arange(n, dtype=np.float64))
    cuts = [int(new_index[i + 1]) for i in gaps.breaks]
    return Filled(
        t=np.interp(q, idx, t), columns=out, filled=q != np.floor(q), source=source,
        segments=tuple(pairwise([0, *cuts, q.size])),
    )


@dataclass(frozen=True, eq=False)
class Resampled:
    """Segments put on a uniform grid and concatenated."""

    t: np.ndarray
    """Grid times [s]; each segment starts 1000 intervals after the previous one ended, so that the
    concatenated axis is visibly not continuous."""
    columns: dict[str, np.ndarray]
    segments: tuple[tuple[int, int], ...]
    """Half-open ranges of the kept segments in the output."""


def resample_uniform(
    t: np.ndarray,
    columns: Mapping[str, np.ndarray],
    ts: float,
    segments: tuple[tuple[int, int], ...],
    min_len: int,
) -> Resampled:
    """Each segment of (``t``, ``columns``) on a grid of interval ``ts`` from its first sample, by linear
    interpolation between neighbouring samples (for samples with arrival jitter). Segments of fewer than
    ``min_len`` grid points are dropped; no segment kept leaves empty arrays."""
    out: dict[str, list[np.ndarray]] = {k: [] for k in columns}
    tgrid: list[np.ndarray] = []
    kept: list[tuple[int, int]] = []
    n_total = 0
    t_offset = 0.0
    for a, b in segments:
        if b - a < 2:
            continue
        tp = t[a:b]
        n = math.floor((tp[-1] - tp[0]) / ts + 1e-9) + 1
        if n < min_len:
            continue
        g = tp[0] + ts * np.arange(n)
        for k, v in columns.items():
            out[k].append(np.interp(g, tp, v[a:b]))
        tgrid.append(g - g[0] + t_offset)
        t_offset += n * ts + 1000.0 * ts
        kept.append((n_total, n_total + n))
        n_total += n
    cat = lambda parts: np.concatenate(parts) if parts else np.zeros(0)  # noqa: E731
    return Resampled(t=cat(tgrid), columns={k: cat(v) for k, v in out.items()}, segments=tuple(kept))


EXCITATION_RESOLUTION_FACTOR = 4.0
"""r counts as an excitation when its rms exceeds this many times the rms of the columns' rounding
(:func:`excitation_detected`)."""


def _resolution(x: np.ndarray) -> float:
    """The quantum of a logged column [its unit]: smallest step between its distinct values (0 when it
    looks continuous, i.e. more distinct values than a quantised column of its range would have)."""
    v = np.unique(np.round(np.asarray(x, float), 9))
    if v.size < 2:
        return 0.0
    q = float(np.min(np.diff(v)))
    return q if q > 1e-8 else 0.0


def excitation_detected(s: PlantSignals) -> bool:
    """Whether r = (GridFreq − ApplFreqSig)/f0 is an excitation and not rounding.

    GridFreq written with 3 decimals and ApplFreqSig with 6 differ by up to 0.5 mHz everywhere: their
    peak-to-peak difference alone (the old test, 1 mHz) took that for an excitation and ran Z_cu on a
    normal-operation log (1.5 pp off). r must exceed the rounding of both columns clearly: rms(r) above
    EXCITATION_RESOLUTION_FACTOR × (q_f + q_a)/√12 (q the columns' quanta) and above 0.1 mHz.
    """
    if not s.has_excitation:
        return False
    f = s.f0 * (1.0 + np.asarray(s.y, float))
    fa = f - s.f0 * np.asarray(s.r, float)
    q = _resolution(f) + _resolution(fa)
    rms = float(np.std(np.asarray(s.r, float)) * s.f0)
    return rms > max(EXCITATION_RESOLUTION_FACTOR * q / np.sqrt(12.0), 1e-4)


# --- the power measurement chain ----------------------------------------------------------------------


def transducer(x: np.ndarray, Ts: float, lag_s: float, delay_s: float) -> np.ndarray:
    """``x`` sampled every ``Ts`` [s] through a first-order lag of time constant ``lag_s`` and a dead time
    of ``delay_s`` [s] (rounded to whole samples): the model of a power transducer's response (the zoo's
    loggers, :mod:`fcrlive.sim.logger`) and of its alignment (:class:`PowerChain`). The lag runs on the
    samples with its exact pole e^(−Ts/T) and unit gain, from rest at the first value; the dead time
    holds the first value before the record."""
    x = np.asarray(x, float)
    out = x.copy()
    if lag_s > 0 and len(x):
        from scipy.signal import lfilter

        a = math.exp(-Ts / lag_s)
        # s[n] = a s[n−1] + x[n] from rest at x[0] (s[−1] = x[0]/(1 − a)), scaled to unit gain
        out = (1.0 - a) * lfilter([1.0], [1.0, -a], x, zi=[a * x[0] / (1.0 - a)])[0]
    k = round(delay_s / Ts)
    if k > 0 and len(out):
        out = np.r_[np.full(min(k, len(out)), out[0]), out[: max(len(out) - k, 0)]]
    return out


@dataclass(frozen=True)
class PowerChain:
    """How the logged power (InsAcPow) lags the frequency and the governor's own columns: a transducer's
    first-order lag ``lag_s`` [s] and a dead time ``delay_s`` [s] (a meter's averaging window, or a
    power column stamped by another device), from the meter's data sheet or a test.

    Why it matters: Z_cu with H forms w = y + G_J u; a power that lags by τ leaves G_J (u_logged − u) ≈
    −(τ/2H) u in w, which the fit of G_jp takes for part of the turbine path. On the zoo's excited 30-min
    controller-rate logs with 0.1 % meter noise (7 plants, 5 seeds) a 0.2 s lag moved max|S| by +3.4 %
    median (from +0.7 %), and 0.5 s with 0.2 s of dead time by +12.5 % with 10 of 22 intervals missing
    the truth; max|G_1| +17 %, 11 of 24 missing (docs/zoo.md).

    :meth:`restore` takes the chain off the power: the exact inverse of the sampled lag, then the power
    advanced by the dead time. It raises the meter's white noise at high frequencies (by up to
    (1 + a)/(1 − a), a = e^(−Ts/T)), which Z_cu with H tolerates: u reaches its fit only through the
    low-pass G_J, as output noise that the controller never saw. Putting the chain on the other signals
    instead (y, c and a through the same lag, u as logged: no noise amplified, every transfer function
    between the signals unchanged) was tried and is wrong in closed loop: it smears the process noise in
    y over past samples that the controller had already answered in c, the bias the block means avoid
    (experiments.ZCU_TS_ID): max|S| +6.5 % and +14.4 % median on the logs above, G_p +2.4/+4.1 %.

    Not given at all (None, as opposed to a chain of 0 and 0: a power known to be aligned), Z_cu with H
    profiles the log for one (:func:`fcrlive.analysis.experiments.power_chain_profile`) and widens its
    intervals by the effect of one it finds."""

    lag_s: float = 0.0
    delay_s: float = 0.0

    def __post_init__(self) -> None:
        for f in ("lag_s", "delay_s"):
            v = getattr(self, f)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                from fcrlive.errors import ConfigError

                raise ConfigError(f"power chain: {f} must be a finite number >= 0 s, got {v}")

    @property
    def active(self) -> bool:
        return self.lag_s > 0 or self.delay_s > 0

    def describe(self) -> str:
        return f"power transducer lag {self.lag_s:g} s, dead time {self.delay_s:g} s"

    def restore(self, s: PlantSignals) -> PlantSignals:
        """``s`` with u taken back through the chain (:meth:`restored`); the other signals as logged."""
        from dataclasses import replace

        if not self.active:
            return s
        return replace(s, u=self.restored(s.u, float(s.Ts), s.segments))

    def restored(self, x: np.ndarray, Ts: float, segments) -> np.ndarray:
        """``x`` (sampled every ``Ts`` [s]) taken back through the chain per gap-free segment: the exact
        inverse of :func:`transducer`'s lag, then advanced by the dead time (the last dead time of each
        segment holds its last value)."""
        x = np.asarray(x, float)
        out = x.copy()
        k = round(self.delay_s / Ts)
        for lo, hi in segments:
            v = x[lo:hi]
            if self.lag_s > 0 and len(v) > 1:
                a = math.exp(-Ts / self.lag_s)
                v = np.r_[v[0], (v[1:] - a * v[:-1]) / (1.0 - a)]
            if k > 0 and len(v):
                v = np.r_[v[min(k, len(v)):], np.full(min(k, len(v)), v[-1])]
            out[lo:hi] = v
        return out
