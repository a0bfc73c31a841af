"""TSO CSV logs: round trip, format details, leniency on reading, and one DataError per bad input."""

from __future__ import annotations

import types
from datetime import datetime, timedelta

import numpy as np
import pytest

from fcrlive import cli
from fcrlive.errors import DataError
from fcrlive.tso.csvlog import TsoLog, format_timestamp, read_log, write_log

START = datetime(2026, 11, 1, 0, 0, 0)


def _log(n: int = 500, dt: float = 0.1, period_s: float | None = None, seed: int = 0) -> TsoLog:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    return TsoLog.from_arrays(
        t,
        {
            "InsAcPow": 225.0 + rng.normal(scale=2.0, size=n),
            "GridFreq": 50.0 + 0.02 * rng.normal(size=n),
            "ApplFreqSig": 50.0 + 0.1 * np.sin(2 * np.pi * t / 40.0),
            "ContMode_Fcrn": np.array(["FCRN4"] * n),
        },
        START,
        period_s=period_s,
    )


def _stamp(i: int, dt: float = 0.1) -> str:
    return format_timestamp(START + timedelta(seconds=i * dt))


def _write_rows(path, header: str, rows: list[str], newline: str = "\r\n") -> str:
    path.write_bytes((newline.join([header, *rows]) + newline).encode("ascii"))
    return str(path)


def _good_rows(n: int = 200, dt: float = 0.1) -> list[str]:
    return [f"{_stamp(i, dt)},{200 + 0.01 * i:.3f},{50 + 0.001 * (i % 7):.3f}" for i in range(n)]


# --- round trip and format --------------------------------------------------------------------------


def test_round_trip_exact_to_written_resolution(tmp_path):
    log = _log()
    path = write_log(tmp_path / "x.csv", log)
    back = read_log(path)
    assert back.start == START
    assert back.period_s is None
    assert list(back.columns) == ["InsAcPow", "GridFreq", "ApplFreqSig", "ContMode_Fcrn"]
    assert np.max(np.abs(back.t_s - log.t_s)) < 1e-9
    for name in ("InsAcPow", "GridFreq", "ApplFreqSig"):
        assert np.max(np.abs(back.columns[name] - log.columns[name])) <= 0.5e-6 + 1e-12
    assert (back.columns["ContMode_Fcrn"] == "FCRN4").all()
    assert back.sample_s == pytest.approx(0.1)
    assert back.segments == ((0, 500),)
    assert not back.filled.any()
    assert back.gaps == ()
    assert back.units["InsAcPow"] == "MW" and back.units["GridFreq"] == "Hz"
    assert back.rows[0] == 2 and back.rows[-1] == 501


def test_written_file_is_ascii_crlf_with_millisecond_stamps(tmp_path):
    path = write_log(tmp_path / "x.csv", _log(n=150), decimals={"InsAcPow": 3})
    raw = path.read_bytes()
    raw.decode("ascii")
    assert raw.count(b"\r\n") == 151
    assert raw.count(b"\n") == 151  # no bare LF
    lines = raw.decode("ascii").split("\r\n")
    assert lines[0] == "DateTime,InsAcPow,GridFreq,ApplFreqSig,ContMode_Fcrn"
    assert lines[1].startswith("20261101T000000.000,")
    assert lines[2].startswith("20261101T000000.100,")
    power = lines[1].split(",")[1]
    assert len(power.split(".")[1]) == 3
    back = read_log(path)
    assert np.max(np.abs(back.columns["InsAcPow"] - _log(n=150).columns["InsAcPow"])) <= 0.5e-3 + 1e-9


def test_sine_headers_carry_period_and_are_detected(tmp_path):
    path = write_log(tmp_path / "s.csv", _log(period_s=40.0))
    header = path.read_bytes().split(b"\r\n")[0].decode()
    assert header == "DateTime40,InsAcPow40,GridFreq40,ApplFreqSig40,ContMode_Fcrn40"
    back = read_log(path)
    assert back.period_s == 40.0
    assert "InsAcPow" in back.columns and "InsAcPow40" not in back.columns


