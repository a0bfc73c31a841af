"""``fcrlive prequal DIR``: evaluate a Nordic FCR prequalification application (every TSO test file of
DIR) against TR v1.1 or Statnett's 2024 document; table, JSON or HTML report. docs/prequal.md."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

NAME = "prequal"
HELP = "Evaluate the FCR prequalification test files of a directory (TR v1.1): requirements, K_red, capacity."


def configure(p: argparse.ArgumentParser) -> None:
    p.add_argument("dir", type=Path, metavar="DIR", help="directory of TSO test files (*.csv, TSO names)")
    p.add_argument(
        "--unit",
        type=Path,
        metavar="UNIT.toml",
        help="unit description with [unit.prequal] (default: DIR/unit.toml when present)",
    )
    p.add_argument(
        "--document",
        choices=("nordic-2025", "statnett-2024"),
        default="nordic-2025",
        help="requirements document: Nordic TR v1.1 (default) or Statnett 2024 (Req. 4 limit 1.7 s)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON document instead of the table")
    p.add_argument("--report", type=Path, metavar="FILE.html", help="write the application report here")
    p.add_argument(
        "--pdf",
        type=Path,
        metavar="FILE.pdf",
        help="also print the report to this PDF (headless Chromium; needs --report)",
    )
    p.add_argument("--store", type=Path, metavar="DB", help="daemon store: continuous-identification history")


def run(args: argparse.Namespace) -> int:
    from fcrlive.errors import UserError
    from fcrlive.prequal.load import evaluate_dir

    if args.store is not None and args.report is None:
        raise UserError("--store is used by the report: give --report FILE.html too", where="--store")
    if args.pdf is not None and args.report is None:
        raise UserError("--pdf prints the HTML report: give --report FILE.html too", where="--pdf")
    if args.store is not None and not args.store.exists():
        raise UserError("no such file", where=str(args.store))

    def bar(logs):
        import sys

        from tqdm import tqdm

        return tqdm(logs, desc="evaluating", unit="file", file=sys.stderr, disable=len(logs) < 2, leave=False)

    result = evaluate_dir(args.dir, args.unit, args.document, progress=bar)
    if args.report is not None:
        try:
            from fcrlive.prequal.report import write_report
        except ImportError:
            raise UserError(
                "the HTML report (fcrlive.prequal.report) is not available in this build", where="--report"
            ) from None
        write_report(result, args.report, store=args.store, pdf=args.pdf)
    if args.json:
        from fcrlive.prequal.jsonout import to_json_dict

        print(json.dumps(to_json_dict(result), indent=2, allow_nan=False, ensure_ascii=False))
    else:
        from fcrlive.prequal.text import text_table

        print(text_table(result))
    return 0
