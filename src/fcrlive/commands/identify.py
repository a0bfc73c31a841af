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
        "--plant",
        type=Path,
        metavar="PLANT.toml",
        help="plant description: controller for zcu, droop for sine-test normalisation",
    )
    p.add_argument(
        "--method",
        default="auto",
        choices=("auto", "zu", "zur", "zcu", "sine"),
        help="identification method (default: auto, see docs/identify.md)",
    )
    p.add_argument("--ts-id", type=float, default=0.5, help="identification sample time [s] (default 0.5)")
    p.add_argument(
        "--fme",
        type=float,
        default=None,
        metavar="T_FME",
        help="multiply F by 1/(T_FME s + 1) (test signal generated inside the controller)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON document instead of the table")
    p.add_argument("--plot", type=Path, metavar="DIR", help="write Bode, Nyquist and Req. 9 plots here")


def run(args: argparse.Namespace) -> int:
    from fcrlive.analysis.identify import identify_files
    from fcrlive.analysis.report import text_summary
    from fcrlive.errors import UserError

    if not args.rated_mw > 0:
        raise UserError(f"--rated-mw must be positive, got {args.rated_mw:g}", where="--rated-mw")
    if not args.ts_id > 0:
        raise UserError(f"--ts-id must be positive, got {args.ts_id:g}", where="--ts-id")
    plant = None
    if args.plant is not None:
        from fcrlive.plant.description import load_plant

        plant = load_plant(args.plant)
    res = identify_files(
        args.files,
        rated_mw=args.rated_mw,
        f0=args.f0,
        kd=args.kd,
        plant=plant,
        method=args.method,
        ts_id=args.ts_id,
        t_fme_s=args.fme,
    )
    if args.plot is not None:
        _plots(args.plot, res)
    if args.json:
        print(json.dumps(res.report.to_json_dict(), indent=2, allow_nan=False))
    else:
        print(text_summary(res.report))
    return 0


def _plots(folder: Path, res) -> None:
    import numpy as np

    from fcrlive.analysis import plots
    from fcrlive.analysis.tso_checks import FCRN_PERFORMANCE, FCRN_STABILITY

    folder.mkdir(parents=True, exist_ok=True)
    a = res.assessment
    if a.responses is not None:
        fr = a.responses
        wmax = float(np.pi / res.report.identification_ts_s) * 0.999
        w = np.geomspace(1e-3, wmax, 600)
        R = fr(w)
        for key in ("G_1", "S", "G_p"):
            if key in R:
                g = R[key]
                val = dict(zip(w, g.value))
                sd = dict(zip(w, np.hypot(g.sd_real, g.sd_imag)))

                def interp(x, d=val):
                    x = np.asarray(x, float)
                    ks = np.array(list(d.keys()))
                    vs = np.array(list(d.values()))
                    return np.interp(np.log(x), np.log(ks), vs.real) + 1j * np.interp(
                        np.log(x), np.log(ks), vs.imag
                    )

                plots.plot_bode(
                    folder / f"bode_{key}.png",
                    [(key, interp)],
                    omega=w,
                    sd={key: lambda x, d=sd: interp(x, d)},
                    title=f"{key} ({a.method})",
                )
    if a.F_callable is not None:
        wmax = float(np.pi / res.report.identification_ts_s) * 0.999
        plots.plot_nyquist(folder / "nyquist_FG.png", a.F_callable, FCRN_STABILITY, omega_range=(1e-4, wmax))
        k = a.tso["fcrn"].k_red_dyn if a.tso else None
        plots.plot_performance(
            folder / "req9.png", a.F_callable, FCRN_PERFORMANCE, omega_range=(1e-4, wmax), k_red_dyn=k
        )
    elif a.gp_kind == "G_req" and a.f:
        w = np.array([2 * np.pi / p.period_s for p in a.f])
        F = np.array([p.value for p in a.f])
        sd = [(p.abs_hi - abs(p.value)) / 1.96 for p in a.f]
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
