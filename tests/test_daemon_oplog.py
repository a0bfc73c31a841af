"""The 1 Hz operation log (fcrlive.daemon.oplog): decimation, retention, export as a TSO file with the TSO
file name (fcrlive export --oplog)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from fcrlive.cli import main
from fcrlive.daemon.oplog import OPLOG_SIGNALS, Decimator, OplogWriter, read_oplog
from fcrlive.daemon.sample import Quality, Sample
from fcrlive.daemon.store import connect
from fcrlive.tso.csvlog import read_log
from fcrlive.tso.names import parse_tso_filename

T0 = 1_793_491_200.0  # 2026-11-01T00:00:00Z


def _samples(t0: float, seconds: float, hz: float = 50.0, bad=(), exc_hz: float = 0.0):
    n = round(seconds * hz)
    for i in range(n):
        t = t0 + i / hz
        v = {"power": 100.0 + i, "grid_freq": 50.0 + 1e-4 * i, "excitation_applied": exc_hz,
             "controller_output": 60.0, "guide_vane": 59.0}
        q = Quality.OK
        if any(a <= t - t0 < b for a, b in bad):
            q, v = Quality.MISSING, dict.fromkeys(v, math.nan)
        yield Sample(t, i / hz, i, v, q)


def test_one_row_per_second_first_good_sample_and_gaps_marked():
    d = Decimator(1.0)
    rows = []
    for s in _samples(T0 + 0.5, 6.0, bad=[(1.5, 3.15)]):  # T0+2 s..T0+3.65 s bad
        rows += d.add(s)
    t = [r[0] for r in rows]
    assert t == [T0 + k for k in range(0, 6)]  # every tick, closed when the next one starts
    q = [r[1] for r in rows]
    assert q == [Quality.OK, Quality.OK, Quality.MISSING, Quality.OK, Quality.OK, Quality.OK]
    power = dict(zip(t, (r[2 + OPLOG_SIGNALS.index("power")] for r in rows), strict=True))
    assert power[T0 + 1] == 100.0 + 25  # the first sample at or after the tick (t0 + 0.5 + 25/50)
    assert power[T0 + 3] == 100.0 + 158  # 3.16 s after T0 + 0.5: the first good one of that second
    assert math.isnan(power[T0 + 2])


def test_writer_stores_and_expires(tmp_path):
    db = tmp_path / "s.sqlite"
    now = time.time()
    with OplogWriter(db, 1.0, retention_days=14) as w:
        for s in _samples(now - 15 * 86400, 5.0):  # older than 14 days
            w.add(s)
        for s in _samples(now - 10.0, 5.0):
            w.add(s)
    with OplogWriter(db, 1.0, retention_days=14):  # expiry runs at start
        pass
    con = connect(db, readonly=True)
    t = [r[0] for r in con.execute("SELECT t FROM oplog ORDER BY t")]
    con.close()
    assert t and min(t) > now - 14 * 86400  # the 15-day-old rows are gone
    assert len(t) == 5


def test_export_oplog_as_a_tso_file_with_the_tso_name(tmp_path, capsys):
    db = tmp_path / "s.sqlite"
    with OplogWriter(db, 1.0, retention_days=366 * 30) as w:
        for s in _samples(T0, 121.0, bad=[(30.0, 32.0)]):
            w.add(s)
    outdir = tmp_path / "out"
    outdir.mkdir()
    rc = main(["export", "--db", str(db), "--oplog", "--from", "2026-11-01T00:00Z", "--to",
               "2026-11-01T00:02Z", "--out", str(outdir), "--resource", "FCPG1", "--area", "NO5"])
    assert rc == 0, capsys.readouterr().err
    [f] = list(outdir.iterdir())
    assert f.name == "FCPG1_Fcrn_Operation_NO5_UTC_20261101T0000-20261101T0002_1s.csv"
    name = parse_tso_filename(f)
    assert name.sample_s == 1.0 and name.test_type == "Operation"
    log = read_log(f)
    # no excitation applied: no ApplFreqSig
    assert set(log.columns) == {"InsAcPow", "GridFreq", "ContOutSig", "GuideVane"}
    assert log.duration_s == pytest.approx(119.0, abs=1.0)
    # the two seconds without good data are absent rows (a gap in the time stamps), not interpolated
    con = connect(db, readonly=True)
    w = read_oplog(con, T0, T0 + 120)
    con.close()
    assert np.count_nonzero(w.quality == Quality.MISSING) == 2
    rows = f.read_bytes().split(b"\r\n")[1:]
    assert len([r for r in rows if r]) == np.count_nonzero(w.ok) == 118


def test_export_oplog_to_a_directory_needs_the_area(tmp_path, capsys):
    db = tmp_path / "s.sqlite"
    with OplogWriter(db, 1.0, retention_days=366 * 30) as w:
        for s in _samples(T0, 10.0):
            w.add(s)
    rc = main(["export", "--db", str(db), "--oplog", "--from", str(T0), "--to", str(T0 + 10), "--out",
               str(tmp_path), "--resource", "G1"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--area" in err[0]
