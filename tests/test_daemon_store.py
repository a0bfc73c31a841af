"""Window store: WAL, batched commits, crash safety (SIGKILL), windows with gaps, results, runs."""

from __future__ import annotations

import math
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from fcrlive.daemon.sample import Quality, Sample
from fcrlive.daemon.store import (
    ResultRow,
    SampleWriter,
    connect,
    read_results,
    read_runs,
    read_window,
    write_samples,
)

SIGNALS = ("power", "grid_freq")


def _samples(n, t0=1_000_000.0, dt=0.1, bad=()):
    for i in range(n):
        q = Quality.COMM_ERROR if i in bad else Quality.OK
        v = {"power": math.nan, "grid_freq": math.nan} if i in bad else {"power": 50.0 + i, "grid_freq": 50.0}
        yield Sample(t0 + i * dt, t0 + i * dt - 5, i, v, q, latency_s=0.001)


def test_window_roundtrip_with_gaps(tmp_path):
    db = tmp_path / "s.sqlite"
    # 100 samples at 10 Hz, samples 20-29 comm errors, then the daemon is down 5 s (no rows)
    samples = list(_samples(50, bad=range(20, 30)))
    samples += [Sample(s.t_wall + 10.0, s.t_device, s.seq + 50, s.values, s.quality) for s in _samples(50)]
    assert write_samples(db, SIGNALS, samples) == 100
    with connect(db, readonly=True) as con:
        assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        w = read_window(con, 1_000_000.0, 1_000_000.0 + 20.0)
    assert len(w) == 100
    assert np.isnan(w.signals["power"][20:30]).all() and w.signals["power"][31] == 81.0
    assert (w.quality[20:30] == Quality.COMM_ERROR).all()
    assert w.quality_counts()["comm_error"] == 10
    assert w.ok_fraction() == pytest.approx(0.9)
    assert w.period_s == pytest.approx(0.1)
    gaps = w.gaps()
    assert len(gaps) == 3
    assert gaps[0] == pytest.approx((1_000_001.9, 1_000_003.0))  # comm errors
    assert gaps[1] == pytest.approx((1_000_004.9, 1_000_010.0))  # no rows at all
    assert gaps[2][0] == pytest.approx(1_000_014.9)  # window runs past the data


def test_results_and_runs(tmp_path):
    db = tmp_path / "s.sqlite"
    with SampleWriter(db, SIGNALS, info={"unit": "G1"}) as w:
        w.add_result(ResultRow(t=10.0, t1=0.0, t2=9.0, method="auto", ok_fraction=0.97,
                               quality={"gaps": 1}, result={"droop": 0.04}, duration_s=0.5))
        w.add_result(ResultRow(t=20.0, t1=10.0, t2=19.0, method="auto", ok_fraction=0.2,
                               quality={}, result=None, duration_s=0.0, error="too few samples"))
        assert w.flush()
    with SampleWriter(db, (*SIGNALS, "guide_vane")) as w2:  # a map that grew a signal
        assert w2.previous_run_unclean is None
    con = connect(db, readonly=True)
    res = read_results(con)
    assert [r.t for r in res] == [20.0, 10.0]
    assert res[1].result == {"droop": 0.04} and res[0].error == "too few samples"
    runs = read_runs(con)
    assert len(runs) == 2 and all(r["clean"] == 1 for r in runs)
    assert "guide_vane" in read_window(con, 0, 1).signals


CHILD = textwrap.dedent("""
    import sys, time
    from fcrlive.daemon.sample import Quality, Sample
    from fcrlive.daemon.store import SampleWriter
    w = SampleWriter(sys.argv[1], ("power", "grid_freq"), commit_interval_s=1.0).open()
    i = 0
    t0 = time.monotonic()
    while True:
        w.add(Sample(1000.0 + i * 0.02, float("nan"), i, {"power": float(i), "grid_freq": 50.0}, Quality.OK))
        print(i, flush=True)
        i += 1
        time.sleep(max(0.0, t0 + i * 0.02 - time.monotonic()))
""")


