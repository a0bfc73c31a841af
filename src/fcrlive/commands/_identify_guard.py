"""What stands between ``fcrlive identify`` and confident nonsense: logs checked before identification,
errors from identification tied to the files, results that cannot be right not shown as numbers.

- :func:`read_signals`: read each log, check it (:mod:`fcrlive.tso.plausibility`: units, outliers, missing
  samples) and map it to the paper's signals; every problem names its file.
- :func:`identification_error`: an error of the identification stage (which knows signals, not files) as
  one line naming the files and saying what to do.
- :func:`screen_result`: a droop outside :data:`DROOP_RANGE` is not a plant's: DataError (not
  identifiable, with the reason; the units or the log are wrong, so nothing else is shown). The rules that
  null a quantity with its reason (an interval wider than the value, none, zero width; a Z_ur search that
  did not converge) are :mod:`fcrlive.analysis.quality`'s, applied inside the identification.
"""

from __future__ import annotations

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


def screen_result(res, paths: Sequence[Path]):
    """The identification, or DataError when its droop is outside :data:`DROOP_RANGE` (module docstring).
    The width rule and the other rules of an honest result are applied by the identification itself
    (:mod:`fcrlive.analysis.quality`), for the daemon and prequal too; this is what only the CLI adds."""
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
    return res


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
