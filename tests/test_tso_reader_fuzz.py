"""The TSO log reader on arbitrary input (hypothesis): arbitrary bytes and arbitrary mutations of a valid
log give a log or a DataError, never another exception or a hang; the result does not depend on how the
file is cut into chunks; numbers are read exactly as float() reads them, by the strict ASCII grammar."""

from __future__ import annotations

import os
import re
from datetime import datetime, timedelta

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fcrlive.errors import DataError
from fcrlive.tso import csvparse
from fcrlive.tso.csvlog import format_timestamp, parse_table, read_log
from fcrlive.tso.plausibility import check_log

START = datetime(2026, 11, 1)
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _valid(n: int = 120, header: str = "DateTime,InsAcPow,GridFreq,ContMode_Fcrn,Remark") -> bytes:
    rng = np.random.default_rng(0)
    rows = [header]
    for i in range(n):
        stamp = format_timestamp(START + timedelta(seconds=0.1 * i))
        rows.append(f"{stamp},{225 + rng.normal():.6f},{50 + 0.02 * rng.normal():.6f},FCRN4,{i}")
    return ("\r\n".join(rows) + "\r\n").encode("ascii")


VALID = _valid()
TOKENS = [b"nan", b"1e999", b"-inf", "\u0663".encode(), b"2_25.0", b'"', b"\r", b"\n", b"\x00", b",", b";",
          b" ", b"\xef\xbb\xbf", b"\xff\xfe", b"1e30", b"-", b".", b"e", b"T", b"20261131T000000.000"]


def _outcome(fn):
    try:
        return fn()
    except DataError as exc:
        assert "\n" not in str(exc)
        assert exc.where
        return exc


def _parse(data: bytes, chunk: int | None = None, where: str = "fuzz.csv"):
    source = data if chunk is None else (data[i : i + chunk] for i in range(0, len(data), chunk))
    return _outcome(lambda: parse_table(source, where=where, min_samples=2, min_duration_s=0.0))


@pytest.mark.timeout(120)
@FUZZ
@given(st.binary(max_size=3000))
def test_arbitrary_bytes_give_a_table_or_a_data_error(data):
    _parse(data)
    _parse(VALID[:60] + data)


@st.composite
def mutated(draw):
    data = bytearray(VALID)
    for _ in range(draw(st.integers(1, 6))):
        kind = draw(st.sampled_from(["flip", "insert", "delete", "token", "dup_line", "truncate"]))
        pos = draw(st.integers(0, len(data)))
        if kind == "flip" and pos < len(data):
            data[pos] = draw(st.integers(0, 255))
        elif kind == "insert":
            data[pos:pos] = draw(st.binary(min_size=1, max_size=20))
        elif kind == "delete":
            del data[pos : pos + draw(st.integers(1, 40))]
        elif kind == "token":
            data[pos:pos] = draw(st.sampled_from(TOKENS))
        elif kind == "dup_line":
            start = data.rfind(b"\n", 0, pos) + 1
            end = data.find(b"\n", pos)
            if end > start:
                data[end + 1 : end + 1] = data[start : end + 1]
        elif kind == "truncate":
            del data[pos:]
    return bytes(data)


@pytest.mark.timeout(300)
@FUZZ
@given(mutated(), st.integers(1, 200))
def test_mutated_logs_give_a_log_or_a_data_error_whatever_the_chunks(tmp_path, monkeypatch, data, chunk):
    monkeypatch.setattr(csvparse, "BLOCK_LINES", 7)  # many blocks, and block boundaries everywhere
    monkeypatch.setattr(csvparse, "BLOCK_BYTES", 500)
    whole = _parse(data)
    pieces = _parse(data, chunk)
    if isinstance(whole, DataError):
        assert isinstance(pieces, DataError), str(whole)
        assert str(pieces) == str(whole)
    else:
        assert not isinstance(pieces, DataError), str(pieces)
        np.testing.assert_array_equal(pieces.t_us, whole.t_us)
        np.testing.assert_array_equal(pieces.rows, whole.rows)
        assert pieces.columns.keys() == whole.columns.keys()
        for k in whole.columns:
            np.testing.assert_array_equal(pieces.columns[k], whole.columns[k])
    path = tmp_path / "m.csv"
    path.write_bytes(data)
    log = _outcome(lambda: read_log(path, min_samples=2, min_duration_s=0.0))
    if not isinstance(log, DataError):
        _outcome(lambda: check_log(log, rated_mw=300.0))


