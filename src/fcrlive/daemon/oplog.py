"""The operation log: every TSO column at 1 Hz (configurable), kept 14 days (Technical Requirements 6.2).

A station must keep its operational data for at least 14 days and deliver any stretch of it as a TSO CSV
file (with the TSO file name) within five working days. Controller-rate samples are far too many for
that (50 Hz: millions of rows a day) and are kept only for the identification windows
(``[store] controller_rate_hours``); this log keeps what the TSO asks for:

* table ``oplog(t, quality, power, grid_freq, excitation_applied, controller_output, guide_vane)`` in the
  same SQLite file, one row per ``interval_s`` tick [UNIX s, tick time]: the first good sample at or
  after the tick, as a logger sampling at that rate would record it (an instantaneous value, like the
  TSO's own files); a tick without a good sample is a row with quality MISSING and no values (a gap);
* its own writer thread and connection (WAL: the sample writer is never blocked for long), committed
  every second, rows older than ``retention_days`` deleted every 10 minutes.

``fcrlive export --oplog`` writes a stretch as a TSO file (InsAcPow, GridFreq, ContOutSig, GuideVane;
ApplFreqSig only where an excitation was applied) named by the TSO convention.
"""

from __future__ import annotations

import logging
import math
import queue
import sqlite3
import threading
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from fcrlive.daemon.sample import Quality, Sample

log = logging.getLogger("fcrlive.oplog")

OPLOG_SIGNALS = ("power", "grid_freq", "excitation_applied", "controller_output", "guide_vane")
"""Stored per row: the sources of InsAcPow, GridFreq, ApplFreqSig (grid_freq − excitation_applied),
ContOutSig and GuideVane (fcrlive.daemon.tsoexport.COLUMN_MAP)."""


class Decimator:
    """Samples → one row per ``interval_s`` tick (pure): ``add(sample)`` returns the rows completed."""

    def __init__(self, interval_s: float, signals: Sequence[str] = OPLOG_SIGNALS):
        self.interval_s = float(interval_s)
        self.signals = tuple(signals)
        self._tick: int | None = None
        self._row: tuple | None = None

    def _empty(self, k: int) -> tuple:
        return (k * self.interval_s, int(Quality.MISSING), *([math.nan] * len(self.signals)))

    def add(self, s: Sample) -> list[tuple]:
        k = math.floor(s.t_wall / self.interval_s)
        out: list[tuple] = []
        if self._tick is None:
            self._tick = k
        if k > self._tick:  # close the current tick (and mark ticks without any sample)
            out.append(self._row or self._empty(self._tick))
            out += [self._empty(j) for j in range(self._tick + 1, min(k, self._tick + 3600))]
            self._tick, self._row = k, None
        if k == self._tick and self._row is None and s.quality == Quality.OK:
            vals = tuple(float(s.values.get(n, math.nan)) for n in self.signals)
            self._row = (k * self.interval_s, int(Quality.OK), *vals)
        return out


class OplogWriter:
    """``with OplogWriter(path, interval_s, retention_days) as w: w.add(sample)`` (non-blocking)."""

    def __init__(self, path: str | Path, interval_s: float = 1.0, retention_days: float = 14.0,
                 signals: Sequence[str] = OPLOG_SIGNALS):
        self.path = Path(path)
        self.decimator = Decimator(interval_s, signals)
        self.signals = tuple(signals)
        self.retention_s = retention_days * 86400.0
        self.rows = 0
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    def __enter__(self) -> OplogWriter:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    def open(self) -> OplogWriter:
        from fcrlive.daemon.store import connect

        con = connect(self.path)
        ensure_oplog(con, self.signals)
        self._thread = threading.Thread(target=self._run, args=(con,), name="oplog-writer", daemon=True)
        self._thread.start()
        return self

    def add(self, s: Sample) -> None:
        for row in self.decimator.add(s):
            self._q.put(row)

    def close(self) -> None:
        if self._thread is not None:
            self._q.put(None)
            self._thread.join(30)
            self._thread = None
        if self._error is not None:
            raise RuntimeError(f"operation log writer failed: {self._error}") from self._error

    def _run(self, con: sqlite3.Connection) -> None:
        cols = ", ".join(f'"{n}"' for n in self.signals)
        marks = ", ".join("?" * (2 + len(self.signals)))
        sql = f"INSERT OR REPLACE INTO oplog(t, quality, {cols}) VALUES ({marks})"
        rows: list[tuple] = []
        next_expire = 0.0
        next_commit = time.monotonic() + 1.0
        try:
            while True:
                try:
                    item = self._q.get(timeout=1.0)
                except queue.Empty:
                    item = ...
                stop = item is None
                if isinstance(item, tuple):
                    rows.append(item)
                now = time.monotonic()
                if rows and (stop or now >= next_commit):  # at most a second lost on a crash
                    with con:
                        con.executemany(sql, [tuple(None if isinstance(v, float) and math.isnan(v) else v
                                                    for v in r) for r in rows])
                    self.rows += len(rows)
                    rows = []
                    next_commit = now + 1.0
                if now >= next_expire:
                    with con:
                        con.execute("DELETE FROM oplog WHERE t < ?", (time.time() - self.retention_s,))
                    next_expire = now + 600.0
                if stop:
                    break
        except BaseException as exc:  # surfaced by close()
            self._error = exc
            log.exception("operation log writer failed")
        finally:
            con.close()


def ensure_oplog(con: sqlite3.Connection, signals: Sequence[str] = OPLOG_SIGNALS) -> None:
    with con:
        con.execute("CREATE TABLE IF NOT EXISTS oplog(t REAL PRIMARY KEY, quality INTEGER NOT NULL)")
        have = {r[1] for r in con.execute("PRAGMA table_info(oplog)")}
        for n in signals:
            if n not in have:
                con.execute(f'ALTER TABLE oplog ADD COLUMN "{n}" REAL')


def read_oplog(con: sqlite3.Connection, t1: float, t2: float):
    """The operation log between t1 and t2 [UNIX s] as a :class:`fcrlive.daemon.store.Window`
    (``seq`` = tick index, ``t_device`` NaN)."""
    from fcrlive.daemon.store import Window

    have = [r[1] for r in con.execute("PRAGMA table_info(oplog)")]
    if not have:
        return None
    sig = [c for c in have if c not in ("t", "quality")]
    sel = ", ".join(["t", "quality", *(f'"{c}"' for c in sig)])
    rows = con.execute(f"SELECT {sel} FROM oplog WHERE t >= ? AND t <= ? ORDER BY t", (t1, t2)).fetchall()
    arr = np.array(rows, dtype=float).reshape(len(rows), 2 + len(sig))
    t = arr[:, 0]
    period = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    return Window(t1=t1, t2=t2, t=t, t_device=np.full(t.size, np.nan),
                  seq=np.round(t / period), quality=np.nan_to_num(arr[:, 1], nan=2).astype(np.int8),
                  signals={c: arr[:, 2 + i] for i, c in enumerate(sig)},
                  run=np.zeros(t.size, dtype=np.int64))
