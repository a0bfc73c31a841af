"""``fcrlive simulate --tso-test NAME --out-dir DIR``: the prequalification test programme on the simulated
plant (:mod:`fcrlive.prequal.programme`), one TSO file per test (test IDs of TR Appendix 2 Table 21,
``Sine<period>`` per sine test, ``Operation``) and ``DIR/unit.toml``, the unit description of the
simulated plant, so that ``fcrlive prequal DIR`` can evaluate the whole application.
"""

from __future__ import annotations

import argparse
import sys
from datetime import timedelta
from pathlib import Path

DEFAULT_TEST_SAMPLE_MS = 100
"""Logging interval of the test files [ms]: 10 Hz meets TR 4.3 (≥ 10 Hz FCR-D, ≥ 5 Hz FCR-N)."""
DEFAULT_OPERATION_SAMPLE_MS = 20
"""Logging interval of the normal-operation file [ms]: the controller rate, what the daemon records."""


def configure(p: argparse.ArgumentParser) -> None:
    """The --tso-test options (added to ``fcrlive simulate``)."""
    from fcrlive.prequal.programme import GROUPS, TEST_NAMES

    names = ", ".join([*TEST_NAMES, *GROUPS, "all"])
    g = p.add_argument_group("prequalification test programme (TR v1.1 test profiles)")
    g.add_argument(
        "--tso-test",
        action="append",
        metavar="NAME",
        help=f"simulate this test (repeatable): {names}",
    )
    g.add_argument("--out-dir", type=Path, metavar="DIR", help="where the test files and unit.toml go")
    g.add_argument(
        "--endurance",
        action="store_true",
        help="the endurance variants (15-min FCR-N steps, 900 s after FCR-D ramp 3) at the high-load, "
        "low-droop point (or the only one)",
    )
    g.add_argument(
        "--sine-periods",
        metavar="T1,T2,...",
        help="sine periods [s] to run (default: all ten of TR Table 6, for every service)",
    )
    g.add_argument(
        "--test-noise-pct",
        type=float,
        default=0.1,
        help="power meter noise in the test files, %% of rated power (std; default 0.1); --snr-db sets "
        "the process noise of the operation file only",
    )
    g.add_argument(
        "--operation-minutes", type=float, default=60.0, help="normal-operation log length [min] (TR 5.4: 60)"
    )


def _periods(text: str | None) -> tuple[float, ...] | None:
    from fcrlive.errors import UserError

    if text is None:
        return None
    try:
        out = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise UserError(f"--sine-periods {text!r} is not a list of numbers", where="--sine-periods") from None
    if not out or any(not x > 0 for x in out):
        raise UserError(f"--sine-periods {text!r} must be positive periods in s", where="--sine-periods")
    return out


def _description(args: argparse.Namespace):
    """(plant, resolved [unit.prequal] or None)."""
    if args.plant is not None:
        from fcrlive.plant.description import load_unit_description

        d = load_unit_description(args.plant)
        return d.plant, d.prequal
    from fcrlive.plant.params import preset

    return preset(args.preset), None


def run(args: argparse.Namespace, start) -> int:
    """Run the programme; ``start`` the time stamp of the first sample (UTC)."""
    from tqdm import tqdm

    from fcrlive.commands.simulate import AREA, RESOURCE, TIMEZONE, _next_minute, _summary, _write
    from fcrlive.errors import UserError
    from fcrlive.prequal import programme as pg
    from fcrlive.tso.names import tso_filename

    if args.out_dir is None:
        raise UserError("--tso-test needs --out-dir DIR", where="--out-dir")
    if args.out_dir.exists() and not args.out_dir.is_dir():
        raise UserError(f"{args.out_dir} exists and is not a directory", where="--out-dir")
    if not args.test_noise_pct >= 0:
        raise UserError("--test-noise-pct must be >= 0", where="--test-noise-pct")
    if not args.operation_minutes > 0:
        raise UserError("--operation-minutes must be positive", where="--operation-minutes")
    plant, prequal = _description(args)
    fcrd = prequal.fcrd if prequal is not None else "dynamic"
    try:
        names = pg.expand_names(args.tso_test, fcrd)
    except ValueError as exc:
        raise UserError(str(exc), where="--tso-test") from None
    points = pg.points_of(plant, prequal)
    tests = pg.plan(names, points, endurance=args.endurance, sine_periods=_periods(args.sine_periods))
    if not tests:
        raise UserError(f"no test of {', '.join(names)} is run at the described operating points",
                        where="--tso-test")
    tc_ms = plant.unit.governor.Tc * 1000.0
    explicit = args.sample_ms
    sample_ms = {
        "test": explicit or DEFAULT_TEST_SAMPLE_MS,
        "operation": explicit or max(DEFAULT_OPERATION_SAMPLE_MS, tc_ms),
    }
    for ms in sample_ms.values():
        if abs(ms / tc_ms - round(ms / tc_ms)) > 1e-9 or ms <= 0:
            raise UserError(f"--sample-ms {ms:g} is not a whole multiple of the controller step {tc_ms:g} ms",
                            where="--sample-ms")
    resource = prequal.resource if prequal is not None else RESOURCE
    area = prequal.area if prequal is not None else AREA

    out = args.out_dir
    out.mkdir(parents=True, exist_ok=True)
    unit_path = out / "unit.toml"
    # the plant's own operating point only (no [unit.prequal]): one set point and one droop, the TR 5.1
    # exemptions; a description says for itself
    single = (prequal.single_setpoint, prequal.single_droop) if prequal is not None else (True, True)
    text = pg.unit_toml(plant, points, resource=resource, area=area, fcrd=fcrd,
                        single_setpoint=single[0], single_droop=single[1])
    unit_path.write_text(text, encoding="ascii")
    t0 = start
    bar = tqdm(tests, desc="TSO tests", unit="test", file=sys.stderr, disable=len(tests) < 2)
    for k, test in enumerate(bar):
        bar.set_postfix_str(test.label, refresh=True)
        sample_s = sample_ms["operation" if test.profile is None else "test"] / 1000.0
        try:
            _, log = pg.run_test(plant, test, start=t0, sample_s=sample_s, snr_db=args.snr_db,
                                 seed=args.seed + k, operation_s=args.operation_minutes * 60.0,
                                 test_noise_pu=args.test_noise_pct / 100.0)
        except ValueError as exc:
            raise UserError(f"{test.label}: {exc}") from None
        end = t0 + timedelta(seconds=log.duration_s + sample_s)
        name = tso_filename(resource, test.service, test.test_type, area, TIMEZONE, t0, end, sample_s)
        path = _write(out / name, log)
        tqdm.write(_summary(path, log), file=sys.stdout)
        t0 = _next_minute(end)
    print(f"{unit_path}: unit description ({len(points)} operating point{'s' if len(points) > 1 else ''})")
    return 0
