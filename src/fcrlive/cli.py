"""The ``fcrlive`` command line: dispatches to the modules in :mod:`fcrlive.commands`."""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys

from fcrlive import __version__, commands
from fcrlive.blas import one_thread
from fcrlive.errors import UserError


def _command_modules():
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda i: i.name):
        if info.name.startswith("_"):
            continue
        yield importlib.import_module(f"fcrlive.commands.{info.name}")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fcrlive",
        description="Live identification of hydro governors for Nordic FCR (droop, max|S|, TSO checks).",
    )
    parser.add_argument("--version", action="version", version=f"fcrlive {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in _command_modules():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP)
        mod.configure(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    try:
        # one BLAS thread: the same log gives the same numbers whatever the machine's thread count
        with one_thread():
            return int(args._run(args) or 0)
    except UserError as exc:
        for line in str(exc).splitlines() or [""]:  # several configuration problems: one line each
            print(f"fcrlive {args.command}: error: {line}", file=sys.stderr)
        return exc.exit_status
    except KeyboardInterrupt:
        print(f"fcrlive {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # `fcrlive model --json | head`: the reader left; not an error of ours. Point stdout at
        # devnull so the interpreter's final flush does not raise again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())
