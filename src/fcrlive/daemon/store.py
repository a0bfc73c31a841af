"""SQLite window store: samples, identification results and run bookkeeping.

Layout (one file, WAL mode so readers never block the writer):

* ``samples(t, t_device, seq, run, quality, latency, <one REAL column per signal>)`` with an index
  on ``t`` [UNIX s]; NaN values are stored as NULL and read back as NaN.
* ``results(id, t, t1, t2, method, ok_fraction, quality, result, duration_s, error, result_quality)``:
  one row per identification run; ``quality``, ``result`` and ``result_quality`` (the quality rule's
  verdict, docs/daemon.md; added to older stores on open) are JSON text.
* ``runs(id, started, stopped, last_seen, pid, version, clean, info)``: one row per daemon start, so
  a restart after a crash (``clean = 0``) is visible.

Writes happen on ONE writer thread with its own connection; the event loop only puts samples on a
queue (``SampleWriter.add`` never blocks). The writer commits at least every ``commit_interval_s``
(≤ 1 s), so a killed process loses at most the last uncommitted second. ``synchronous=NORMAL`` in WAL
mode keeps every committed transaction across a process crash (only an OS crash / power loss can
roll back the last few transactions).
"""

from __future__ import annotations

import json
import logging
import math
import os
import queue
import sqlite3
import threading
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fcrlive.daemon.sample import Quality, Sample
from fcrlive.signals import GAP_FACTOR

log = logging.getLogger("fcrlive.store")

FIXED_COLUMNS = ("t", "t_device", "seq", "run", "quality", "latency")
SCHEMA_VERSION = 1
STALE_GRACE = 3
"""Consecutive STALE samples after an OK one that still count as covered (:attr:`Window.covered`)."""


def _q(name: str) -> str:
    """Quoted SQL identifier (signal names are validated identifiers; quoting guards keywords)."""
    return '"' + name.replace('"', '""') + '"'


def connect(path: str | Path, readonly: bool = False) -> sqlite3.Connection:
    """A connection with the store's pragmas (WAL, NORMAL sync, busy timeout)."""
    if readonly:
        con = sqlite3.connect(f"file:{Path(path)}?mode=ro", uri=True, timeout=10, check_same_thread=False)
    else:
        from fcrlive.daemon.storefile import prepare  # 0600; no mkdir -p outside the state directory

        prepare(path)
        con = sqlite3.connect(str(path), timeout=10, check_same_thread=False)
        con.execute("PRAGMA journal_mode=WAL")
        con.execute("PRAGMA synchronous=NORMAL")
    con.execute("PRAGMA busy_timeout=10000")
    return con


def ensure_schema(con: sqlite3.Connection, signals: Sequence[str]) -> None:
    """Create tables and add missing signal columns (a register map may grow)."""
    bad = [s for s in signals if s in FIXED_COLUMNS]
    if bad:
        raise ValueError(f"signal names {bad} clash with the store's own columns {FIXED_COLUMNS}")
    with con:
        con.execute("CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value TEXT)")
        con.execute("INSERT OR IGNORE INTO meta VALUES('schema_version', ?)", (str(SCHEMA_VERSION),))
        con.execute(
            "CREATE TABLE IF NOT EXISTS runs(id INTEGER PRIMARY KEY, started REAL NOT NULL, stopped REAL,"
            " last_seen REAL, pid INTEGER, version TEXT, clean INTEGER NOT NULL DEFAULT 0, info TEXT)")
        con.execute(
            "CREATE TABLE IF NOT EXISTS samples(t REAL NOT NULL, t_device REAL, seq INTEGER, run INTEGER,"
            " quality INTEGER NOT NULL, latency REAL)")
        con.execute("CREATE INDEX IF NOT EXISTS samples_t ON samples(t)")
        con.execute(
            "CREATE TABLE IF NOT EXISTS results(id INTEGER PRIMARY KEY, t REAL NOT NULL, t1 REAL NOT NULL,"
            " t2 REAL NOT NULL, method TEXT, ok_fraction REAL, quality TEXT, result TEXT, duration_s REAL,"
            " error TEXT)")
        con.execute("CREATE INDEX IF NOT EXISTS results_t ON results(t)")
        if "result_quality" not in _columns(con, "results"):
            con.execute("ALTER TABLE results ADD COLUMN result_quality TEXT")
        have = _columns(con, "samples")
        for s in signals:
            if s not in have:
                con.execute(f"ALTER TABLE samples ADD COLUMN {_q(s)} REAL")


def _columns(con: sqlite3.Connection, table: str) -> set[str]:
    return {r[1] for r in con.execute(f"PRAGMA table_info({table})")}


