"""Monte Carlo study: the estimates of one run as row fields, and the figures of merit of a cell
(eqs. 35-36, bias, coverage; package docstring). Pure."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from fcrlive.analysis.montecarlo.config import GRID, SCALARS, Truth, period_tag
from fcrlive.constants import Z95


def nrmse(estimates, true_value: float) -> float:
    """Eq. 35: sqrt(mean((a0 − a_i)²)) over the finite estimates (NaN if none)."""
    a = np.asarray(estimates, float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return float("nan")
    return float(np.sqrt(np.mean((true_value - a) ** 2)))



def nrmse_omega(estimates, true_values) -> np.ndarray:
    """Eq. 36 per frequency: sqrt(mean_i |G − G_i|²/|G|²); ``estimates`` (L, P) complex, truth (P,).

    Rows with a non-finite value at a frequency are left out at that frequency."""
    G = np.asarray(true_values, complex)
    E = np.asarray(estimates, complex).reshape(-1, G.size)
    err = np.abs(E - G[None, :]) ** 2 / np.abs(G[None, :]) ** 2
    out = np.full(G.size, np.nan)
    for j in range(G.size):
        e = err[:, j][np.isfinite(err[:, j])]
        if e.size:
            out[j] = math.sqrt(float(np.mean(e)))
    return out



def coverage(lo, hi, true_value) -> float:
    """Fraction of the intervals [lo, hi] (finite ones) that contain the truth (broadcast)."""
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    ok = np.isfinite(lo) & np.isfinite(hi)
    if not np.any(ok):
        return float("nan")
    tv = np.broadcast_to(np.asarray(true_value, float), lo.shape)
    return float(np.mean((lo[ok] <= tv[ok]) & (tv[ok] <= hi[ok])))



def closed_loop_estimates(exp, periods_s: Sequence[float], grid: np.ndarray = GRID) -> tuple[dict, dict]:
    """(row fields, responses on ``grid``) from an fcrlive.analysis.experiments.ExperimentResult."""
    fr = exp.responses
    wmax = exp.omega_max * 0.999
    row: dict = {}
    g0 = fr(np.array([1e-7]))["G_1"]
    v, sd = float(g0.value.real[0]), float(g0.sd_real[0])
    row.update(g1_static=v, g1_static_lo=v - Z95 * sd, g1_static_hi=v + Z95 * sd)
    # The same band as `fcrlive identify` reports: peaks beyond the data's passband are model artefacts.
    from fcrlive.analysis.assess import peak_band
    from fcrlive.gridsearch import uncertain_peak

    band = peak_band(exp.Ts)
    for name, key in (("max_g1", "G_1"), ("max_s", "S")):
        if key in exp.identifiable:
            pk = uncertain_peak(lambda w, k=key: fr(w)[k], *band, 1500)
            lo, hi = pk.ci95()
            row.update({name: pk.value, f"{name}_lo": lo, f"{name}_hi": hi, f"{name}_omega": pk.omega})
    keys = [k for k in ("G_1", "S", "G_p") if k in exp.identifiable]
    g = grid[grid < wmax]
    R = fr(g)
    resp = {}
    for k in keys:
        full = np.full(grid.size, np.nan + 0j)
        full[: g.size] = R[k].value
        resp[k] = full
    if "G_p" in exp.identifiable:
        Gp = fr(2 * np.pi / np.asarray(periods_s, float))["G_p"]
        lo, hi = Gp.ci95_abs()
        for T, val, a, b in zip(periods_s, Gp.value, lo, hi):
            t = period_tag(T)
            row.update({f"gp_re_{t}": val.real, f"gp_im_{t}": val.imag, f"gp_lo_{t}": a, f"gp_hi_{t}": b})
    return row, resp



def sine_estimates(results: Sequence) -> dict:
    """Row fields from sine_fit.SineTestResult per period: G_req and the 95 % interval of |G_req|."""
    row = {}
    for r in results:
        t = period_tag(r.period_s)
        g = complex(r.G_req)
        sd = r.gain_se * abs(g) / r.gain if r.gain > 0 else float("nan")
        row.update({
            f"gp_re_{t}": g.real,
            f"gp_im_{t}": g.imag,
            f"gp_lo_{t}": max(abs(g) - Z95 * sd, 0.0),
            f"gp_hi_{t}": abs(g) + Z95 * sd,
            f"lin_{t}": r.linearity,
        })
    return row



def _col(rows: list[dict], key: str) -> np.ndarray:
    return np.array([float(r.get(key, np.nan)) if r.get(key) is not None else np.nan for r in rows])



def summarise_cell(rows: list[dict], tr: Truth) -> dict:
    """The figures of merit of one (SNR, length, method) cell (package docstring)."""
    ok = [r for r in rows if r["status"] == "ok"]
    failed = [r for r in rows if r["status"] != "ok"]
    reasons: dict[str, int] = {}
    for r in failed:
        reasons[r["reason"]] = reasons.get(r["reason"], 0) + 1
    out: dict = {"runs": len(rows), "ok": len(ok), "failed": len(failed),
                 "failure_reasons": dict(sorted(reasons.items(), key=lambda kv: -kv[1]))}
    for q in SCALARS:
        a = _col(ok, q)
        if not np.any(np.isfinite(a)):
            continue
        a0 = tr.scalar(q)
        e = nrmse(a, a0)
        out[q] = {
            "truth": a0,
            "n": int(np.isfinite(a).sum()),
            "mean": float(np.nanmean(a)),
            "bias": float(np.nanmean(a) - a0),
            "rel_bias": float(np.nanmean(a) / a0 - 1.0),
            "nrmse": e,
            "rel_nrmse": e / abs(a0),
            "coverage": coverage(_col(ok, f"{q}_lo"), _col(ok, f"{q}_hi"), a0),
            "median_abs_err": float(np.nanmedian(np.abs(a - a0))),
        }
    tags = [period_tag(T) for T in tr.periods_s]
    if ok and any(f"gp_re_{tags[0]}" in r for r in ok):
        G = np.column_stack([_col(ok, f"gp_re_{t}") + 1j * _col(ok, f"gp_im_{t}") for t in tags])
        lo = np.column_stack([_col(ok, f"gp_lo_{t}") for t in tags])
        hi = np.column_stack([_col(ok, f"gp_hi_{t}") for t in tags])
        absG = np.abs(G)
        out["gp"] = {
            "periods_s": list(tr.periods_s),
            "nrmse": nrmse_omega(G, tr.gp).tolist(),
            "nrmse_vs_greq": nrmse_omega(G, tr.greq).tolist(),
            "median_rel_err": np.nanmedian(np.abs(G / tr.gp[None, :] - 1.0), axis=0).tolist(),
            "rel_bias_abs": (np.nanmean(absG, axis=0) / np.abs(tr.gp) - 1.0).tolist(),
            "rel_bias_abs_vs_greq": (np.nanmean(absG, axis=0) / np.abs(tr.greq) - 1.0).tolist(),
            "coverage": [coverage(lo[:, j], hi[:, j], abs(tr.gp[j])) for j in range(len(tags))],
            "coverage_vs_greq": [coverage(lo[:, j], hi[:, j], abs(tr.greq[j])) for j in range(len(tags))],
        }
    return out
