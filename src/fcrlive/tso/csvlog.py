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

Gaps (the gap rule of :mod:`fcrlive.signals`: an interval longer than 1.5x the median) are reported in
:attr:`TsoLog.gaps`. Up to ``max_fill`` missing samples (default 3) on the sampling grid are filled by
linear interpolation and flagged in :attr:`TsoLog.filled`; longer gaps split the log into
:attr:`TsoLog.segments`, never interpolated.

Reading is a sequence of steps: the file's bytes in bounded chunks (:mod:`fcrlive.tso.rawfile`), the
parsing core (:func:`parse_table`: header, rows, time stamps and typed columns, vectorised in blocks of
lines by :mod:`fcrlive.tso.csvparse`), the file name, the sample grid (:func:`_regularise`), and
the notes.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

from fcrlive.errors import DataError
from fcrlive.signals import GAP_FACTOR, Filled, fill_gaps, find_gaps, is_gap, median_interval
from fcrlive.tso import csvparse
from fcrlive.tso.csvparse import NUMBER
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

_COMPACT_TS = re.compile(r"^(\d{4})(\d{2})(\d{2})T(\d{2})(\d{2})(\d{2})(?:\.(\d{1,9}))?$", re.ASCII)
_PERIOD_SUFFIX = re.compile(r"^datetime(\d+(?:\.\d+)?)$", re.IGNORECASE)
_HEADER_UNIT = re.compile(r"^(.*?)\s*[\[(]([^\])]*)[\])]$")
_EPOCH = datetime(1970, 1, 1)