def signal_columns(con: sqlite3.Connection) -> tuple[str, ...]:
    """Signal columns present in the samples table, in table order."""
    return tuple(r[1] for r in con.execute("PRAGMA table_info(samples)") if r[1] not in FIXED_COLUMNS)


# ---------------------------------------------------------------------------------------------------
# Reading

@dataclass(frozen=True)
class Window:
    """Samples in [t1, t2] as arrays; NaN marks unusable values.

    ``t`` [UNIX s] arrival times, ``quality`` (:class:`Quality` codes), ``signals[name]`` in the
    point's unit. ``period_s`` is the nominal sampling period estimated from the data (median Δt).
    """

    t1: float
    t2: float
    t: np.ndarray
    t_device: np.ndarray
    seq: np.ndarray
    quality: np.ndarray
    signals: dict[str, np.ndarray]
    run: np.ndarray | None = None
    """Daemon run id of each sample (``seq`` restarts with every run)."""

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def ok(self) -> np.ndarray:
        """Mask of samples with quality OK."""
        return self.quality == Quality.OK

    @property
    def covered(self) -> np.ndarray:
        """Mask of samples that lose nothing: OK, or a short run of STALE right after an OK sample.

        A poller faster than the device's own update rate reads the same device sample twice (STALE):
        the data are complete, nothing is missing. A long STALE run (a frozen device) is a gap.
        """
        ok = self.ok
        stale = self.quality == Quality.STALE
        i = np.arange(self.t.size)
        run_start = np.maximum.accumulate(np.where(stale, -1, i))  # last non-stale index at or before i
        before_ok = np.zeros_like(ok)
        has_prev = run_start >= 0
        before_ok[has_prev] = ok[run_start[has_prev]]
        return ok | (stale & before_ok & (i - run_start <= STALE_GRACE))

    @property
    def period_s(self) -> float:
        """Median sampling interval [s] (NaN for fewer than 2 samples)."""
        return float(np.median(np.diff(self.t))) if self.t.size > 1 else math.nan

    def ok_fraction(self, expected: int | None = None) -> float:
        """Fraction of :attr:`covered` samples; against ``expected`` samples when given (rows absent
        count as bad)."""
        n = expected if expected is not None else self.t.size
        return float(np.count_nonzero(self.covered)) / n if n else 0.0

    def quality_counts(self) -> dict[str, int]:
        """Number of samples per quality name."""
        return {q.name.lower(): int(np.count_nonzero(self.quality == q)) for q in Quality}

    def gaps(self, max_dt: float | None = None) -> list[tuple[float, float]]:
        """Intervals ``(start, end)`` [UNIX s] without :attr:`covered` samples.

        A gap is a run of non-OK samples, or a jump in ``t`` longer than ``max_dt`` (default the gap
        rule of :mod:`fcrlive.signals`: ``GAP_FACTOR`` (1.5) × the median period) where no rows were
        stored at all (daemon down). Also covers a missing start or end of the window.
        """
        if self.t.size == 0:
            return [(self.t1, self.t2)]
        max_dt = GAP_FACTOR * self.period_s if max_dt is None and self.t.size > 1 else (max_dt or math.inf)
        gaps: list[tuple[float, float]] = []
        ok = self.covered
        last_ok_t = self.t1
        in_gap = self.t[0] - self.t1 > max_dt or not ok[0]
        for i in range(self.t.size):
            if ok[i]:
                if in_gap or self.t[i] - last_ok_t > max_dt:
                    gaps.append((last_ok_t, float(self.t[i])))
                in_gap = False
                last_ok_t = float(self.t[i])
            else:
                in_gap = True
        if in_gap or self.t2 - last_ok_t > max_dt:
            gaps.append((last_ok_t, self.t2))
        return gaps


def read_window(con: sqlite3.Connection, t1: float, t2: float,
                signals: Sequence[str] | None = None) -> Window:
    """Every stored sample with ``t1 ≤ t ≤ t2`` [UNIX s]; ``signals`` default to all columns."""
    cols = tuple(signals) if signals is not None else signal_columns(con)
    sel = ", ".join(("t", "t_device", "seq", "quality", "run", *(_q(c) for c in cols)))
    rows = con.execute(f"SELECT {sel} FROM samples WHERE t >= ? AND t <= ? ORDER BY t", (t1, t2)).fetchall()
    arr = np.array(rows, dtype=float).reshape(len(rows), 5 + len(cols))
    return Window(
        t1=t1, t2=t2, t=arr[:, 0], t_device=arr[:, 1], seq=arr[:, 2],
        quality=np.nan_to_num(arr[:, 3], nan=Quality.MISSING).astype(np.int8),
        signals={c: arr[:, 5 + i] for i, c in enumerate(cols)},
        run=np.nan_to_num(arr[:, 4], nan=-1).astype(np.int64),
    )