def test_sine_header_without_suffix_is_refused(tmp_path):
    p = _write_rows(tmp_path / "s.csv", "DateTime40,InsAcPow40,GridFreq", _good_rows())
    with pytest.raises(DataError) as e:
        read_log(p)
    assert e.value.where == f"{p}, row 1"
    assert "'GridFreq'" in e.value.message and "'40'" in e.value.message


def test_lenient_reading_lf_bom_case_trailing_comma_quotes(tmp_path):
    rows = [r + "," for r in _good_rows()]
    rows[3] = rows[3].replace(",200", ',"200', 1).replace(",50", '",50', 1)
    path = tmp_path / "lf.csv"
    path.write_bytes(b"\xef\xbb\xbf" + ("\n".join(["datetime,insacpow,GRIDFREQ,", *rows]) + "\n").encode())
    log = read_log(path)
    assert list(log.columns) == ["InsAcPow", "GridFreq"]
    assert len(log) == 200
    assert log.columns["InsAcPow"][3] == pytest.approx(200.03)


def test_timestamp_variants_agree(tmp_path):
    # ISO 8601 with separators, fewer fractional digits, and microseconds all read to the same times.
    n = 120
    iso = [f"2026-11-01T00:00:{i // 10:02d}.{i % 10}00" for i in range(n)]
    short = [f"20261101T0000{i // 10:02d}.{i % 10}" for i in range(n)]
    micro = [f"20261101T0000{i // 10:02d}.{i % 10}00000" for i in range(n)]
    logs = []
    for k, stamps in enumerate((iso, short, micro)):
        rows = [f"{s},{i:.1f},50.0" for i, s in enumerate(stamps)]
        logs.append(read_log(_write_rows(tmp_path / f"v{k}.csv", "DateTime,InsAcPow,GridFreq", rows)))
    for log in logs:
        assert log.start == START
        np.testing.assert_allclose(log.t_s, np.arange(n) * 0.1, atol=1e-9)


def test_period_suffix_and_timezone_from_tso_file_name(tmp_path):
    name = "FCPG1_Fcrn_Sine40_NO5_CET_20261101T0000-20261101T0100_100ms.csv"
    log = _log(period_s=40.0)
    back = read_log(write_log(tmp_path / name, log))
    assert back.timezone == "CET"
    assert back.name is not None and back.name.period_s == 40.0
    assert back.notes == ()
    mismatch = read_log(write_log(tmp_path / name.replace("100ms", "20ms"), log))
    assert any("20ms" in n or "0.02 s" in n for n in mismatch.notes)


# --- gaps -------------------------------------------------------------------------------------------


def test_gaps_are_reported_short_ones_filled_long_ones_split(tmp_path):
    n = 200
    keep = [i for i in range(n) if not (30 <= i < 32 or 100 <= i < 110)]
    rows = [f"{_stamp(i)},{10.0 + 0.5 * i:.3f},{50 + 0.001 * i:.3f}" for i in keep]
    p = _write_rows(tmp_path / "g.csv", "DateTime,InsAcPow,GridFreq", rows)
    log = read_log(p)
    assert len(log.gaps) == 2
    short, long_ = log.gaps
    assert short.missing == 2 and short.filled and short.length_s == pytest.approx(0.3)
    assert short.start == datetime(2026, 11, 1, 0, 0, 2, 900000)
    assert short.row == 2 + 30  # the sample after the gap: index 32 is the 31st data row
    assert long_.missing == 10 and not long_.filled and long_.length_s == pytest.approx(1.1)
    # 2 samples filled exactly on the line; the 10-sample hole is not interpolated but split.
    assert len(log) == n - 10
    assert log.filled.sum() == 2 and np.flatnonzero(log.filled).tolist() == [30, 31]
    np.testing.assert_allclose(log.columns["InsAcPow"][:100], 10.0 + 0.5 * np.arange(100), atol=1e-9)
    np.testing.assert_allclose(log.t_s[:100], 0.1 * np.arange(100), atol=1e-9)
    assert log.segments == ((0, 100), (100, 190))
    assert log.t_s[100] == pytest.approx(11.0)
    assert (log.rows[log.filled] == 0).all()
    assert any("log split here" in note for note in log.notes)
    assert "gap of 1.100 s (10 samples missing)" in str(long_)
    # filled samples are not written back: the file keeps what was measured
    again = read_log(write_log(tmp_path / "g2.csv", log))
    assert len(again) == len(log) and again.gaps == log.gaps