# --- data objects -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Gap:
    """A hole in the time stamps: an interval longer than 1.5x the median sample interval (the gap rule of
    :mod:`fcrlive.signals`)."""

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

        Gaps (intervals longer than 1.5x the median, :mod:`fcrlive.signals`) are recorded, never filled,
        and split the log into segments, as when reading a file.
        """
        t = np.asarray(t_s, dtype=np.float64)
        if t.ndim != 1 or t.size < 2 or not np.all(np.diff(t) > 0):
            raise ValueError("t_s must be a 1-D strictly increasing array of at least 2 samples")
        t = t - t[0]
        cols = {}
        for k, v in columns.items():
            a = np.asarray(v)
            cols[k] = a if a.dtype.kind in "US" else a.astype(np.float64)
        found = find_gaps(t)
        gaps = tuple(
            Gap(
                row=0,
                start=start + timedelta(seconds=float(t[i])),
                t_s=float(t[i]),
                length_s=float(t[i + 1] - t[i]),
                missing=int(m),
                filled=False,
            )
            for i, m in zip(found.index, found.missing)
        )
        return cls(
            t_s=t,
            start=start,
            columns=cols,
            period_s=period_s,
            units=dict(units or {}),
            timezone=timezone,
            sample_s=found.ts,
            segments=found.segments,
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
        if not s.isascii():
            raise ValueError("time stamps are ASCII")
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
    out = np.empty(len(values), dtype=np.int64)
    for i, v in enumerate(values):
        try:
            out[i] = _parse_one_timestamp(v)
        except (ValueError, OverflowError):
            raise DataError(
                f"cannot read time stamp {v!r} (expected YYYYMMDDThhmmss.nnn)",
                where=f"{where}, row {rows[i]}",
            ) from None
    return out


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
    """Float64 array by the strict ASCII number grammar (:data:`fcrlive.tso.csvparse.NUMBER`); for
    ``strict`` columns any bad/empty/non-finite value raises DataError.

    Non-strict columns allow empty cells (NaN) and return None if a value is not a number (then the
    caller keeps the column as text).
    """
    out = np.empty(len(values), dtype=np.float64)
    for i, v in enumerate(values):
        s = v.strip()
        if not s:
            if strict:
                raise DataError(f"column {name}: empty value", where=f"{where}, row {rows[i]}")
            out[i] = np.nan
            continue
        if NUMBER.fullmatch(s):
            out[i] = float(s)
            if strict and not math.isfinite(out[i]):
                raise DataError(
                    f"column {name}: value {s!r} is not a finite number", where=f"{where}, row {rows[i]}"
                )
            continue
        if not strict:
            return None
        if s.lower().lstrip("+-") in ("nan", "inf", "infinity"):
            raise DataError(
                f"column {name}: value {s!r} is not a finite number", where=f"{where}, row {rows[i]}"
            )
        if "," in s or (s.count(".") == 0 and s.replace(",", "").isdigit()):
            hint = " (decimal comma? the format uses '.')"
        elif not s.isascii():
            hint = " (non-ASCII characters; the format is ASCII digits 0-9)"
        else:
            hint = " (the format is ASCII digits, '.' decimals, e.g. 50.012)"
        raise DataError(
            f"column {name}: cannot read {s[:40]!r}{'...' if len(s) > 40 else ''} as a number{hint}",
            where=f"{where}, row {rows[i]}",
        )
    return out


def _chunks(source: str | bytes | Path | Iterable[bytes], where: str) -> Iterable[bytes]:
    """The bytes to parse: a path is read in bounded chunks (:mod:`fcrlive.tso.rawfile`), text encoded."""
    from fcrlive.tso.rawfile import iter_bytes

    if isinstance(source, Path):
        return iter_bytes(source, where)
    if isinstance(source, str):
        return [source.encode("utf-8")]
    if isinstance(source, (bytes, bytearray, memoryview)):
        return [bytes(source)]
    return source


def _read_header_line(line: bytes, where: str) -> list[str]:
    text = _decode(line).rstrip("\n")
    text = text[:-1] if text.endswith("\r") else text
    if not text.strip():
        raise DataError("empty file: no header line", where=where)
    if ";" in text and "," not in text:
        raise DataError(
            "semicolon separated; the TSO format is comma separated with '.' decimals", where=where
        )
    try:
        return next(csv.reader([text]))
    except csv.Error as exc:
        raise DataError(
            f"header line cannot be read as CSV ({exc}): is it a TSO log?", where=f"{where}, row 1"
        ) from None


@dataclass(frozen=True)
class Header:
    """The header line of a TSO CSV file, interpreted."""

    names: list[str]
    """Canonical column names, ``DateTime`` first, period suffix stripped."""
    units: dict[str, str]
    """Units given in the header (``GridFreq [Hz]``)."""
    period_s: float | None
    """Sine-test period [s] from the header suffix (``DateTime40``), None for other logs."""


def _parse_header(record: list[str], required: tuple[str, ...], where: str) -> Header:
    """Canonical names, units and sine-test period of the header record; DataError when a name is empty,
    repeated, the first is not DateTime or a required column is missing."""
    header = list(record)
    if len(header) > 1 and header[-1].strip() == "":
        header = header[:-1]  # trailing comma
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
    return Header(names=names, units=units, period_s=period_s)


def _data_records(
    records: list[list[str]], ncol: int, where: str, rows: list[int] | None = None
) -> tuple[list[list[str]], np.ndarray]:
    """The data records with ``ncol`` fields each and their file rows (blank lines skipped, a trailing
    comma dropped); DataError naming the row with another number of fields. ``rows``: the file row of
    each record (default: 2, 3, ...)."""
    cells: list[list[str]] = []
    row_numbers: list[int] = []
    for k, rec in enumerate(records):
        i = rows[k] if rows is not None else k + 2
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
    return cells, np.asarray(row_numbers, dtype=np.int64)


def _stamp_text(us: int) -> str:
    """A time stamp [µs since 1970] as ``YYYYMMDDThhmmss.nnn`` (6 fractional digits if not whole ms)."""
    dt = _us_to_datetime(us)
    if dt.microsecond % 1000:
        return f"{dt:%Y%m%dT%H%M%S.%f}"
    return format_timestamp(dt)


def _check_time_order(t_us: np.ndarray, rows: np.ndarray, where: str) -> None:
    """DataError at the first time stamp that repeats or goes backwards."""
    dt_us = np.diff(t_us)
    if np.any(dt_us <= 0):
        i = int(np.argmax(dt_us <= 0))
        what = "repeats" if dt_us[i] == 0 else "goes backwards"
        raise DataError(
            f"time stamp {what}: {_stamp_text(t_us[i + 1])!r} after {_stamp_text(t_us[i])!r}",
            where=f"{where}, row {rows[i + 1]}",
        )


def _slow_block(block: bytes, first_row: int, ncol: int, kinds: list[str], names: list[str],
                where: str) -> csvparse.Block:
    """One block parsed record by record (quotes, blanks, UTF-8 text, or a problem to report)."""
    lines = _decode(block).split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    lines = [ln[:-1] if ln.endswith("\r") else ln for ln in lines]
    reader = csv.reader(lines)
    records: list[list[str]] = []
    rows: list[int] = []
    try:
        for rec in reader:
            records.append(rec)
            rows.append(first_row + reader.line_num - 1)
    except csv.Error as exc:
        what = (
            f"a field longer than {csv.field_size_limit() // 1024} KiB, which no TSO value is"
            if "field larger" in str(exc)
            else f"cannot be read as CSV ({exc})"
        )
        raise DataError(
            f"{what}: is it a TSO log, and the right file?",
            where=f"{where}, row {first_row + reader.line_num - 1}",
        ) from None
    cells, row_arr = _data_records(records, ncol, where, rows)
    cols = list(zip(*cells)) if cells else [()] * ncol
    stamps = [s.strip() for s in cols[0]]
    t_us = _parse_timestamps(stamps, row_arr, where)
    values: list[np.ndarray | None] = []
    texts: list[np.ndarray] = []
    for name, kind, col in zip(names, kinds, cols[1:]):
        vals = list(col)
        texts.append(np.array([v.strip().encode("utf-8") for v in vals], dtype="S") if vals
                     else np.empty(0, "S1"))
        values.append(None if kind == "text" else _float_column(vals, name, row_arr, where, kind == "strict"))
    return csvparse.Block(row_arr, t_us, np.array([s.encode() for s in stamps], dtype="S"), values, texts)


@dataclass(frozen=True, eq=False)
class Table:
    """A TSO CSV file parsed: one entry per data record, as in the file (no gap handling yet)."""

    header: Header
    rows: np.ndarray
    """File row of each record (row 1 is the header)."""
    t_us: np.ndarray
    """Time stamps [µs since 1970-01-01], int64, strictly increasing."""
    columns: dict[str, np.ndarray]
    """Canonical name (without DateTime) -> float64 array or text array."""

    def stamp(self, i: int) -> str:
        """The time stamp of record ``i`` as ``YYYYMMDDThhmmss.nnn`` (for messages)."""
        return _stamp_text(int(self.t_us[i]))


def _column_kinds(names: list[str], required: tuple[str, ...]) -> list[str]:
    """"text" (identifier columns), "strict" (signal and required columns: finite numbers) or "num"
    (numbers with empty cells allowed, or text if any value is not a number)."""
    return [
        "text" if n in TEXT_COLUMNS else "strict" if n in SIGNAL_COLUMNS or n in required else "num"
        for n in names
    ]


def parse_table(
    source: str | bytes | Path | Iterable[bytes],
    *,
    where: str,
    required: tuple[str, ...] = REQUIRED_COLUMNS,
    min_samples: int = 20,
    min_duration_s: float = 10.0,
) -> Table:
    """The parsing core: a TSO CSV file (a path, read in bounded chunks, its text or bytes, or an iterable
    of byte chunks) -> :class:`Table`.

    Blocks of lines are parsed vectorised (:mod:`fcrlive.tso.csvparse`); a block that the fast path does
    not take is parsed record by record, which reports the first problem with its row. Checks: the header
    (:func:`_parse_header`); in each record, in file order, the number of fields, the time stamp and the
    values (``SIGNAL_COLUMNS`` and ``required`` finite numbers by the strict ASCII grammar); time stamps
    strictly increasing; at least ``min_samples`` records spanning at least ``min_duration_s`` [s].
    DataError(where="WHERE, row N" or "WHERE") otherwise.
    """
    blocks = csvparse.blocks(_chunks(source, where), where)
    first = next(blocks, None)
    if first is None:
        raise DataError("empty file: no header line", where=where)
    header = _parse_header(_read_header_line(first[1], where), required, where)
    ncol = len(header.names)
    names = header.names[1:]
    kinds = _column_kinds(names, required)
    want_text = [k != "strict" for k in kinds]
    rows: list[np.ndarray] = []
    times: list[np.ndarray] = []
    values: list[list[np.ndarray | None]] = [[] for _ in names]
    texts: list[list[np.ndarray]] = [[] for _ in names]
    last: tuple[int, int] | None = None  # (t_us, row) of the previous block's last record
    for row0, block in blocks:
        b = csvparse.parse_block(block, row0, ncol, want_text)
        if b is not None and any(
            k == "strict" and (v is None or not np.isfinite(v).all()) for k, v in zip(kinds, b.values)
        ):
            b = None  # let the slow path name the bad value
        if b is None:
            b = _slow_block(block, row0, ncol, kinds, names, where)
        elif b.t_us is None:
            b.t_us = _parse_timestamps([s.decode("ascii") for s in b.stamps], b.rows, where)
        if b.rows.size == 0:
            continue
        if last is not None:
            _check_time_order(np.array([last[0], b.t_us[0]]), np.array([last[1], b.rows[0]]), where)
        _check_time_order(b.t_us, b.rows, where)
        last = (int(b.t_us[-1]), int(b.rows[-1]))
        rows.append(b.rows)
        times.append(b.t_us)
        for j, kind in enumerate(kinds):
            values[j].append(b.values[j])
            if kind != "strict":
                texts[j].append(b.texts[j])
    n = sum(r.size for r in rows)
    if n < max(min_samples, 2):
        raise DataError(f"log too short: {n} samples, need at least {max(min_samples, 2)}", where=where)
    t_us = np.concatenate(times)
    duration = (t_us[-1] - t_us[0]) / 1e6
    if duration < min_duration_s:
        raise DataError(f"log too short: {duration:.3f} s, need at least {min_duration_s:g} s", where=where)
    columns: dict[str, np.ndarray] = {}
    for j, (name, kind) in enumerate(zip(names, kinds)):
        if kind != "text" and all(v is not None for v in values[j]):
            columns[name] = np.concatenate(values[j])
        else:
            raw = np.concatenate(texts[j])
            columns[name] = np.char.strip(np.char.decode(raw, "utf-8", errors="replace"))
        values[j] = texts[j] = []  # free as we go
    return Table(header=header, rows=np.concatenate(rows), t_us=t_us, columns=columns)


def _tso_name(path: Path) -> TsoFileName | None:
    """The parsed file name when it follows the TSO naming convention, else None."""
    try:
        return parse_tso_filename(path.name)
    except DataError:
        return None


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
    table = parse_table(
        path,
        where=where,
        required=required,
        min_samples=min_samples,
        min_duration_s=min_duration_s,
    )
    fname = _tso_name(path)
    grid = _regularise(table, where=where, max_fill=max_fill, jitter=jitter)
    return TsoLog(
        t_s=grid.samples.t,
        start=_us_to_datetime(table.t_us[0]),
        columns=grid.samples.columns,
        period_s=table.header.period_s,
        units=table.header.units,
        timezone=fname.timezone if fname else "UTC",
        path=path,
        sample_s=grid.sample_s,
        filled=grid.samples.filled,
        segments=grid.samples.segments,
        gaps=grid.gaps,
        rows=grid.rows,
        name=fname,
        notes=_notes(fname, table.header.period_s, grid),
    )


@dataclass(frozen=True, eq=False)
class _Grid:
    """A table on its sampling grid: short gaps filled, segments split at long ones."""

    samples: Filled
    rows: np.ndarray
    """File row of each sample, 0 for the filled ones."""
    gaps: tuple[Gap, ...]
    sample_s: float


def _regularise(table: Table, *, where: str, max_fill: int, jitter: float) -> _Grid:
    """Check the sample interval, report gaps, fill short ones, split at long ones (the gap rule and the
    filling of :mod:`fcrlive.signals`)."""
    t_us, rows = table.t_us, table.rows
    dt = np.diff(t_us).astype(np.float64)
    ts = median_interval(t_us)
    tol = max(jitter * ts, 1000.0)  # time stamps have 1 ms resolution
    irregular = ~is_gap(dt, ts) & (np.abs(dt - ts) > tol)
    if np.any(irregular):
        i = int(np.argmax(irregular))
        raise DataError(
            f"non-uniform sample interval: {dt[i] / 1e6:.3f} s from {table.stamp(i)!r} to "
            f"{table.stamp(i + 1)!r}, "
            f"the median is {ts / 1e6:.3f} s (tolerance ±{tol / 1e6:.3f} s; gaps are > {GAP_FACTOR:g}x the "
            "median)",
            where=f"{where}, row {rows[i + 1]}",
        )
    found = find_gaps(t_us, ts=ts, max_fill=max_fill, tol=tol)
    gaps = tuple(
        Gap(
            row=int(rows[i + 1]),
            start=_us_to_datetime(t_us[i]),
            t_s=(t_us[i] - t_us[0]) / 1e6,
            length_s=dt[i] / 1e6,
            missing=int(m),
            filled=bool(f),
        )
        for i, m, f in zip(found.index, found.missing, found.filled)
    )
    t_rel = (t_us - t_us[0]).astype(np.float64) / 1e6
    out = fill_gaps(t_rel, table.columns, found)
    return _Grid(samples=out, rows=np.where(out.filled, 0, rows[out.source]), gaps=gaps, sample_s=ts / 1e6)


def _notes(fname: TsoFileName | None, period_s: float | None, grid: _Grid) -> tuple[str, ...]:
    """Where the file name and the data disagree, and every gap."""
    notes: list[str] = []
    if fname is not None:
        if abs(fname.sample_s - grid.sample_s) > 0.01 * fname.sample_s + 1e-3:
            notes.append(
                f"file name says {fname.sample_s:g} s sampling, the time stamps say {grid.sample_s:g} s"
            )
        if period_s is not None and fname.period_s is not None and fname.period_s != period_s:
            notes.append(f"file name says period {fname.period_s:g} s, the headers say {period_s:g} s")
    notes.extend(str(g) for g in grid.gaps)
    return tuple(notes)


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
    cols: list[np.ndarray] = []
    fmts: list[str] = ["%s"]
    for name, col in log.columns.items():
        col = col[keep]
        if col.dtype.kind in "fiub":
            d = decimals if isinstance(decimals, int) else decimals.get(name, DEFAULT_DECIMALS)
            values = np.asarray(col, dtype=np.float64)
            if not np.all(np.isfinite(values)):
                raise ValueError(f"column {name} has non-finite values; the TSO format cannot hold them")
            cols.append(values)
            fmts.append(f"%.{int(d)}f")
        else:
            strs = np.asarray(col, dtype=str)
            for s in strs:
                if not s.isascii() or any(ch in s for ch in ',"\r\n'):
                    raise ValueError(f"column {name}: value {s!r} cannot be written (ASCII, no comma)")
            cols.append(strs)
            fmts.append("%s")
    row_fmt = ",".join(fmts) + "\r\n"
    # In chunks of rows: a day of samples as one list of Python strings would take gigabytes.
    with path.open("wb") as f:
        f.write((",".join(f"{h}{suffix}" for h in headers) + "\r\n").encode("ascii"))
        for lo in range(0, ms.size, _WRITE_ROWS):
            hi = min(lo + _WRITE_ROWS, ms.size)
            iso = np.datetime_as_string(start_ms + ms[lo:hi].astype("timedelta64[ms]"), unit="ms")
            stamps = np.char.replace(np.char.replace(iso, "-", ""), ":", "")
            parts = [stamps.tolist(), *(c[lo:hi].tolist() for c in cols)]
            f.write("".join(row_fmt % r for r in zip(*parts)).encode("ascii"))
    return path


_WRITE_ROWS = 50_000
"""Rows formatted and written at a time by :func:`write_log`."""
