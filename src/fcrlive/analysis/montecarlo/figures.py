"""Monte Carlo study: PNG figures like the paper's Figs. 4-10."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fcrlive.analysis.montecarlo.config import METHOD_LABELS

if TYPE_CHECKING:
    from fcrlive.analysis.montecarlo.runner import StudyResult


_STYLES = {12.0: "-", 6.0: "--", 0.0: ":"}

_COLORS = {"zcu": "C0", "zur": "C1", "zu": "C2", "sine": "C3"}



def _cell(cells, snr, mins, m):
    for c in cells:
        if c["snr_db"] == snr and c["minutes"] == mins and c["method"] == m:
            return c
    return None



def make_figures(res: StudyResult, out_dir: Path) -> list[Path]:
    """PNG figures like the paper's Figs. 4-10 (package docstring); returns the paths written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cfg, cells, tr = res.config, res.cells, res.truth
    snrs = sorted(cfg.snr_db, reverse=True)
    paths = []

    def save(fig, name):
        p = out_dir / name
        fig.tight_layout()
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(p)

    # Figs. 7a, 7b, 8: NRMSE of scalars vs SNR per method
    for q, name, title in (
        ("g1_static", "fig7a_nrmse_g1_static.png", "NRMSE of G_1(1) (eq. 35)"),
        ("max_g1", "fig7b_nrmse_max_g1.png", "NRMSE of max|G_1| (eq. 35)"),
        ("max_s", "fig8_nrmse_max_s.png", "NRMSE of max|S| (eq. 35)"),
    ):
        fig, ax = plt.subplots(figsize=(5.5, 3.8))
        drawn = False
        for m in cfg.methods:
            for mins in sorted(cfg.minutes, reverse=True):
                ys = [(_cell(cells, s, mins, m) or {}).get(q, {}).get("nrmse", np.nan) for s in snrs]
                if np.all(~np.isfinite(ys)):
                    continue
                ax.plot(snrs, ys, marker="o", color=_COLORS[m], ls="-" if mins == max(cfg.minutes) else "--",
                        label=f"{METHOD_LABELS[m]}, {mins:g} min")
                drawn = True
        ax.set_xlabel("SNR [dB]")
        ax.set_ylabel("NRMSE [pu]")
        ax.set_title(f"{title}; truth {tr.scalar(q):.4g}")
        ax.set_yscale("log")
        ax.invert_xaxis()
        ax.grid(True, which="both", alpha=0.3)
        if drawn:
            ax.legend(fontsize=8)
        save(fig, name)

    # Figs. 9, 10: NRMSE(Ω) of G_p vs period, Z_cu vs sine test, per length
    for mins in sorted(cfg.minutes, reverse=True):
        fig, ax = plt.subplots(figsize=(6, 4))
        drawn = False
        for m in ("zcu", "zur", "sine"):
            if m not in cfg.methods or (m == "zur" and "zcu" in cfg.methods):
                continue
            for s in snrs:
                c = _cell(cells, s, mins, m)
                if c is None or "gp" not in c:
                    continue
                ax.plot(c["gp"]["periods_s"], c["gp"]["nrmse"], marker="o", color=_COLORS[m],
                        ls=_STYLES.get(s, "-."), label=f"{METHOD_LABELS[m]}, {s:g} dB")
                drawn = True
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("period [s]")
        ax.set_ylabel("NRMSE(Ω) of G_p (eq. 36)")
        ax.set_title(f"G_p at the Table 1 periods, {mins:g} min datasets")
        ax.grid(True, which="both", alpha=0.3)
        if drawn:
            ax.legend(fontsize=8)
        tag = "fig9" if mins == max(cfg.minutes) else "fig10"
        save(fig, f"{tag}_nrmse_gp_{mins:g}min.png")

    # Figs. 4-6: mean |G| over the runs vs the truth (longest datasets)
    mins = max(cfg.minutes)
    ms = [m for m in cfg.methods if m != "sine"]
    for stat, fname in (("", "fig4-6_mean_responses.png"), ("_median", "fig4-6_median_responses.png")):
        if not ms:
            break
        fig, axes = plt.subplots(1, 3, figsize=(13, 4))
        for ax, g in zip(axes, ("G_1", "S", "G_p")):
            ax.loglog(tr.grid, np.abs(tr.responses[g]), "k-", lw=2, label="analytic")
            for m in ms:
                for s in snrs:
                    mr = res.mean_responses.get((s, mins, m), {}).get(g + stat)
                    if mr is None or not np.any(np.isfinite(mr)):
                        continue
                    ax.loglog(tr.grid, mr, color=_COLORS[m], ls=_STYLES.get(s, "-."),
                              label=f"{METHOD_LABELS[m]}, {s:g} dB")
            if g == "G_p" and "sine" in cfg.methods and not stat:
                for s in snrs:
                    c = _cell(cells, s, mins, "sine")
                    if c and "gp" in c:
                        w = 2 * np.pi / np.array(c["gp"]["periods_s"])
                        mag = np.abs(tr.gp) * (1 + np.array(c["gp"]["rel_bias_abs"]))
                        ax.loglog(w, mag, ls="none", marker="x", color=_COLORS["sine"],
                                  label=f"sine test, {s:g} dB")
            ax.set_title(f"{'median' if stat else 'mean'} |{g}| over the runs, {mins:g} min")
            ax.set_xlabel("ω [rad/s]")
            ax.grid(True, which="both", alpha=0.3)
        axes[0].legend(fontsize=7)
        save(fig, fname)
    return paths
