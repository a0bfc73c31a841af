"""``fcrlive model``: the analytic model of a plant (G_1(0), max|G_1|, max|S|, responses at TSO periods)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

NAME = "model"
HELP = "Analytic model of a plant: G_1(0), max|G_1|, max|S|, droop, responses at the TSO sine periods."


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--preset",
        default="paper-plant1",
        help="preset plant (default: paper-plant1); the base for --plant files without their own preset",
    )
    parser.add_argument("--plant", metavar="FILE.toml", help="plant description file (docs/plant-toml.md)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of a table")


def _resolve_plant(args: argparse.Namespace):
    from fcrlive.plant.description import load_plant
    from fcrlive.plant.params import preset

    base = preset(args.preset)
    # A file without its own ``preset`` key overrides --preset.
    return load_plant(args.plant, base=base) if args.plant else base


def _cplx(h: complex) -> dict[str, float]:
    return {
        "abs": abs(h),
        "phase_deg": math.degrees(math.atan2(h.imag, h.real)),
        "re": h.real,
        "im": h.imag,
    }


def summary(plant) -> dict[str, Any]:
    """The JSON-ready summary of ``plant`` that ``fcrlive model --json`` prints."""
    from fcrlive.constants import TSO_PERIODS_S
    from fcrlive.plant.description import plant_to_dict
    from fcrlive.plant.transfer import analytic, freqresp, peak, static_gain

    tfs = analytic(plant)
    gov = plant.unit.governor
    g1_peak = peak(tfs.G_1)
    s_peak = peak(tfs.S)
    d1_peak = peak(tfs.discrete.G_1)
    ds_peak = peak(tfs.discrete.S)
    responses = []
    for T in TSO_PERIODS_S:
        w = 2.0 * math.pi / T
        responses.append(
            {
                "period_s": T,
                "omega_rad_s": w,
                **{
                    key: _cplx(complex(freqresp(getattr(tfs, name), w)))
                    for key, name in (("g1", "G_1"), ("s", "S"), ("gp", "G_p"), ("f", "F"), ("greq", "G_req"))
                },
            }
        )

    def pk(p) -> dict[str, float]:
        return {"value": p.value, "omega_rad_s": p.omega_rad_s, "period_s": p.period_s}

    return {
        "plant": plant.unit.name,
        "rated_mw": plant.unit.rated_mw,
        "droop_placement": gov.droop_placement,
        "droop_signal": gov.droop_signal,
        "pm0": plant.unit.turbine.Pm0,
        "tc_s": gov.Tc,
        "g1_static": static_gain(tfs.G_1),
        "max_abs_g1": pk(g1_peak),
        "max_abs_s": pk(s_peak),
        "droop": tfs.droop,
        "effective_droop": tfs.effective_droop,
        "gp_static": static_gain(tfs.G_p),
        "k11": tfs.K11,
        "discrete": {
            "tc_s": gov.Tc,
            "u_hold": tfs.discrete.u_hold,
            "g1_static": static_gain(tfs.discrete.G_1),
            "max_abs_g1": pk(d1_peak),
            "max_abs_s": pk(ds_peak),
        },
        "responses": responses,
        "units": {
            "g1": "pu speed / pu power (machine base), u = ΔPe to control error",
            "s": "dimensionless, r to control error",
            "gp": "pu power / pu speed, control error to power (incl. the speed filter)",
            "f": "TSO-normalised rho*Gp/Gt(0), unit static gain",
            "greq": "industry sine test (paper eq. 13), pu power / pu speed",
            "droop": "pu speed / pu gate",
            "effective_droop": "pu speed / pu power = 1/Gp(0)",
            "omega_rad_s": "rad/s",
        },
        "parameters": plant_to_dict(plant),
    }


def _table(s: dict[str, Any]) -> str:
    g1, sp = s["max_abs_g1"], s["max_abs_s"]
    d = s["discrete"]
    lines = [
        f"plant {s['plant']} ({s['rated_mw']:g} MW), droop {s['droop_placement']}/{s['droop_signal']}, "
        f"Pm0 = {s['pm0']:g} pu, Tc = {s['tc_s']:g} s; per unit on the machine base",
        f"  droop ρ                 {s['droop']:.4g} pu speed/pu gate  (effective 1/G_p(0) = "
        f"{s['effective_droop']:.4g} pu speed/pu power = {100 * s['effective_droop']:.3g} %)",
        f"  G_1(0)                  {s['g1_static']:.4f} pu speed/pu power",
        f"  max|G_1|                {g1['value']:.4f} at {g1['omega_rad_s']:.4f} rad/s "
        f"(T = {g1['period_s']:.1f} s)",
        f"  max|S|                  {sp['value']:.4f} at {sp['omega_rad_s']:.4f} rad/s "
        f"(T = {sp['period_s']:.1f} s)",
        f"  at Tc (u {d['u_hold']})         max|G_1(z)| {d['max_abs_g1']['value']:.4f}, "
        f"max|S(z)| {d['max_abs_s']['value']:.4f}",
        f"  K11 (for G_req)         {s['k11']:.1f} pu power/(pu speed·s)",
        "",
        "  T [s]  ω [rad/s]   |G_1|  ∠G_1[°]    |S|   ∠S[°]   |G_p|  ∠G_p[°]    |F|   ∠F[°]"
        "  |G_req| ∠G_req[°]",
    ]
    for r in s["responses"]:
        cells = [f"{r['period_s']:6.0f}", f"{r['omega_rad_s']:9.4f}"]
        for k in ("g1", "s", "gp", "f", "greq"):
            cells += [f"{r[k]['abs']:7.4f}", f"{r[k]['phase_deg']:7.1f}"]
        lines.append(" ".join(cells))
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    plant = _resolve_plant(args)
    s = summary(plant)
    if args.json:
        json.dump(s, sys.stdout, indent=2, ensure_ascii=False)
        sys.stdout.write("\n")
    else:
        print(_table(s))
    return 0
