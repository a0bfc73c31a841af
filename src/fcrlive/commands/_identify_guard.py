"""What stands between ``fcrlive identify`` and confident nonsense: logs checked before identification,
errors from identification tied to the files, results that cannot be right not shown as numbers.

- :func:`read_signals`: read each log, check it (:mod:`fcrlive.tso.plausibility`: units, outliers, missing
  samples) and map it to the paper's signals; every problem names its file.
- :func:`identification_error`: an error of the identification stage (which knows signals, not files) as
  one line naming the files and saying what to do.
- :func:`screen_result`: a droop outside :data:`DROOP_RANGE` is not a plant's: DataError (not
  identifiable, with the reason; the units or the log are wrong, so nothing else is shown). A droop, G_1(0),
  max|G_1| or max|S| whose 95 % interval is wider than itself is shown as "not identifiable" (null in the
  JSON) with a warning that says why.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from fcrlive.errors import DataError, UserError

DROOP_RANGE = (0.005, 0.30)
"""Droops a hydro governor can have (0.5-30 %): anything else is a failed identification, not a plant."""


def read_signals(paths: Sequence[Path], rated_mw: float, f0: float) -> list:
    from fcrlive.tso.csvlog import read_log
    from fcrlive.tso.plausibility import check_log
    from fcrlive.tso.signals import plant_signals

    out = []
    for p in paths:
        log = read_log(p)
        check_log(log, rated_mw, f0)
        out.append(plant_signals(log, rated_mw, f0=f0))
    return out


_HINTS = (
    ("of usable data", "give a longer log, or several logs of the unit at once"),
    ("is constant", "a signal does not move: check that InsAcPow and GridFreq are the unit's live values"),
    ("could not identify a PI controller", "give the plant description (--plant PLANT.toml), log at the "
     "controller rate (e.g. 20 ms), or use --method zur"),
    ("needs an excitation", ""),
    ("sine-test", ""),
    ("different sample intervals", "identify logs of one sampling interval together"),
)


def identification_error(exc: UserError, paths: Sequence[Path]) -> UserError:
    """``exc`` with the files named and a hint on what to do (one line)."""
    names = ", ".join(str(p) for p in paths)
    msg = exc.message.replace("\n", " ")
    hint = next((h for key, h in _HINTS if key in msg), None)
    if hint is None:
        hint = "the log does not support this identification; check the log or try another --method"
    where = names if not exc.where else f"{names} ({exc.where})"
    text = f"{msg}: {hint}" if hint and hint not in msg else msg
    return type(exc)(text, where=where)


def _wide(v) -> bool:
    """True when a value with an interval is not a number one can use: missing, non-finite, or its 95 %
    interval wider than its magnitude."""
    if v is None or v.value is None:
        return False
    lo, hi = v.ci95
    if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
        return True
    return (hi - lo) > abs(v.value)


def screen_result(res, paths: Sequence[Path]):
    """The identification with absurd numbers taken out (module docstring); DataError for the droop."""
    rep = res.report
    names = ", ".join(str(p) for p in paths)
    d = rep.droop
    if d is not None and d.value is not None and not (DROOP_RANGE[0] <= d.value <= DROOP_RANGE[1]):
        lo, hi = d.ci95
        interval = "" if lo is None or hi is None else f" [{100 * lo:.3g}, {100 * hi:.3g}]"
        raise DataError(
            f"not identifiable: the droop came out {100 * d.value:.4g} %{interval}, outside the "
            f"{100 * DROOP_RANGE[0]:g}-{100 * DROOP_RANGE[1]:g} % a governor can have; check the log "
            "(units, --rated-mw, gaps, outliers) or give a longer log with more movement of frequency and "
            "power",
            where=names,
        )
    update, warnings, ni = {}, list(rep.warnings), dict(rep.not_identifiable)
    for key, label, scale in (
        ("droop", "droop [%]", 100.0),
        ("g1_static", "G_1(0)", 1.0),
        ("max_abs_g1", "max|G_1|", 1.0),
        ("max_abs_s", "max|S|", 1.0),
    ):
        v = getattr(rep, key)
        if _wide(v):
            lo, hi = (f"{scale * x:.3g}" if x is not None else "?" for x in v.ci95)
            why = (
                f"{label} not identifiable: {scale * v.value:.3g} with a 95 % interval [{lo}, {hi}] wider "
                "than itself (too little movement of frequency and power in the log for it)"
            )
            # the same reason in the quantity and in not_identifiable as the estimators give theirs
            update[key] = v.model_copy(update={"value": None, "ci95": (None, None), "reason": why})
            ni.setdefault(key, why)
            warnings.append(why)
    if not update:
        return res
    from dataclasses import replace

    update.update(warnings=warnings, not_identifiable=ni)
    return replace(res, report=rep.model_copy(update=update))


_MAX_NOTES_PER_LOG = 5


def with_log_notes(res, signals: Sequence) -> object:
    """The identification with each log's own notes (its gaps: filled or split into segments, file name
    and data disagreeing) in the report, file by file, so a reader sees what was done to the data."""
    notes = []
    for sig in signals:
        src = Path(sig.sources[0]).name if sig.sources else "log"
        own = [n for n in sig.notes if n not in res.report.notes]
        gaps = [n for n in own if n.startswith("gap of ")]
        other = [n for n in own if not n.startswith("gap of ")]
        notes += [f"{src}: {n}" for n in other]
        if len(gaps) > _MAX_NOTES_PER_LOG:
            split = sum("log split here" in n for n in gaps)
            notes += [f"{src}: {n}" for n in gaps[:3]]
            notes.append(
                f"{src}: and {len(gaps) - 3} more gaps ({len(gaps) - split} filled, {split} splitting the "
                f"log into {len(sig.segments)} gap-free segments)"
            )
        else:
            notes += [f"{src}: {n}" for n in gaps]
        if len(sig.segments) > 1 and len(gaps) <= _MAX_NOTES_PER_LOG:
            notes.append(
                f"{src}: {len(sig.segments)} gap-free segments, each an experiment of its own (no filter "
                "runs across a gap)"
            )
    if not notes:
        return res
    from dataclasses import replace

    return replace(res, report=res.report.model_copy(update={"notes": [*res.report.notes, *notes]}))
