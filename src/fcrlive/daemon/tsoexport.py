"""Stored samples → a TSO data log (pure): column mapping, good rows only, timestamps on the tick grid.

Mapping (TR Table 19 headers ← register-map signal names):

| header | from | unit |
|---|---|---|
| InsAcPow | power | MW |
| GridFreq | grid_freq | Hz |
| ApplFreqSig | grid_freq − excitation_applied (only when an excitation was applied) | Hz |
| ContOutSig | controller_output | % |
| GuideVane | guide_vane | % |

Only samples with quality OK and finite values in every written column are kept: a bad sample is a
gap in the file (the TSO reader finds gaps by their time stamps). Time stamps are, by default, the
poller's scheduled tick times (``t`` snapped to the run's tick grid by ``seq``), because a TSO log is
read as regularly sampled and arrival jitter is not information; ``timestamps="arrival"`` keeps the
measured arrival times; ``timestamps="device"`` uses the device's own clock (``device_time``), the
right axis for an accelerated simulated governor.
"""

from __future__ import annotations

from datetime import UTC, datetime

import numpy as np

from fcrlive.daemon.store import Window

COLUMN_MAP = {"InsAcPow": "power", "GridFreq": "grid_freq", "ContOutSig": "controller_output",
              "GuideVane": "guide_vane"}
EXCITATION_SIGNAL = "excitation_applied"


def grid_times(w: Window) -> np.ndarray:
    """Tick times [UNIX s]: per run, ``offset + seq·period`` with period and offset fitted robustly
    (medians) to the arrival times."""
    t = w.t.copy()
    runs = w.run if w.run is not None else np.zeros(t.size, dtype=np.int64)
    for r in np.unique(runs):
        m = runs == r
        if np.count_nonzero(m) < 2:
            continue
        ts, sq = w.t[m], w.seq[m]
        ds = np.diff(sq)
        ok = ds > 0
        if not np.any(ok):
            continue
        period = float(np.median(np.diff(ts)[ok] / ds[ok]))
        offset = float(np.median(ts - sq * period))
        t[m] = offset + sq * period
    return t


def window_to_log(w: Window, timestamps: str = "grid"):
    """A :class:`fcrlive.tso.csvlog.TsoLog` of the good samples of ``w`` (DataError when < 2 remain)."""
    from fcrlive.errors import DataError
    from fcrlive.tso.csvlog import TsoLog

    cols: dict[str, np.ndarray] = {}
    for header, name in COLUMN_MAP.items():
        if name in w.signals:
            cols[header] = w.signals[name]
    if "InsAcPow" not in cols or "GridFreq" not in cols:
        raise DataError("the store has no power and grid_freq signals to export")
    exc = w.signals.get(EXCITATION_SIGNAL)
    if exc is not None and np.any(np.nan_to_num(exc) != 0):
        cols["ApplFreqSig"] = w.signals["grid_freq"] - np.nan_to_num(exc)
        cols = {k: cols[k] for k in ("InsAcPow", "GridFreq", "ApplFreqSig", "ContOutSig", "GuideVane")
                if k in cols}
    if timestamps == "device":
        # the device's own clock, anchored at the first arrival: right for an accelerated simulator,
        # whose samples are seconds apart in device time but milliseconds apart on the wall
        t = w.t[0] + (w.t_device - np.nanmin(w.t_device)) if np.any(np.isfinite(w.t_device)) else w.t
    elif timestamps == "grid":
        t = grid_times(w)
    else:
        t = w.t
    keep = w.ok & np.isfinite(t) & np.all([np.isfinite(c) for c in cols.values()], axis=0)
    keep &= np.concatenate(([True], np.diff(t) > 0.0005))  # never two rows in one millisecond
    if np.count_nonzero(keep) < 2:
        raise DataError(f"only {int(np.count_nonzero(keep))} good sample(s) between the given times")
    t = t[keep]
    start = datetime.fromtimestamp(float(t[0]), UTC).replace(tzinfo=None)
    return TsoLog.from_arrays(t - t[0], {k: v[keep] for k, v in cols.items()}, start)
