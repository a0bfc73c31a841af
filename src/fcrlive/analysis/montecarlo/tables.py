"""Monte Carlo study: the runs as CSV and the cell summaries as Markdown tables."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from fcrlive.analysis.montecarlo.config import METHOD_LABELS, SCALARS, Truth, period_tag


def row_columns(periods_s: Sequence[float]) -> list[str]:
    cols = ["snr_db", "minutes", "method", "run", "seed", "status", "reason", "ident_s", "warnings"]
    for q in SCALARS:
        cols += [q, f"{q}_lo", f"{q}_hi"]
        if q != "g1_static":
            cols.append(f"{q}_omega")
    for T in periods_s:
        t = period_tag(T)
        cols += [f"gp_re_{t}", f"gp_im_{t}", f"gp_lo_{t}", f"gp_hi_{t}", f"lin_{t}"]
    return cols



def write_csv(rows: list[dict], path: Path, periods_s: Sequence[float]) -> None:
    import csv

    cols = row_columns(periods_s)
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.9g}" if isinstance(v, float) else v) for k, v in r.items()})



def _fmt(x, nd=3, pct=False) -> str:
    if x is None or not isinstance(x, (int, float)) or not math.isfinite(x):
        return "–"
    return f"{100 * x:.0f} %" if pct else f"{x:.{nd}g}"



def markdown_table(cells: list[dict], tr: Truth) -> str:
    """The per-cell summary (relative NRMSE and bias, coverage) as a Markdown table."""
    head = (
        "| SNR | length | method | ok/runs | G_1(1) NRMSE (rel.) | bias | cov. "
        "| max\\|G_1\\| NRMSE (rel.) | bias | cov. | max\\|S\\| NRMSE (rel.) | bias | cov. "
        "| G_p NRMSE(Ω) mean (max; med.) | \\|G_p\\| cov. |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for c in cells:
        parts = [f"{c['snr_db']:g} dB", f"{c['minutes']:g} min", METHOD_LABELS[c["method"]],
                 f"{c['ok']}/{c['runs']}"]
        for q in SCALARS:
            s = c.get(q)
            if s is None:
                parts += ["–", "–", "–"]
            else:
                med = _fmt(s["median_abs_err"] / abs(s["truth"]), pct=True)
                parts += [f"{s['nrmse']:.3g} ({_fmt(s['rel_nrmse'], pct=True)}; med. {med})",
                          f"{s['bias']:+.3g}", _fmt(s["coverage"], pct=True)]
        g = c.get("gp")
        if g is None:
            parts += ["–", "–"]
        else:
            e = np.array(g["nrmse"], float)
            cov = np.array(g["coverage"], float)
            med = float(np.nanmean(g["median_rel_err"]))
            parts += [f"{np.nanmean(e):.3g} ({np.nanmax(e):.3g}; med. {_fmt(med, pct=True)})"
                      if np.any(np.isfinite(e)) else "–",
                      _fmt(float(np.nanmean(cov)) if np.any(np.isfinite(cov)) else float("nan"), pct=True)]
        lines.append("| " + " | ".join(parts) + " |")
    truth_line = (
        f"Truth: G_1(1) = {tr.g1_static:.4g}, max|G_1| = {tr.max_g1:.4g}, max|S| = {tr.max_s:.4g}. "
        "NRMSE absolute (eq. 35) with, in brackets, the NRMSE relative to the truth and the median "
        "relative error (robust to the few wild runs that dominate an RMS); bias = mean estimate − truth; "
        "cov. = coverage of the reported 95 % intervals (successful runs); NRMSE(Ω) (eq. 36, relative, "
        "complex) of G_p averaged over the Table 1 periods (max over them; median relative error "
        "averaged over them); for the sine test G_i = Ĝ_req compared with G_p as in the paper."
    )
    return head + "\n".join(lines) + "\n\n" + truth_line + "\n"



def markdown_gp_table(cells: list[dict]) -> str:
    """NRMSE(Ω) of G_p per period (eq. 36), one row per cell holding G_p estimates."""
    cs = [c for c in cells if "gp" in c]
    if not cs:
        return ""
    periods = cs[0]["gp"]["periods_s"]
    head = "| SNR | length | method | " + " | ".join(f"{p:g} s" for p in periods) + " |\n"
    head += "|---|---|---|" + "---|" * len(periods) + "\n"
    lines = []
    for c in cs:
        e = c["gp"]["nrmse"]
        lines.append(f"| {c['snr_db']:g} dB | {c['minutes']:g} min | {METHOD_LABELS[c['method']]} | "
                     + " | ".join(_fmt(x, 2) for x in e) + " |")
        if c["method"] == "sine":
            e = c["gp"]["nrmse_vs_greq"]
            lines.append(f"| {c['snr_db']:g} dB | {c['minutes']:g} min | sine vs G_req | "
                         + " | ".join(_fmt(x, 2) for x in e) + " |")
    return head + "\n".join(lines) + "\n"
