"""Is a log what it says it is? Units, single-sample outliers and missing samples, before identification.

A log that parses can still be wrong in ways that give confident nonsense: GridFreq written in mHz,
InsAcPow in kW (or a wrong ``--rated-mw``), one corrupt sample (1e30), a tenth of the rows missing. Each
check raises :class:`fcrlive.errors.DataError` naming the file, the rows where it applies, and what to do.
Pure: a :class:`~fcrlive.tso.csvlog.TsoLog` in, nothing out.

The rules (constants below):

- frequency columns (GridFreq, ApplFreqSig): the median within ``f0 ± FREQ_BAND_HZ``, and every sample;
- InsAcPow: the 99th percentile of |P| within ``POWER_LIMIT`` × rated, and every sample;
- single-sample outliers in every signal column: a sample that jumps away from both neighbours, in opposite
  directions, farther from the line through them than ``SPIKE_SPREAD`` × the column's robust range (0.5 to
  99.5 percentile), ``SPIKE_MAD`` × the robust spread (1.4826·MAD) of that distance over the log, and 3
  steps of the logger's resolution. A step (one jump) is not an outlier, nor is a one-sample pulse of an
  excitation (at most the range): about 10 standard deviations on white noise;
- missing samples: at most ``MAX_MISSING_FRACTION`` of the samples on the sampling grid, whether filled
  or split into segments: a log that lost more (a lossy export, threshold-based logging) is not a regularly
  sampled record and is refused rather than interpolated.
"""

from __future__ import annotations

import numpy as np

from fcrlive.errors import DataError
from fcrlive.tso.csvlog import SIGNAL_COLUMNS, TsoLog

FREQ_BAND_HZ = 5.0
"""Frequencies farther than this from f0 [Hz] are not a grid's (45-55 Hz at 50 Hz)."""

POWER_LIMIT = 1.5
"""|InsAcPow| above this multiple of the rated power is not the unit's [pu]."""

SPIKE_SPREAD = 1.5
SPIKE_MAD = 8.0

MAX_MISSING_FRACTION = 0.01
"""Largest fraction of samples that may be missing on the sampling grid."""

_MAX_ROWS_LISTED = 5


def check_log(log: TsoLog, rated_mw: float, f0: float = 50.0) -> None:
    """DataError (one line: file, rows, what to do) when the log fails one of the module's rules."""
    where = log.source()
    _check_missing(log, where)
    with np.errstate(all="ignore"):
        for name in ("GridFreq", "ApplFreqSig"):
            if name in log.columns:
                _check_frequency(log, name, f0, where)
        if "InsAcPow" in log.columns:
            _check_power(log, rated_mw, where)
        for name in SIGNAL_COLUMNS:
            col = log.columns.get(name)
            if col is not None and col.dtype.kind == "f":
                _check_spikes(log, name, where)


def _rows(log: TsoLog, idx: np.ndarray) -> str:
    rows = [str(int(log.rows[i])) for i in idx[:_MAX_ROWS_LISTED]]
    more = f" and {idx.size - _MAX_ROWS_LISTED} more" if idx.size > _MAX_ROWS_LISTED else ""
    return f"row{'s' if idx.size > 1 else ''} {', '.join(rows)}{more}"


def _check_missing(log: TsoLog, where: str) -> None:
    missing = sum(g.missing for g in log.gaps)
    total = len(log) + sum(g.missing for g in log.gaps if not g.filled)
    if total and missing > MAX_MISSING_FRACTION * total:
        raise DataError(
            f"{missing} of {total} samples ({100 * missing / total:.1f} %) are missing in {len(log.gaps)} "
            f"gaps at the {log.sample_s:g} s sampling interval: not a regularly sampled log, and "
            "interpolating across that many gaps would make up the data (at most "
            f"{100 * MAX_MISSING_FRACTION:g} % may be missing): export the log without losses, or cut it to "
            "its gap-free stretches",
            where=where,
        )