def test_rows_are_counted_across_chunks_and_blocks(monkeypatch):
    monkeypatch.setattr(csvparse, "BLOCK_LINES", 33)
    data = bytearray(_valid(400))
    lines = bytes(data).split(b"\r\n")
    lines[300] = lines[300].replace(b",FCRN4", b"x,FCRN4")  # row 301 of the file: a bad GridFreq
    bad = b"\r\n".join(lines)
    for chunk in (7, 64, 1000, None):
        err = _parse(bad, chunk)
        assert isinstance(err, DataError) and err.where == "fuzz.csv, row 301", (chunk, str(err))


NUM = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False).map(repr),
    st.floats(allow_nan=False, allow_infinity=False, width=32).map(lambda x: f"{x:.6f}"),
    st.from_regex(re.compile(r"[+-]?([0-9]{1,20}\.?[0-9]{0,20}|\.[0-9]{1,20})([eE][+-]?[0-9]{1,3})?"),
                  fullmatch=True),
)


@settings(max_examples=300, deadline=None)
@given(st.lists(NUM, min_size=1, max_size=40))
def test_numbers_are_read_exactly_as_float_reads_them(values):
    values = [v for v in values if len(v) <= csvparse.MAX_FIELD_BYTES]
    if not values:
        return
    b = [v.encode() for v in values]
    width = max(len(x) for x in b)
    m = np.zeros((len(b), width), np.uint8)
    for i, x in enumerate(b):
        m[i, : len(x)] = list(x)
    got = csvparse.parse_numbers(m, np.array([len(x) for x in b]))
    want = np.array([float(v) for v in values])
    assert got is not None
    np.testing.assert_array_equal(got, want)
    assert (np.signbit(got) == np.signbit(want)).all()


@pytest.mark.parametrize(
    "text", ["2_25.0", "\u0662\u0662\u0665.0", "nan", "inf", "1e", "0x10", "1,5", " 1 e3"]
)
def test_what_float_accepts_but_the_grammar_does_not(tmp_path, text):
    rows = _valid(50).decode().split("\r\n")
    fields = rows[20].split(",")
    fields[1] = f'"{text}"' if "," in text else text
    rows[20] = ",".join(fields)
    p = tmp_path / "g.csv"
    p.write_bytes("\r\n".join(rows).encode("utf-8"))
    with pytest.raises(DataError) as e:
        read_log(p, min_samples=2)
    assert e.value.where == f"{p}, row 21"
    assert "InsAcPow" in e.value.message


@pytest.mark.timeout(30)
def test_special_files_are_refused_before_opening(tmp_path):
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    for path, text in ((fifo, "FIFO"), ("/dev/zero", "device"), (tmp_path, "directory")):
        with pytest.raises(DataError, match=text):
            read_log(path)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=30, max_size=80),
    st.integers(0, 9),
    st.sampled_from(["%.{k}f", "%+.{k}f", "%.{k}e", "%r"]),
)
def test_signal_columns_are_read_as_float_reads_them(values, k, style):
    texts = [repr(v) if style == "%r" else style.format(k=k) % v for v in values]
    rows = ["DateTime,InsAcPow,GridFreq"]
    for i, t in enumerate(texts):
        rows.append(f"{format_timestamp(START + timedelta(seconds=0.1 * i))},{t},{t}")
    table = parse_table(("\r\n".join(rows) + "\r\n").encode(), where="v.csv", min_samples=2, min_duration_s=0)
    want = np.array([float(t) for t in texts])
    for name in ("InsAcPow", "GridFreq"):
        np.testing.assert_array_equal(table.columns[name], want)
        assert (np.signbit(table.columns[name]) == np.signbit(want)).all()
