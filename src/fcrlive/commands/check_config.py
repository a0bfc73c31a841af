"""``fcrlive check-config FILE [--connect]``: validate a daemon configuration; optionally try its peers."""

from __future__ import annotations

import argparse

NAME = "check-config"
HELP = ("validate a daemon config file (and its register map / DBC); --connect also tries the device and "
        "the broker once")


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", metavar="FILE", help="daemon configuration (TOML)")
    parser.add_argument("-q", "--quiet", action="store_true", help="print nothing when valid")
    parser.add_argument("--connect", action="store_true",
                        help="also connect once to the Modbus device (read its input registers, and its "
                             "rated_power register against [unit] rated_mw) and to the MQTT broker; exit 2 "
                             "with one line per problem")
    parser.add_argument("--timeout", type=float, default=3.0, metavar="S",
                        help="per-peer timeout for --connect [s] (default 3)")


def run(args: argparse.Namespace) -> int:
    import asyncio
    import sys

    from fcrlive.daemon.config import load_config
    from fcrlive.daemon.config.docs import summary

    cfg = load_config(args.config)  # also what `run` would refuse at start (daemon.config.checks)
    for w in cfg.warnings:
        print(f"fcrlive check-config: warning: {w}", file=sys.stderr)
    if args.connect:
        from fcrlive.daemon.reach import check_peers

        problems = asyncio.run(check_peers(cfg, args.timeout))
        if problems:
            for p in problems:
                print(f"fcrlive check-config: error: {p}", file=sys.stderr)
            return 2
    if not args.quiet:
        print(f"{args.config}: OK" + (" (device and broker answered)" if args.connect else ""))
        print(summary(cfg))
    return 0
