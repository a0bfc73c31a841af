"""``python -m fcrlive.excitation``: drive a governor's excitation until SIGTERM/SIGINT, printing one JSON
line per event on stdout (a test and demo tool; the daemon embeds ExcitationTask).

Writing needs the same explicit enabling as the daemon, in one of two ways:

* ``--config FILE``: a daemon configuration with ``[excitation] enabled = true`` and its
  ``[excitation.limits]``; the device (``[source.modbus]``), the generator and the points come from it.
  Refused when the file does not enable writing (the environment may only disable it, as for the daemon);
* ``--port P --register-map FILE --i-understand-this-writes --amplitude-hz A`` (no default amplitude):
  the same settings from flags, validated by the same model (:class:`ExcitationSettings`).

Before anything is written it says on stderr what it will write where. The chain is the daemon's:
generator → :class:`SafetyGuard` → :class:`ExcitationWriter`, zero on every way out. It has the shape of an
``fcrlive`` subcommand (``configure``, ``run``), but the leading underscore keeps :mod:`fcrlive.cli` from
listing it. Bad flags or files: one line on stderr, exit status 2.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import sys
import time
from typing import Any

NAME = "excite"
HELP = ("Drive the excitation of a Modbus governor until SIGTERM/SIGINT (test and demo tool; the daemon "
        "embeds ExcitationTask). Writes only with --config FILE ([excitation] enabled = true) or "
        "--i-understand-this-writes --amplitude-hz A.")
PROG = "python -m fcrlive.excitation"
ENABLE_FLAG = "--i-understand-this-writes"


def configure(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", metavar="FILE", help="daemon configuration with [excitation] enabled = true "
                   "and [excitation.limits]: device, limits, generator and points from it")
    p.add_argument(ENABLE_FLAG, dest="i_understand", action="store_true",
                   help="without --config: write to the device given by --port/--register-map")
    p.add_argument("--host", default=None, help="device address (default 127.0.0.1; with --config: its)")
    p.add_argument("--port", type=int, default=None, help="device port (with --config: its)")
    p.add_argument("--register-map", help="register map TOML of the device (without --config)")
    p.add_argument("--kind", default="white", choices=("white", "prbs", "multisine", "sine"))
    p.add_argument("--amplitude-hz", type=float, default=None,
                   help="bound on |r| [Hz], at most 0.1; required without --config")
    p.add_argument("--period-s", type=float, default=0.1, help="tick = generator sample time [s]")
    p.add_argument("--seed", type=int, default=None, help="generator seed (default: --config's, else 0)")
    p.add_argument("--holdoff-s", type=float, default=30.0)
    p.add_argument("--rate-limit", type=float, default=1.0, help="Hz/s")
    p.add_argument("--seconds", type=float, default=None, help="stop by itself after this long")
    p.add_argument("--clock-scale", type=float, default=1.0,
                   help="guard clock = scale·monotonic (the simulated governor's --speed)")
    p.add_argument("--log-level", default="WARNING")


def _settings_from_flags(args: argparse.Namespace):
    """ExcitationSettings and ModbusParams from flags; ConfigError (one line per problem) when wrong."""
    from pydantic import ValidationError

    from fcrlive.configerrors import explain_all
    from fcrlive.errors import ConfigError, ConfigProblems
    from fcrlive.excitation.config import ExcitationSettings
    from fcrlive.modbus.client import ModbusParams
    from fcrlive.modbus.mapfile import load_register_map

    missing = [flag for flag, v in (("--port", args.port), ("--register-map", args.register_map),
                                    ("--amplitude-hz", args.amplitude_hz)) if v is None]
    if missing:
        raise ConfigError(f"{ENABLE_FLAG} needs {', '.join(missing)} (no defaults for a write path)")
    flags = {"limits.amplitude_hz": "--amplitude-hz", "limits.holdoff_s": "--holdoff-s",
             "limits.rate_limit_hz_per_s": "--rate-limit", "period_s": "--period-s"}
    try:
        settings = ExcitationSettings(
            enabled=True, period_s=args.period_s,
            limits={"amplitude_hz": args.amplitude_hz, "rate_limit_hz_per_s": args.rate_limit,
                    "holdoff_s": args.holdoff_s},
            generator={"kind": args.kind, "seed": 0 if args.seed is None else args.seed})
    except ValidationError as exc:
        problems = []
        for key, msg in explain_all(exc, ExcitationSettings):
            # a limit's error comes for the whole table and names the field: point at its flag
            flag = next((f for k, f in flags.items()
                         if k == key or (key == "limits" and k.removeprefix("limits.") + " =" in msg)), key)
            problems.append(ConfigError(msg, where=flag))
        raise (problems[0] if len(problems) == 1 else ConfigProblems(problems)) from None
    rmap = load_register_map(args.register_map)
    params = ModbusParams(args.host or "127.0.0.1", args.port, rmap, timeout_s=0.2, backoff_max_s=1.0)
    return settings, params, 50.0


def _settings_from_config(args: argparse.Namespace):
    from dataclasses import replace

    from fcrlive.daemon.config import load_config
    from fcrlive.errors import ConfigError
    from fcrlive.modbus.client import ModbusParams

    cfg = load_config(args.config, startup_checks=False)
    if not cfg.excitation.enabled:
        raise ConfigError("[excitation] enabled = true is not set: nothing may be written", where=args.config)
    params = ModbusParams.from_config(cfg.source.modbus)
    if args.host is not None or args.port is not None:
        params = replace(params, host=args.host or params.host, port=args.port or params.port)
    return cfg.excitation, params, cfg.unit.f0


def plan(settings, params, f0: float, seed: int) -> str:
    """One line saying what will be written where (printed before the first write)."""
    pts = settings.points.to_points()
    rmap = params.register_map
    off = rmap.point(pts.offset)
    lim = settings.guard_limits()
    gen = settings.make_generator(seed=seed, f0=f0)
    also = " + ".join(n for n in (pts.enable, pts.heartbeat) if n)
    return (f"{PROG}: WRITING to the governor at {params.host}:{params.port} unit {rmap.unit_id}: "
            f"{pts.offset} (holding {off.address}, {off.type}) + {also} every {settings.period_s:g} s; "
            f"{gen.kind} r[n] |r| ≤ {gen.amplitude_hz:g} Hz (seed {gen.seed}) through the safety guard "
            f"(hold-off {lim.holdoff_s:g} s, rate limit {lim.rate_limit_hz_per_s:g} Hz/s, budget "
            f"{lim.budget_s_per_day:g} s/day, band ±{lim.band_hz:g} Hz); SIGTERM/SIGINT ramps to a "
            "verified zero")


def build(args: argparse.Namespace):
    """``(settings, params, f0)`` from ``--config`` or the flags; ConfigError unless writing was enabled
    explicitly."""
    from fcrlive.errors import ConfigError

    if args.config is not None:
        if args.i_understand or args.register_map is not None or args.amplitude_hz is not None:
            raise ConfigError(f"--config takes the device, the map and the limits from the file; do not "
                              f"combine it with {ENABLE_FLAG}, --register-map or --amplitude-hz")
        return _settings_from_config(args)
    if not args.i_understand:
        raise ConfigError(f"refusing to write to a governor without explicit enabling: give --config FILE "
                          f"([excitation] enabled = true with [excitation.limits]) or {ENABLE_FLAG} "
                          "--amplitude-hz A (docs/excitation-safety.md)")
    return _settings_from_flags(args)


async def _amain(args: argparse.Namespace, settings, params, f0: float, seed: int) -> int:
    import os
    import signal

    scale = args.clock_scale

    def say(kind: str, **data: Any) -> None:
        print(json.dumps({"event": kind, **data}), flush=True)

    task = settings.make_task(params, f0=f0, seed=seed,
                              clock=(lambda: scale * time.monotonic()) if scale != 1.0 else time.monotonic,
                              on_event=lambda e: say("state", **e.to_dict()))
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(
            sig, lambda s=sig: (say("signal", signal=signal.Signals(s).name), task.stop()))
    async with task:
        say("armed", pid=os.getpid(), host=params.host, port=params.port, offset=settings.points.offset,
            amplitude_hz=task.generator.amplitude_hz)
        if args.seconds is not None:
            loop.call_later(args.seconds, task.stop)
        await task.run()
    say("exit", reason=task.stats.exit_reason, zero_written=task.stats.exit_zero_ok,
        device_applies_zero=task.stats.exit_applied_zero, max_abs_written_hz=task.stats.max_abs_written_hz)
    return 0 if task.stats.exit_zero_ok else 1


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=args.log_level, format="%(asctime)s %(levelname)s %(name)s %(message)s")
    import secrets

    settings, params, f0 = build(args)
    seed = args.seed if args.seed is not None else settings.generator.seed
    seed = secrets.randbits(63) if seed is None else seed
    print(plan(settings, params, f0, seed), file=sys.stderr, flush=True)
    return asyncio.run(_amain(args, settings, params, f0, seed))


def main(argv: list[str] | None = None) -> int:
    """``python -m fcrlive.excitation``: parse ``argv`` and run; bad input is one line, exit status 2."""
    from fcrlive.errors import UserError

    parser = argparse.ArgumentParser(prog=PROG, description=HELP)
    configure(parser)
    args = parser.parse_args(argv)
    try:
        return run(args)
    except UserError as exc:
        for line in str(exc).splitlines() or [""]:
            print(f"{PROG}: error: {line}", file=sys.stderr)
        return exc.exit_status
