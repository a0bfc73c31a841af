"""``fcrlive simulate``: write a simulated plant log (and sine-test logs) in the TSO CSV format.

The normal-operation log maps the simulation to TSO columns as :func:`fcrlive.tso.signals.log_from_sim`
documents (GridFreq is the governor's sampled speed written as a frequency). Sine tests follow TR
Table 6: one file per period of :data:`fcrlive.constants.TSO_PERIODS_S`, headers suffixed with the
period, TestType ``Sine<period>``.
"""

from __future__ import annotations

import argparse
import os
import sys
from datetime import datetime, timedelta
from pathlib import Path

NAME = "simulate"
HELP = "Simulate a plant and write TSO CSV logs (normal operation and/or sine tests)."

RESOURCE = "FCPSIM1"
SERVICE = "Fcrn"
AREA = "NO5"
TIMEZONE = "UTC"


def configure(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", default="paper-plant1", help="plant preset (default: %(default)s)")
    p.add_argument("--plant", type=Path, metavar="FILE.toml", help="plant description; overrides --preset")
    p.add_argument("--minutes", type=float, default=30.0, help="normal-operation log length [min]")
    p.add_argument(
        "--excitation", action="store_true", help="add the paper's white-noise excitation r (ApplFreqSig)"
    )
    p.add_argument("--snr-db", type=float, default=None,
                   help="signal-to-noise ratio [dB] (default 12; a zoo plant's own with --zoo-plant)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--sample-ms",
        type=int,
        default=None,
        help="logging interval [ms], a whole multiple of the controller sample time (default: the controller "
        "rate, 20 ms for the paper's plant; --tso-test: 100 for tests, 20 for operation)",
    )
    _configure_zoo(p)
    # a str, not a Path: Path("out/") drops the trailing slash that says "directory"
    p.add_argument("--out", metavar="FILE.csv|DIR", help="normal-operation log; a directory gets a TSO name")
    p.add_argument(
        "--sine-tests", type=Path, metavar="DIR", help="write one sine-test log per TSO period here"
    )
    p.add_argument(
        "--start",
        default="20261101T0000",
        metavar="YYYYMMDDThhmm",
        help="time stamp of the first sample, UTC (default %(default)s)",
    )
    from fcrlive.commands import _simulate_tso as simulate_tso

    simulate_tso.configure(p)


def _configure_zoo(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("validation zoo and measurement chain (docs/zoo.md)")
    g.add_argument("--list-zoo", action="store_true",
                   help="list the zoo's plants (with their truth) and loggers")
    g.add_argument("--zoo-plant", metavar="NAME",
                   help="simulate this zoo plant, or held-out-K (a plant drawn at random by its number K, "
                   "which no estimator was developed on); overrides --preset/--plant")
    g.add_argument("--logger", metavar="NAME", help="write the log through this zoo logger")
    g.add_argument("--log-every", type=int, metavar="K",
                   help="instantaneous samples at 1/K of the controller rate")
    g.add_argument("--block-average", type=float, metavar="S",
                   help="a historian's block averages over S seconds")
    g.add_argument("--meter-noise-pct", type=float, metavar="PCT",
                   help="power meter noise [%% of rated power]")
    g.add_argument("--noise-at", choices=["log", "meter"],
                   help="meter noise on each logged value (log) or at the controller rate (meter)")
    g.add_argument("--freq-resolution-mhz", type=float, metavar="MHZ", help="GridFreq resolution [mHz]")
    g.add_argument("--jitter-ms", type=float, metavar="MS", help="sampling jitter, uniform in ±MS [ms]")
    g.add_argument("--power-lag-s", type=float, metavar="S",
                   help="time constant of the power transducer's first-order lag [s]")
    g.add_argument("--power-delay-s", type=float, metavar="S", help="dead time of the power measurement [s]")
    g.add_argument("--columns", choices=["tso", "governor"],
                   help="tso: GridFreq/ApplFreqSig/InsAcPow; governor: also ContOutSig/GuideVane")


_LOGGER_OPTIONS = {"log_every": "every", "block_average": "block_s", "meter_noise_pct": "meter_noise_pct",
                   "noise_at": "noise_at", "freq_resolution_mhz": "freq_resolution_mhz",
                   "jitter_ms": "jitter_ms", "power_lag_s": "power_lag_s", "power_delay_s": "power_delay_s",
                   "columns": "columns"}


def _logger(args: argparse.Namespace):
    """The measurement chain the options ask for (a zoo logger with overrides), or None."""
    from dataclasses import replace

    from fcrlive.errors import ConfigError, UserError
    from fcrlive.sim import logger as lg
    from fcrlive.sim import zoo

    changes = {f: getattr(args, o) for o, f in _LOGGER_OPTIONS.items() if getattr(args, o) is not None}
    if args.logger is None and not changes:
        return None
    if args.sample_ms is not None:
        raise UserError("--sample-ms goes with the plain log; with a logger use --log-every/--block-average",
                        where="--sample-ms")
    if changes.get("block_s") is not None and "every" not in changes:
        changes["every"] = 1
    if changes.get("every", 1) > 1 and "block_s" not in changes:
        changes["block_s"] = None
    try:
        base = zoo.zoo_logger(args.logger) if args.logger is not None else lg.Logger(name="custom")
        logger = replace(base, **changes)
        if changes:
            logger = replace(logger, name=f"{base.name}+options")
        logger.check()
    except ConfigError as exc:
        raise UserError(str(exc), where="--logger" if args.logger else "logger options") from None
    return logger


def _start(text: str) -> datetime:
    from fcrlive.errors import UserError

    for fmt in ("%Y%m%dT%H%M", "%Y%m%dT%H%M%S"):
        try:
            return datetime.strptime(text, fmt)
        except ValueError:
            pass
    raise UserError(f"--start {text!r} is not YYYYMMDDThhmm", where="--start")


def _summary(path: Path, log) -> str:
    import numpy as np

    p = log.columns["InsAcPow"]
    f = log.columns["GridFreq"]
    return (
        f"{path}: {len(log)} samples, {log.duration_s:.1f} s, "
        f"power std {np.std(p):.3f} MW, frequency std {1e3 * np.std(f):.2f} mHz"
    )


def _write(path: Path, log, decimals=None) -> Path:
    from fcrlive.errors import UserError
    from fcrlive.tso.csvlog import DEFAULT_DECIMALS, write_log

    try:
        return write_log(path, log, decimals=DEFAULT_DECIMALS if decimals is None else decimals)
    except OSError as exc:
        raise UserError(f"cannot write the log: {exc.strerror or exc}", where=str(path)) from None


def _next_minute(t: datetime) -> datetime:
    up = t.replace(second=0, microsecond=0)
    return up if up == t else up + timedelta(minutes=1)


def run(args: argparse.Namespace) -> int:
    from fcrlive.constants import TSO_PERIODS_S
    from fcrlive.errors import UserError
    from fcrlive.tso.names import sine_test_type, tso_filename
    from fcrlive.tso.signals import log_from_sim, log_from_sine

    if args.list_zoo:
        from fcrlive.sim import zoo

        print(zoo.table())
        return 0
    if args.tso_test:
        from fcrlive.commands import _simulate_tso as simulate_tso

        zoo_opts = [o for o in ("zoo_plant", "logger", *_LOGGER_OPTIONS) if getattr(args, o) is not None]
        if zoo_opts:
            opt = "--" + zoo_opts[0].replace("_", "-")
            raise UserError("a zoo plant or logger goes with --out, not with --tso-test (which simulates "
                            "--preset or --plant)", where=opt)
        if args.snr_db is None:
            args.snr_db = 12.0
        return simulate_tso.run(args, _start(args.start))
    if args.out is None and args.sine_tests is None:
        raise UserError("nothing to do: give --out FILE.csv, --sine-tests DIR and/or --tso-test NAME")
    if not args.minutes > 0:
        raise UserError(f"--minutes must be positive, got {args.minutes:g}", where="--minutes")
    start = _start(args.start)
    plant = _load_plant(args)
    zp = _zoo_plant(args)
    snr_db = args.snr_db if args.snr_db is not None else zp.snr_db if zp is not None else 12.0
    model = zp.model if zp is not None else "nonlinear"
    logger = _logger(args)
    tc_ms = round(plant.unit.governor.Tc * 1000.0, 6)
    sample_ms = args.sample_ms if args.sample_ms is not None else tc_ms
    if sample_ms <= 0 or abs(sample_ms / tc_ms - round(sample_ms / tc_ms)) > 1e-9:
        raise UserError(
            f"--sample-ms {sample_ms:g} is not a whole multiple of the controller step {tc_ms:g} ms",
            where="--sample-ms",
        )
    sample_s = sample_ms / 1000.0
    if zp is not None:
        from fcrlive.sim import zoo

        print(f"zoo plant {zp.name}: {zoo.truth(zp.name).summary()}", file=sys.stderr)

    from fcrlive.sim import SimConfig, simulate, sine_test

    out_dir = None
    if args.out is not None:
        # Check where the log goes before spending time on the simulation.
        if Path(args.out).is_dir() or args.out.endswith(("/", os.sep)):
            out_dir = Path(args.out)
        elif not Path(args.out).parent.is_dir():
            raise UserError(f"directory {Path(args.out).parent} does not exist", where="--out")
    if args.sine_tests is not None and args.sine_tests.exists() and not args.sine_tests.is_dir():
        raise UserError(f"{args.sine_tests} exists and is not a directory", where="--sine-tests")

    if args.out is not None:
        config = SimConfig(
            duration_s=args.minutes * 60.0, snr_db=snr_db, excitation=args.excitation, seed=args.seed,
            model=model,
        )
        result = simulate(plant, config)
        decimals = None
        if logger is None:
            log = log_from_sim(result, start=start, sample_s=sample_s, excitation=args.excitation)
        else:
            from fcrlive.sim import logger as lg
            from fcrlive.sim.zoo import logger_seed

            log = lg.log(result, logger, seed=logger_seed(args.seed, logger.name), start=start)
            decimals = lg.COLUMN_DECIMALS if logger.round_columns else None
            print(f"logger {logger.name}: {logger.summary(plant.unit.governor.Tc)}", file=sys.stderr)
        log_s = float(log.sample_s)
        out = Path(args.out)
        if out_dir is not None:
            out_dir.mkdir(parents=True, exist_ok=True)
            end = start + timedelta(seconds=log.duration_s + log_s)
            out = out_dir / tso_filename(RESOURCE, SERVICE, "Operation", AREA, TIMEZONE, start, end, log_s)
        _write(out, log, decimals)
        print(_summary(out, log))

    if args.sine_tests is not None:
        folder = args.sine_tests
        folder.mkdir(parents=True, exist_ok=True)
        t0 = start
        for k, period in enumerate(TSO_PERIODS_S, start=1):
            print(f"sine test {k}/{len(TSO_PERIODS_S)}: period {period:g} s ...", file=sys.stderr, flush=True)
            # The same process noise as in operation (sized from the closed loop at --snr-db): a plant
            # does not get quieter during a test. The simulator picks the duration (settling + periods).
            res = sine_test(
                plant, period, amplitude_hz=0.1, config=SimConfig(snr_db=snr_db, seed=args.seed, model=model)
            )
            log = log_from_sine(res, start=t0, sample_s=sample_s)
            end = t0 + timedelta(seconds=log.duration_s + sample_s)
            name = tso_filename(RESOURCE, SERVICE, sine_test_type(period), AREA, TIMEZONE, t0, end, sample_s)
            path = _write(folder / name, log)
            print(_summary(path, log))
            t0 = _next_minute(end)  # tests run one after the other
    return 0


def _zoo_plant(args: argparse.Namespace):
    if args.zoo_plant is None:
        return None
    from fcrlive.errors import ConfigError, UserError
    from fcrlive.sim import zoo

    try:
        return zoo.zoo_plant(args.zoo_plant)
    except ConfigError as exc:
        raise UserError(str(exc), where="--zoo-plant") from None


def _load_plant(args: argparse.Namespace):
    if args.zoo_plant is not None:
        return _zoo_plant(args).plant
    if args.plant is not None:
        from fcrlive.plant.description import load_plant

        return load_plant(args.plant)
    from fcrlive.plant.params import preset

    return preset(args.preset)