def test_short_gap_off_the_grid_splits_and_max_fill_zero_never_fills(tmp_path):
    stamps = [i * 0.1 for i in range(50)] + [5.0 + 0.25 + i * 0.1 for i in range(50)]
    rows = [f"{format_timestamp(START + timedelta(seconds=s))},1.0,50.0" for s in stamps]
    p = _write_rows(tmp_path / "o.csv", "DateTime,InsAcPow,GridFreq", rows)
    log = read_log(p)
    assert len(log.gaps) == 1 and not log.gaps[0].filled
    assert log.segments == ((0, 50), (50, 100))
    keep = [i for i in range(120) if i != 40]
    p2 = _write_rows(tmp_path / "z.csv", "DateTime,InsAcPow,GridFreq", [_good_rows(120)[i] for i in keep])
    assert read_log(p2).filled.sum() == 1
    nofill = read_log(p2, max_fill=0)
    assert not nofill.filled.any() and len(nofill.segments) == 2


# --- bad input: one DataError each, naming file and row ---------------------------------------------

HEADER = "DateTime,InsAcPow,GridFreq"


def _bad(rows_edit):
    rows = _good_rows()
    rows_edit(rows)
    return rows


BAD_CASES = {
    "bad timestamp": (
        HEADER,
        _bad(lambda r: r.__setitem__(5, "2026-11-01 noon,200.0,50.0")),
        7,
        "'2026-11-01 noon'",
    ),
    "31 november": (
        HEADER,
        _bad(lambda r: r.__setitem__(5, "20261131T000000.500,200.0,50.0")),
        7,
        "'20261131T000000.500'",
    ),
    "bad number": (
        HEADER,
        _bad(lambda r: r.__setitem__(9, r[9].rsplit(",", 1)[0] + ",5O.01")),
        11,
        "'5O.01'",
    ),
    "nan": (HEADER, _bad(lambda r: r.__setitem__(12, r[12].rsplit(",", 1)[0] + ",NaN")), 14, "'NaN'"),
    "empty": (HEADER, _bad(lambda r: r.__setitem__(13, r[13].rsplit(",", 1)[0] + ",")), 15, "empty value"),
    "backwards": (HEADER, _bad(lambda r: r.__setitem__(20, r[18])), 22, "goes backwards"),
    "repeats": (HEADER, _bad(lambda r: r.__setitem__(20, r[19])), 22, "repeats"),
    "field count": (HEADER, _bad(lambda r: r.__setitem__(30, r[30] + ",1,2")), 32, "5 fields"),
    "non-uniform": (
        HEADER,
        _bad(lambda r: r.__setitem__(50, _stamp(50.3) + r[50][19:])),
        52,
        "non-uniform sample interval",
    ),
    "first column": ("Time,InsAcPow,GridFreq", _good_rows(), 1, "DateTime"),
    "duplicate": ("DateTime,InsAcPow,InsAcPow,GridFreq", [r + ",1" for r in _good_rows()], 1, "twice"),
}


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_bad_rows_raise_data_error_with_file_and_row(tmp_path, case):
    header, rows, row, text = BAD_CASES[case]
    p = _write_rows(tmp_path / "bad.csv", header, rows)
    with pytest.raises(DataError) as e:
        read_log(p)
    assert e.value.where == f"{p}, row {row}", str(e.value)
    assert text in e.value.message
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(
    ("header", "rows", "kwargs", "text"),
    [
        ("DateTime,InsAcPow", _good_rows(), {}, "missing required column GridFreq"),
        ("DateTime,Foo", _good_rows(), {}, "missing required columns InsAcPow, GridFreq"),
        (HEADER, _good_rows(), {"required": ("InsAcPow", "GridFreq", "ApplFreqSig")}, "ApplFreqSig"),
        (HEADER, _good_rows(10), {}, "too short: 10 samples"),
        (HEADER, _good_rows(50), {"min_duration_s": 60.0}, "too short: 4.900 s"),
        (HEADER.replace(",", ";"), [r.replace(",", ";") for r in _good_rows()], {}, "semicolon"),
        ("", [], {}, "empty file"),
    ],
)
def test_whole_file_problems(tmp_path, header, rows, kwargs, text):
    p = _write_rows(tmp_path / "bad.csv", header, rows)
    with pytest.raises(DataError) as e:
        read_log(p, **kwargs)
    assert e.value.where == p
    assert text in e.value.message


