"""The prequalification application report: one self-contained HTML file (and a PDF of it).

:func:`write_report` renders a :class:`fcrlive.prequal.model.PrequalResult` with what TR v1.1
Sections 2.3 (the application) and 5.4 (test reports) ask for:

1. the verdict and the capacity per service (K_red,ss, K_red,dyn, C = min(K)·|ΔP_ss,theo|, eqs. 3, 5);
2. the unit and governor data and the tested operating points (Section 2.3, 5.1);
3. which requirement was met by which test (Table 2);
4. every test with its time series, the requirement drawn on it, and its requirements and figures;
5. the frequency domain: the Nyquist curve of F·G with the 0.43 and 0.95·0.43 circles (Req. 8) and
   the closed loop against the disturbance profile (Req. 9);
6. the measurement-chain checks (Section 4);
7. the continuous identification between tests, from the daemon's SQLite store (``store=``);
8. the document version and the conventions used.

Self-contained: inline CSS (with print rules: A4, no page breaks inside figures and tables), inline
SVG figures (matplotlib, long series reduced to a min/max envelope), no scripts, no external files.
:func:`write_pdf` prints it with headless Chromium (``--print-to-pdf``).
"""

from __future__ import annotations

import datetime as _dt
import html
import io
import math
import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fcrlive.prequal.model import (
    Curve,
    FrequencyPoint,
    PrequalResult,
    RequirementResult,
    Series,
    TestEvaluation,
)

__all__ = ["find_chromium", "render_html", "write_pdf", "write_report"]

SERVICE_NAMES = {"Fcrn": "FCR-N", "FcrdUp": "FCR-D upwards", "FcrdDo": "FCR-D downwards"}
KIND_NAMES = {
    "fcrn-steps": "FCR-N step sequence (TR Table 3)",
    "fcrd-ramps": "FCR-D fast ramp test (TR Table 4)",
    "fcrd-static": "Static FCR-D ramp test (TR Table 5)",
    "linearity": "Linearity step sequence (TR 3.4.2)",
    "sine": "Sine test (TR Table 6)",
    "sine-set": "Sine tests together: Req. 8 and 9 (TR 3.2, 3.3)",
    "operation": "Normal operation: Req. 8 and 9 from the identification (TR Table 2, 5.4)",
}
REQUIREMENTS: tuple[tuple[str, str, str], ...] = (
    ("1", "Steady state response (1b: combination of reserves)", "3.1.1, 3.1.2, 3.1.3"),
    ("2", "Power after 7.5 s", "3.1.2, 3.1.3"),
    ("3", "Energy from 0 to 7.5 s", "3.1.2, 3.1.3"),
    ("4", "Deactivation", "3.1.2, 3.1.3"),
    ("5", "Activation of static FCR-D (5a overshoot, 5b delay)", "3.1.3"),
    ("6", "Re-activation of static FCR-D", "3.1.3"),
    ("7", "Deactivation rate of static FCR-D", "3.1.3"),
    ("8", "Frequency-domain stability", "3.2, 4.4"),
    ("9", "Frequency-domain performance", "3.3, 4.4"),
    ("10", "Dynamic linearity", "3.4.1"),
    ("11", "Linearity (non-continuous, static FCR-D)", "3.4.2"),
    ("12", "Endurance", "3.1.1, 3.1.2, 3.5"),
    ("13", "Mode shifting", "3.1.2"),
)
"""TR v1.1 Table 2: requirement number, title, section."""

_MAX_POINTS = 1600
"""Points per plotted series; longer series are drawn as their min/max envelope."""


# --------------------------------------------------------------------------------------------------
# Small formatting helpers


def _e(x: Any) -> str:
    return html.escape(str(x), quote=True)


def _num(x: float | None, digits: int = 4) -> str:
    if x is None:
        return "–"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return str(x)
    if not math.isfinite(x):
        return "–"
    if x != 0 and (abs(x) >= 1e5 or abs(x) < 1e-3):
        return f"{x:.3g}"
    return f"{x:.{digits}g}" if abs(x) < 1 else f"{x:.{max(digits - 1, 1)}f}".rstrip("0").rstrip(".")


def _limit(r: RequirementResult) -> str:
    lim = r.limit
    if lim is None:
        return "–"
    if isinstance(lim, tuple | list):
        return f"[{_num(lim[0])}, {_num(lim[1])}]"
    op = {">=": "≥", "<=": "≤", ">": ">", "<": "<", "within": "", "info": ""}.get(r.comparison, "")
    return f"{op} {_num(float(lim))}".strip()


def _status_cell(passed: bool | None, text: str | None = None) -> str:
    status = "undecided" if passed is None else ("pass" if passed else "fail")
    label = text or {"pass": "pass", "fail": "FAIL", "undecided": "undecided"}[status]
    return f'<span class="badge {status}">{_e(label)}</span>'


def _verdict_badge(status: str) -> str:
    cls = {"pass": "pass", "fail": "fail"}.get(status, "undecided")
    return f'<span class="badge big {cls}">{_e(status.upper())}</span>'


def _service(s: str) -> str:
    return SERVICE_NAMES.get(s, s)


def _anchor(ev: TestEvaluation, i: int) -> str:
    return f"test-{i}"


# --------------------------------------------------------------------------------------------------
# Figures (matplotlib, object API: no pyplot state)

_FIG_COUNT = [0]


def _figure(w_in: float, h_in: float, nrows: int = 1, sharex: bool = True, ratios=None):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w_in, h_in), layout="constrained")
    kw = {"height_ratios": ratios} if ratios else {}
    axes = fig.subplots(nrows, 1, sharex=sharex, squeeze=False, gridspec_kw=kw)[:, 0]
    for ax in axes:
        ax.grid(True, color="#d8dde3", linewidth=0.6)
        ax.tick_params(labelsize=8)
    return fig, axes


def _svg(fig, alt: str) -> str:
    import matplotlib

    _FIG_COUNT[0] += 1
    buf = io.StringIO()
    # unique ids per inline SVG (clip paths, markers) and text kept as text (selectable, small)
    with matplotlib.rc_context(
        {"svg.hashsalt": f"fcrlive-{_FIG_COUNT[0]}", "svg.fonttype": "none", "font.family": "sans-serif"}
    ):
        fig.savefig(buf, format="svg")
    text = buf.getvalue()
    start = text.find("<svg")
    svg = text[start:]
    svg = svg.replace("<svg ", f'<svg role="img" aria-label="{_e(alt)}" ', 1)
    return f'<figure class="plot">{svg}<figcaption>{_e(alt)}</figcaption></figure>'