def time_span(con: sqlite3.Connection) -> tuple[float, float] | None:
    """``(first, last)`` sample time [UNIX s], None when empty."""
    row = con.execute("SELECT min(t), max(t) FROM samples").fetchone()
    return None if row[0] is None else (float(row[0]), float(row[1]))


@dataclass(frozen=True)
class StoredResult:
    """One identification run from the results table (``result`` parsed from JSON)."""

    id: int
    t: float
    t1: float
    t2: float
    method: str
    ok_fraction: float
    quality: dict
    result: dict | None
    duration_s: float
    error: str | None
    result_quality: dict | None = None


def read_results(con: sqlite3.Connection, since: float = 0.0, limit: int = 100) -> list[StoredResult]:
    """Results with ``t ≥ since``, newest first."""
    # a read-only reader may meet a store written before result_quality existed
    rq = "result_quality" if "result_quality" in _columns(con, "results") else "NULL"
    rows = con.execute(
        f"SELECT id, t, t1, t2, method, ok_fraction, quality, result, duration_s, error, {rq} FROM results "
        "WHERE t >= ? ORDER BY t DESC LIMIT ?", (since, limit)).fetchall()
    return [StoredResult(r[0], r[1], r[2], r[3], r[4], r[5], json.loads(r[6] or "{}"),
                         json.loads(r[7]) if r[7] else None, r[8], r[9],
                         json.loads(r[10]) if r[10] else None) for r in rows]


def read_runs(con: sqlite3.Connection) -> list[dict[str, Any]]:
    """Run bookkeeping rows, oldest first."""
    cur = con.execute(
        "SELECT id, started, stopped, last_seen, pid, version, clean, info FROM runs ORDER BY id")
    keys = [d[0] for d in cur.description]
    return [dict(zip(keys, r)) for r in cur.fetchall()]


# ---------------------------------------------------------------------------------------------------
# Writing

@dataclass
class _Flush:
    done: threading.Event = field(default_factory=threading.Event)


@dataclass(frozen=True)
class ResultRow:
    """An identification outcome to store (times UNIX s, ``result`` JSON-able or None on error)."""

    t: float
    t1: float
    t2: float
    method: str
    ok_fraction: float
    quality: dict
    result: Any
    duration_s: float
    error: str | None = None
    result_quality: dict | None = None


