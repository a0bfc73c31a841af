"""Opening a log file safely: a regular file only, a bounded read, and a look at the first bytes.

A TSO log is a text file. Anything else that a user may point the reader at is refused with one line
that says what the file is and what to do, before reading it (a FIFO with no writer would block forever,
``/dev/zero`` would fill the memory) or after a look at its first bytes (gzip, zip/xlsx, UTF-16, binary
data, line ends that are CR only).
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from pathlib import Path

from fcrlive.errors import DataError

MAX_FILE_BYTES = 4 * 1024**3
"""Largest log read [bytes]: 4 GiB holds 24 h at 50 Hz with 20 columns; a larger file is refused."""

CHUNK_BYTES = 4 * 1024**2
"""Bytes read at a time [bytes]."""

_SNIFF_BYTES = 64 * 1024


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _refuse_special(mode: int, where: str) -> None:
    if not stat.S_ISREG(mode):
        raise DataError(
            f"is {_kind(mode)}, not a regular file: give the CSV log file itself (copy a stream to a file "
            "first)",
            where=where,
        )


def sniff(head: bytes, where: str) -> None:
    """DataError when the first bytes show a compressed, UTF-16 or binary file, or CR-only line ends."""
    if head.startswith(b"\x1f\x8b"):
        raise DataError("is gzip-compressed, not a CSV text: decompress it first (gunzip)", where=where)
    if head.startswith((b"PK\x03\x04", b"BZh", b"\xfd7zXZ", b"\x28\xb5\x2f\xfd")):
        raise DataError(
            "is compressed or a zip/xlsx archive, not a CSV text: extract it, or export the sheet as CSV",
            where=where,
        )
    if head.startswith((b"\xff\xfe", b"\xfe\xff")) or (
        len(head) >= 4 and (head[1::2].count(0) > len(head) // 4 or head[0::2].count(0) > len(head) // 4)
    ):
        raise DataError(
            "is UTF-16 encoded; the TSO format is ASCII: save it as ASCII or UTF-8 CSV", where=where
        )
    if b"\x00" in head:
        raise DataError("holds binary data (NUL bytes), not a CSV text: give the CSV log file", where=where)
    if b"\r" in head and b"\n" not in head:
        raise DataError(
            "line ends are CR only (old Mac style); the TSO format uses CRLF: convert the line ends "
            "(e.g. tr '\\r' '\\n')",
            where=where,
        )


def iter_bytes(path: Path, where: str, *, max_bytes: int = MAX_FILE_BYTES,
               chunk: int = CHUNK_BYTES) -> Iterator[bytes]:
    """The file's bytes in chunks (the first chunk sniffed). Refuses, before opening, what is not a regular
    file (a FIFO would block, a device may never end), and a file over ``max_bytes``."""
    try:
        st = os.stat(path)
    except OSError as exc:
        raise DataError(f"cannot read the file: {exc.strerror or exc}", where=where) from None
    _refuse_special(st.st_mode, where)
    if st.st_size > max_bytes:
        raise DataError(
            f"is {st.st_size / 1024**3:.1f} GiB, more than the {max_bytes / 1024**3:.0f} GiB a log may have: "
            "split it into shorter logs",
            where=where,
        )
    try:
        # O_NONBLOCK: should the path have been swapped for a FIFO since the stat, opening does not block.
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise DataError(f"cannot read the file: {exc.strerror or exc}", where=where) from None
    with os.fdopen(fd, "rb", buffering=0) as f:
        _refuse_special(os.fstat(fd).st_mode, where)
        total = 0
        first = True
        while True:
            try:
                data = f.read(chunk)
            except OSError as exc:
                raise DataError(f"cannot read the file: {exc.strerror or exc}", where=where) from None
            if not data:
                return
            total += len(data)
            if total > max_bytes:
                raise DataError(f"grew past {max_bytes / 1024**3:.0f} GiB while being read", where=where)
            if first:
                sniff(data[:_SNIFF_BYTES], where)
                first = False
            yield data


def read_bytes(path: Path, where: str, *, max_bytes: int = MAX_FILE_BYTES) -> bytes:
    """The whole file (see :func:`iter_bytes`)."""
    return b"".join(iter_bytes(path, where, max_bytes=max_bytes))
