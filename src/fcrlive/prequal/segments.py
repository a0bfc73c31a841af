"""The applied-frequency profile of a test cut into plateaus and the changes between them, and the
integrals the time-domain requirements use. Pure numpy.

A plateau is a maximal run of samples within ``tol_hz`` of its first sample lasting at least
``min_s``; its level is the median. A change (step or ramp) starts where a plateau ends: for a ramp the
start is extrapolated back along the ramp's measured slope to the old level, so a ramp sampled at
10 Hz starting between two samples still gets its exact start time (Req. 2-4 read the power 4.4 s and
7.5 s after it).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import median_filter

LEVEL_TOL_HZ = 0.004
"""A plateau's samples stay within this of its first sample [Hz]: below half of the closest two levels
of any TR profile (49.89 vs 49.90 Hz, ramps 4 and 8)."""


@dataclass(frozen=True)
class Plateau:
    """Samples ``i0``..``i1 - 1`` at ``level`` [Hz]; ``t0`` the change into it started, ``t_end`` the
    last sample of it [s]."""

    level: float
    i0: int
    i1: int
    t_change: float
    """Start of the change (step or ramp) that led into this plateau [s]; the first sample for the first."""
    t_first: float
    """First sample on the level [s]."""
    t_end: float
    """Last sample on the level [s]."""

    @property
    def duration_s(self) -> float:
        return self.t_end - self.t_change


def plateaus(
    t: np.ndarray, f: np.ndarray, *, tol_hz: float = LEVEL_TOL_HZ, min_s: float = 0.5
) -> list[Plateau]:
    """The plateaus of ``f`` (see the module docstring), merged when two in a row share a level.

    Runs are found on a 5-sample running median of ``f`` (which leaves a noise-free piecewise-monotone
    profile unchanged and keeps a measured applied frequency's noise from splitting a level); a sample
    belongs to a run while it stays within ``tol_hz`` of the run's mean.
    """
    t = np.asarray(t, float)
    f = np.asarray(f, float)
    fs = median_filter(f, size=5, mode="nearest") if f.size >= 5 else f
    n = len(f)
    runs: list[tuple[int, int]] = []
    i = 0
    while i < n:
        total, j = fs[i], i + 1
        while j < n and abs(fs[j] - total / (j - i)) <= tol_hz:
            total += fs[j]
            j += 1
        if t[j - 1] - t[i] >= min_s:
            runs.append((i, j))
        i = j
    merged: list[tuple[int, int]] = []
    for a, b in runs:
        # one plateau split by a short spike (not by a ramp away and back: ramps 1-2 of Table 4)
        if merged:
            pa, pb = merged[-1]
            level = np.median(f[pa:pb])
            gap = fs[pb:a]
            if (
                abs(np.median(f[a:b]) - level) <= tol_hz
                and t[a] - t[pb - 1] <= 1.0
                and (gap.size == 0 or np.max(np.abs(gap - level)) <= 5 * tol_hz)
            ):
                merged[-1] = (pa, b)
                continue
        merged.append((a, b))
    out: list[Plateau] = []
    for k, (a, b) in enumerate(merged):
        level = float(np.median(f[a:b]))
        if k == 0:
            t_change = float(t[a])
        else:
            prev_level = out[-1].level
            pb = merged[k - 1][1]  # first sample after the previous plateau
            t_change = _change_start(t, f, pb, a, prev_level, level, tol_hz)
        out.append(Plateau(level, a, b, t_change, float(t[a]), float(t[b - 1])))
    return out


def _change_start(
    t: np.ndarray, f: np.ndarray, j: int, m: int, old_level: float, new_level: float, tol_hz: float
) -> float:
    """Start of the change from ``old_level`` to ``new_level`` whose first sample off the old plateau is
    ``j`` and first sample on the new one ``m``."""
    seg = slice(j, m)
    on_ramp = (np.abs(f[seg] - old_level) > 3 * tol_hz) & (np.abs(f[seg] - new_level) > 3 * tol_hz)
    if on_ramp.sum() >= 3:
        # a line through the samples clearly on the ramp (least squares: a measured applied frequency is
        # noisy), back to the old level; exact for a sampled linear ramp
        tt, ff = t[seg][on_ramp], f[seg][on_ramp]
        slope, icpt = np.polyfit(tt - tt[0], ff, 1)
        if slope != 0:
            return float(tt[0] + (old_level - icpt) / slope)
    if m - j >= 2:
        slope = (f[m - 1] - f[j]) / (t[m - 1] - t[j])
        if slope != 0:
            return float(t[j] - (f[j] - old_level) / slope)
    if m - j == 1 and m < len(f):
        # one sample on the ramp: the slope from it to the first sample on the new level
        slope = (f[m] - f[j]) / (t[m] - t[j])
        if slope != 0:
            return float(max(t[j - 1], t[j] - (f[j] - old_level) / slope))
    return float(t[j] if m > j else t[j - 1] if j > 0 else t[j])


def match_levels(
    found: Sequence[Plateau], levels: Sequence[float], *, tol_hz: float = LEVEL_TOL_HZ
) -> list[Plateau] | None:
    """The plateaus matching ``levels`` in order (a subsequence of ``found``), or None."""
    out: list[Plateau] = []
    k = 0
    for lv in levels:
        while k < len(found) and abs(found[k].level - lv) > tol_hz:
            k += 1
        if k == len(found):
            return None
        out.append(found[k])
        k += 1
    return out


# --------------------------------------------------------------------------------------------------
# Reading the power


def mean_window(t: np.ndarray, y: np.ndarray, a: float, b: float) -> float:
    """Time average of the linear interpolant of ``y`` over [a, b] [same unit as y]."""
    if b <= a:
        return float(np.interp(a, t, y))
    return integrate(t, y, a, b) / (b - a)


def integrate(t: np.ndarray, y: np.ndarray, a: float, b: float) -> float:
    """∫_a^b of the linear interpolant of ``y`` (exact for piecewise-linear data) [unit of y · s]."""
    tt, yy = _window(t, y, a, b)
    return float(np.sum(0.5 * (yy[1:] + yy[:-1]) * np.diff(tt)))


def _window(t: np.ndarray, y: np.ndarray, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    inner = (t > a) & (t < b)
    tt = np.concatenate(([a], t[inner], [b]))
    yy = np.concatenate(([np.interp(a, t, y)], y[inner], [np.interp(b, t, y)]))
    return tt, yy


def max_running_integral(t: np.ndarray, y: np.ndarray, a: float, b: float) -> tuple[float, float]:
    """max over k ∈ [a, b] of ∫_a^k y dt and the k where it is reached (Req. 4), exact for the linear
    interpolant: the zero crossings of y, where the running integral peaks, are added to the grid."""
    tt, yy = _window(t, y, a, b)
    cross = np.flatnonzero((yy[:-1] > 0) & (yy[1:] < 0))
    if cross.size:
        tc = tt[cross] + yy[cross] / (yy[cross] - yy[cross + 1]) * (tt[cross + 1] - tt[cross])
        tt = np.insert(tt, cross + 1, tc)
        yy = np.insert(yy, cross + 1, 0.0)
    run = np.concatenate(([0.0], np.cumsum(0.5 * (yy[1:] + yy[:-1]) * np.diff(tt))))
    k = int(np.argmax(run))
    return float(run[k]), float(tt[k])


def moving_average(t: np.ndarray, y: np.ndarray, width_s: float) -> np.ndarray:
    """Trailing moving average over ``width_s`` at every sample (TR eq. 13: the last k samples); the
    first samples average what there is."""
    dt = float(np.median(np.diff(t)))
    k = max(1, round(width_s / dt))
    c = np.concatenate(([0.0], np.cumsum(y)))
    idx = np.arange(1, len(y) + 1)
    lo = np.maximum(idx - k, 0)
    return (c[idx] - c[lo]) / (idx - lo)