class SampleWriter:
    """Owns the writer thread. ``with SampleWriter(path, signals) as w: w.add(sample)``.

    ``add`` and ``add_result`` are non-blocking and thread-safe (callable from the event loop);
    ``flush()`` blocks until everything added so far is committed (call it via ``asyncio.to_thread``).
    """

    def __init__(self, path: str | Path, signals: Sequence[str], commit_interval_s: float = 1.0,
                 retention_hours: float | None = None, info: dict | None = None, version: str = ""):
        if not 0 < commit_interval_s <= 1.0:
            raise ValueError("commit_interval_s must be in (0, 1] s")
        self.path = Path(path)
        self.signals = tuple(signals)
        self.commit_interval_s = commit_interval_s
        self.retention_s = retention_hours * 3600.0 if retention_hours else None
        self.info = info or {}
        self.version = version
        self.run_id: int | None = None
        self.previous_run_unclean: dict | None = None
        """The previous run's bookkeeping row when it did not stop cleanly (crash, SIGKILL)."""
        self.committed = 0
        self.commits = 0
        self.last_commit_wall = math.nan
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self._insert = (f"INSERT INTO samples(t, t_device, seq, run, quality, latency"
                        f"{''.join(', ' + _q(s) for s in self.signals)}) VALUES "
                        f"({', '.join('?' * (6 + len(self.signals)))})")

    def open(self) -> SampleWriter:
        """Create/upgrade the schema, record the run, start the writer thread."""
        con = connect(self.path)
        ensure_schema(con, self.signals)
        last = con.execute(
            "SELECT id, started, last_seen, pid, clean FROM runs ORDER BY id DESC LIMIT 1").fetchone()
        if last and not last[4]:
            self.previous_run_unclean = dict(zip(("id", "started", "last_seen", "pid", "clean"), last))
            log.warning("store: previous run %d did not stop cleanly (last seen %s)", last[0], last[2])
        with con:
            now = time.time()
            self.run_id = con.execute(
                "INSERT INTO runs(started, last_seen, pid, version, clean, info) VALUES (?,?,?,?,0,?)",
                (now, now, os.getpid(), self.version, json.dumps(self.info))).lastrowid
        self._thread = threading.Thread(target=self._run, args=(con,), name="store-writer", daemon=True)
        self._thread.start()
        return self

    def __enter__(self) -> SampleWriter:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    def add(self, sample: Sample) -> None:
        """Queue ``sample`` for the next commit (never blocks)."""
        self._q.put(sample)

    def add_result(self, row: ResultRow) -> None:
        """Queue an identification result (committed with the next batch)."""
        self._q.put(row)

    def flush(self, timeout: float | None = 10.0) -> bool:
        """Commit everything queued so far; True when done within ``timeout`` s."""
        self._check()
        f = _Flush()
        self._q.put(f)
        return f.done.wait(timeout)

    def close(self) -> None:
        """Flush, mark the run as cleanly stopped, stop the thread."""
        if self._thread is None:
            return
        self._q.put(None)
        self._thread.join(30)
        self._thread = None
        self._check()

    def _check(self) -> None:
        if self._error is not None:
            raise RuntimeError(f"store writer failed: {self._error}") from self._error

    def _row(self, s: Sample) -> tuple:
        v = s.values
        return (s.t_wall, s.t_device, s.seq, self.run_id, int(s.quality), s.latency_s,
                *(v.get(n, math.nan) for n in self.signals))

    def _run(self, con: sqlite3.Connection) -> None:
        rows: list[tuple] = []
        results: list[ResultRow] = []
        waiters: list[_Flush] = []
        next_commit = time.monotonic() + self.commit_interval_s
        next_retention = time.monotonic()
        stop = False
        try:
            while not stop:
                timeout = max(0.0, next_commit - time.monotonic())
                try:
                    item = self._q.get(timeout=timeout)
                except queue.Empty:
                    item = ...
                while True:  # drain whatever is queued without waiting
                    if item is None:
                        stop = True
                    elif isinstance(item, Sample):
                        rows.append(self._row(item))
                    elif isinstance(item, ResultRow):
                        results.append(item)
                    elif isinstance(item, _Flush):
                        waiters.append(item)
                    try:
                        item = self._q.get_nowait()
                    except queue.Empty:
                        break
                now = time.monotonic()
                if now >= next_commit or waiters or stop:
                    self._commit(con, rows, results, clean=stop)
                    rows, results = [], []
                    for w in waiters:
                        w.done.set()
                    waiters = []
                    next_commit = now + self.commit_interval_s
                if self.retention_s and now >= next_retention:
                    self._expire(con)
                    next_retention = now + 60.0
        except BaseException as exc:  # surfaced by flush()/close()
            self._error = exc
            log.exception("store writer failed")
            for w in waiters:
                w.done.set()
        finally:
            con.close()

    def _commit(self, con: sqlite3.Connection, rows: list[tuple], results: list[ResultRow],
                clean: bool = False) -> None:
        wall = time.time()
        with con:
            if rows:
                con.executemany(self._insert, rows)
            for r in results:
                con.execute(
                    "INSERT INTO results(t, t1, t2, method, ok_fraction, quality, result, duration_s, error,"
                    " result_quality) VALUES (?,?,?,?,?,?,?,?,?,?)",
                    (r.t, r.t1, r.t2, r.method, r.ok_fraction, json.dumps(r.quality),
                     None if r.result is None else (r.result if isinstance(r.result, str)
                                                    else json.dumps(r.result)),
                     r.duration_s, r.error,
                     None if r.result_quality is None else json.dumps(r.result_quality)))
            if clean:
                con.execute("UPDATE runs SET last_seen=?, stopped=?, clean=1 WHERE id=?",
                            (wall, wall, self.run_id))
            else:
                con.execute("UPDATE runs SET last_seen=? WHERE id=?", (wall, self.run_id))
        self.committed += len(rows)
        self.commits += 1
        self.last_commit_wall = wall

    def _expire(self, con: sqlite3.Connection) -> None:
        cutoff = time.time() - self.retention_s
        with con:
            n = con.execute("DELETE FROM samples WHERE t < ?", (cutoff,)).rowcount
        if n:
            log.info("store: retention deleted %d samples older than %.0f h", n, self.retention_s / 3600)


def write_samples(path: str | Path, signals: Sequence[str], samples: Iterable[Sample]) -> int:
    """Write ``samples`` in one go (tools, tests); returns the count."""
    n = 0
    with SampleWriter(path, signals) as w:
        for s in samples:
            w.add(s)
            n += 1
    return n
