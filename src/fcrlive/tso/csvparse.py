"""The byte-level parser behind :func:`fcrlive.tso.csvlog.parse_table`: vectorised, in blocks of lines.

The file is read in chunks (:mod:`fcrlive.tso.rawfile`) and cut into blocks of whole lines. Each block is
parsed with numpy on its bytes: line and comma positions, one ``(rows, width)`` byte matrix per column,
the number grammar checked on that matrix and the value computed from its digits. Nothing is turned into
a Python object per value, so a day of 10 Hz samples reads in seconds with memory proportional to the
result, not to the text.

The fast path takes what well-formed logs are: ASCII, no quotes, no blanks inside a line, one record per
line with the header's number of fields (or a trailing comma). A block with anything else (quotes, a
UTF-8 header's characters in a text column, a bad number, a wrong field count) returns None from
:func:`parse_block`; the caller then parses that block the slow way, which reports the first problem with
its row, or accepts what the documented leniency allows.

Numbers: the strict ASCII grammar ``[+-]?(D+[.D*]|.D+)([eE][+-]?D+)?`` (D a digit 0-9), nothing else:
not ``nan``/``inf``, not ``2_25.0``, not Arabic-Indic digits, which Python's ``float()`` would all accept.
The value is the one ``float()`` gives: an integer mantissa below 2**53 and a power of ten up to 10**22 are
both exact in binary64, so one multiplication or division rounds correctly (Clinger's fast path, as
CPython's own parser does); the few values outside that (more than 15 significant digits, large exponents)
go through ``float()`` after the grammar check.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from fcrlive.errors import DataError

NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
"""The strict ASCII number grammar (use with ``fullmatch``)."""

MAX_LINE_BYTES = 1024 * 1024
"""A line longer than this [bytes] is not a TSO record."""

MAX_FIELD_BYTES = 64
"""A numeric field longer than this [bytes] takes the slow path (which says what is wrong with it)."""

_POW10_I = 10 ** np.arange(19, dtype=np.int64)
_POW10_F = 10.0 ** np.arange(23)
_NL, _CR, _COMMA = 10, 13, 44


BLOCK_LINES = 50_000
"""A block ends after this many lines, ..."""

BLOCK_BYTES = 4 * 1024 * 1024
"""... or at the first line end past this many bytes [bytes]: blocks are cut by the content alone, never
by how the file was read, so the first problem found does not depend on the chunk size."""


def blocks(chunks: Iterable[bytes], where: str) -> Iterator[tuple[int, bytes]]:
    """(first row, bytes of whole lines) from a stream of chunks; the header line comes alone as row 1.

    A UTF-8 byte-order mark is dropped. The last line may lack its line end (one is added). DataError for
    a line longer than :data:`MAX_LINE_BYTES`.
    """
    pending: list[bytes] = []
    size = lines = tail = 0  # bytes, line ends, bytes after the last line end in pending
    row = 1  # file row of the first line in pending
    first = True
    waiting = False  # a block is due but its line end has not come: scan again on the next line end
    for chunk in chunks:
        if first and chunk:
            first = False
            if chunk.startswith(b"\xef\xbb\xbf"):
                chunk = chunk[3:]
        if not chunk:
            continue
        pending.append(chunk)
        size += len(chunk)
        k = chunk.count(b"\n")
        lines += k
        tail = len(chunk) - 1 - chunk.rfind(b"\n") if k else tail + len(chunk)
        if tail > MAX_LINE_BYTES:
            _check_line_length(tail, row + lines, where)
        if waiting and not k:
            continue
        while lines and (row == 1 or lines >= BLOCK_LINES or size >= BLOCK_BYTES):
            buf = b"".join(pending)
            cut = _cut(buf, header=row == 1)
            waiting = cut is None
            if cut is None:
                pending = [buf]
                break
            block, rest = buf[:cut], buf[cut:]
            pending, size = ([rest], len(rest)) if rest else ([], 0)
            n = block.count(b"\n")
            lines -= n
            yield row, block
            row += n
    buf = b"".join(pending)
    while buf:
        cut = _cut(buf, header=row == 1) or len(buf)
        block, buf = buf[:cut], buf[cut:]
        yield row, block if block.endswith(b"\n") else block + b"\n"
        row += block.count(b"\n") + (not block.endswith(b"\n"))
    if row == 1:
        yield 1, b""


def _cut(buf: bytes, *, header: bool) -> int | None:
    """Where the first block of ``buf`` ends (after a line end), or None when ``buf`` holds less than a
    block: the header line alone; else :data:`BLOCK_LINES` lines or the first line end at or past
    :data:`BLOCK_BYTES`."""
    if header:
        i = buf.find(b"\n")
        return None if i < 0 else i + 1
    nl = np.flatnonzero(np.frombuffer(buf, dtype=np.uint8) == _NL)
    cuts = []
    if nl.size >= BLOCK_LINES:
        cuts.append(int(nl[BLOCK_LINES - 1]) + 1)
    k = int(np.searchsorted(nl, BLOCK_BYTES - 1))
    if k < nl.size:
        cuts.append(int(nl[k]) + 1)
    return min(cuts) if cuts else None


def _check_line_length(length: int, row: int, where: str) -> None:
    if length > MAX_LINE_BYTES:
        raise DataError(
            f"line longer than {MAX_LINE_BYTES // 1024} KiB with no line end: not a TSO log record "
            "(is it the right file?)",
            where=f"{where}, row {row}",
        )


@dataclass
class Block:
    """One block of data records parsed."""

    rows: np.ndarray
    """File row of each record (int64)."""
    t_us: np.ndarray | None
    """Time stamps [µs since 1970] (int64), None when they are not all the compact form of one width."""
    stamps: np.ndarray
    """The time-stamp fields as bytes (``S`` array), for the slow time-stamp parser and messages."""
    values: list[np.ndarray | None]
    """Per column after DateTime: float64 values, or None where a value is not a number (or empty)."""
    texts: list[np.ndarray]
    """Per column after DateTime: the fields as bytes (``S`` array)."""


_FAST_BYTES = bytes([_NL, _CR, *(c for c in range(33, 127) if c != 34)])
"""What the fast path takes: printable ASCII but the blank and the quote (the slow path unquotes), and line
ends."""
_PAD = 64  # zero bytes in front of a block, so that every field can be gathered as a window ending at it


def parse_block(block: bytes, first_row: int, ncol: int, want_text: list[bool] | None = None) -> Block | None:
    """The records of ``block`` (whole lines, ``ncol`` fields each), or None when the block needs the slow
    path (see the module docstring). ``want_text[j]``: keep column j's fields as bytes too (columns after
    DateTime; default all)."""
    if ncol < 2 or block.translate(None, _FAST_BYTES):
        return None
    a = np.frombuffer(bytes(_PAD) + block, dtype=np.uint8)
    nl = np.flatnonzero(a == _NL)
    if nl.size == 0:
        return None
    starts = np.empty_like(nl)
    starts[0] = _PAD
    starts[1:] = nl[:-1] + 1
    ends = nl.copy()
    ncr = block.count(b"\r")
    if ncr:
        crlf = (a[np.maximum(nl - 1, 0)] == _CR) & (nl > starts)
        if np.count_nonzero(crlf) != ncr:
            return None  # a CR that is not part of a CRLF
        ends -= crlf
    rows = first_row + np.arange(nl.size, dtype=np.int64)
    nonblank = ends > starts
    if not np.all(nonblank):
        starts, ends, rows = starts[nonblank], ends[nonblank], rows[nonblank]
        if starts.size == 0:
            return Block(rows, np.empty(0, np.int64), np.empty(0, "S1"), [np.empty(0)] * (ncol - 1),
                         [np.empty(0, "S1")] * (ncol - 1))
    commas = np.flatnonzero(a == _COMMA)
    first = np.searchsorted(commas, starts)
    count = np.searchsorted(commas, ends) - first
    trailing = count == ncol
    if not np.all((count == ncol - 1) | trailing):
        return None
    if np.any(trailing) and np.any(commas[first[trailing] + ncol - 1] != ends[trailing] - 1):
        return None  # a last field after the header's count that is not empty
    seps = [commas[first + j] for j in range(ncol - 1)]
    field_starts = [starts] + [c + 1 for c in seps]
    field_ends = [*seps, np.where(trailing, ends - 1, ends)]
    stamps = _matrix(a, field_starts[0], field_ends[0])
    if stamps is None:
        return None
    t_us = compact_timestamps(stamps)
    values: list[np.ndarray | None] = []
    texts: list[np.ndarray] = []
    for j in range(1, ncol):
        fs, fe = field_starts[j], field_ends[j]
        keep_text = want_text is None or want_text[j - 1]
        v = None if keep_text else fixed_numbers(a, fs, fe)
        m = None
        if v is None:
            m = _matrix(a, fs, fe)
            if m is None:
                return None
            v = parse_numbers(m, fe - fs)
        values.append(v)
        texts.append(_as_bytes(m) if keep_text else np.empty(0, "S1"))
    return Block(rows, t_us, _as_bytes(stamps) if t_us is None else np.empty(0, "S1"), values, texts)


def fixed_numbers(a: np.ndarray, s: np.ndarray, e: np.ndarray) -> np.ndarray | None:
    """Float64 values of the fields a[s:e] when they all have the same number of fractional digits and no
    exponent (what loggers write: ``%.6f``), at most 15 digits and an optional sign; None otherwise (the
    general :func:`parse_numbers` then decides). Aligned at the right end, every field's digits have fixed
    powers of ten, so the mantissa is one matrix-vector product of exact integers (below 2**53, exact in
    any summation order) and the value one correctly rounded division."""
    w = e - s
    if w.size == 0:
        return np.empty(0)
    width = int(w.max())
    if width > 17 or int(w.min()) == 0:
        return None
    pos = np.arange(width - 1, -1, -1)  # bytes to the right of each column of the matrix
    m = np.lib.stride_tricks.sliding_window_view(a, width)[e - width]  # a copy: row gathers
    first = bytes(a[s[0] : e[0]])
    if first.count(b".") != 1:
        return None
    k = len(first) - 1 - first.index(b".")  # fractional digits
    dotcol = width - 1 - k
    if width - 1 > 15 or (w < k + 1).any():
        return None  # too many digits to be exact, or a field too short to hold the dot
    if int(w.min()) < width:  # what lies left of a shorter field counts as leading zeros
        m = np.where(pos[None, :] >= w[:, None], np.uint8(48), m)
    if not (m[:, dotcol] == 46).all():
        return None
    m[:, dotcol] = 48
    idx = np.arange(m.shape[0])
    leadcol = width - w
    lead = m[idx, leadcol]
    neg = lead == 45
    sign = neg | (lead == 43)
    if sign.any():
        m[idx[sign], leadcol[sign]] = 48
    m -= 48
    if (m > 9).any() or (w - sign - 1 < 1).any():
        return None  # a byte that is not a digit, or no digit at all (".", "-.")
    weights = np.zeros(width)
    other = pos != k
    weights[other] = 10.0 ** (pos[other] - (pos[other] > k))
    out = m @ weights
    if k:
        out /= _POW10_F[k]
    return np.where(neg, -out, out) if neg.any() else out


def _matrix(a: np.ndarray, s: np.ndarray, e: np.ndarray) -> np.ndarray | None:
    """The fields a[s:e] as a (n, width) uint8 matrix padded with zeros; None if a field is too long."""
    w = e - s
    width = int(w.max()) if w.size else 0
    if width > MAX_FIELD_BYTES:
        return None
    width = max(width, 1)
    # fields gathered as windows that end where they end, then shifted to start at column 0
    m = np.lib.stride_tricks.sliding_window_view(a, width)[np.minimum(s, a.size - width)]
    short = w < width
    if short.any():
        rows = np.flatnonzero(short)
        m[rows] = 0
        for k in np.unique(w[rows]):
            r = rows[w[rows] == k]
            if k:
                m[r, :k] = a[s[r][:, None] + np.arange(k)]
    return m


def _as_bytes(m: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(m).view(f"S{m.shape[1]}").ravel()


def parse_numbers(m: np.ndarray, w: np.ndarray) -> np.ndarray | None:
    """Float64 values of the fields in the byte matrix ``m`` (widths ``w``), NaN for empty fields, or None if
    any field breaks the strict number grammar."""
    n, width = m.shape
    if n == 0:
        return np.empty(0)
    pos = np.arange(width)
    inside = pos < w[:, None]
    digit = (m >= 48) & (m <= 57)
    dot = m == 46
    e = (m == 101) | (m == 69)
    sign = (m == 43) | (m == 45)
    if np.any(inside & ~(digit | dot | e | sign)):
        return None
    empty = w == 0
    ne = e.sum(axis=1)
    if np.any(ne > 1) or np.any(dot.sum(axis=1) > 1):
        return None
    epos = np.where(ne == 1, np.argmax(e, axis=1), w)
    before_e = pos < epos[:, None]
    after_e = pos > epos[:, None]
    # a sign only first or right after the exponent mark; the dot only in the mantissa
    sign_ok = (pos == 0) | (pos == (epos + 1)[:, None])
    if np.any(sign & ~sign_ok) or np.any(dot & ~before_e):
        return None
    mant = digit & before_e
    expd = digit & after_e
    nmant = mant.sum(axis=1)
    nexp = expd.sum(axis=1)
    if np.any((nmant == 0) & ~empty) or np.any((ne == 1) & (nexp == 0)):
        return None
    d = (m.astype(np.int64) - 48) * digit
    # powers of ten of each mantissa digit: the mantissa digits to its right
    right = np.cumsum(mant[:, ::-1], axis=1)[:, ::-1] - mant
    dotpos = np.where(dot.any(axis=1), np.argmax(dot, axis=1), epos)
    nfrac = (mant & (pos > dotpos[:, None])).sum(axis=1)
    big = (nmant > 18) | (nexp > 4) | empty
    safe_right = np.where(mant & ~big[:, None], right, 0)
    mantissa = (d * mant * _POW10_I[np.minimum(safe_right, 18)]).sum(axis=1)
    eright = np.cumsum(expd[:, ::-1], axis=1)[:, ::-1] - expd
    expo = (d * expd * _POW10_I[np.minimum(np.where(expd & ~big[:, None], eright, 0), 18)]).sum(axis=1)
    exp_neg = np.any(sign & (pos == (epos + 1)[:, None]) & (m == 45), axis=1)
    expo = np.where(exp_neg, -expo, expo)
    e10 = expo - nfrac
    neg = m[:, 0] == 45
    exact = (~big & (mantissa < 2**53) & (np.abs(e10) <= 22)) | empty
    k = np.clip(np.abs(e10), 0, 22)
    mf = mantissa.astype(np.float64)
    out = np.where(e10 >= 0, mf * _POW10_F[k], mf / _POW10_F[k])
    out = np.where(neg, -out, out)
    out[empty] = np.nan
    if not np.all(exact):
        for i in np.flatnonzero(~exact):
            out[i] = float(bytes(m[i, : w[i]]))
    return out


def compact_timestamps(m: np.ndarray) -> np.ndarray | None:
    """Microseconds since 1970 (int64) of ``YYYYMMDDThhmmss[.f...]`` stamps of one width in the byte matrix
    ``m``; None when they are not all that form (the caller then reads them one by one)."""
    n, width = m.shape
    if n == 0:
        return np.empty(0, np.int64)
    if width < 15 or width == 16 or width > 25:
        return None
    if (m[:, 8] != ord("T")).any() or (width > 15 and (m[:, 15] != ord(".")).any()):
        return None
    d = m - np.uint8(48)  # wraps around for bytes below '0': then > 9 too
    d[:, 8] = 0
    if width > 15:
        d[:, 15] = 0
    if (d > 9).any():
        return None

    def num(lo: int, hi: int) -> np.ndarray:
        out = d[:, lo].astype(np.int64)
        for j in range(lo + 1, hi):
            out *= 10
            out += d[:, j]
        return out

    if (m[:, :8] == m[0, :8]).all():  # one day in the block: the date once
        year, month, day = num(0, 4)[:1], num(4, 6)[:1], num(6, 8)[:1]
    else:
        year, month, day = num(0, 4), num(4, 6), num(6, 8)
    hour, minute, sec = num(9, 11), num(11, 13), num(13, 15)
    if ((month < 1) | (month > 12) | (day < 1) | (year < 1)).any():
        return None
    if ((hour > 23) | (minute > 59) | (sec > 59)).any():
        return None
    months = (year - 1970).astype("datetime64[Y]").astype("datetime64[M]") + (month - 1).astype(
        "timedelta64[M]"
    )
    dates = months.astype("datetime64[D]") + (day - 1).astype("timedelta64[D]")
    if (dates.astype("datetime64[M]") != months).any():  # e.g. 31 November
        return None
    us = ((hour * 60 + minute) * 60 + sec) * 1_000_000
    us += dates.astype("datetime64[us]").astype(np.int64)
    nfrac = width - 16
    if nfrac > 0:
        frac = num(16, width)
        if nfrac <= 6:
            us += frac * 10 ** (6 - nfrac)
        else:
            us += np.rint(frac / 10 ** (nfrac - 6)).astype(np.int64)
    return us
