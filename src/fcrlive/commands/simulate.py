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
    p.add_argument("--snr-db", type=float, default=12.0, help="signal-to-noise ratio [dB] (default 12)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--sample-ms",
        type=int,
        default=20,
        help="logging interval [ms], a whole multiple of the controller sample time (default 20)",
    )
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


def _write(path: Path, log) -> Path:
    from fcrlive.errors import UserError
    from fcrlive.tso.csvlog import write_log

    try:
        return write_log(path, log)
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

    if args.out is None and args.sine_tests is None:
        raise UserError("nothing to do: give --out FILE.csv and/or --sine-tests DIR")
    if not args.minutes > 0:
        raise UserError(f"--minutes must be positive, got {args.minutes:g}", where="--minutes")
    start = _start(args.start)
    plant = _load_plant(args)
    tc_ms = round(plant.unit.governor.Tc * 1000.0, 6)
    if args.sample_ms <= 0 or abs(args.sample_ms / tc_ms - round(args.sample_ms / tc_ms)) > 1e-9:
        raise UserError(
            f"--sample-ms {args.sample_ms} is not a whole multiple of the controller step {tc_ms:g} ms",
            where="--sample-ms",
        )
    sample_s = args.sample_ms / 1000.0

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
            duration_s=args.minutes * 60.0, snr_db=args.snr_db, excitation=args.excitation, seed=args.seed
        )
        result = simulate(plant, config)
        log = log_from_sim(result, start=start, sample_s=sample_s, excitation=args.excitation)
        out = Path(args.out)
        if out_dir is not None:
            out_dir.mkdir(parents=True, exist_ok=True)
            end = start + timedelta(seconds=log.duration_s + sample_s)
            out = out_dir / tso_filename(RESOURCE, SERVICE, "Operation", AREA, TIMEZONE, start, end, sample_s)
        _write(out, log)
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
                plant, period, amplitude_hz=0.1, config=SimConfig(snr_db=args.snr_db, seed=args.seed)
            )
            log = log_from_sine(res, start=t0, sample_s=sample_s)
            end = t0 + timedelta(seconds=log.duration_s + sample_s)
            name = tso_filename(RESOURCE, SERVICE, sine_test_type(period), AREA, TIMEZONE, t0, end, sample_s)
            path = _write(folder / name, log)
            print(_summary(path, log))
            t0 = _next_minute(end)  # tests run one after the other
    return 0


def _load_plant(args: argparse.Namespace):
    if args.plant is not None:
        from fcrlive.plant.description import load_plant

        return load_plant(args.plant)
    from fcrlive.plant.params import preset

    return preset(args.preset)
