"""Read and write TSO data logs (Nordic FCR Test Program §11.1, TR Table 19).

The format: comma separated, '.' decimal, CRLF record delimiter, ASCII, one header line. The first column
is ``DateTime`` as ``YYYYMMDDThhmmss.nnn`` (wall-clock time in the file name's time zone, UTC unless
stated); the others are TR Table 19 headers (``InsAcPow`` [MW], ``GridFreq`` [Hz], ``ApplFreqSig`` [Hz],
``ContOutSig``, ``GuideVane`` [%], ...). Sine-test files carry the period after EVERY header
(``DateTime40,InsAcPow40,GridFreq40``): the reader strips it and reports ``period_s``.

Reading is lenient about the container (LF or CRLF, a UTF-8 byte-order mark, quoted fields, header case,
a trailing comma, fewer or more fractional digits in the time stamp) and strict about the data: every
problem that would make an identification silently wrong raises :class:`fcrlive.errors.DataError` with
``where="FILE, row N"`` (row 1 is the header, so N is the line an editor shows). Writing is strict:
ASCII, CRLF, fixed decimals, millisecond time stamps.

Gaps (an interval longer than 1.5x the median) are reported in :attr:`TsoLog.gaps`. Up to ``max_fill``
missing samples (default 3) on the sampling grid are filled by linear interpolation and flagged in
:attr:`TsoLog.filled`; longer gaps split the log into :attr:`TsoLog.segments`, never interpolated.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from itertools import pairwise
from pathlib import Path

import numpy as np

from fcrlive.errors import DataError
from fcrlive.tso.names import TsoFileName, parse_tso_filename

# --- column vocabulary ------------------------------------------------------------------------------

KNOWN_UNITS: dict[str, str] = {
    "InsAcPow": "MW",
    "GridFreq": "Hz",
    "ApplFreqSig": "Hz",
    # TR Table 19 leaves the unit of the controller output open; fcrlive's simulated logs write % of
    # full gate demand, and the signal mapping divides by 100 unless told otherwise.
    "ContOutSig": "%",
    "ContSetP": "% or MW",
    "CalcBaseline": "MW",
    "GuideVane": "%",
    "BladeAng": "% or deg",
    "UppWatLev": "m.a.s.l.",
    "LowWatLev": "m.a.s.l.",
    "Pmin": "MW",
    "Pmax": "MW",
    "InsAcPow_station": "MW",
    "AmbTemp": "degC",
    "CoolTemp": "degC",
    "WindSpeed": "m/s",
    "SolarIrr": "W/m2",
    "SOC": "%",
}
for _svc in ("Fcrn", "FcrdUp", "FcrdDo"):
    KNOWN_UNITS.update(
        {
            f"ContMode_{_svc}": "id",
            f"Cap_{_svc}": "MW",
            f"ContStatus_{_svc}": "on/off",
            f"RegStr_{_svc}": "MW/Hz",
            f"Activated_{_svc}": "MW",
            f"ResSize_{_svc}": "min",
            f"NEM_MW_{_svc}": "MW",
            f"NEM_{_svc}": "on/off",
            f"AEM_{_svc}": "on/off",
        }
    )
"""Units of the TR Table 19 headers (other headers are kept with an empty unit)."""

TEXT_COLUMNS: frozenset[str] = frozenset(f"ContMode_{s}" for s in ("Fcrn", "FcrdUp", "FcrdDo"))
"""Columns that are alphanumeric identifiers (e.g. ``FCRN4``): kept as text."""

SIGNAL_COLUMNS: tuple[str, ...] = ("InsAcPow", "GridFreq", "ApplFreqSig", "ContOutSig", "GuideVane")
"""Columns that feed the identification: every value must be a finite number."""

REQUIRED_COLUMNS: tuple[str, ...] = ("InsAcPow", "GridFreq")
"""Columns the no-excitation method needs (power and frequency): required by default."""

_CANONICAL = {name.lower(): name for name in KNOWN_UNITS}
_CANONICAL["datetime"] = "DateTime"

_COMPACT_TS = re.compile(r"^(\d{4})(\d{2})(\d{2})T(\d{2})(\d{2})(\d{2})(?:\.(\d{1,9}))?$")
_PERIOD_SUFFIX = re.compile(r"^datetime(\d+(?:\.\d+)?)$", re.IGNORECASE)
_HEADER_UNIT = re.compile(r"^(.*?)\s*[\[(]([^\])]*)[\])]$")
_EPOCH = datetime(1970, 1, 1)


# --- data objects -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Gap:
    """A hole in the time stamps: an interval longer than 1.5x the median sample interval."""

    row: int
    """File row of the first sample after the gap (row 1 is the header)."""
    start: datetime
    """Time stamp of the last sample before the gap (as written, in the log's time zone)."""
    t_s: float
    """Seconds since the first sample of the last sample before the gap [s]."""
    length_s: float
    """Time between the samples on either side of the gap [s]."""
    missing: int
    """Samples missing at the nominal interval."""
    filled: bool
    """True: filled by linear interpolation (short gap on the grid); False: the log is split here."""

    def __str__(self) -> str:
        action = "filled linearly" if self.filled else "log split here"
        return (
            f"gap of {self.length_s:.3f} s ({self.missing} sample{'s' if self.missing != 1 else ''} "
            f"missing) after {format_timestamp(self.start)} (before row {self.row}): {action}"
        )


@dataclass(frozen=True, eq=False)
class TsoLog:
    """A TSO data log in memory.

    ``columns`` maps the canonical header (period suffix stripped) to a float64 array, or to an array of
    str for identifier columns (``ContMode_*``) and unknown non-numeric columns. ``t_s`` and every
    column have one entry per sample, including samples filled across short gaps (``filled``).
    """

    t_s: np.ndarray
    """Time of each sample since the first sample [s], float64."""
    start: datetime
    """Wall-clock time of the first sample in ``timezone`` (naive datetime)."""
    columns: dict[str, np.ndarray]
    period_s: float | None = None
    """Sine-test period [s] from the header suffix, None for other logs."""
    units: dict[str, str] = field(default_factory=dict)
    timezone: str = "UTC"
    path: Path | None = None
    sample_s: float = float("nan")
    """Nominal (median) sample interval [s]."""
    filled: np.ndarray | None = None
    """True for samples interpolated across a short gap; all False if None was given."""
    segments: tuple[tuple[int, int], ...] = ()
    """Half-open index ranges [start, stop) of gap-free stretches; identification splits here."""
    gaps: tuple[Gap, ...] = ()
    rows: np.ndarray | None = None
    """File row of each sample (0 for filled or synthesised samples)."""
    name: TsoFileName | None = None
    """The parsed file name, when the file follows the TSO naming convention."""
    notes: tuple[str, ...] = ()
    """Things worth telling the user that are not errors (e.g. name and data disagree)."""

    def __post_init__(self) -> None:
        t = np.asarray(self.t_s, dtype=np.float64)
        object.__setattr__(self, "t_s", t)
        n = t.shape[0]
        for name, col in self.columns.items():
            if len(col) != n:
                raise ValueError(f"column {name!r} has {len(col)} samples, time has {n}")
        if self.filled is None:
            object.__setattr__(self, "filled", np.zeros(n, dtype=bool))
        if self.rows is None:
            object.__setattr__(self, "rows", np.zeros(n, dtype=np.int64))
        if not self.segments and n:
            object.__setattr__(self, "segments", ((0, n),))
        if math.isnan(self.sample_s) and n > 1:
            object.__setattr__(self, "sample_s", float(np.median(np.diff(t))))
        units = {k: KNOWN_UNITS.get(k, "") for k in self.columns}
        units.update(self.units)
        object.__setattr__(self, "units", units)

    @classmethod
    def from_arrays(
        cls,
        t_s: np.ndarray,
        columns: Mapping[str, np.ndarray],
        start: datetime,
        *,
        period_s: float | None = None,
        timezone: str = "UTC",
        units: Mapping[str, str] | None = None,
    ) -> TsoLog:
        """A log from arrays (e.g. a simulation or a store export), no filled samples.

        Intervals longer than 1.5x the median are recorded as gaps (never filled) and split the log
        into segments, as when reading a file.
        """
        t = np.asarray(t_s, dtype=np.float64)
        if t.ndim != 1 or t.size < 2 or not np.all(np.diff(t) > 0):
            raise ValueError("t_s must be a 1-D strictly increasing array of at least 2 samples")
        t = t - t[0]
        cols = {}
        for k, v in columns.items():
            a = np.asarray(v)
            cols[k] = a if a.dtype.kind in "US" else a.astype(np.float64)
        dt = np.diff(t)
        ts = float(np.median(dt))
        breaks = np.flatnonzero(dt > 1.5 * ts)
        gaps = tuple(
            Gap(
                row=0,
                start=start + timedelta(seconds=float(t[i])),
                t_s=float(t[i]),
                length_s=float(dt[i]),
                missing=round(dt[i] / ts) - 1,
                filled=False,
            )
            for i in breaks
        )
        bounds = [0, *(int(i) + 1 for i in breaks), t.size]
        return cls(
            t_s=t,
            start=start,
            columns=cols,
            period_s=period_s,
            units=dict(units or {}),
            timezone=timezone,
            sample_s=ts,
            segments=tuple(pairwise(bounds)),
            gaps=gaps,
        )

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample [s]."""
        return float(self.t_s[-1] - self.t_s[0]) if len(self) else 0.0

    @property
    def valid(self) -> np.ndarray:
        """True for measured samples (not filled across a gap)."""
        return ~self.filled

    def has(self, name: str) -> bool:
        return name in self.columns

    def source(self) -> str:
        return str(self.path) if self.path is not None else "<memory>"


# --- time stamps ------------------------------------------------------------------------------------


def format_timestamp(dt: datetime) -> str:
    """``YYYYMMDDThhmmss.nnn`` (milliseconds, truncated to the nearest ms by rounding)."""
    ms = round(dt.microsecond / 1000.0)
    base = dt.replace(microsecond=0) + timedelta(milliseconds=ms)
    return f"{base:%Y%m%dT%H%M%S}.{(base.microsecond // 1000):03d}"


def _parse_one_timestamp(text: str) -> int:
    """Microseconds since 1970-01-01 of one time stamp; ValueError when it cannot be read."""
    s = text.strip()
    m = _COMPACT_TS.match(s)
    if m:
        y, mo, d, h, mi, sec = (int(g) for g in m.groups()[:6])
        frac = m.group(7) or ""
        dt = datetime(y, mo, d, h, mi, sec)
        us = _frac_to_us(frac)
    else:
        # Lenient: ISO 8601 with separators (2026-11-01T00:00:00.020, optionally with an offset).
        dt = datetime.fromisoformat(s)
        if dt.tzinfo is not None:
            dt = dt.astimezone(UTC).replace(tzinfo=None)
        us = dt.microsecond
        dt = dt.replace(microsecond=0)
    return (dt - _EPOCH) // timedelta(microseconds=1) + us


def _frac_to_us(frac: str) -> int:
    if not frac:
        return 0
    if len(frac) <= 6:
        return int(frac) * 10 ** (6 - len(frac))
    return round(int(frac) / 10 ** (len(frac) - 6))


def _parse_timestamps(values: list[str], rows: np.ndarray, where: str) -> np.ndarray:
    """Microseconds since 1970 (int64) for each time stamp; DataError quoting the first bad one."""
    n = len(values)
    fast = _parse_timestamps_fast(values)
    if fast is not None:
        return fast
    out = np.empty(n, dtype=np.int64)
    for i, v in enumerate(values):
        try:
            out[i] = _parse_one_timestamp(v)
        except (ValueError, OverflowError):
            raise DataError(
                f"cannot read time stamp {v!r} (expected YYYYMMDDThhmmss.nnn)",
                where=f"{where}, row {rows[i]}",
            ) from None
    return out


def _parse_timestamps_fast(values: list[str]) -> np.ndarray | None:
    """Vectorised parse when all stamps are the compact form of one length; None to fall back."""
    n = len(values)
    width = len(values[0])
    if width < 15 or width == 16 or width > 25:
        return None
    try:
        raw = "".join(values).encode("ascii")
    except UnicodeEncodeError:
        return None
    if len(raw) != n * width:
        return None
    b = np.frombuffer(raw, dtype=np.uint8).reshape(n, width)
    if np.any(b[:, 8] != ord("T")) or (width > 15 and np.any(b[:, 15] != ord("."))):
        return None
    digit_cols = [*range(8), *range(9, 15), *range(16, width)]
    d = b[:, digit_cols].astype(np.int64) - ord("0")
    if np.any((d < 0) | (d > 9)):
        return None

    def num(cols: slice) -> np.ndarray:
        part = d[:, cols]
        weights = 10 ** np.arange(part.shape[1] - 1, -1, -1, dtype=np.int64)
        return part @ weights

    year, month, day = num(slice(0, 4)), num(slice(4, 6)), num(slice(6, 8))
    hour, minute, sec = num(slice(8, 10)), num(slice(10, 12)), num(slice(12, 14))
    if np.any((month < 1) | (month > 12) | (day < 1) | (hour > 23) | (minute > 59) | (sec > 59)):
        return None
    months = (year - 1970).astype("datetime64[Y]").astype("datetime64[M]") + (month - 1).astype(
        "timedelta64[M]"
    )
    dates = months.astype("datetime64[D]") + (day - 1).astype("timedelta64[D]")
    if np.any(dates.astype("datetime64[M]") != months):  # e.g. 31 November
        return None
    us = dates.astype("datetime64[us]").astype(np.int64)
    us += ((hour * 60 + minute) * 60 + sec) * 1_000_000
    nfrac = width - 16
    if nfrac > 0:
        frac = num(slice(14, 14 + nfrac))
        if nfrac <= 6:
            us += frac * 10 ** (6 - nfrac)
        else:
            us += np.rint(frac / 10 ** (nfrac - 6)).astype(np.int64)
    return us


def _us_to_datetime(us: int) -> datetime:
    return _EPOCH + timedelta(microseconds=int(us))


# --- reading ----------------------------------------------------------------------------------------


def _decode(raw: bytes) -> str:
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        # Lenient: headers from old Windows tools may be Latin-1; the numbers are ASCII either way.
        return raw.decode("latin-1")


def _canonical_header(h: str) -> tuple[str, str | None]:
    """Canonical column name and a unit given in the header (``GridFreq [Hz]``), if any."""
    h = h.strip()
    if h.startswith("[") and h.endswith("]") and h.count("[") == 1:
        h = h[1:-1].strip()
    unit = None
    m = _HEADER_UNIT.match(h)
    if m and m.group(1):
        h, unit = m.group(1).strip(), m.group(2).strip()
    return _CANONICAL.get(h.lower(), h), unit


def _strip_period(headers: list[str], where: str) -> tuple[list[str], float | None]:
    m = _PERIOD_SUFFIX.match(headers[0].strip())
    if not m:
        return headers, None
    suffix = m.group(1)
    out = ["DateTime"]
    for h in headers[1:]:
        hs = h.strip()
        base, unit = hs, ""
        um = _HEADER_UNIT.match(hs)
        if um and um.group(1):
            base, unit = um.group(1).strip(), hs[len(um.group(1)) :]
        if not base.endswith(suffix) or len(base) == len(suffix):
            raise DataError(
                f"header {hs!r} lacks the period suffix {suffix!r} that {headers[0].strip()!r} carries "
                "(a sine-test file carries the period on every header)",
                where=f"{where}, row 1",
            )
        out.append(base[: -len(suffix)] + unit)
    return out, float(suffix)


def _float_column(
    values: list[str], name: str, rows: np.ndarray, where: str, strict: bool
) -> np.ndarray | None:
    """Float64 array; for ``strict`` columns any bad/empty/non-finite value raises DataError.

    Non-strict columns allow empty cells (NaN) and return None if a value is not a number (then the
    caller keeps the column as text).
    """
    try:
        arr = np.array(values, dtype=np.float64)
    except ValueError:
        arr = None
    if arr is not None:
        if strict:
            bad = ~np.isfinite(arr)
            if np.any(bad):
                i = int(np.argmax(bad))
                raise DataError(
                    f"column {name}: value {values[i].strip()!r} is not a finite number",
                    where=f"{where}, row {rows[i]}",
                )
        return arr
    out = np.empty(len(values), dtype=np.float64)
    for i, v in enumerate(values):
        s = v.strip()
        if not s:
            if strict:
                raise DataError(f"column {name}: empty value", where=f"{where}, row {rows[i]}")
            out[i] = np.nan
            continue
        try:
            out[i] = float(s)
        except ValueError:
            if strict:
                hint = " (decimal comma? the format uses '.')" if "," in s or s.count(".") == 0 else ""
                raise DataError(
                    f"column {name}: cannot read {s!r} as a number{hint}", where=f"{where}, row {rows[i]}"
                ) from None
            return None
    return out


def read_log(
    path: str | Path,
    *,
    required: tuple[str, ...] = REQUIRED_COLUMNS,
    min_samples: int = 20,
    min_duration_s: float = 10.0,
    max_fill: int = 3,
    jitter: float = 0.2,
) -> TsoLog:
    """Read a TSO CSV log.

    ``required``: columns that must be present (after the period suffix is stripped).
    ``min_samples``, ``min_duration_s``: a log shorter than either is refused [samples, s].
    ``max_fill``: gaps of at most this many missing samples, on the sampling grid, are filled by linear
    interpolation and flagged; longer gaps split the log into segments (0 disables filling).
    ``jitter``: an interval may differ from the median by this fraction (at least 1 ms, the time-stamp
    resolution) and still count as regular; anything between that and 1.5x the median is refused as a
    non-uniform sample interval.

    Raises DataError(where="FILE, row N" or "FILE") naming the problem.
    """
    path = Path(path)
    where = str(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DataError(f"cannot read the file: {exc.strerror or exc}", where=where) from None
    text = _decode(raw)
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    lines = [ln[:-1] if ln.endswith("\r") else ln for ln in lines]
    if not lines or not lines[0].strip():
        raise DataError("empty file: no header line", where=where)
    if ";" in lines[0] and "," not in lines[0]:
        raise DataError(
            "semicolon separated; the TSO format is comma separated with '.' decimals", where=where
        )

    records = list(csv.reader(lines))
    header = [h for h in records[0]]
    trailing_comma = len(header) > 1 and header[-1].strip() == ""
    if trailing_comma:
        header = header[:-1]
    header, period_s = _strip_period(header, where)
    names: list[str] = []
    units: dict[str, str] = {}
    for h in header:
        name, unit = _canonical_header(h)
        if not name:
            raise DataError("empty column header", where=f"{where}, row 1")
        if name in names:
            raise DataError(f"column {name} appears twice in the header", where=f"{where}, row 1")
        names.append(name)
        if unit is not None:
            units[name] = unit
    if names[0] != "DateTime":
        raise DataError(
            f"first column must be DateTime, found {header[0].strip()!r}", where=f"{where}, row 1"
        )
    missing = [c for c in required if c not in names]
    if missing:
        raise DataError(
            f"missing required column{'s' if len(missing) > 1 else ''} {', '.join(missing)} "
            f"(found {', '.join(names[1:]) or 'none'})",
            where=where,
        )

    ncol = len(names)
    cells: list[list[str]] = []
    row_numbers: list[int] = []
    for i, rec in enumerate(records[1:], start=2):
        if not rec or (len(rec) == 1 and not rec[0].strip()):
            continue  # blank line: harmless
        if len(rec) == ncol + 1 and not rec[-1].strip():
            rec = rec[:-1]  # trailing comma
        if len(rec) != ncol:
            hint = " (decimal commas? the format uses '.')" if len(rec) > ncol else ""
            raise DataError(
                f"row has {len(rec)} fields, the header has {ncol}{hint}", where=f"{where}, row {i}"
            )
        cells.append(rec)
        row_numbers.append(i)
    rows = np.asarray(row_numbers, dtype=np.int64)
    n = len(cells)
    if n < max(min_samples, 2):
        raise DataError(f"log too short: {n} samples, need at least {max(min_samples, 2)}", where=where)

    cols_text = list(zip(*cells))
    stamps = [s.strip() for s in cols_text[0]]
    t_us = _parse_timestamps(stamps, rows, where)
    dt_us = np.diff(t_us)
    if np.any(dt_us <= 0):
        i = int(np.argmax(dt_us <= 0))
        what = "repeats" if dt_us[i] == 0 else "goes backwards"
        raise DataError(
            f"time stamp {what}: {stamps[i + 1]!r} after {stamps[i]!r}", where=f"{where}, row {rows[i + 1]}"
        )
    duration = (t_us[-1] - t_us[0]) / 1e6
    if duration < min_duration_s:
        raise DataError(f"log too short: {duration:.3f} s, need at least {min_duration_s:g} s", where=where)

    columns: dict[str, np.ndarray] = {}
    for name, values in zip(names[1:], cols_text[1:]):
        values = list(values)
        if name in TEXT_COLUMNS:
            columns[name] = np.array([v.strip() for v in values], dtype=str)
            continue
        strict = name in SIGNAL_COLUMNS or name in required
        arr = _float_column(values, name, rows, where, strict)
        columns[name] = arr if arr is not None else np.array([v.strip() for v in values], dtype=str)

    fname: TsoFileName | None
    notes: list[str] = []
    try:
        fname = parse_tso_filename(path.name)
    except DataError:
        fname = None
    timezone = fname.timezone if fname else "UTC"

    log = _regularise(t_us, columns, rows, where=where, max_fill=max_fill, jitter=jitter, stamps=stamps)
    t_s, columns, filled, rows2, segments, gaps, sample_s = log
    if fname is not None:
        if abs(fname.sample_s - sample_s) > 0.01 * fname.sample_s + 1e-3:
            notes.append(f"file name says {fname.sample_s:g} s sampling, the time stamps say {sample_s:g} s")
        if period_s is not None and fname.period_s is not None and fname.period_s != period_s:
            notes.append(f"file name says period {fname.period_s:g} s, the headers say {period_s:g} s")
    for g in gaps:
        notes.append(str(g))
    return TsoLog(
        t_s=t_s,
        start=_us_to_datetime(t_us[0]),
        columns=columns,
        period_s=period_s,
        units=units,
        timezone=timezone,
        path=path,
        sample_s=sample_s,
        filled=filled,
        segments=segments,
        gaps=gaps,
        rows=rows2,
        name=fname,
        notes=tuple(notes),
    )


def _regularise(t_us, columns, rows, *, where, max_fill, jitter, stamps):
    """Check the sample interval, report gaps, fill short ones, split at long ones."""
    n = t_us.shape[0]
    dt = np.diff(t_us).astype(np.float64)
    ts = float(np.median(dt))
    tol = max(jitter * ts, 1000.0)  # time stamps have 1 ms resolution
    is_gap = dt > 1.5 * ts
    irregular = ~is_gap & (np.abs(dt - ts) > tol)
    if np.any(irregular):
        i = int(np.argmax(irregular))
        raise DataError(
            f"non-uniform sample interval: {dt[i] / 1e6:.3f} s from {stamps[i]!r} to {stamps[i + 1]!r}, "
            f"the median is {ts / 1e6:.3f} s (tolerance ±{tol / 1e6:.3f} s; gaps are > 1.5x the median)",
            where=f"{where}, row {rows[i + 1]}",
        )
    gaps: list[Gap] = []
    fills: list[tuple[int, int]] = []  # (interval index i, number of sub-intervals k)
    breaks: list[int] = []  # interval indices where the log is split
    for i in np.flatnonzero(is_gap):
        i = int(i)
        k = round(dt[i] / ts)
        on_grid = abs(dt[i] - k * ts) <= tol
        fill = on_grid and (k - 1) <= max_fill
        gaps.append(
            Gap(
                row=int(rows[i + 1]),
                start=_us_to_datetime(t_us[i]),
                t_s=(t_us[i] - t_us[0]) / 1e6,
                length_s=dt[i] / 1e6,
                missing=k - 1,
                filled=fill,
            )
        )
        if fill:
            fills.append((i, k))
        else:
            breaks.append(i)

    t_rel = (t_us - t_us[0]).astype(np.float64) / 1e6
    if fills:
        pieces: list[np.ndarray] = []
        prev = 0
        for i, k in fills:
            pieces.append(np.arange(prev, i + 1, dtype=np.float64))
            pieces.append(i + np.arange(1, k, dtype=np.float64) / k)
            prev = i + 1
        pieces.append(np.arange(prev, n, dtype=np.float64))
        q = np.concatenate(pieces)
        idx = np.arange(n, dtype=np.float64)
        filled = q != np.floor(q)
        base = np.floor(q).astype(np.int64)
        t_rel = np.interp(q, idx, t_rel)
        new_cols = {}
        for name, col in columns.items():
            if col.dtype.kind == "f":
                new_cols[name] = np.interp(q, idx, col)
            else:
                new_cols[name] = col[base]  # identifiers: hold the previous value
        columns = new_cols
        rows = np.where(filled, 0, rows[base])
        new_index = np.searchsorted(q, np.arange(n, dtype=np.float64))
    else:
        filled = np.zeros(n, dtype=bool)
        new_index = np.arange(n)
    total = t_rel.shape[0]
    cuts = [int(new_index[i + 1]) for i in breaks]
    bounds = [0, *cuts, total]
    segments = tuple(pairwise(bounds))
    return t_rel, columns, filled, rows, segments, tuple(gaps), ts / 1e6


# --- writing ----------------------------------------------------------------------------------------

DEFAULT_DECIMALS = 6
"""Decimals written for numbers. The TR asks for at least 3; 6 keeps simulated frequency deviations
(a few mHz) from being quantised, so identification from a written file sees the simulated signal."""


def write_log(
    path: str | Path,
    log: TsoLog,
    *,
    decimals: int | Mapping[str, int] = DEFAULT_DECIMALS,
) -> Path:
    """Write ``log`` in the TSO format (strict): ASCII, comma, '.' decimal, CRLF, header line.

    Time stamps are written to the millisecond from ``log.start`` + ``log.t_s``. Sine-test logs
    (``period_s`` set) get the period appended to every header. Samples filled across gaps are not
    written: the file holds what was measured. ``decimals`` is one number for all columns or a mapping
    column -> decimals (others get DEFAULT_DECIMALS). Raises ValueError on data that cannot be written
    faithfully (non-finite numbers, non-ASCII text, commas in text).
    """
    path = Path(path)
    keep = ~log.filled
    suffix = "" if log.period_s is None else f"{log.period_s:g}"
    headers = ["DateTime", *log.columns]
    for h in headers:
        if not h.isascii() or any(ch in h for ch in ',"\r\n') or not h.strip():
            raise ValueError(f"header {h!r} cannot be written (ASCII, no comma, quote or newline)")
    ms = np.rint(log.t_s[keep] * 1000.0).astype(np.int64)
    if np.any(np.diff(ms) <= 0):
        raise ValueError("samples closer than 1 ms cannot be written with millisecond time stamps")
    start_ms = np.datetime64(log.start.replace(tzinfo=None), "ms")
    iso = np.datetime_as_string(start_ms + ms.astype("timedelta64[ms]"), unit="ms")
    stamps = np.char.replace(np.char.replace(iso, "-", ""), ":", "")
    out_cols: list[np.ndarray] = [stamps]
    for name, col in log.columns.items():
        col = col[keep]
        if col.dtype.kind in "fiub":
            d = decimals if isinstance(decimals, int) else decimals.get(name, DEFAULT_DECIMALS)
            values = np.asarray(col, dtype=np.float64)
            if not np.all(np.isfinite(values)):
                raise ValueError(f"column {name} has non-finite values; the TSO format cannot hold them")
            out_cols.append(np.char.mod(f"%.{int(d)}f", values))
        else:
            strs = np.asarray(col, dtype=str)
            for s in strs:
                if not s.isascii() or any(ch in s for ch in ',"\r\n'):
                    raise ValueError(f"column {name}: value {s!r} cannot be written (ASCII, no comma)")
            out_cols.append(strs)
    lines = [",".join(f"{h}{suffix}" for h in headers)]
    lines.extend(",".join(r) for r in zip(*(c.tolist() for c in out_cols)))
    data = ("\r\n".join(lines) + "\r\n").encode("ascii")
    path.write_bytes(data)
    return path
