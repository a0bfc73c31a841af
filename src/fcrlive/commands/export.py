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
    parser.add_argument("--out", required=True, metavar="FILE.csv|DIR",
                        help="output file, or an existing directory: the file then gets the TSO file name "
                             "(Resource_Service_Operation_Area_UTC_Interval_SamplingRate.csv; needs --area)")
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument("--config", metavar="FILE", help="daemon config: use its [store] path")
    src.add_argument("--db", metavar="FILE", help="the SQLite store directly")
    parser.add_argument("--timestamps", choices=("grid", "arrival", "device"), default="grid",
                        help="grid: the poller's tick times (default); arrival: measured arrival times; "
                             "device: the device's own clock (an accelerated simulator)")
    parser.add_argument("--oplog", action="store_true",
                        help="export the operation log (every TSO column at 1 Hz, kept 14 days; TR 6.2) "
                             "instead of the controller-rate samples")
    parser.add_argument("--resource", help="TSO file name: resource id (default: the config's unit name)")
    parser.add_argument("--area", help="TSO file name: bidding area, e.g. NO5")
    parser.add_argument("--service", default="Fcrn", choices=("Fcrn", "FcrdUp", "FcrdDo"),
                        help="TSO file name: service (default Fcrn)")


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


def tso_name(args: argparse.Namespace, unit: str | None, t1: float, t2: float, w) -> str:
    """The TSO file name (Technical Requirements 6.2.1) of an export, UTC, interval to the minute."""
    from datetime import UTC, datetime

    import numpy as np

    from fcrlive.errors import UserError
    from fcrlive.tso.names import tso_filename

    resource = args.resource or unit
    if not resource or not args.area:
        raise UserError("--out is a directory: the TSO file name needs --area "
                        "(and --resource without --config)")
    dt = np.diff(w.t[w.ok]) if len(w) > 1 else np.array([1.0])
    sample_s = float(np.median(dt)) if dt.size else 1.0
    sample_s = round(sample_s, 3) if sample_s < 1.0 else round(sample_s)
    start, end = (datetime.fromtimestamp(x, UTC).replace(tzinfo=None) for x in (t1, t2))
    try:
        return tso_filename(resource, args.service, "Operation", args.area, "UTC", start, end, sample_s)
    except ValueError as exc:
        raise UserError(f"cannot build the TSO file name: {exc}") from None


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from fcrlive.daemon.store import connect, read_window
    from fcrlive.daemon.tsoexport import window_to_log
    from fcrlive.errors import UserError
    from fcrlive.tso.csvlog import write_log

    t1, t2 = parse_time(args.t1, "--from"), parse_time(args.t2, "--to")
    if t2 <= t1:
        raise UserError("--to must be after --from")
    unit = None
    if args.config:
        from fcrlive.daemon.config import load_config

        cfg = load_config(args.config, startup_checks=False)  # only its store and unit name are read
        db, unit = cfg.store.path, cfg.unit.name
    else:
        db = Path(args.db)
    if not db.exists():
        raise UserError("no such store", where=str(db))
    con = connect(db, readonly=True)
    try:
        if args.oplog:
            from fcrlive.daemon.oplog import read_oplog

            w = read_oplog(con, t1, t2)
            if w is None:
                raise UserError("the store has no operation log", where=str(db))
        else:
            w = read_window(con, t1, t2)
    finally:
        con.close()
    log = window_to_log(w, timestamps="arrival" if args.oplog else args.timestamps)
    out = Path(args.out)
    if out.is_dir():
        out = out / tso_name(args, unit, t1, t2, w)
    write_log(out, log)
    print(f"{out}: {len(log)} samples, {log.duration_s:.1f} s, "
          f"{w.quality_counts()['ok']}/{len(w)} stored samples ok, columns {', '.join(log.columns)}")
    return 0
