"""``fcrlive identify``: identify a unit from TSO logs (droop, max|S|, max|G_1|, G_p, TSO checks).

Pipeline in :mod:`fcrlive.analysis.identify`; JSON schema in docs/identify.md.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

NAME = "identify"
HELP = "Identify droop, max|S|, max|G_1| and G_p from TSO logs and check the FCR requirements."


def configure(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "files",
        nargs="+",
        type=Path,
        metavar="FILE.csv",
        help="TSO logs: one operation log, several (multi-experiment) or a set of sine tests",
    )
    p.add_argument(
        "--rated-mw", type=float, required=True, help="rated power of the unit [MW] (machine base)"
    )
    p.add_argument("--f0", type=float, default=50.0, help="nominal frequency [Hz] (default 50)")
    p.add_argument(
        "--kd",
        type=float,
        default=0.0,
        help="speed damping Kd [pu] for the effective droop 1/(1/G_1(0) - Kd) (default 0)",
    )
    p.add_argument(
        "--h",
        type=float,
        default=None,
        metavar="H",
        help="inertia constant H [s] on the machine base (generator data sheet; default: from --plant); "
        "with it, logs without excitation or slower than the controller use the lowband method",
    )
    p.add_argument(
        "--plant",
        type=Path,
        metavar="PLANT.toml",
        help="plant description: controller for zcu, droop for sine-test normalisation",
    )
    p.add_argument(
        "--method",
        default="auto",
        choices=("auto", "zu", "zur", "zcu", "sine", "lowband"),
        help="identification method (default: auto, see docs/identify.md)",
    )
    p.add_argument("--ts-id", type=float, default=None,
                   help="identification sample time [s] (default 0.25 for zcu with --h, 0.5 otherwise)")
    p.add_argument(
        "--fme",
        type=float,
        default=None,
        metavar="T_FME",
        help="multiply F by 1/(T_FME s + 1) (test signal generated inside the controller)",
    )
    p.add_argument(
        "--power-lag-s",
        type=float,
        default=None,
        metavar="S",
        help="time constant of the power transducer's first-order lag [s] (data sheet): Z_cu with --h takes "
        "it off InsAcPow before it uses the swing equation. Not given (nor --power-delay-s): Z_cu with --h "
        "profiles the log for a chain and widens its intervals by the effect of one it finds",
    )
    p.add_argument(
        "--power-delay-s",
        type=float,
        default=None,
        metavar="S",
        help="dead time of the power measurement against the frequency columns [s] (0 when only "
        "--power-lag-s is given)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON document instead of the table")
    p.add_argument("--plot", type=Path, metavar="DIR", help="write Bode, Nyquist and Req. 9 plots here")


def run(args: argparse.Namespace) -> int:
    from fcrlive.analysis.identify import identify_full
    from fcrlive.analysis.report import text_summary
    from fcrlive.commands._identify_guard import (
        identification_error,
        read_signals,
        screen_result,
        with_log_notes,
    )
    from fcrlive.errors import UserError

    _check_options(args)
    plant = None
    if args.plant is not None:
        from fcrlive.plant.description import load_plant

        plant = load_plant(args.plant)
    signals = read_signals(args.files, args.rated_mw, args.f0)
    from fcrlive.signals import PowerChain

    try:
        res = identify_full(
            signals,
            rated_mw=args.rated_mw,
            f0=args.f0,
            kd=args.kd,
            plant=plant,
            method=args.method,
            ts_id=args.ts_id,
            t_fme_s=args.fme,
            h=args.h,
            power_chain=(None if args.power_lag_s is None and args.power_delay_s is None
                         else PowerChain(args.power_lag_s or 0.0, args.power_delay_s or 0.0)),
        )
    except UserError as exc:
        raise identification_error(exc, args.files) from None
    res = with_log_notes(screen_result(res, args.files), signals)
    if args.plot is not None:
        try:
            _plots(args.plot, res)
        except OSError as exc:
            raise UserError(
                f"cannot write the plots to {args.plot}: {exc.strerror or exc} (give a writable directory)",
                where="--plot",
            ) from None
    if args.json:
        print(json.dumps(_json_safe(res.report.to_json_dict()), indent=2, allow_nan=False))
    else:
        print(text_summary(res.report))
    return 0


def _check_options(args: argparse.Namespace) -> None:
    """One-line errors for option values that would give nonsense (NaN, inf, zero or negative), and a
    --plot directory that cannot be written, before the identification spends time."""
    import math

    from fcrlive.errors import UserError

    positive = {"--rated-mw": args.rated_mw, "--f0": args.f0}
    if args.ts_id is not None:
        positive["--ts-id"] = args.ts_id
    if args.fme is not None:
        positive["--fme"] = args.fme
    for opt, value in positive.items():
        if not (math.isfinite(value) and value > 0):
            raise UserError(f"{opt} must be a positive finite number, got {value:g}", where=opt)
    if not math.isfinite(args.kd):
        raise UserError(f"--kd must be a finite number [pu], got {args.kd:g}", where="--kd")
    if args.h is not None and not (math.isfinite(args.h) and args.h > 0):
        raise UserError(f"--h must be a positive finite number [s], got {args.h:g}", where="--h")
    for opt, value in (("--power-lag-s", args.power_lag_s), ("--power-delay-s", args.power_delay_s)):
        if value is not None and not (math.isfinite(value) and 0 <= value <= 5.0):
            raise UserError(f"{opt} must be a number of seconds in [0, 5], got {value:g}", where=opt)
    if args.plot is not None:
        _check_plot_dir(args.plot)


def _check_plot_dir(folder: Path) -> None:
    import os
    import tempfile

    from fcrlive.errors import UserError

    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise UserError(
            f"cannot write plots to {folder}: {exc.strerror or exc} (give a writable directory)",
            where="--plot",
        ) from None
    if not os.access(folder, os.W_OK):
        raise UserError(f"cannot write plots to {folder} (give a writable directory)", where="--plot")


def _json_safe(doc):
    """The document with every non-finite float as null: JSON has no NaN or infinity."""
    import math

    if isinstance(doc, float):
        return doc if math.isfinite(doc) else None
    if isinstance(doc, dict):
        return {k: _json_safe(v) for k, v in doc.items()}
    if isinstance(doc, (list, tuple)):
        return [_json_safe(v) for v in doc]
    return doc


def _plots(folder: Path, res) -> None:
    import numpy as np

    from fcrlive.analysis import plots
    from fcrlive.analysis.tso_checks import FCRN_PERFORMANCE, FCRN_STABILITY

    folder.mkdir(parents=True, exist_ok=True)
    a = res.assessment
    ts = res.report.identification_ts_s
    wmax = float(np.pi / ts) * 0.999 if ts else None
    if a.responses is not None:
        R = a.responses(np.geomspace(1e-3, wmax, 600))
        for key in ("G_1", "S", "G_p"):
            if key in R:
                plots.plot_bode(folder / f"bode_{key}.png", [(key, R[key])], title=f"{key} ({a.method})")
    if a.F_callable is not None:
        plots.plot_nyquist(folder / "nyquist_FG.png", a.F_callable, FCRN_STABILITY, omega_range=(1e-4, wmax))
        k = a.tso["fcrn"].k_red_dyn if a.tso else None
        plots.plot_performance(
            folder / "req9.png", a.F_callable, FCRN_PERFORMANCE, omega_range=(1e-4, wmax), k_red_dyn=k
        )
    elif a.gp_kind == "G_req" and a.f:
        w = np.array([2 * np.pi / p.period_s for p in a.f])
        F = np.array([p.value for p in a.f])
        sd = res.experiment.F_sd
        plots.plot_bode(
            folder / "bode_F_sine.png",
            [],
            omega=np.geomspace(w.min(), w.max(), 50),
            points=[("F (sine tests)", w, F, sd)],
            title="F from sine tests",
        )
        from fcrlive.analysis.tso_checks import interpolate_points

        plots.plot_nyquist(
            folder / "nyquist_FG.png",
            interpolate_points(w, F),
            FCRN_STABILITY,
            omega_range=(w.min(), w.max()),
            points=(w, F),
        )