def test_missing_file(tmp_path):
    with pytest.raises(DataError) as e:
        read_log(tmp_path / "nope.csv")
    assert e.value.where.endswith("nope.csv")


def test_unknown_columns_kept_as_is(tmp_path):
    rows = [r + f",{'on' if i % 2 else 'off'},{i}," for i, r in enumerate(_good_rows())]
    p = _write_rows(tmp_path / "x.csv", HEADER + ",Remark,ContSetP,Cap_Fcrn", rows)
    log = read_log(p)
    assert log.columns["Remark"].dtype.kind == "U" and log.columns["Remark"][1] == "on"
    assert log.columns["ContSetP"][7] == 7.0
    assert np.isnan(log.columns["Cap_Fcrn"]).all()  # "per test" values may be left empty


def test_write_refuses_non_finite_and_commas(tmp_path):
    log = _log(n=30)
    log.columns["GridFreq"][3] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        write_log(tmp_path / "x.csv", log)
    bad = TsoLog.from_arrays(np.arange(3.0), {"Remark": np.array(["a", "b,c", "d"])}, START)
    with pytest.raises(ValueError, match="cannot be written"):
        write_log(tmp_path / "y.csv", bad)


# --- through the CLI: exit status 2, one line, no traceback -----------------------------------------


def test_cli_bad_file_is_one_line_exit_2(tmp_path, monkeypatch, capsys):
    # A stand-in command that reads a log, registered the way fcrlive.cli discovers commands.
    def configure(p):
        p.add_argument("file")

    def run(args):
        read_log(args.file)
        return 0

    mod = types.SimpleNamespace(NAME="readlog", HELP="read a TSO log", configure=configure, run=run)
    monkeypatch.setattr(cli, "_command_modules", lambda: iter([mod]))
    p = _write_rows(tmp_path / "bad.csv", HEADER, _bad(lambda r: r.__setitem__(5, "garbage,1,2")))
    assert cli.main(["readlog", p]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith(f"fcrlive readlog: error: {p}, row 7: cannot read time stamp 'garbage'")
    assert "Traceback" not in err
    good = _write_rows(tmp_path / "good.csv", HEADER, _good_rows())
    assert cli.main(["readlog", good]) == 0


def test_from_arrays_splits_at_gaps_like_the_reader(tmp_path):
    t = np.concatenate([np.arange(100) * 0.1, 12.0 + np.arange(100) * 0.1])
    log = TsoLog.from_arrays(t, {"InsAcPow": np.ones(200), "GridFreq": np.full(200, 50.0)}, START)
    assert log.segments == ((0, 100), (100, 200))
    assert len(log.gaps) == 1 and log.gaps[0].missing == 20 and not log.gaps[0].filled
    back = read_log(write_log(tmp_path / "g.csv", log))
    assert back.segments == log.segments
    assert back.gaps[0].length_s == pytest.approx(log.gaps[0].length_s)