def test_sigkill_loses_at_most_the_last_second(tmp_path):
    db = tmp_path / "s.sqlite"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(db)], stdout=subprocess.PIPE, text=True,
                            env=env)
    last = -1
    try:
        for line in proc.stdout:  # let it write ~2.7 s of 50 Hz samples, then kill it hard
            last = int(line)
            if last >= 135:
                break
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(10)
    con = sqlite3.connect(db)
    seqs = [r[0] for r in con.execute("SELECT seq FROM samples ORDER BY t")]
    con.close()
    assert seqs == list(range(len(seqs))), "committed samples must be a gap-free prefix"
    # samples are produced at 50 Hz: at most ~1 s (50 samples) plus scheduling slack may be lost
    assert last - len(seqs) < 50 + 15
    assert len(seqs) >= 50
    # reopening keeps everything and records the crash
    with SampleWriter(db, SIGNALS) as w:
        assert w.previous_run_unclean is not None
        w.add(Sample(5000.0, math.nan, 0, {"power": 1.0, "grid_freq": 50.0}, Quality.OK))
    con = connect(db, readonly=True)
    assert con.execute("SELECT count(*) FROM samples").fetchone()[0] == len(seqs) + 1
    runs = read_runs(con)
    assert [r["clean"] for r in runs] == [0, 1]


# A second process takes the exclusive lock on the -shm's "dead man switch" byte only when no live
# connection holds it shared; it then re-initialises the wal-index: ftruncate(-shm, 3) under the mapping
# of every connection that lost its lock, whose next commit dies of SIGBUS (unix VFS, UNIX_SHM_DMS).
PROBE_DMS = textwrap.dedent("""
    import fcntl, os, sys
    fd = os.open(sys.argv[1], os.O_RDWR)
    try:
        fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB, 1, 128)
        print("free")
    except OSError:
        print("held")
    os.close(fd)
""")


def test_another_writing_connection_keeps_the_writers_locks(tmp_path):
    """Opening a second writing connection while the sample writer runs (the operation log does, at every
    daemon start) must not drop the writer's locks: closing any descriptor of a file drops all of the
    process's POSIX locks on it (then the e2e SIGKILL test's daemon could die of SIGBUS)."""
    db = tmp_path / "s.sqlite"
    with SampleWriter(db, SIGNALS) as w:
        for s in _samples(20):
            w.add(s)
        assert w.flush()

        def dms() -> str:
            return subprocess.run([sys.executable, "-c", PROBE_DMS, f"{db}-shm"], capture_output=True,
                                  text=True, check=True).stdout.strip()

        assert dms() == "held"
        connect(db).close()
        assert dms() == "held"
        w.add(Sample(5000.0, math.nan, 0, {"power": 1.0, "grid_freq": 50.0}, Quality.OK))
        assert w.flush()
    con = connect(db, readonly=True)
    assert con.execute("SELECT count(*) FROM samples").fetchone()[0] == 21
    con.close()


def test_retention_deletes_old_samples(tmp_path):
    db = tmp_path / "s.sqlite"
    now = time.time()
    old = Sample(now - 7200, math.nan, 0, {"power": 1.0}, Quality.OK)
    new = Sample(now, math.nan, 1, {"power": 2.0}, Quality.OK)
    write_samples(db, SIGNALS, [old, new])
    with SampleWriter(db, SIGNALS, retention_hours=1.0) as w:
        assert w.flush()
    con = connect(db, readonly=True)
    assert [r[0] for r in con.execute("SELECT seq FROM samples")] == [1]


def test_short_stale_runs_after_ok_are_covered_long_ones_are_gaps():
    """A poller faster than the device reads one device sample twice: not lost data. A frozen device is."""
    import numpy as np

    from fcrlive.daemon.sample import Quality as Q
    from fcrlive.daemon.store import STALE_GRACE, Window

    q = np.array([Q.OK, Q.STALE, Q.OK] + [Q.STALE] * (STALE_GRACE + 2) + [Q.OK, Q.COMM_ERROR, Q.STALE, Q.OK])
    n = q.size
    w = Window(0.0, float(n), np.arange(float(n)), np.arange(float(n)), np.arange(n), q, {})
    expected = [1, 1, 1] + [1] * STALE_GRACE + [0, 0] + [1, 0, 0, 1]
    assert w.covered.astype(int).tolist() == expected
    assert w.ok_fraction() == sum(expected) / n
    assert len(w.gaps()) == 2  # the frozen stretch and the comm error (+ the stale read after it)
