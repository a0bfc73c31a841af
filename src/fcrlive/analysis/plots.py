"""PNG plots of the FCR checks (matplotlib, Agg backend): Bode with a 95 % band, Nyquist of F·G, Req. 9.

Every function takes identified responses (:class:`fcrlive.ident.FreqResp`: values and their
uncertainty on its own ω grid), response functions (:data:`~fcrlive.analysis.tso_checks.ResponseFunction`,
``fr(omega [rad/s])``, evaluated on the plot's grid) or sampled points, writes one PNG file and returns
its path. The TSO band of periods (10-300 s) is shaded.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display on servers and in tests; set before pyplot is imported
import matplotlib.pyplot as plt
import numpy as np

from fcrlive.analysis.tso_checks import (
    FCRN_PERFORMANCE,
    FCRN_STABILITY,
    PERFORMANCE_MARGIN,
    STABILITY_RADIUS,
    STABILITY_TOLERANCE,
    TSO_BAND_PERIODS_S,
    PowerSystemModel,
    ResponseFunction,
    as_response,
    band_omega,
    disturbance_profile,
    evaluate,
)
from fcrlive.constants import Z95
from fcrlive.ident import FreqResp

__all__ = ["plot_bode", "plot_nyquist", "plot_performance"]


def _save(fig, path) -> Path:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(p, dpi=110)
    plt.close(fig)
    return p


DEFAULT_OMEGA = np.logspace(-3, 1, 800)
"""Where a Bode plot evaluates a response function when no ω is given [rad/s]."""


def _on_grid(fr, w: np.ndarray | None) -> tuple[FreqResp | None, np.ndarray, np.ndarray]:
    """(the FreqResp or None, ω, values): a FreqResp on its own grid (within ``w``'s range when given), a
    response function on ``w`` (default :data:`DEFAULT_OMEGA`)."""
    if isinstance(fr, FreqResp):
        if w is not None:
            fr = fr[(fr.omega >= w.min()) & (fr.omega <= w.max())]
        return fr, fr.omega, fr.value
    w = DEFAULT_OMEGA if w is None else w
    return None, w, evaluate(as_response(fr), w)


def _shade_band(ax, x_axis: str, band_s: tuple[float, float]) -> None:
    if x_axis == "period":
        lo, hi = sorted(band_s)
    else:
        lo, hi = band_omega(band_s)
    ax.axvspan(lo, hi, color="0.9", zorder=0, label="TSO band")


def plot_bode(
    path,
    responses: Sequence[tuple[str, FreqResp | ResponseFunction]],
    *,
    omega=None,
    sd: dict[str, object] | None = None,
    points: Sequence[tuple[str, Sequence[float], Sequence[complex], Sequence[float] | None]] = (),
    x_axis: str = "omega",
    band_s: tuple[float, float] = TSO_BAND_PERIODS_S,
    title: str = "",
    z: float = Z95,
) -> Path:
    """Bode plot (magnitude, phase in degrees) of labelled responses, with 95 % bands.

    responses: (label, response) pairs. A FreqResp is drawn on its own ω grid (within ``omega``'s range
    when given) with its own 95 % bands of |G| and arg G. A response function is evaluated on ``omega``
    (default 1e-3-10 rad/s); sd: label → function of the circular sd of that response, the band is
    |X| ± z·sd and arg X ± z·sd/|X| (first-order). points: (label, ω, values, sd or None) e.g. sine
    tests, drawn as markers with error bars. x_axis: "omega" [rad/s] or "period" [s].
    """
    if x_axis not in ("omega", "period"):
        raise ValueError("x_axis must be 'omega' or 'period'")
    fig, (am, ap) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    for ax in (am, ap):
        _shade_band(ax, x_axis, band_s)
    grid = None if omega is None else np.asarray(omega, float)
    for label, fr in responses:
        resp, w, v = _on_grid(fr, grid)
        x = w if x_axis == "omega" else 2 * np.pi / w
        mag, ph = np.abs(v), np.degrees(np.unwrap(np.angle(v)))
        (line,) = am.loglog(x, mag, label=label)
        ap.semilogx(x, ph, color=line.get_color())
        band = _bands(resp, w, mag, ph, (sd or {}).get(label), z)
        if band is not None:
            (m_lo, m_hi), (p_lo, p_hi) = band
            am.fill_between(x, np.maximum(m_lo, mag * 1e-3), m_hi, color=line.get_color(), alpha=0.2)
            ap.fill_between(x, p_lo, p_hi, color=line.get_color(), alpha=0.2)
    for label, pw, pv, psd in points:
        pw, pv = np.asarray(pw, float), np.asarray(pv, complex)
        px = pw if x_axis == "omega" else 2 * np.pi / pw
        e_m = None if psd is None else z * np.asarray(psd, float)
        e_p = None if psd is None else np.degrees(np.minimum(z * np.asarray(psd, float) / np.abs(pv), np.pi))
        am.errorbar(px, np.abs(pv), yerr=e_m, fmt="o", ms=4, capsize=2, label=label)
        ap.errorbar(px, np.degrees(np.angle(pv)), yerr=e_p, fmt="o", ms=4, capsize=2)
    am.set_ylabel("magnitude")
    ap.set_ylabel("phase [deg]")
    ap.set_xlabel("ω [rad/s]" if x_axis == "omega" else "period [s]")
    am.grid(True, which="both", alpha=0.3)
    ap.grid(True, which="both", alpha=0.3)
    am.legend(fontsize=8)
    if title:
        am.set_title(title)
    fig.tight_layout()
    return _save(fig, path)


def _bands(resp: FreqResp | None, w, mag, ph_deg, sd_fun, z):
    """((|X| lo, hi), (arg X lo, hi) [deg]): the 95 % bands of a FreqResp from its own sd of |G| and
    arg G, of a response function from ``sd_fun`` (circular sd); None without an uncertainty."""
    if resp is not None:
        s_abs, s_ph = resp.sd_abs, resp.sd_phase
    elif sd_fun is not None:
        s_abs = np.abs(evaluate(as_response(sd_fun), w))
        s_ph = s_abs / np.maximum(mag, 1e-300)
    else:
        return None
    dph = np.degrees(np.minimum(z * s_ph, np.pi))
    return (mag - z * s_abs, mag + z * s_abs), (ph_deg - dph, ph_deg + dph)


def plot_nyquist(
    path,
    F,
    G: PowerSystemModel = FCRN_STABILITY,
    *,
    omega_range: tuple[float, float] = (1e-4, 10.0),
    band_s: tuple[float, float] = TSO_BAND_PERIODS_S,
    points: tuple[Sequence[float], Sequence[complex]] | None = None,
    radius: float = STABILITY_RADIUS,
    title: str = "",
) -> Path:
    """Nyquist plot of F·G (ω > 0 solid, ω < 0 mirrored dotted) with −1, the 0.43 and 0.4085 circles.

    ``F``: a FreqResp (drawn on its grid within ``omega_range``) or a response function. The part inside
    the tested band is drawn thicker; ``points`` (ω, F) adds e.g. sine-test values.
    """
    _, w, Fv = _on_grid(F, np.logspace(np.log10(omega_range[0]), np.log10(omega_range[1]), 3000))
    L = Fv * G(w)
    lo, hi = band_omega(band_s)
    inb = (w >= lo) & (w <= hi)
    fig, ax = plt.subplots(figsize=(6.5, 6))
    ax.plot(L.real, L.imag, color="C0", lw=1, label="F·G")
    ax.plot(L.real, -L.imag, color="C0", lw=0.8, ls=":")
    ax.plot(
        np.where(inb, L.real, np.nan), np.where(inb, L.imag, np.nan), color="C3", lw=2.5, label="tested band"
    )
    if points is not None:
        pw, pv = np.asarray(points[0], float), np.asarray(points[1], complex)
        pL = pv * G(pw)
        ax.plot(pL.real, pL.imag, "ks", ms=4, label="points")
    th = np.linspace(0, 2 * np.pi, 400)
    for r, ls, lab in ((radius, "-", f"r = {radius:g}"), (radius * (1 - STABILITY_TOLERANCE), "--", None)):
        ax.plot(
            -1 + r * np.cos(th),
            r * np.sin(th),
            color="k",
            ls=ls,
            lw=0.8,
            label=lab or f"r = {radius * (1 - STABILITY_TOLERANCE):.4g}",
        )
    ax.plot([-1], [0], "k+", ms=12, mew=2)
    lim = 3.0
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.axhline(0, color="0.7", lw=0.5)
    ax.axvline(0, color="0.7", lw=0.5)
    ax.set_xlabel("Re")
    ax.set_ylabel("Im")
    ax.set_title(title or f"Nyquist of F·G ({G.name})")
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    return _save(fig, path)


def plot_performance(
    path,
    F,
    G: PowerSystemModel = FCRN_PERFORMANCE,
    *,
    omega_range: tuple[float, float] = (1e-4, 10.0),
    k_red_dyn: float | None = None,
    band_s: tuple[float, float] = TSO_BAND_PERIODS_S,
    margin: float = PERFORMANCE_MARGIN,
    title: str = "",
) -> Path:
    """Req. 9: K_margin·|G/(1 + F G)| against |1/D(jω)| vs ω; with F/K_red,dyn if given. ``F``: a FreqResp
    (on its grid within ``omega_range``) or a response function."""
    _, w, Fv = _on_grid(F, np.logspace(np.log10(omega_range[0]), np.log10(omega_range[1]), 2000))
    Gv = G(w)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    _shade_band(ax, "omega", band_s)
    ax.loglog(w, margin * np.abs(Gv / (1 + Fv * Gv)), label=f"{margin:g}·|G/(1+FG)|")
    if k_red_dyn is not None and 0 < k_red_dyn < 1:
        ax.loglog(
            w,
            margin * np.abs(Gv / (1 + Fv * Gv / k_red_dyn)),
            ls="--",
            label=f"F/K_red,dyn, K = {k_red_dyn:.3f}",
        )
    ax.loglog(w, np.abs(1 / disturbance_profile(w)), color="k", label="|1/D|")
    ax.set_xlabel("ω [rad/s]")
    ax.set_ylabel("magnitude [pu]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title or f"Req. 9 ({G.name})")
    fig.tight_layout()
    return _save(fig, path)
