"""``fcrlive export``: write a stored stretch of samples as a TSO-format CSV log."""

from __future__ import annotations

import argparse

NAME = "export"
HELP = "write stored samples between two times as a TSO CSV log (DateTime, InsAcPow, GridFreq, ...)"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--from", dest="t1", required=True, metavar="T1",
                        help="start: ISO 8601 (UTC unless an offset is given, e.g. 2026-11-01T00:00Z) "
                             "or UNIX seconds")
    parser.add_argument("--to", dest="t2", required=True, metavar="T2", help="end, same forms")
    parser.add_argument("--out", required=True, metavar="FILE.csv", help="output file")
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument("--config", metavar="FILE", help="daemon config: use its [store] path")
    src.add_argument("--db", metavar="FILE", help="the SQLite store directly")
    parser.add_argument("--timestamps", choices=("grid", "arrival", "device"), default="grid",
                        help="grid: the poller's tick times (default); arrival: measured arrival times; "
                             "device: the device's own clock (an accelerated simulator)")


def parse_time(text: str, where: str) -> float:
    """ISO 8601 (naive = UTC) or UNIX seconds → UNIX seconds; UserError otherwise."""
    from datetime import UTC, datetime

    from fcrlive.errors import UserError

    try:
        return float(text)
    except ValueError:
        pass
    try:
        dt = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise UserError(f"cannot read time {text!r} (ISO 8601 like 2026-11-01T00:00:00Z, or UNIX s)",
                        where=where) from None
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=UTC)
    return dt.timestamp()


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from fcrlive.daemon.store import connect, read_window
    from fcrlive.daemon.tsoexport import window_to_log
    from fcrlive.errors import UserError
    from fcrlive.tso.csvlog import write_log

    t1, t2 = parse_time(args.t1, "--from"), parse_time(args.t2, "--to")
    if t2 <= t1:
        raise UserError("--to must be after --from")
    if args.config:
        from fcrlive.daemon.config import load_config

        db = load_config(args.config).store.path
    else:
        db = Path(args.db)
    if not db.exists():
        raise UserError("no such store", where=str(db))
    con = connect(db, readonly=True)
    try:
        w = read_window(con, t1, t2)
    finally:
        con.close()
    log = window_to_log(w, timestamps=args.timestamps)
    write_log(args.out, log)
    print(f"{args.out}: {len(log)} samples, {log.duration_s:.1f} s, "
          f"{w.quality_counts()['ok']}/{len(w)} stored samples ok, columns {', '.join(log.columns)}")
    return 0
