"""Map a TSO log to the paper's Fig. 1 signals (:class:`fcrlive.signals.PlantSignals`, pu on the machine
base) and a simulation back to a log.

Signals, with f0 the nominal frequency [Hz] and rated_mw the unit's rating [MW]:

- ``u = (InsAcPow − P0)/rated_mw``: electrical power deviation ΔPe [pu]; P0 is the mean power unless
  given (the value used is kept in :attr:`PlantSignals.p0_mw`).
- ``y = (GridFreq − f0)/f0``: the frequency the governor would see in normal operation [pu].
- ``r = (GridFreq − ApplFreqSig)/f0`` when the applied frequency is logged, else 0 [pu]: during a test the
  governor sees ApplFreqSig instead of the grid, so its input differs from the grid by −r.
- ``epsilon = r − y = (f0 − ApplFreqSig)/f0`` (applied frequency logged), else ``−y`` [pu]: the control
  error the governor acts on.
- ``c = ContOutSig·cont_out_scale`` and ``a = GuideVane·guide_vane_scale`` [pu] when logged (default scale
  1/100: % of full gate demand / full opening).

Detrending is left to the identification; nothing here removes means other than P0.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

import numpy as np

from fcrlive.constants import F0_HZ
from fcrlive.errors import DataError
from fcrlive.signals import EXCITATION_THRESHOLD_HZ, PlantSignals, is_excited
from fcrlive.tso.csvlog import TsoLog


def plant_signals(
    log: TsoLog,
    rated_mw: float,
    *,
    f0: float = F0_HZ,
    p0_mw: float | None = None,
    cont_out_scale: float = 0.01,
    guide_vane_scale: float = 0.01,
    excitation_threshold_hz: float = EXCITATION_THRESHOLD_HZ,
) -> PlantSignals:
    """The paper's signals from a TSO log (see the module docstring for the formulas).

    ``rated_mw``: the unit's rating [MW] (the machine base). ``p0_mw``: operating-point power [MW];
    None uses the mean of the measured InsAcPow samples. ``cont_out_scale``/``guide_vane_scale``: pu per
    logged unit of ContOutSig/GuideVane (0.01 for %). Raises DataError when power or frequency is
    missing, or ``rated_mw``/``f0`` are not positive.
    """
    where = log.source()
    if not rated_mw > 0:
        raise DataError(f"rated power must be positive, got {rated_mw!r} MW", where=where)
    if not f0 > 0:
        raise DataError(f"nominal frequency must be positive, got {f0!r} Hz", where=where)
    missing = [c for c in ("InsAcPow", "GridFreq") if c not in log.columns]
    if missing:
        raise DataError(
            f"missing required column{'s' if len(missing) > 1 else ''} {', '.join(missing)}", where
        )
    p = _numeric(log, "InsAcPow")
    f = _numeric(log, "GridFreq")
    notes = list(log.notes)
    if p0_mw is None:
        p0_mw = float(np.mean(p[log.valid]))
    u = (p - p0_mw) / rated_mw
    y = (f - f0) / f0
    if "ApplFreqSig" in log.columns:
        fa = _numeric(log, "ApplFreqSig")
        r = (f - fa) / f0
        epsilon = (f0 - fa) / f0
        has_excitation = is_excited(f - fa, excitation_threshold_hz)
        if not has_excitation:
            notes.append(
                f"ApplFreqSig follows GridFreq within {excitation_threshold_hz * 1e3:g} mHz: no excitation"
            )
    else:
        r = np.zeros_like(y)
        epsilon = -y
        has_excitation = False
        notes.append("no ApplFreqSig column: r = 0, epsilon = -y (no excitation)")
    c = _numeric(log, "ContOutSig") * cont_out_scale if "ContOutSig" in log.columns else None
    a = _numeric(log, "GuideVane") * guide_vane_scale if "GuideVane" in log.columns else None
    return PlantSignals(
        t=log.t_s.copy(),
        Ts=float(log.sample_s),
        u=u,
        y=y,
        r=r,
        epsilon=epsilon,
        c=c,
        a=a,
        rated_mw=float(rated_mw),
        f0=float(f0),
        p0_mw=float(p0_mw),
        has_excitation=has_excitation,
        filled=log.filled.copy(),
        segments=log.segments,
        period_s=log.period_s,
        sources=(log.source(),),
        notes=tuple(notes),
    )


def _numeric(log: TsoLog, name: str) -> np.ndarray:
    col = log.columns[name]
    if col.dtype.kind != "f":
        raise DataError(f"column {name} is not numeric", where=log.source())
    if not np.all(np.isfinite(col)):
        raise DataError(f"column {name} has empty or non-finite values", where=log.source())
    return col


# --- simulation -> log ------------------------------------------------------------------------------

DEFAULT_START = datetime(2026, 11, 1, 0, 0, 0)
"""Start time written into simulated logs when none is given (UTC)."""


def _decimation(t: np.ndarray, sample_s: float | None) -> int:
    """Keep every k-th sample so that the interval becomes ``sample_s`` [s]."""
    if sample_s is None:
        return 1
    dt = float(np.median(np.diff(t)))
    k = round(sample_s / dt)
    if k < 1 or abs(k * dt - sample_s) > 1e-6 * sample_s:
        raise ValueError(f"sample interval {sample_s} s is not a whole multiple of the simulation's {dt} s")
    return k


def log_from_sim(
    result: Any,
    *,
    start: datetime = DEFAULT_START,
    sample_s: float | None = None,
    excitation: bool | None = None,
) -> TsoLog:
    """A TSO log of a simulation result (``fcrlive.sim.SimResult``).

    Columns: ``InsAcPow = pe_mw`` [MW]; ``GridFreq = f0·(1 + y)`` [Hz], i.e. the governor's sampled
    speed of unit 1 written as a frequency, NOT the simulated grid (bus) frequency, so that
    identification from the file sees exactly the y of the simulation; ``ApplFreqSig = f0·(1 + y − r)``
    [Hz] when excitation was used (then epsilon from the file equals the simulated epsilon);
    ``ContOutSig = 100·c`` and ``GuideVane = 100·a`` [%]. ``sample_s`` picks every k-th sample (a logger
    samples, it does not filter); it must be a whole multiple of the simulation step. ``excitation``
    None: write ApplFreqSig when r is not all zero.
    """
    t = np.asarray(result.t, dtype=np.float64)
    k = _decimation(t, sample_s)
    sel = slice(None, None, k)
    f0 = float(getattr(result, "f0", F0_HZ))
    y = np.asarray(result.y, dtype=np.float64)
    r = np.asarray(getattr(result, "r", np.zeros_like(y)), dtype=np.float64)
    if excitation is None:
        excitation = bool(np.any(r != 0))
    cols: dict[str, np.ndarray] = {
        "InsAcPow": np.asarray(result.pe_mw, dtype=np.float64)[sel],
        "GridFreq": (f0 * (1.0 + y))[sel],
    }
    if excitation:
        cols["ApplFreqSig"] = (f0 * (1.0 + y - r))[sel]
    for name, attr in (("ContOutSig", "c"), ("GuideVane", "a")):
        v = getattr(result, attr, None)
        if v is not None:
            cols[name] = 100.0 * np.asarray(v, dtype=np.float64)[sel]
    return TsoLog.from_arrays(t[sel], cols, start)


def log_from_sine(result: Any, *, start: datetime = DEFAULT_START, sample_s: float | None = None) -> TsoLog:
    """A sine-test TSO log (period-suffixed headers) of ``fcrlive.sim.SineTestResult``.

    ``InsAcPow = pe_mw``, ``GridFreq = grid_freq_hz``, ``ApplFreqSig = applied_freq_hz`` (the artificial
    frequency fed to the governor), ``ContOutSig = 100·c``, ``GuideVane = 100·a``.
    """
    t = np.asarray(result.t, dtype=np.float64)
    k = _decimation(t, sample_s)
    sel = slice(None, None, k)
    cols: dict[str, np.ndarray] = {
        "InsAcPow": np.asarray(result.pe_mw, dtype=np.float64)[sel],
        "GridFreq": np.asarray(result.grid_freq_hz, dtype=np.float64)[sel],
        "ApplFreqSig": np.asarray(result.applied_freq_hz, dtype=np.float64)[sel],
    }
    for name, attr in (("ContOutSig", "c"), ("GuideVane", "a")):
        v = getattr(result, attr, None)
        if v is not None:
            cols[name] = 100.0 * np.asarray(v, dtype=np.float64)[sel]
    return TsoLog.from_arrays(t[sel], cols, start, period_s=float(result.period_s))
