"""``fcrlive run --config FILE``: the daemon (sample → store → identify → publish) until SIGTERM/SIGINT."""

from __future__ import annotations

import argparse

NAME = "run"
HELP = "run the daemon: sample the governor, keep windows in SQLite, re-identify, publish over MQTT"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", required=True, metavar="FILE", help="daemon configuration (TOML)")
    parser.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR"),
                        help="log level (default INFO); logs are key=value lines on stderr")


def run(args: argparse.Namespace) -> int:
    from fcrlive.daemon.service import main

    return main(args.config, args.log_level)
