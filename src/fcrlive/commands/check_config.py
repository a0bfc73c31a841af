"""``fcrlive check-config FILE``: validate a daemon configuration without connecting to anything."""

from __future__ import annotations

import argparse

NAME = "check-config"
HELP = "validate a daemon config file (and its register map / DBC) without connecting; print a summary"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", metavar="FILE", help="daemon configuration (TOML)")
    parser.add_argument("-q", "--quiet", action="store_true", help="print nothing when valid")


def run(args: argparse.Namespace) -> int:
    from fcrlive.daemon.config import load_config, summary

    cfg = load_config(args.config)
    if not args.quiet:
        print(f"{args.config}: OK")
        print(summary(cfg))
    return 0