def _reduce(t: np.ndarray, *ys: np.ndarray) -> tuple[np.ndarray, ...]:
    """Min/max envelope of long series (every bucket keeps its min and max, in time order)."""
    t = np.asarray(t, dtype=float)
    n = t.size
    if n <= _MAX_POINTS:
        return (t, *(np.asarray(y, dtype=float) for y in ys))
    k = math.ceil(n / (_MAX_POINTS // 2))
    m = n // k * k
    out_t = np.repeat(t[:m].reshape(-1, k)[:, [0, -1]].ravel(), 1)
    outs = []
    for y in ys:
        yb = np.asarray(y, dtype=float)[:m].reshape(-1, k)
        lo, hi = np.nanmin(yb, axis=1), np.nanmax(yb, axis=1)
        first_is_min = np.nanargmin(yb, axis=1) <= np.nanargmax(yb, axis=1)
        pair = np.where(first_is_min[:, None], np.stack([lo, hi], 1), np.stack([hi, lo], 1))
        outs.append(pair.ravel())
    return (out_t, *outs)


_CURVE_COLOURS = ("#c0392b", "#8e44ad", "#16a085", "#d35400", "#2c3e50", "#7f8c8d")


_NUMBERED = re.compile(r"\s*\(?(?:step|ramp|period)\s*\d+\)?", re.I)


def _draw_curves(ax, curves: Iterable[Curve]) -> None:
    """Curves and bands; curves that differ only by a step/ramp number share one colour and one
    legend entry (a linearity test has a band per step)."""
    colours: dict[str, str] = {}
    for c in curves:
        key = _NUMBERED.sub("", c.label).strip() + f"|{c.requirement}"
        first = key not in colours
        col = colours.setdefault(key, _CURVE_COLOURS[len(colours) % len(_CURVE_COLOURS)])
        base = _NUMBERED.sub("", c.label).strip() or c.label
        label = (f"{base} (Req. {c.requirement})" if c.requirement else base) if first else "_nolegend_"
        t = np.asarray(c.t_s, dtype=float)
        if c.lower is not None and c.upper is not None:
            tt, lo, hi = _reduce(t, c.lower, c.upper)
            ax.fill_between(tt, lo, hi, color=col, alpha=0.15, linewidth=0, label=label)
            if c.value is not None and np.any(np.isfinite(c.value)):
                tt, v = _reduce(t, c.value)
                ax.plot(tt, v, color=col, linewidth=0.9, linestyle="--")
        elif c.value is not None:
            tt, v = _reduce(t, c.value)
            ax.plot(tt, v, color=col, linewidth=1.1, linestyle="--", label=label)


def _draw_series(axf, axp, axe, s: Series, legend: bool = True) -> None:
    t, f, p = _reduce(s.t_s, s.applied_freq_hz, s.power_mw)
    axf.plot(t, f, color="#1f5fa8", linewidth=0.9, label="applied frequency")
    _draw_curves(axf, [c for c in s.curves if c.axis == "frequency"])
    axf.set_ylabel("f [Hz]", fontsize=8)
    axp.plot(t, p, color="#222", linewidth=0.7, label="active power")
    if math.isfinite(s.power_baseline_mw):
        axp.axhline(
            s.power_baseline_mw, color="#888", linewidth=0.8, linestyle=":", label="P before activation"
        )
    _draw_curves(axp, [c for c in s.curves if c.axis == "power"])
    axp.set_ylabel("P [MW]", fontsize=8)
    if axe is not None:
        _draw_curves(axe, [c for c in s.curves if c.axis == "energy"])
        axe.set_ylabel("E [MW·s]", fontsize=8)
    for m in s.markers:
        ax = {"frequency": axf, "power": axp}.get(m.axis, axe if axe is not None else axp)
        ax.plot([m.t_s], [m.value], marker="o", markersize=5, color="#e67e22", linestyle="none")
        ax.annotate(
            m.label, (m.t_s, m.value), textcoords="offset points", xytext=(4, 4), fontsize=7, color="#a04000"
        )
    if legend:
        for ax in (axf, axp, axe):
            if ax is not None and ax.get_legend_handles_labels()[1]:
                # outside, right of the axes: it never hides the response
                ax.legend(fontsize=6.5, loc="upper left", bbox_to_anchor=(1.005, 1.0), frameon=False)


def _series_figure(ev: TestEvaluation, compact: bool = False) -> str | None:
    s: Series | None = ev.series
    if s is None or len(s.t_s) < 2:
        return None
    energy = any(c.axis == "energy" for c in s.curves)
    n = 3 if energy else 2
    w, h = (7.6, 2.8) if compact else (7.6, 1.6 + 1.5 * n)
    fig, axes = _figure(w, h, n, ratios=[1, 2, 1.4][:n])
    _draw_series(axes[0], axes[1], axes[2] if energy else None, s)
    axes[-1].set_xlabel("time from the start of the file [s]", fontsize=8)
    what = KIND_NAMES.get(ev.kind, ev.kind)
    period = ev.figures.get("period_s")
    title = f"{ev.test_id} {_service(ev.service)}: {what}" + (f", T = {period:g} s" if period else "")
    return _svg(fig, title)


def _zoom_windows(ev: TestEvaluation) -> list[tuple[str, float, float]]:
    """Where the FCR-D requirements are read: ramp 1 (Req. 4; static: Req. 2, 3, 5) and ramp 5 (Req. 2, 3)."""
    out = []
    t1, t5 = ev.figures.get("t_ramp1_s"), ev.figures.get("t_ramp5_s")
    if ev.kind == "fcrd-ramps":
        if t1 is not None and math.isfinite(t1):
            out.append(("ramps 1-2: deactivation (Req. 4)", t1 - 5.0, t1 + 50.0))
        if t5 is not None and math.isfinite(t5):
            out.append(("ramp 5: activation (Req. 2, 3)", t5 - 5.0, t5 + 55.0))
    elif ev.kind == "fcrd-static" and t1 is not None and math.isfinite(t1):
        out.append(("ramp 1: activation (Req. 2, 3, 5)", t1 - 5.0, t1 + 60.0))
        t2 = ev.figures.get("t_ramp2_s")
        if t2 is not None and math.isfinite(t2):
            out.append(("ramp 2: deactivation (Req. 7)", t2 - 10.0, t2 + 110.0))
    return out


def _ylim(ax, lo_x: float, hi_x: float) -> None:
    ys = []
    for line in ax.get_lines():
        x, y = (np.asarray(v, dtype=float) for v in line.get_data())
        if x.size == y.size and x.size:
            sel = (x >= lo_x) & (x <= hi_x) & np.isfinite(y)
            if x.size == 2 and x[0] == 0 and x[1] == 1:  # axhline (axes coordinates in x)
                ys.extend(y[np.isfinite(y)])
            elif sel.any():
                ys.extend(y[sel])
    if ys:
        lo, hi = float(np.min(ys)), float(np.max(ys))
        pad = 0.06 * (hi - lo) if hi > lo else max(abs(hi) * 0.01, 0.1)
        ax.set_ylim(lo - pad, hi + pad)


def _zoom_figure(ev: TestEvaluation) -> str | None:
    s = ev.series
    wins = _zoom_windows(ev)
    if s is None or not wins:
        return None
    from matplotlib.figure import Figure

    energy = any(c.axis == "energy" for c in s.curves)
    n = 3 if energy else 2
    fig = Figure(figsize=(7.6, 1.3 + 1.4 * n), layout="constrained")
    grid = fig.subplots(
        n, len(wins), sharex="col", squeeze=False, gridspec_kw={"height_ratios": [1, 2, 1.4][:n]}
    )
    for j, (label, lo, hi) in enumerate(wins):
        col = grid[:, j]
        for ax in col:
            ax.grid(True, color="#d8dde3", linewidth=0.6)
            ax.tick_params(labelsize=7)
        _draw_series(col[0], col[1], col[2] if energy else None, s, legend=False)
        for ax in col:
            ax.set_xlim(lo, hi)
            _ylim(ax, lo, hi)
        col[0].set_title(label, fontsize=8)
        col[-1].set_xlabel("time [s]", fontsize=8)
    return _svg(
        fig, f"{ev.test_id} {_service(ev.service)}: where Req. 2, 3 and 4 are read (zoom; legend above)"
    )


def _stability_model(service: str):
    from fcrlive.analysis import tso_checks as tc

    return tc.FCRN_STABILITY if service == "Fcrn" else tc.FCRD_STABILITY


def _performance_model(service: str):
    from fcrlive.analysis import tso_checks as tc

    return tc.FCRN_PERFORMANCE if service == "Fcrn" else tc.FCRD_PERFORMANCE


def _points(ev: TestEvaluation) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    pts: Sequence[FrequencyPoint] = sorted(ev.points, key=lambda q: -q.period_s)  # low ω first
    T = np.array([q.period_s for q in pts], dtype=float)
    F = np.array([q.F for q in pts], dtype=complex)
    sd = np.array([q.F_sd for q in pts], dtype=float)
    return T, F, sd


def _nyquist_figure(ev: TestEvaluation, exemption: bool) -> str | None:
    from fcrlive.analysis import tso_checks as tc

    T, F, sd = _points(ev)
    if T.size == 0:
        return None
    w = 2 * np.pi / T
    G = _stability_model(ev.service)(w)
    L = F * G
    fig, (ax,) = _figure(5.6, 5.0, 1)
    th = np.linspace(0, 2 * np.pi, 361)
    circles = [
        (tc.STABILITY_RADIUS, "0.43 (Req. 8)", "#c0392b", "-"),
        (tc.STABILITY_RADIUS * (1 - tc.STABILITY_TOLERANCE), "0.95·0.43 (accepted margin)", "#e67e22", "--"),
    ]
    if exemption and ev.service == "Fcrn":
        circles.append(
            (tc.STABILITY_RADIUS * tc.FCRN_EXEMPTION_FACTOR, "0.75·0.43 (FCR-N exemption)", "#7f8c8d", ":")
        )
    for r, label, col, ls in circles:
        ax.plot(-1 + r * np.cos(th), r * np.sin(th), color=col, linestyle=ls, linewidth=1.2, label=label)
    ax.plot([-1], [0], marker="+", color="#c0392b", markersize=9, linestyle="none")
    ax.plot(
        L.real,
        L.imag,
        color="#1f5fa8",
        linewidth=1.0,
        marker="o",
        markersize=3.5,
        label="F(jω)·G(jω), measured periods (joined linearly)",
    )
    if np.any(np.isfinite(sd)):
        err = np.abs(G) * np.where(np.isfinite(sd), sd, 0.0)
        for x, y, e in zip(L.real, L.imag, err):
            if e > 0:
                ax.add_patch(_circle_patch(x, y, 1.96 * e))
    for x, y, t in zip(L.real, L.imag, T):
        ax.annotate(
            f"{t:g} s", (x, y), textcoords="offset points", xytext=(4, -8), fontsize=6.5, color="#1f5fa8"
        )
    # The view that matters is around −1; points far from it are listed instead of squeezing the view.
    x0, x1, y0, y1 = -2.2, 1.2, -2.4, 1.0
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal", adjustable="box")
    out = [f"{t:g} s" for t, z in zip(T, L) if not (x0 <= z.real <= x1 and y0 <= z.imag <= y1)]
    if out:
        ax.text(
            0.02,
            0.02,
            "outside the view: " + ", ".join(out),
            transform=ax.transAxes,
            fontsize=6.5,
            color="#1f5fa8",
            va="bottom",
        )
    ax.set_xlabel("Re", fontsize=8)
    ax.set_ylabel("Im", fontsize=8)
    ax.legend(fontsize=7, loc="lower right")
    return _svg(
        fig,
        f"Nyquist curve of F·G, {_service(ev.service)} stability model (TR eq. 10-11, Table 7), {ev.test_id}",
    )


def _circle_patch(x: float, y: float, r: float):
    from matplotlib.patches import Circle

    return Circle((x, y), r, fill=False, edgecolor="#1f5fa8", linewidth=0.5, alpha=0.6)


def _req9_figure(ev: TestEvaluation, k_red_dyn: float | None) -> str | None:
    from fcrlive.analysis import tso_checks as tc

    T, F, _ = _points(ev)
    if T.size == 0:
        return None
    w = 2 * np.pi / T
    Gp = _performance_model(ev.service)(w)
    Gc = tc.PERFORMANCE_MARGIN * np.abs(Gp / (1 + F * Gp))
    lim = 1.0 / np.abs(tc.disturbance_profile(w))
    fig, (ax,) = _figure(5.6, 3.4, 1)
    ax.loglog(T, lim, color="#c0392b", linewidth=1.2, label="|1/D(jω)|, D = 1/(70 s + 1) (requirement)")
    ax.loglog(
        T,
        Gc,
        color="#1f5fa8",
        marker="o",
        markersize=3.5,
        linewidth=1.0,
        label="0.95·|G/(1 + F G)| (measured F)",
    )
    if k_red_dyn is not None and 0 < k_red_dyn < 1:
        Gk = tc.PERFORMANCE_MARGIN * np.abs(Gp / (1 + F / k_red_dyn * Gp))
        ax.loglog(
            T,
            Gk,
            color="#16a085",
            marker="s",
            markersize=3,
            linewidth=0.9,
            linestyle="--",
            label=f"with K_red,dyn = {k_red_dyn:.3f}",
        )
    ax.set_xlabel("period T [s]", fontsize=8)
    ax.set_ylabel("gain [pu]", fontsize=8)
    ax.legend(fontsize=7, loc="best")
    return _svg(
        fig,
        f"Req. 9: closed loop against the disturbance profile, {_service(ev.service)} "
        f"performance model, {ev.test_id}",
    )


# --------------------------------------------------------------------------------------------------
# Tables


def _req_table(reqs: Mapping[str, RequirementResult], caption: str = "") -> str:
    if not reqs:
        return ""
    rows = []
    for key, r in reqs.items():
        interval = ""
        if r.value_interval is not None:
            interval = f' <span class="ci">[{_num(r.value_interval[0])}, {_num(r.value_interval[1])}]</span>'
        kred = "" if r.k_red is None else _num(r.k_red)
        rows.append(
            f"<tr><td>{_e(key)}</td><td>{_e(r.title)}</td><td class='n'>{_num(r.value)}{interval}</td>"
            f"<td class='n'>{_e(_limit(r))}</td><td>{_e(r.unit)}</td><td class='n'>{_e(kred)}</td>"
            f"<td>{_status_cell(r.passed)}</td><td class='note'>{_e(r.note)}</td></tr>"
        )
    cap = f"<caption>{_e(caption)}</caption>" if caption else ""
    return (
        f'<table class="req">{cap}<thead><tr><th>Req.</th><th>requirement</th><th>value</th><th>limit</th>'
        "<th>unit</th><th>K_red</th><th>status</th><th>note</th></tr></thead><tbody>"
        + "".join(rows)
        + "</tbody></table>"
    )


_FIGURE_NAMES = {
    "dp_ss_mw": ("ΔP_ss measured", "MW"),
    "dp_ss_theo_mw": ("|ΔP_ss,theo|", "MW"),
    "dp_7p5s_mw": ("ΔP 7.5 s after ramp 5", "MW"),
    "e_7p5s_mws": ("E_7.5s", "MW·s"),
    "deactivation_mws": ("deactivation energy (Req. 4)", "MW·s"),
    "k_red_ss": ("K_red,ss", ""),
    "k_red_dyn": ("K_red,dyn", ""),
    "period_s": ("period", "s"),
}


def _figures_table(figs: Mapping[str, float]) -> str:
    if not figs:
        return ""
    cells = []
    for k, v in figs.items():
        name, unit = _FIGURE_NAMES.get(k, (k, ""))
        cells.append(
            f"<tr><td>{_e(name)}</td><td class='n'>{_num(v, 5)}</td><td>{_e(unit)}</td>"
            f"<td class='key'>{_e(k)}</td></tr>"
        )
    return (
        '<table class="figs"><thead><tr><th>figure</th><th>value</th><th>unit</th><th>key</th></tr>'
        "</thead><tbody>" + "".join(cells) + "</tbody></table>"
    )


def _unit_section(result: PrequalResult) -> str:
    u = result.unit
    if u is None:
        return (
            '<section id="unit"><h2>1. Unit and governor</h2><p class="warn">No unit description '
            "(<code>[unit.prequal]</code>) was given: ΔP_ss,theo, the operating points and the governor "
            "data are unknown, and the requirements that need them are undecided.</p></section>"
        )
    rows = [
        ("Resource", u.resource),
        ("Bidding area", u.area),
        ("Unit", result.unit_name or "–"),
        ("Rated power", f"{_num(u.rated_mw)} MW"),
        ("Minimum power", f"{_num(u.p_min_mw)} MW"),
        ("Maximum power", f"{_num(u.p_max_mw)} MW"),
        ("Nominal frequency", f"{_num(u.f0_hz)} Hz"),
        ("Inertia constant H (rated power base)", f"{_num(u.H)} s"),
        ("Speed damping Kd", f"{_num(u.Kd)} pu/pu"),
        ("Services applied for", ", ".join(_service(s) for s in u.services)),
        ("FCR-D type", u.fcrd),
        ("Mode shifting", "yes" if u.mode_shifting else "no"),
        ("FCR-N stability exemption (75 %)", "requested" if u.fcrn_exemption else "no"),
        ("Single set point / single droop (TR 5.1)",
         f"{'yes' if u.single_setpoint else 'no'} / {'yes' if u.single_droop else 'no'}"),
        (
            "Steady-state response method (TR App. 1)",
            "droop: ΔP_ss,theo = Δf/(f0·e_p)·P_rated (example 1)"
            if u.dp_ss_method == "droop"
            else "table of values per operating point",
        ),
        (
            "Frequency measurement T_FME (TR 4.4)",
            f"{_num(u.t_fme_s)} s (test signal generated after the measurement)"
            if u.t_fme_s
            else "external test signal (F_FME not applied)",
        ),
        (
            "Stated power accuracy",
            f"{_num(u.power_accuracy_pct)} %" if u.power_accuracy_pct else "not stated",
        ),
        (
            "Stated frequency accuracy",
            f"{_num(u.frequency_accuracy_mhz)} mHz" if u.frequency_accuracy_mhz else "not stated",
        ),
        ("Governor type", u.governor_type or "not stated"),
        ("Governor settings", ", ".join(f"{k} = {v}" for k, v in u.governor_settings) or "not stated"),
    ]
    body = "".join(f"<tr><th scope='row'>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in rows)
    pts = []
    for p in u.points:
        dp = ", ".join(f"{_service(s)} {_num(v)} MW" for s, v in p.dp_ss_theo_mw.items())
        pts.append(
            f"<tr><td>{_e(p.name)}</td><td class='n'>{_num(p.power_mw)}</td>"
            f"<td class='n'>{_num(p.droop)}</td><td class='n'>{_num(p.droop_fcrd)}</td>"
            f"<td>{_e(dp)}</td><td>{_e(', '.join(p.test_ids))}</td></tr>"
        )
    points = (
        (
            '<table class="points"><caption>Tested operating points (TR 5.1, Appendix 2 Table 21)</caption>'
            "<thead><tr><th>point</th><th>set point [MW]</th><th>droop e_p FCR-N [pu]</th>"
            "<th>droop FCR-D [pu]</th><th>|ΔP_ss,theo| (full activation)</th><th>test IDs</th></tr></thead>"
            "<tbody>" + "".join(pts) + "</tbody></table>"
        )
        if pts
        else '<p class="warn">No operating points described.</p>'
    )
    return (
        '<section id="unit"><h2>1. Unit and governor (TR 2.3)</h2>'
        f'<table class="kv"><tbody>{body}</tbody></table>{points}</section>'
    )


def _link_files(text: str, files: dict[str, tuple[str, str]]) -> str:
    """Escaped ``text`` with the file names in it replaced by links to their tests."""
    out = _e(text)
    for name, (anchor, label) in files.items():
        esc = _e(name)
        if esc in out:
            out = out.replace(esc, f'<a href="#{anchor}">{_e(label)}</a>')
    return out


def _file_links(result: PrequalResult, anchors: dict[int, str]) -> dict[str, tuple[str, str]]:
    files: dict[str, tuple[str, str]] = {}
    for ev in result.tests:
        label = _test_label(ev)
        for f in ev.files or (ev.file,):
            files.setdefault(f, (anchors[id(ev)], label))
        files.setdefault(ev.file, (anchors[id(ev)], label))
    # longest first: a sine set's joined names contain the single files' names
    return dict(sorted(files.items(), key=lambda kv: -len(kv[0])))


def _test_label(ev: TestEvaluation) -> str:
    if ev.kind == "sine":
        return f"{ev.test_id} {ev.figures.get('period_s', 0):g} s"
    if ev.kind == "sine-set":
        return f"{ev.test_id} sines"
    if ev.kind == "fcrd-static":
        return f"{ev.test_id} static"
    return ev.test_id


_FAILED = re.compile(
    r"^Req\. (?P<num>\S+) (?P<title>[^:]*?)(?: at [^:]*| \(step \d+\))*: (?P<rest>.*) \((?P<where>[^()]*)\)$"
)


def _group_failures(items: Sequence[str]) -> list[str]:
    """Failures of one requirement in one file (a linearity test's steps) as one line: how many, and
    the worst one when the evaluation names it."""
    groups: dict[tuple[str, str], list[str]] = {}
    order: list[tuple[str, str] | str] = []
    for x in items:
        m = _FAILED.match(x)
        if m is None:
            order.append(x)
            continue
        key = (m.group("num"), m.group("where"))
        if key not in groups:
            order.append(key)
        groups.setdefault(key, []).append(x)
    out = []
    for k in order:
        if isinstance(k, str):
            out.append(k)
            continue
        g = groups[k]
        if len(g) <= 2:
            out.extend(g)
            continue
        worst = next((x for x in g if "worst" in x), g[0])
        m = _FAILED.match(worst)
        n_steps = sum("worst" not in x for x in g)
        title = m.group("title").replace(", all steps (the worst)", "") if m else ""
        out.append(
            f"Req. {k[0]} {title}: {n_steps} not met; the worst {m.group('rest') if m else ''} ({k[1]})"
        )
    return out


def _summary_section(result: PrequalResult, anchors: dict[int, str]) -> str:
    files = _file_links(result, anchors)
    rows, findings = [], []
    for s, v in result.verdict.items():
        c = result.capacity.get(s)
        cap = "–" if c is None or c.capacity_mw is None else f"{_num(c.capacity_mw)} MW"
        rows.append(
            f"<tr><td>{_e(_service(s))}</td><td>{_verdict_badge(v.status)}</td>"
            f"<td class='n'>{_num(c.k_red_ss if c else None)}</td>"
            f"<td class='n'>{_num(c.k_red_dyn if c else None)}</td>"
            f"<td class='n'>{_num(c.k_min if c else None)}</td>"
            f"<td class='n'>{_num(c.dp_ss_theo_mw if c else None)}</td><td class='n'><b>{_e(cap)}</b></td>"
            f"<td class='n'>{len(v.failed)}</td><td class='n'>{len(v.missing)}</td></tr>"
        )
        items = []
        if v.failed:
            items.append(
                "<p><b>Not met</b></p><ul>"
                + "".join(f"<li>{_link_files(x, files)}</li>" for x in _group_failures(v.failed))
                + "</ul>"
            )
        if v.missing:
            items.append(
                "<p><b>Missing</b></p><ul>" + "".join(f"<li>{_e(x)}</li>" for x in v.missing) + "</ul>"
            )
        if c is not None and c.note:
            items.append(f'<p class="note">Capacity: {_e(c.note)}</p>')
        if items:
            findings.append(
                f'<div class="finding"><h3>{_e(_service(s))} {_verdict_badge(v.status)}</h3>'
                + "".join(items)
                + "</div>"
            )
    table = (
        '<table class="summary"><caption>Capacity per service: C = min(K_red,ss, K_red,dyn)·|ΔP_ss,theo| '
        "(TR eqs. 3 and 5; one reduction factor for all operating points)</caption><thead><tr>"
        "<th>service</th><th>verdict</th><th>K_red,ss</th><th>K_red,dyn</th><th>K min</th>"
        "<th>|ΔP_ss,theo| [MW]</th><th>capacity</th><th>not met</th><th>missing</th></tr></thead><tbody>"
        + "".join(rows)
        + "</tbody></table>"
    )
    return f'<section id="summary"><h2 class="first">Summary</h2>{table}{"".join(findings)}</section>'


def _coverage_section(result: PrequalResult, anchors: dict[int, str]) -> str:
    services = list(result.verdict) or ["Fcrn", "FcrdUp", "FcrdDo"]
    head = "".join(f"<th>{_e(_service(s))}</th>" for s in services)
    rows = []
    for num, title, section in REQUIREMENTS:
        cells = []
        for s in services:
            found: dict[str, tuple[bool | None, str]] = {}  # anchor -> (worst status, label)
            sines: list[bool | None] = []
            for ev in result.tests:
                if ev.service != s:
                    continue
                for key, r in ev.requirements.items():
                    base = key.split("-")[0]
                    if not (
                        base == num or (num == "1" and base == "1b") or (num == "5" and base in ("5a", "5b"))
                    ):
                        continue
                    if ev.kind == "sine":
                        sines.append(r.passed)
                        continue
                    a = anchors[id(ev)]
                    old = found.get(a, (True, ""))[0]
                    worst = False if False in (old, r.passed) else (None if None in (old, r.passed) else True)
                    found[a] = (worst, _test_label(ev))
            links = [f'<a href="#{a}">{_e(label)}</a>' for a, (_, label) in found.items()]
            states = [p for p, _ in found.values()] + sines
            if sines:
                first = next(anchors[id(e)] for e in result.tests if e.kind == "sine" and e.service == s)
                links.append(
                    f'<a href="#{first}">{len(sines)} sine period{"s" if len(sines) > 1 else ""}</a>'
                )
            if not states:
                cells.append('<td class="none">not tested</td>')
                continue
            worst = False if False in states else (None if None in states else True)
            cells.append(f"<td>{_status_cell(worst)} <span class='tests'>{', '.join(links)}</span></td>")
        rows.append(f"<tr><td>{num}</td><td>{_e(title)}</td><td>{_e(section)}</td>{''.join(cells)}</tr>")
    return (
        '<section id="coverage"><h2>2. Requirements and the tests that cover them (TR Table 2)</h2>'
        "<p>The worst status over the tests of a service; for FCR-D, one direction's sine tests may stand "
        "for both when the parameters are the same (TR Table 2, *).</p>"
        '<table class="coverage"><thead><tr><th>Req.</th><th>requirement</th><th>TR section</th>'
        f"{head}</tr></thead><tbody>{''.join(rows)}</tbody></table></section>"
    )


def _test_block(ev: TestEvaluation, anchor: str, result: PrequalResult) -> str:
    parts = [f'<article class="test" id="{anchor}">']
    status = ev.passed
    period = ev.figures.get("period_s")
    title = f"{ev.test_id} · {_service(ev.service)} · {KIND_NAMES.get(ev.kind, ev.kind)}"
    if ev.kind == "sine" and period:
        title += f" · T = {period:g} s"
    parts.append(f"<h3>{_e(title)} {_status_cell(status)}</h3>")
    meta = []
    if ev.operating_point:
        meta.append(f"operating point: {_e(ev.operating_point)}")
    files = ev.files or (ev.file,)
    meta.append(
        "file" + ("s" if len(files) > 1 else "") + ": " + ", ".join(f"<code>{_e(f)}</code>" for f in files)
    )
    parts.append('<p class="meta">' + "<br>".join(meta) + "</p>")
    fig = _series_figure(ev, compact=ev.kind == "sine")
    if fig:
        parts.append(fig)
    zoom = _zoom_figure(ev) if ev.kind in ("fcrd-ramps", "fcrd-static") else None
    if zoom:
        parts.append(zoom)
    if ev.kind in ("sine-set", "operation") and ev.points:
        u = result.unit
        nyq = _nyquist_figure(ev, bool(u and u.fcrn_exemption))
        r9req = ev.requirements.get("9")
        k9 = ev.figures.get("k_red_dyn") if r9req is not None and r9req.passed is False else None
        r9 = _req9_figure(ev, k9)
        parts.append('<div class="pair">' + (nyq or "") + (r9 or "") + "</div>")
        parts.append(_points_table(ev))
    parts.append(_req_table(ev.requirements))
    parts.append(_figures_table(ev.figures))
    if ev.checks:
        parts.append(_req_table(ev.checks, "Measurement chain (TR Section 4)"))
    if ev.notes:
        parts.append('<ul class="notes">' + "".join(f"<li>{_e(n)}</li>" for n in ev.notes) + "</ul>")
    parts.append("</article>")
    return "".join(p for p in parts if p)


def _points_table(ev: TestEvaluation) -> str:
    T, F, sd = _points(ev)
    rows = []
    for t, f, s, q in zip(T, F, sd, sorted(ev.points, key=lambda q: -q.period_s)):
        lin = "" if not math.isfinite(q.linearity) else _num(q.linearity, 3)
        rows.append(
            f"<tr><td class='n'>{t:g}</td><td class='n'>{abs(f):.4f}</td>"
            f"<td class='n'>{math.degrees(np.angle(f)):.1f}</td><td class='n'>{_num(float(s), 3)}</td>"
            f"<td class='n'>{lin}</td></tr>"
        )
    return (
        '<table class="points"><caption>F(jω), the normalised FCR response (TR eqs. 7-9)</caption><thead><tr>'
        "<th>period [s]</th><th>|F|</th><th>arg F [°]</th><th>sd of F</th><th>Req. 10 ratio</th></tr></thead>"
        "<tbody>" + "".join(rows) + "</tbody></table>"
    )


def _checks_section(result: PrequalResult, anchors: dict[int, str]) -> str:
    rows = []
    for ev in result.tests:
        for key, r in ev.checks.items():
            rows.append(
                f"<tr><td><a href='#{anchors[id(ev)]}'>{_e(ev.test_id)}</a></td><td>{_e(r.title or key)}</td>"
                f"<td class='n'>{_num(r.value)}</td><td class='n'>{_e(_limit(r))}</td><td>{_e(r.unit)}</td>"
                f"<td>{_status_cell(r.passed)}</td><td class='note'>{_e(r.note)}</td></tr>"
            )
    for key, r in result.checks.items():
        rows.append(
            f"<tr><td>application</td><td>{_e(r.title or key)}</td><td class='n'>{_num(r.value)}</td>"
            f"<td class='n'>{_e(_limit(r))}</td><td>{_e(r.unit)}</td><td>{_status_cell(r.passed)}</td>"
            f"<td class='note'>{_e(r.note)}</td></tr>"
        )
    if not rows:
        body = "<p>No measurement-chain checks were made.</p>"
    else:
        body = (
            '<table class="checks"><thead><tr><th>test</th><th>check</th><th>value</th><th>limit</th>'
            "<th>unit</th><th>status</th><th>note</th></tr></thead><tbody>"
            + "".join(rows)
            + "</tbody></table>"
        )
    return (
        '<section id="measurement"><h2>5. Measurement chain (TR Section 4)</h2>'
        "<p>Sampling rate (TR 4.3: ≥ 5 Hz FCR-N tests, ≥ 10 Hz FCR-D tests, ≥ 1 Hz operation) and resolution "
        "(TR 4.2: 0.01 MW, 5 mHz) from the data themselves; accuracy (TR 4.1, Table 15) as stated in the "
        "unit "
        f"description.</p>{body}</section>"
    )


# --------------------------------------------------------------------------------------------------
# Continuous identification (the daemon's store)


def _history(store: str | os.PathLike) -> list[dict[str, Any]]:
    """The stored identification results, oldest first: t, window, method, droop [%] with std, peaks,
    TSO verdicts, result quality."""
    import sqlite3

    from pydantic import ValidationError

    from fcrlive.analysis.report import IdentifyReport
    from fcrlive.daemon.payloads import headline_scalars
    from fcrlive.daemon.store import connect, read_results
    from fcrlive.errors import DataError

    path = Path(store)
    if not path.is_file():
        raise DataError("no such store", where=str(path))
    try:
        con = connect(path, readonly=True)
        try:
            rows = read_results(con, limit=100_000)
        finally:
            con.close()
    except sqlite3.Error as exc:
        raise DataError(f"cannot read the store's results: {exc}", where=str(path)) from None
    out = []
    for r in reversed(rows):
        error = r.error
        rep = None
        if r.result is not None:
            # the daemon stores IdentifyReport.to_json_dict(); a result it cannot read back (another
            # schema version) is listed with why, not guessed at
            try:
                rep = IdentifyReport.model_validate(r.result)
            except ValidationError as exc:
                error = f"stored result not readable: {exc.error_count()} field(s) do not match the report"
        sc = headline_scalars(rep, r.t, r.t2) if rep is not None else {}
        tso = {k: v.passed for k, v in (rep.tso or {}).items()} if rep is not None else {}
        out.append(
            {
                "t": r.t,
                "t1": r.t1,
                "t2": r.t2,
                "method": r.method or "",
                "error": error,
                "droop": sc.get("droop"),
                "max_abs_s": sc.get("max_abs_s"),
                "max_abs_g1": sc.get("max_abs_g1"),
                "tso": tso,
                "quality": (r.result_quality or {}).get("level", ""),
            }
        )
    return out


def _or_nan(x: float | None) -> float:
    return float("nan") if x is None else float(x)


def _utc(t: float) -> str:
    return _dt.datetime.fromtimestamp(t, _dt.UTC).strftime("%Y-%m-%d %H:%M")


def _history_section(store: str | os.PathLike | None, hist: list[dict[str, Any]] | None) -> str:
    head = '<section id="history"><h2>6. Continuous identification between the tests</h2>'
    if store is None or hist is None:
        return (
            head + "<p>No daemon store was given (<code>--store</code>): the identification from normal "
            "operation between the tests is not part of this report.</p></section>"
        )
    if not hist:
        return head + f"<p>The store <code>{_e(store)}</code> holds no identification results.</p></section>"
    ok = [h for h in hist if h["droop"] is not None and h["droop"].value is not None]
    parts = [
        head,
        f"<p>{len(hist)} identification runs from <code>{_e(Path(store).name)}</code>, "
        f"{_utc(hist[0]['t1'])} to {_utc(hist[-1]['t2'])} UTC; {len(ok)} with a droop estimate. "
        "Droop with its 95 % interval at the end of each window; rejected results "
        "(the daemon's result-quality rule) are drawn hollow.</p>",
    ]
    if ok:
        fig, axes = _figure(7.6, 4.6, 2)
        t = np.array([(h["t2"] - ok[0]["t2"]) / 3600.0 for h in ok])
        d = np.array([h["droop"].value for h in ok])
        lo = np.array([_or_nan(h["droop"].ci95[0]) for h in ok])
        hi = np.array([_or_nan(h["droop"].ci95[1]) for h in ok])
        rej = np.array([h["quality"] == "rejected" for h in ok])
        # the interval is not symmetric in general (the droop's); an unknown end draws no bar
        yerr = np.nan_to_num(np.vstack([d - lo, hi - d]))
        axes[0].errorbar(t, d, yerr=yerr, fmt="none", ecolor="#9bb7d4", elinewidth=0.8)
        axes[0].plot(t[~rej], d[~rej], "o", color="#1f5fa8", markersize=3.5, label="droop")
        if rej.any():
            axes[0].plot(t[rej], d[rej], "o", mfc="none", color="#c0392b", markersize=4, label="rejected")
        axes[0].set_ylabel("droop [%]", fontsize=8)
        axes[0].legend(fontsize=7)
        for key, label, col in (("max_abs_s", "max|S|", "#8e44ad"), ("max_abs_g1", "max|G_1|", "#16a085")):
            v = np.array(
                [h[key].value if h[key] is not None and h[key].value is not None else np.nan for h in ok]
            )
            if np.any(np.isfinite(v)):
                axes[1].plot(t, v, "o-", color=col, markersize=3, linewidth=0.7, label=label)
        axes[1].set_ylabel("peak gain [pu]", fontsize=8)
        axes[1].set_xlabel(f"hours after {_utc(ok[0]['t2'])} UTC", fontsize=8)
        if axes[1].get_legend_handles_labels()[1]:
            axes[1].legend(fontsize=7)
        parts.append(_svg(fig, "Continuous identification from normal operation (daemon store)"))
    rows = []
    for h in hist[-30:][::-1]:
        d = h["droop"]
        if d is None or d.value is None:
            ds = "–"
        elif d.ci95[0] is None or d.ci95[1] is None:
            ds = f"{d.value:.2f} (interval unknown)"
        else:
            ds = f"{d.value:.2f} [{d.ci95[0]:.2f}, {d.ci95[1]:.2f}]"
        tso = ", ".join(f"{k}: {'pass' if v else 'fail' if v is False else '?'}" for k, v in h["tso"].items())
        s = h["max_abs_s"]
        rows.append(
            f"<tr><td>{_utc(h['t1'])} – {_utc(h['t2'])[11:]}</td><td>{_e(h['method'])}</td>"
            f"<td class='n'>{_e(ds)}</td>"
            f"<td class='n'>{_num(s.value if s else None)}</td><td>{_e(tso)}</td><td>{_e(h['quality'])}</td>"
            f"<td class='note'>{_e(h['error'] or '')}</td></tr>"
        )
    parts.append(
        '<table class="history"><caption>The latest runs (newest first, at most 30)</caption><thead><tr>'
        "<th>window (UTC)</th><th>method</th><th>droop [%] (95 %)</th><th>max|S|</th><th>TSO checks</th>"
        "<th>result quality</th><th>error</th></tr></thead><tbody>" + "".join(rows) + "</tbody></table>"
    )
    parts.append("</section>")
    return "".join(parts)


# --------------------------------------------------------------------------------------------------
# The page

_CSS = """
:root{--ink:#1d232a;--muted:#5b6670;--line:#d8dde3;--pass:#1e7d45;--fail:#b3261e;--und:#9a6700;--acc:#1f5fa8}
*{box-sizing:border-box}
body{font:15px/1.5 system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;color:var(--ink);
 margin:0;background:#f4f6f8}
main{max-width:1080px;margin:0 auto;padding:24px 32px 64px;background:#fff}
header.top{border-bottom:3px solid var(--acc);margin-bottom:16px;padding-bottom:8px}
h1{font-size:1.7em;margin:.2em 0}h2{font-size:1.3em;margin-top:2em;border-bottom:1px solid var(--line);
 padding-bottom:.2em}h3{font-size:1.05em;margin:1.6em 0 .4em}
.sub{color:var(--muted);margin:0}
nav.toc{background:#f4f6f8;border:1px solid var(--line);padding:8px 16px;border-radius:6px}
nav.toc ol{margin:.3em 0;padding-left:1.4em}nav.toc a{color:var(--acc);text-decoration:none}
table{border-collapse:collapse;width:100%;margin:.6em 0 1em;font-size:.86em}
caption{caption-side:top;text-align:left;font-weight:600;color:var(--muted);padding:.2em 0}
th,td{border-bottom:1px solid var(--line);padding:.25em .5em;text-align:left;vertical-align:top}
thead th{background:#eef1f4;font-weight:600;white-space:nowrap}
tbody tr:nth-child(even){background:#fafbfc}
td.n{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
td.note,.note{color:var(--muted);font-size:.95em}td.key{color:var(--muted);font-family:monospace;font-size:.9em}
td.none{color:#aab}
table.kv th{width:38%;font-weight:600;background:none}
.badge{display:inline-block;padding:0 .5em;border-radius:3px;font-size:.85em;font-weight:700;
 border:1px solid currentColor;white-space:nowrap}
.badge.pass{color:var(--pass);background:#e7f4ec}.badge.fail{color:var(--fail);background:#fbe9e7}
.badge.undecided{color:var(--und);background:#fdf3dc}.badge.big{font-size:1em;padding:.1em .7em}
.ci{color:var(--muted);font-size:.9em}.tests{font-size:.9em}
figure.plot{margin:.6em 0;text-align:center}figure.plot svg{width:100%;height:auto}
figcaption{font-size:.82em;color:var(--muted)}
.pair{display:flex;flex-wrap:wrap;gap:8px}.pair figure{flex:1 1 420px}
article.test{border-top:1px solid var(--line);padding-top:.2em}
p.meta{font-size:.85em;color:var(--muted)}code{font-size:.92em;word-break:break-all}
.finding{border-left:4px solid var(--line);padding:.1em .9em;margin:.8em 0}.finding h3{margin:.3em 0}
.finding ul{margin:.2em 0 .6em;font-size:.9em}.finding p{margin:.3em 0}
.warn{background:#fdf3dc;border-left:4px solid var(--und);padding:.5em .8em}
ul.notes{font-size:.85em;color:var(--muted)}
footer{margin-top:3em;font-size:.8em;color:var(--muted);border-top:1px solid var(--line);padding-top:.6em}
@media print{
 @page{size:A4;margin:14mm 12mm 16mm}
 body{background:#fff;font-size:9.5pt}main{max-width:none;padding:0}
 nav.toc{display:none}
 h2{break-before:page;break-after:avoid}h2.first,section#summary h2{break-before:auto}h3{break-after:avoid}
 figure.plot,table,tr,.badge{break-inside:avoid}
 article.test{break-inside:auto}
 a{color:inherit;text-decoration:none}
 .badge{-webkit-print-color-adjust:exact;print-color-adjust:exact}
 thead{display:table-header-group}
}
"""


def render_html(
    result: PrequalResult, store: str | os.PathLike | None = None, *, generated: _dt.datetime | None = None
) -> str:
    """The report as one HTML document (see the module docstring)."""
    from fcrlive import __version__

    # the store first: a bad one fails before any figure is drawn
    hist = _history(store) if store is not None else None
    _FIG_COUNT[0] = 0
    generated = generated or _dt.datetime.now(_dt.UTC)
    anchors = {id(ev): _anchor(ev, i) for i, ev in enumerate(result.tests)}
    u = result.unit
    who = u.resource if u is not None else (result.unit_name or "unit")
    doc = result.document
    verdicts = " ".join(f"{_e(_service(s))} {_verdict_badge(v.status)}" for s, v in result.verdict.items())
    time_tests = [ev for ev in result.tests if ev.kind not in ("sine", "sine-set", "operation")]
    freq_tests = [ev for ev in result.tests if ev.kind in ("sine-set", "operation")]
    sine_tests = [ev for ev in result.tests if ev.kind == "sine"]
    toc = (
        '<nav class="toc"><b>Contents</b><ol><li><a href="#summary">Summary</a></li>'
        '<li><a href="#unit">Unit and governor</a></li>'
        '<li><a href="#coverage">Requirements and tests</a></li>'
        '<li><a href="#time">Time-domain tests</a></li><li><a href="#freq">Frequency domain</a></li>'
        '<li><a href="#measurement">Measurement chain</a></li><li><a href="#history">Continuous '
        'identification</a></li><li><a href="#document">Document and conventions</a></li></ol></nav>'
    )
    body = [
        '<header class="top">',
        f"<h1>FCR prequalification: {_e(who)}</h1>",
        f'<p class="sub">{_e(result.unit_name) + " · " if result.unit_name else ""}'
        f"evaluated against <b>{_e(doc.title)}</b> (<code>{_e(doc.key)}</code>)</p>",
        f'<p class="sub">Generated {generated:%Y-%m-%d %H:%M} UTC by fcrlive {_e(__version__)} · '
        f"{verdicts}</p>",
        "</header>",
        toc,
        _summary_section(result, anchors),
        _unit_section(result),
        _coverage_section(result, anchors),
        '<section id="time"><h2>3. Time-domain tests</h2><p>Each test: the applied frequency (top), the '
        "active power with the requirement drawn on it (bottom), the requirements and the figures read "
        "from the data.</p>",
        *(_test_block(ev, anchors[id(ev)], result) for ev in time_tests),
        "" if time_tests else "<p>No time-domain test files.</p>",
        "</section>",
        '<section id="freq"><h2>4. Frequency domain: Req. 8, 9 and 10</h2><p>Stability (Req. 8): the '
        "Nyquist curve of F(jω)·G(jω) with the power-system model of TR Table 7 must stay outside the circle "
        "of radius 0.43 around −1; a curve between 0.95·0.43 and 0.43 is accepted. Performance (Req. 9): "
        "0.95·|G/(1 + F G)| below |1/D(jω)|, D(s) = 1/(70 s + 1). The curve between the measured periods "
        "is drawn by linear interpolation.</p>",
        *(_test_block(ev, anchors[id(ev)], result) for ev in freq_tests),
        "" if freq_tests else "<p>No sine tests or normal-operation log: Req. 8 and 9 are not evaluated.</p>",
        "<h3>The single sine tests (Req. 10)</h3>" if sine_tests else "",
        *(_test_block(ev, anchors[id(ev)], result) for ev in sine_tests),
        "</section>",
        _checks_section(result, anchors),
        _history_section(store, hist),
        '<section id="document"><h2>7. Document and conventions</h2><ul>',
        f"<li>Requirements: {_e(doc.title)} (<code>{_e(doc.key)}</code>); Req. 4 deactivation limit "
        f"{doc.deactivation_limit_s:g} s·|ΔP_ss,theo|.</li>",
        "<li>Req. 8 uses the open loop F·G with the critical point −1 (the equation of TR v1.1; the text "
        "writes −F·G in one place).</li>",
        "<li>F(jω) is the response from the frequency control error to power, normalised by "
        "|ΔP_ss,theo| over the one-sided band (0.1 Hz FCR-N, 0.4 Hz FCR-D), TR eq. 7; with a test signal "
        "generated inside the controller it includes F_FME = 1/(T_FME s + 1) (TR 4.4).</li>",
        "<li>The TSOs evaluate applications with their own IT tool, which is not public; this report is "
        "the provider's own evaluation with fcrlive.</li>",
        *(f"<li>{_e(n)}</li>" for n in result.notes),
        "</ul></section>",
        f"<footer>fcrlive {_e(__version__)} · {len(result.tests)} evaluations · generated "
        f"{generated:%Y-%m-%d %H:%M} UTC</footer>",
    ]
    title = f"FCR prequalification: {who}"
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{_e(title)}</title><style>{_CSS}</style></head><body><main>"
        + "".join(body)
        + "</main></body></html>\n"
    )


def write_report(
    result: PrequalResult,
    path: str | os.PathLike,
    store: str | os.PathLike | None = None,
    *,
    pdf: str | os.PathLike | None = None,
) -> Path:
    """Write the HTML report to ``path`` (and, with ``pdf``, a PDF of it via headless Chromium).
    ``store``: the daemon's SQLite store for the continuous-identification history. Raises
    DataError naming the store when it cannot be read; UserError when the file cannot be written."""
    from fcrlive.errors import UserError

    text = render_html(result, store)
    out = Path(path)
    try:
        out.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise UserError(f"cannot write the report: {exc.strerror or exc}", where=str(out)) from None
    if pdf is not None:
        write_pdf(out, pdf)
    return out


# --------------------------------------------------------------------------------------------------
# PDF through headless Chromium

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_chromium() -> str | None:
    """Path of a Chromium/Chrome executable (``$FCRLIVE_CHROMIUM`` first), None when there is none."""
    env = os.environ.get("FCRLIVE_CHROMIUM")
    if env:
        return env if shutil.which(env) or Path(env).is_file() else None
    for name in CHROMIUM_NAMES:
        p = shutil.which(name)
        if p:
            return p
    return None


def chromium_command(chromium: str, *args: str, profile_dir: str) -> list[str]:
    """A headless Chromium command line that runs as root in a container and leaves no state behind."""
    return [
        chromium,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--no-first-run",
        "--no-default-browser-check",
        "--disable-extensions",
        "--allow-file-access-from-files",
        f"--user-data-dir={profile_dir}",
        *args,
    ]


def write_pdf(
    html_path: str | os.PathLike,
    pdf_path: str | os.PathLike,
    *,
    chromium: str | None = None,
    timeout_s: float = 180.0,
) -> Path:
    """Print ``html_path`` to ``pdf_path`` with headless Chromium (``--print-to-pdf``, A4 from the
    report's print CSS, no header/footer). UserError when Chromium is missing or fails."""
    from fcrlive.errors import UserError

    exe = chromium or find_chromium()
    if exe is None:
        raise UserError(
            "no Chromium found for the PDF: install Debian's 'chromium' (./dev does when root) or "
            "set FCRLIVE_CHROMIUM"
        )
    src = Path(html_path).resolve()
    out = Path(pdf_path).resolve()
    with tempfile.TemporaryDirectory(prefix="fcrlive-chromium-") as prof:
        cmd = chromium_command(
            exe, f"--print-to-pdf={out}", "--no-pdf-header-footer", src.as_uri(), profile_dir=prof
        )
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, check=False)
        except subprocess.TimeoutExpired:
            raise UserError(
                f"Chromium did not finish the PDF within {timeout_s:g} s", where=str(out)
            ) from None
        except OSError as exc:
            raise UserError(f"cannot run Chromium: {exc.strerror or exc}", where=exe) from None
    if proc.returncode != 0 or not out.is_file() or out.stat().st_size == 0:
        last = (proc.stderr or "").strip().splitlines()[-1:] or ["no output"]
        raise UserError(
            f"Chromium failed to print the PDF (exit {proc.returncode}): {last[0]}", where=str(out)
        )
    return out