def _check_frequency(log: TsoLog, name: str, f0: float, where: str) -> None:
    x = log.columns[name]
    med = float(np.median(x))
    if abs(med - f0) > FREQ_BAND_HZ:
        if abs(med / 1000.0 - f0) <= FREQ_BAND_HZ:
            hint = f"{name} looks like mHz: the TSO format wants Hz (divide by 1000)"
        elif abs(med * f0 - f0) <= FREQ_BAND_HZ:
            hint = f"{name} looks like per unit: the TSO format wants Hz"
        elif abs(med) <= FREQ_BAND_HZ:
            hint = f"{name} looks like a deviation from {f0:g} Hz: the TSO format wants the frequency in Hz"
        else:
            hint = f"is it the right column, or is --f0 {f0:g} wrong?"
        raise DataError(
            f"column {name}: median {med:.6g} Hz, far outside {f0 - FREQ_BAND_HZ:g}-{f0 + FREQ_BAND_HZ:g} "
            f"Hz: {hint}",
            where=where,
        )
    bad = np.flatnonzero(np.abs(x - f0) > FREQ_BAND_HZ)
    if bad.size:
        raise DataError(
            f"column {name}: {bad.size} sample{'s' if bad.size > 1 else ''} outside "
            f"{f0 - FREQ_BAND_HZ:g}-{f0 + FREQ_BAND_HZ:g} Hz ({_rows(log, bad)}, e.g. {x[bad[0]]:.6g} Hz): "
            "corrupt samples; fix or remove those rows",
            where=where,
        )


def _check_power(log: TsoLog, rated_mw: float, where: str) -> None:
    p = log.columns["InsAcPow"]
    limit = POWER_LIMIT * rated_mw
    p99 = float(np.percentile(np.abs(p), 99))
    if p99 > limit:
        ratio = p99 / rated_mw
        hint = (
            "InsAcPow looks like kW, or --rated-mw is wrong" if ratio > 100 else "is --rated-mw right?"
        )
        raise DataError(
            f"column InsAcPow: |power| reaches {p99:.6g} MW, {ratio:.3g} times the rated {rated_mw:g} MW "
            f"(at most {POWER_LIMIT:g} times is plausible): {hint}",
            where=where,
        )
    bad = np.flatnonzero(np.abs(p) > limit)
    if bad.size:
        raise DataError(
            f"column InsAcPow: {bad.size} sample{'s' if bad.size > 1 else ''} beyond ±{limit:g} MW "
            f"({POWER_LIMIT:g} times the rated {rated_mw:g} MW; {_rows(log, bad)}, e.g. {p[bad[0]]:.6g} MW): "
            "corrupt samples; fix or remove those rows, or check --rated-mw",
            where=where,
        )


def spikes(x: np.ndarray) -> np.ndarray:
    """Indices of single-sample outliers in ``x`` (module docstring)."""
    n = x.size
    if n < 5:
        return np.empty(0, dtype=np.int64)
    with np.errstate(all="ignore"):
        lo, hi = np.percentile(x, [0.5, 99.5])
        d = np.diff(x)
        dev = x[1:-1] - 0.5 * (x[:-2] + x[2:])  # away from the line through the neighbours
        sd = 1.4826 * float(np.median(np.abs(dev - np.median(dev))))
        steps = np.abs(d[d != 0])
        quantum = float(steps.min()) if steps.size else 0.0  # a logger's resolution: one step is no spike
        med = float(np.median(x))
        thr = max(SPIKE_SPREAD * float(hi - lo), SPIKE_MAD * sd, 3.0 * quantum, 1e-9 * max(1.0, abs(med)))
        d1, d2 = d[:-1], d[1:]
        mid = (np.abs(dev) > thr) & (np.abs(d1) > thr / 2) & (np.abs(d2) > thr / 2)
        mid &= np.sign(d1) != np.sign(d2)
        idx = np.flatnonzero(mid) + 1
        ends = [i for i, j in ((0, 1), (n - 1, n - 2)) if abs(x[i] - x[j]) > thr and abs(x[i] - med) > thr]
    return np.union1d(idx, np.asarray(ends, dtype=np.int64)).astype(np.int64)


def _check_spikes(log: TsoLog, name: str, where: str) -> None:
    x = log.columns[name]
    bad = spikes(x)
    if bad.size:
        neighbour = x[bad[0] - 1] if bad[0] > 0 else x[bad[0] + 1]
        raise DataError(
            f"column {name}: {bad.size} single-sample outlier{'s' if bad.size > 1 else ''} "
            f"({_rows(log, bad)}: {x[bad[0]]:.6g} next to {neighbour:.6g}): corrupt samples would bias the "
            "identification; fix or remove those rows",
            where=where,
        )
