"""Time-domain tests (TR v1.1 Section 3.1 and 3.4.2): FCR-N step sequence, FCR-D fast ramps, static
FCR-D ramp test, linearity step sequences. Pure: arrays in, :class:`TestEvaluation` out.

Conventions (fcrlive's reading where the TR leaves it open; docs/prequal.md):

- The profile is found in the applied frequency (plateaus and ramps, :mod:`segments`), not from the
  nominal schedule times: a log may start early or a step may come late.
- Steady-state power P_ss of a plateau: the mean over its last 60 s (over its second half when it is
  shorter than 120 s, e.g. the 30 s stabilisation before ramp 1).
- ΔP(t) is oriented: P(t) − P_base for FCR-N and FCR-D up, P_base − P(t) for FCR-D down, so every
  requirement reads 'more is more'. P_base is the steady state before the activation read (before
  ramp 1 for Req. 4, P_ss,4 for ramp 5).
- Integrals (E_7.5s, Req. 4) are of the linear interpolant of the samples, with the interval ends and
  the zero crossings of the integrand inserted: exact for piecewise-linear data.
- Req. 12 (endurance, "the response shall stay activated as long as the frequency deviation
  persists"): when the long plateau of the endurance variant is logged (15 min), the 60 s moving average
  of ΔP must not fall below the activation it has reached (its running maximum on the plateau, capped
  at |ΔP_ss,theo| so that an overshoot settling is no fall) by more than 5 % of |ΔP_ss,theo| (Req. 1's
  under-delivery tolerance), from 5 min after the change to the end of the plateau. The value is the
  largest fall (≤ 0). How far and how fast the response gets is Req. 1's (and 2-3's) business, not
  Req. 12's: a slow response that only rises keeps its activation.
- 'No decrease after 7.5 s': the smallest ΔP from 7.5 s after the start of ramp 5 to the start of
  ramp 6 minus ΔP_7.5s; fcrlive allows 2 % of |ΔP_ss,theo| for the 'small, well-damped oscillations'
  the TR accepts.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from types import MappingProxyType

import numpy as np

from fcrlive.errors import DataError
from fcrlive.prequal import segments as sg
from fcrlive.prequal.common import (
    K_RED_DYN_MIN_STATIC,
    K_RED_MIN,
    NO_DP,
    Context,
    compare,
    k_red_ss,
    ss_window,
    undecided,
    within,
)
from fcrlive.prequal.model import Curve, Marker, RequirementResult, Series, TestEvaluation

NO_DECREASE_TOL = 0.02
"""Allowed dip below ΔP_7.5s after 7.5 s, as a fraction of |ΔP_ss,theo| (module docstring)."""
ENDURANCE_MIN_S = 840.0
"""A plateau this long [s] is the endurance variant (nominal 900 s; 60 s slack for a hand-timed test)."""
ENDURANCE_SETTLE_S = 300.0
"""Req. 12 is read from this long [s] after the change into the plateau on (the TR's 5-min steps)."""
ENDURANCE_FALL_MAX = 0.05
"""Req. 12: the largest allowed fall below the activation reached, as a fraction of |ΔP_ss,theo|."""
STATIC_RESPONSE_THRESHOLD_MW = 0.01
"""Req. 5b: a response smaller than the required power resolution (TR Table 16) is no response."""
DEACTIVATED_FRACTION = 0.05
"""Req. 6: deactivated once |ΔP| ≤ 5 % of |ΔP_ss,theo| (Req. 1's tolerance) for the rest of the log."""

FCRN_LEVELS = (50.0, 49.95, 50.0, 49.9, 50.1, 50.0)
FAST_UP = (49.9, 49.45, 49.9, 49.5, 49.9, 49.0, 50.0)
FAST_UP_COMBI = (49.7, 49.89)
STATIC_UP = (49.9, 49.5, 49.9)


def _mirror(levels: Sequence[float], service: str) -> tuple[float, ...]:
    return tuple(round(100.0 - x, 6) for x in levels) if service == "FcrdDo" else tuple(levels)


def _levels_text(pl: Sequence[sg.Plateau]) -> str:
    return ", ".join(f"{p.level:.3f}" for p in pl[:14]) + (" ..." if len(pl) > 14 else "")


def _ss(t, p, pl: sg.Plateau) -> float:
    return sg.mean_window(t, p, *ss_window(pl.t_change, pl.t_end))


def _series(t, f, p, curves=(), markers=(), base=float("nan")) -> Series:
    return Series(
        np.asarray(t, float),
        np.asarray(f, float),
        np.asarray(p, float),
        tuple(curves),
        tuple(markers),
        float(base),
    )


def _req1_steady_state(title, dp, dp_theo, hi, k, ctx, note) -> RequirementResult:
    """Req. 1: the steady-state change ``dp`` [MW] against |ΔP_ss,theo| ``dp_theo`` [MW], within −5 % …
    +``hi`` of it for an upward service, mirrored for a downward one; ``note`` has ``{}`` for the sign."""
    if ctx.up:
        value, lo, hi, sign = (dp - dp_theo) / dp_theo, -0.05, hi, "−"
    else:
        value, lo, hi, sign = (dp + dp_theo) / dp_theo, -hi, 0.05, "+"
    return within("1", title, value, lo, hi, "", ctx, note=note.format(sign), k_red=k)


def _band_curve(label, a, b, base, sign, lo, hi, dp, req) -> Curve:
    tt = np.array([a, b])
    lo_v, hi_v = base + sign * lo * dp, base + sign * hi * dp
    return Curve(
        label,
        tt,
        np.full(2, base + sign * dp * 0.5 * (lo + hi)),
        "power",
        np.full(2, min(lo_v, hi_v)),
        np.full(2, max(lo_v, hi_v)),
        req,
    )


def _endurance(num, t, dp_oriented, t_change, t_to, dp_theo, ctx) -> RequirementResult:
    """Req. 12 on the plateau from ``t_change`` to ``t_to`` (module docstring): the largest fall of the
    60 s moving average of the oriented ΔP [MW] below min(its running maximum on the plateau,
    ``dp_theo``), from ENDURANCE_SETTLE_S after the change on, as a fraction of ``dp_theo``."""
    t_from = t_change + ENDURANCE_SETTLE_S
    on = (t >= t_change) & (t <= t_to)
    ma = sg.moving_average(t, dp_oriented, 60.0)[on]
    read = t[on] >= t_from
    if not read.any():
        return undecided(num, "Endurance", "", ctx, "no samples in the endurance window")
    reached = np.minimum(np.maximum.accumulate(ma), dp_theo)
    fall = float(np.min(ma[read] - reached[read])) / dp_theo
    return compare(
        num,
        "Endurance (response stays activated)",
        fall,
        -ENDURANCE_FALL_MAX,
        "",
        ctx,
        note=(
            "largest fall of the 60 s moving average of ΔP below the activation reached (capped at "
            f"|ΔP_ss,theo|), /|ΔP_ss,theo|, from {t_from:.0f} s to {t_to:.0f} s"
        ),
    )


def _frozen(d: dict) -> MappingProxyType:
    return MappingProxyType(dict(d))


def _margin(r: RequirementResult) -> float:
    if r.value is None:
        return -np.inf
    if r.comparison == "within":
        lo, hi = r.limit
        return min(r.value - lo, hi - r.value)
    return r.value - r.limit if r.comparison in (">=", ">") else r.limit - r.value


def _with_summaries(reqs: dict[str, RequirementResult]) -> dict[str, RequirementResult]:
    """Add the plain requirement number as a key where a test evaluates it only under suffixed keys
    (``1-up``/``1-down`` → ``1``): the worst of them, failed if any failed, undecided if any is."""
    out = dict(reqs)
    groups: dict[str, list[RequirementResult]] = {}
    for key, r in reqs.items():
        if key != r.number and key.split("-")[0] == r.number:
            groups.setdefault(r.number, []).append(r)
    for num, rs in groups.items():
        if num in out:
            continue
        states = [r.passed for r in rs]
        if False in states:
            pick = min((r for r in rs if r.passed is False), key=_margin)
        elif None in states:
            pick = next(r for r in rs if r.passed is None)
        else:
            pick = min(rs, key=_margin)
        ks = [r.k_red for r in rs]
        out[num] = dataclasses.replace(
            pick,
            title=pick.title.split(" (")[0].replace(" upwards", "").replace(" downwards", "")
            + " (the worst)",
            passed=False if False in states else (None if None in states else True),
            k_red=min(ks) if all(k is not None for k in ks) else None,
        )
    return out


def _evaluation(ctx: Context, kind, reqs, figs, series, notes=()) -> TestEvaluation:
    reqs = _with_summaries(reqs)
    return TestEvaluation(
        file=ctx.file,
        service=ctx.service,
        test_id=ctx.test_id,
        kind=kind,
        requirements=_frozen(reqs),
        figures=_frozen({k: float(v) for k, v in figs.items() if v is not None}),
        series=series,
        operating_point=ctx.operating_point,
        files=(ctx.file,),
        notes=tuple(notes),
    )


# --------------------------------------------------------------------------------------------------
# FCR-N step sequence (TR 3.1.1, Table 3)


def evaluate_fcrn_steps(t, f, p, ctx: Context) -> TestEvaluation:
    """Req. 1 up/down with ΔP_ss,1 and ΔP_ss,2 (eqs. 1-2), K_red,ss, Req. 12 when the 15-min variant is
    logged. DataError when the applied frequency does not follow Table 3."""
    t, f, p = (np.asarray(x, float) for x in (t, f, p))
    found = sg.plateaus(t, f)
    pl = sg.match_levels(found, FCRN_LEVELS)
    if pl is None:
        raise DataError(
            "applied frequency does not follow the FCR-N step sequence (TR Table 3: 50, 49.95, 50, 49.9, "
            f"50.1, 50 Hz); plateaus found at {_levels_text(found)} Hz"
        )
    _, _, p0, p1, p2, p3 = pl
    P0, P1, P2, P3 = (_ss(t, p, x) for x in (p0, p1, p2, p3))
    base = 0.5 * (P0 + P3)
    dp1, dp2 = P1 - base, P2 - base  # eqs. 1-2
    D = ctx.dp_theo
    reqs: dict[str, RequirementResult] = {}
    figs = {
        "p_ss_0_mw": P0,
        "p_ss_1_mw": P1,
        "p_ss_2_mw": P2,
        "p_ss_3_mw": P3,
        "dp_ss_1_mw": dp1,
        "dp_ss_2_mw": dp2,
        "dp_ss_mw": 0.5 * (dp1 - dp2),
    }
    curves: list[Curve] = []
    markers = [
        Marker(f"P_ss,{k}", 0.5 * sum(ss_window(x.t_change, x.t_end)), v, "power", "1")
        for k, (x, v) in enumerate(((p0, P0), (p1, P1), (p2, P2), (p3, P3)))
    ]
    notes: list[str] = []
    endurance = min(p1.duration_s, p2.duration_s) >= ENDURANCE_MIN_S
    figs["endurance_variant"] = 1.0 if endurance else 0.0
    if D is None:
        reqs["1-up"] = undecided("1", "Steady-state response upwards", "", ctx, NO_DP)
        reqs["1-down"] = undecided("1", "Steady-state response downwards", "", ctx, NO_DP)
    else:
        k = k_red_ss([dp1, -dp2], D, 0.05, 0.2)
        reqs["1-up"] = within(
            "1",
            "Steady-state response upwards (eq. 1)",
            (dp1 - D) / D,
            -0.05,
            0.2,
            "",
            ctx,
            note="(ΔP_ss,1 − |ΔP_ss,theo|)/|ΔP_ss,theo|",
            k_red=k,
        )
        reqs["1-down"] = within(
            "1",
            "Steady-state response downwards (eq. 2)",
            (dp2 + D) / D,
            -0.2,
            0.05,
            "",
            ctx,
            note="(ΔP_ss,2 + |ΔP_ss,theo|)/|ΔP_ss,theo|",
            k_red=k,
        )
        figs.update(dp_ss_theo_mw=D, k_red_ss=k)
        curves.append(
            _band_curve(
                "Req. 1 allowed P_ss,1", *ss_window(p1.t_change, p1.t_end), base, 1, 0.95, 1.2, D, "1"
            )
        )
        curves.append(
            _band_curve(
                "Req. 1 allowed P_ss,2", *ss_window(p2.t_change, p2.t_end), base, -1, 0.95, 1.2, D, "1"
            )
        )
        ideal = base + D * np.clip((50.0 - f) / 0.1, -1, 1)
        curves.append(Curve("ideal steady-state response", t, ideal, "power"))
        if endurance:
            r_up = _endurance("12", t, p - base, p1.t_change, p1.t_end, D, ctx)
            r_dn = _endurance("12", t, base - p, p2.t_change, p2.t_end, D, ctx)
            reqs["12-up"], reqs["12-down"] = r_up, r_dn
    if not endurance:
        notes.append("steps 1-2 shorter than 15 min: not the endurance variant (Req. 12 not evaluated)")
    return _evaluation(ctx, "fcrn-steps", reqs, figs, _series(t, f, p, curves, markers, base), notes)


# --------------------------------------------------------------------------------------------------
# FCR-D: which ramp test


def fcrd_kind(t, f, service: str) -> str:
    """``fcrd-ramps`` (Table 4 fast ramps) or ``fcrd-static`` (Table 5), from the applied frequency."""
    found = sg.plateaus(np.asarray(t, float), np.asarray(f, float))
    if sg.match_levels(found, _mirror(FAST_UP[:1] + FAST_UP[3:6], service)) is not None:
        return "fcrd-ramps"
    if sg.match_levels(found, _mirror(STATIC_UP, service)) is not None:
        return "fcrd-static"
    raise DataError(
        "applied frequency follows neither the FCR-D fast ramp test (TR Table 4) nor the static FCR-D "
        f"ramp test (Table 5); plateaus found at {_levels_text(found)} Hz"
    )


def _activation(t, p, t0, base, sign, D, ctx, reqs, figs, markers, curves, *, k_min, label):
    """Req. 2 and 3 on the activation that starts at t0 (ramp 5, or ramp 1 of static FCR-D)."""
    dp = sign * (p - base)
    dp75 = float(np.interp(t0 + 7.5, t, dp))
    e75 = sg.integrate(t, dp, t0, t0 + 7.5)
    figs.update(dp_7p5s_mw=dp75, e_7p5s_mws=e75)
    markers.append(Marker("ΔP_7.5s", t0 + 7.5, base + sign * dp75, "power", "2"))
    if D is None:
        reqs["2"] = undecided("2", "Power after 7.5 s", "MW", ctx, NO_DP)
        reqs["3"] = undecided("3", "Energy from 0 to 7.5 s", "MWs", ctx, NO_DP)
        return dp, dp75, None
    k = min(1.0, dp75 / (0.86 * D), e75 / (3.2 * D))
    k = k if k > 0 else None
    reqs["2"] = compare(
        "2",
        f"Power 7.5 s after the start of {label}",
        dp75,
        0.86 * D,
        "MW",
        ctx,
        note="ΔP_7.5s ≥ 0.86·|ΔP_ss,theo|",
        k_red=k,
    )
    reqs["3"] = compare(
        "3",
        f"Energy from 0 to 7.5 s after the start of {label} (eq. 4)",
        e75,
        3.2 * D,
        "MWs",
        ctx,
        note="E_7.5s ≥ 3.2 s·|ΔP_ss,theo|",
        k_red=k,
    )
    figs["k_red_dyn"] = k if k is not None else 0.0
    figs["k_red_dyn_min"] = k_min
    curves.append(
        Curve(
            "Req. 2: 0.86·ΔP_ss,theo",
            np.array([t0, t0 + 7.5]),
            np.full(2, base + sign * 0.86 * D),
            "power",
            requirement="2",
        )
    )
    tt = np.linspace(t0, t0 + 7.5, 76)
    run = np.array([sg.integrate(t, dp, t0, x) for x in tt])
    curves.append(Curve("E(t) from the start of the ramp", tt, run, "energy", requirement="3"))
    curves.append(
        Curve(
            "Req. 3: 3.2 s·ΔP_ss,theo",
            np.array([t0, t0 + 7.5]),
            np.full(2, 3.2 * D),
            "energy",
            requirement="3",
        )
    )
    return dp, dp75, k


def _no_decrease(t, dp, dp75, a, b, D, ctx) -> RequirementResult:
    sel = (t >= a) & (t <= b)
    if not sel.any():
        return undecided("2-hold", "No decrease after 7.5 s", "MW", ctx, "no samples after 7.5 s")
    dip = float(dp[sel].min() - dp75)
    tol = NO_DECREASE_TOL * D if D is not None else 0.0
    return compare(
        "2-hold",
        "No decrease below ΔP_7.5s after 7.5 s",
        dip,
        -tol,
        "MW",
        ctx,
        note=f"min ΔP − ΔP_7.5s from {a:.1f} s to {b:.1f} s; {NO_DECREASE_TOL:.0%} of |ΔP_ss,theo| "
        "allowed for small well-damped oscillations (fcrlive's reading)",
    )


# --------------------------------------------------------------------------------------------------
# FCR-D fast ramps (TR 3.1.2, Table 4)


def evaluate_fcrd_ramps(t, f, p, ctx: Context, mode: np.ndarray | None = None) -> TestEvaluation:
    """Req. 1 (ramps 3-4), Req. 2 and 3 (ramp 5), no decrease after 7.5 s, Req. 4 (deactivation, ramps 1-2,
    limit of ``ctx.document``), K_red,ss and K_red,dyn, Req. 1b (ramps 7-8) when logged, Req. 12 for
    the 15-min variant, Req. 13 when the log carries the controller mode (``mode``)."""
    t, f, p = (np.asarray(x, float) for x in (t, f, p))
    s = ctx.sign
    found = sg.plateaus(t, f)
    pl = sg.match_levels(found, _mirror(FAST_UP, ctx.service))
    notes: list[str] = []
    if pl is None:
        # ramp 2 may start before the frequency rests at 49.45 Hz: no plateau there
        core = sg.match_levels(found, _mirror(FAST_UP[:1] + FAST_UP[2:], ctx.service))
        if core is None:
            raise DataError(
                "applied frequency does not follow the FCR-D fast ramp test (TR Table 4); plateaus found at "
                f"{_levels_text(found)} Hz"
            )
        pl = [core[0], None, *core[1:]]
        notes.append("no rest at the ramp-1 level: ramp 1 start taken as the end of the first plateau")
    p0, p1, _p2, p3, p4, p5, p6 = pl
    rest = found[found.index(p6) + 1 :]
    combi = sg.match_levels(rest, _mirror(FAST_UP_COMBI, ctx.service))
    t_r1 = p1.t_change if p1 is not None else p0.t_end
    t_r5, t_r6 = p5.t_change, p6.t_change
    D = ctx.dp_theo
    P0, P3, P4 = _ss(t, p, p0), _ss(t, p, p3), _ss(t, p, p4)
    d_ss = s * (P3 - P4)
    reqs: dict[str, RequirementResult] = {}
    figs: dict[str, float | None] = {
        "p_ss_3_mw": P3,
        "p_ss_4_mw": P4,
        "dp_ss_mw": d_ss,
        "t_ramp1_s": t_r1,
        "t_ramp5_s": t_r5,
        "t_ramp6_s": t_r6,
    }
    markers = [
        Marker("P_ss,3", 0.5 * sum(ss_window(p3.t_change, p3.t_end)), P3, "power", "1"),
        Marker("P_ss,4", 0.5 * sum(ss_window(p4.t_change, p4.t_end)), P4, "power", "1"),
    ]
    curves: list[Curve] = []
    endurance = p3.duration_s >= ENDURANCE_MIN_S
    figs["endurance_variant"] = 1.0 if endurance else 0.0
    k_min = K_RED_MIN[ctx.service]
    # Req. 1
    if D is None:
        reqs["1"] = undecided("1", "Steady-state response (ramps 3-4)", "", ctx, NO_DP)
    else:
        k = k_red_ss([d_ss], D, 0.05, 0.2)
        reqs["1"] = _req1_steady_state(
            "Steady-state response (ramps 3-4)", P3 - P4, D, 0.2, k, ctx,
            "(P_ss,3 − P_ss,4 {} |ΔP_ss,theo|)/|ΔP_ss,theo|",
        )
        figs.update(dp_ss_theo_mw=D, k_red_ss=k)
        curves.append(
            _band_curve("Req. 1 allowed P_ss,3", *ss_window(p3.t_change, p3.t_end), P4, s, 0.95, 1.2, D, "1")
        )
        act = np.clip((_mirror((49.9,), ctx.service)[0] - f) * s / 0.4, 0.0, 1.0)
        curves.append(Curve("ideal steady-state response", t, P4 + s * D * act, "power"))
    # Req. 2, 3 and no decrease (ramp 5)
    dp5, dp75, _k = _activation(
        t, p, t_r5, P4, s, D, ctx, reqs, figs, markers, curves, k_min=k_min, label="ramp 5"
    )
    reqs["2-hold"] = _no_decrease(t, dp5, dp75, t_r5 + 7.5, t_r6, D, ctx)
    # Req. 4 (ramps 1-2)
    dp1 = s * (p - P0)
    t_n = t_r1 + 4.4
    dp_n = float(np.interp(t_n, t, dp1))
    figs.update(dp_nadir_mw=dp_n, t_nadir_s=t_n)
    markers.append(Marker("ΔP at the nadir (4.4 s)", t_n, P0 + s * dp_n, "power", "4"))
    if D is None:
        reqs["4"] = undecided("4", "Deactivation", "MWs", ctx, NO_DP)
    else:
        c = min(abs(dp_n), 0.5 * D)
        t_stop = min(t_n + 40.0, float(t[-1]))
        e, t_k = sg.max_running_integral(t, dp1 - c, t_n, t_stop)
        lim = ctx.document.deactivation_limit_s * D
        note = (
            f"max over k of ∫ from the nadir (4.4 s after the start of ramp 1) to k of (ΔP − min(|ΔP_nadir|, "
            f"0.5·|ΔP_ss,theo|)), k up to 40 s after; limit {ctx.document.deactivation_limit_s:g} s·"
            f"|ΔP_ss,theo| ({ctx.document.key})"
        )
        if t_stop < t_n + 40.0 - 1e-9:
            note += f"; the log covers only {t_stop - t_n:.1f} s after the nadir"
        reqs["4"] = compare(
            "4", "Deactivation (energy after the nadir)", e, lim, "MWs", ctx, op="<=", note=note
        )
        figs.update(deactivation_mws=e, deactivation_limit_mws=lim, t_deactivation_max_s=t_k)
        tt = np.linspace(t_n, t_stop, 401)
        run = np.array([sg.integrate(t, dp1 - c, t_n, x) for x in tt])
        curves.append(
            Curve(
                "Req. 4 running energy above min(|ΔP_nadir|, ΔP_ss,theo/2)",
                tt,
                run,
                "energy",
                requirement="4",
            )
        )
        curves.append(
            Curve(
                f"Req. 4 limit ({ctx.document.key})",
                np.array([t_n, t_stop]),
                np.full(2, lim),
                "energy",
                requirement="4",
            )
        )
        curves.append(
            Curve(
                "min(|ΔP_nadir|, ΔP_ss,theo/2)",
                np.array([t_n, t_stop]),
                np.full(2, P0 + s * c),
                "power",
                requirement="4",
            )
        )
    # Req. 1b (ramps 7-8, FCR-N and FCR-D combined)
    if combi is not None:
        P6 = _ss(t, p, p6)
        figs["p_ss_6_mw"] = P6
        DN = ctx.dp_theo_fcrn
        doc = ctx.document
        for x, lab in zip(combi, ("7", "8")):
            PX = _ss(t, p, x)
            dfx = abs(x.level - p6.level)
            figs[f"p_ss_{lab}_mw"] = PX
            if lab not in doc.req1b_ramps:
                continue
            key = f"1b-{lab}"
            title = f"Combined FCR-N and FCR-D response (ramps 6 and {lab})"
            if D is None or DN is None:
                reqs[key] = undecided(
                    "1b", title, "", ctx, "needs |ΔP_ss,theo| of FCR-N and of FCR-D at this point"
                )
                continue
            expected = DN + abs(dfx - 0.1) / 0.4 * D
            # TR: relative to the expected combined response; Statnett 5.1.5: to |ΔP_FCR-N| alone
            den = DN if doc.req1b_fcrn_denominator else expected
            value = ctx.sign * (PX - P6) - expected
            lo, hi = (-0.05, 0.2)
            if not ctx.up:  # the TR's form for downwards: (P_X − P_6 + E)/den ∈ [−0.2, 0.05]
                value, lo, hi = -value, -0.2, 0.05
            reqs[key] = within(
                "1b",
                title,
                value / den,
                lo,
                hi,
                "",
                ctx,
                note=f"Δf_X = {dfx:.3f} Hz; expected {expected:.3f} MW; relative to "
                + ("|ΔP_FCR-N,ss,theo|" if doc.req1b_fcrn_denominator else "the expected response")
                + f" ({doc.key})",
            )
    # Req. 12
    if endurance and D is not None:
        reqs["12"] = _endurance("12", t, s * (p - P4), p3.t_change, p3.t_end, D, ctx)
    # Req. 13
    if mode is not None and not ctx.mode_shifting and np.unique(np.asarray(mode).astype(str)).size == 1:
        notes.append(
            f"ContMode_{ctx.service} constant and the unit uses no mode shifting: Req. 13 not applicable"
        )
        mode = None
    if mode is not None:
        reqs["13"] = _mode_shifting(t, np.asarray(mode), p0, p1, p3, p4, p5, p6, t_r1, ctx)
    elif ctx.mode_shifting:
        reqs["13"] = undecided(
            "13",
            "Mode shifting",
            "",
            ctx,
            f"the unit uses mode shifting but the log has no ContMode_{ctx.service} column",
        )
    return _evaluation(ctx, "fcrd-ramps", reqs, figs, _series(t, f, p, curves, markers, P4), notes)


def _mode_shifting(t, mode, p0, p1, p3, p4, p5, p6, t_r1, ctx) -> RequirementResult:
    """Req. 13 items 1-4 from the logged mode: the mode in the stabilisation period is the high-stability
    mode, any other value the high-performance mode. Item 5 (bumpless) is for the plot."""
    mode = np.asarray(mode).astype(str)
    stab = mode[p0.i1 - 1]
    hp = mode != stab
    fails: list[str] = []

    def active_then_off(t_a, t_b, label):
        idx = np.flatnonzero(hp & (t >= t_a) & (t <= t_b))
        if idx.size == 0:
            fails.append(f"high-performance mode not activated during {label}")
            return
        on = t[idx[0]]
        after = np.flatnonzero((~hp) & (t > on))
        if after.size == 0 or t[after[0]] - on > 10.0 + 1e-9:
            fails.append(
                f"high-performance mode activated at {on:.1f} s ({label}) not deactivated within 10 s"
            )

    end1 = p1.t_first if p1 is not None else t_r1 + 4.0
    active_then_off(t_r1, end1 + 1.0, "ramp 1")
    if (hp & (t >= p3.t_change) & (t <= p4.t_end)).any():
        fails.append("high-performance mode active during ramps 3-4 (must be blocked)")
    active_then_off(p5.t_change, p5.t_first + 1.0, "ramp 5")
    if (hp & (t >= p6.t_first) & (t <= p6.t_end)).any():
        fails.append("high-performance mode active during ramp 6 (high-stability mode required)")
    return RequirementResult(
        "13",
        "Mode shifting (items 1-4)",
        float(len(fails)),
        0.0,
        "",
        not fails,
        "<=",
        "; ".join(fails)
        if fails
        else f"stability mode {stab!r}; item 5 (bumpless shift) is judged on the plot",
        document=ctx.document.key,
    )


# --------------------------------------------------------------------------------------------------
# Static FCR-D (TR 3.1.3, Table 5)


def evaluate_fcrd_static(t, f, p, ctx: Context) -> TestEvaluation:
    """Req. 1, 2, 3 (K_red,dyn ≥ 0.84), no decrease, 5a, 5b, 6, 7 and 12 on the static FCR-D ramp test."""
    t, f, p = (np.asarray(x, float) for x in (t, f, p))
    s = ctx.sign
    found = sg.plateaus(t, f)
    pl = sg.match_levels(found, _mirror(STATIC_UP, ctx.service))
    if pl is None:
        raise DataError(
            "applied frequency does not follow the static FCR-D ramp test (TR Table 5); plateaus found at "
            f"{_levels_text(found)} Hz"
        )
    p0, p1, p2 = pl
    t_r1, t_r2 = p1.t_change, p2.t_change
    D = ctx.dp_theo
    P0, P1 = _ss(t, p, p0), _ss(t, p, p1)
    d_ss = s * (P1 - P0)
    reqs: dict[str, RequirementResult] = {}
    figs: dict[str, float | None] = {
        "p_ss_0_mw": P0,
        "p_ss_1_mw": P1,
        "dp_ss_mw": d_ss,
        "t_ramp1_s": t_r1,
        "t_ramp2_s": t_r2,
    }
    markers = [
        Marker("P_ss,0", 0.5 * sum(ss_window(p0.t_change, p0.t_end)), P0, "power", "1"),
        Marker("P_ss,1", 0.5 * sum(ss_window(p1.t_change, p1.t_end)), P1, "power", "1"),
    ]
    curves: list[Curve] = []
    notes: list[str] = []
    endurance = p1.duration_s >= ENDURANCE_MIN_S
    figs["endurance_variant"] = 1.0 if endurance else 0.0
    if D is None:
        reqs["1"] = undecided("1", "Steady-state response (ramp 1)", "", ctx, NO_DP)
    else:
        k = k_red_ss([d_ss], D, 0.05, 0.1)
        reqs["1"] = _req1_steady_state(
            "Steady-state response (ramp 1)", P1 - P0, D, 0.1, k, ctx,
            "(P_ss,1 − P_ss,0 {} ΔP_ss,theo)/ΔP_ss,theo",
        )
        figs.update(dp_ss_theo_mw=D, k_red_ss=k)
        curves.append(
            _band_curve("Req. 1 allowed P_ss,1", *ss_window(p1.t_change, p1.t_end), P0, s, 0.95, 1.1, D, "1")
        )
    dp, dp75, _k = _activation(
        t, p, t_r1, P0, s, D, ctx, reqs, figs, markers, curves, k_min=K_RED_DYN_MIN_STATIC, label="ramp 1"
    )
    reqs["2-hold"] = _no_decrease(t, dp, dp75, t_r1 + 7.5, t_r2, D, ctx)
    # Req. 5a, 5b
    sel1 = (t >= t_r1) & (t <= t_r2)
    dp_max = float(dp[sel1].max())
    dp_25 = float(np.interp(t_r1 + 2.5, t, dp))
    figs.update(dp_max_mw=dp_max, dp_2p5s_mw=dp_25)
    if D is None:
        reqs["5a"] = undecided("5a", "Overshoot", "MW", ctx, NO_DP)
    else:
        reqs["5a"] = compare(
            "5a",
            "Overshoot of the response to ramp 1",
            dp_max,
            1.2 * D,
            "MW",
            ctx,
            op="<=",
            note="|ΔP_max| ≤ 1.2·|ΔP_ss,theo|",
        )
        curves.append(
            Curve(
                "Req. 5a: 1.2·ΔP_ss,theo",
                np.array([t_r1, t_r2]),
                np.full(2, P0 + s * 1.2 * D),
                "power",
                requirement="5a",
            )
        )
    reqs["5b"] = compare(
        "5b",
        "Response started within 2.5 s",
        dp_25,
        STATIC_RESPONSE_THRESHOLD_MW,
        "MW",
        ctx,
        op=">",
        note="|ΔP| 2.5 s after the start of ramp 1 above the 0.01 MW resolution",
    )
    markers.append(Marker("ΔP at 2.5 s", t_r1 + 2.5, P0 + s * dp_25, "power", "5b"))
    # Req. 6, 7 (deactivation after ramp 2)
    t_ret = p2.t_first
    t_grace = t_ret + 60.0
    sel2 = t >= t_r2
    if D is None:
        reqs["6"] = undecided("6", "Deactivated within 15 min", "s", ctx, NO_DP)
        reqs["7"] = undecided("7", "Deactivation rate (10 s)", "MW", ctx, NO_DP)
        reqs["7-step"] = undecided("7", "Deactivation rate (1 s)", "MW", ctx, NO_DP)
    else:
        thr = DEACTIVATED_FRACTION * D
        above = np.flatnonzero(sel2 & (np.abs(dp) > thr))
        t_last = float(t[-1])
        if above.size and above[-1] == len(t) - 1:
            covered = t_last - t_grace
            if covered >= 900.0:
                reqs["6"] = compare(
                    "6",
                    "Deactivated within 15 min",
                    covered,
                    900.0,
                    "s",
                    ctx,
                    op="<=",
                    note=f"|ΔP| still above {DEACTIVATED_FRACTION:.0%} of |ΔP_ss,theo| at the end",
                )
            else:
                reqs["6"] = undecided(
                    "6",
                    "Deactivated within 15 min",
                    "s",
                    ctx,
                    f"not deactivated by the end of the log, {covered:.0f} s after the grace start",
                    limit=900.0,
                    op="<=",
                )
        else:
            t_done = float(t[above[-1] + 1]) if above.size else float(t[np.flatnonzero(sel2)[0]])
            figs["t_deactivated_s"] = t_done
            reqs["6"] = compare(
                "6",
                "Deactivated within 15 min",
                max(0.0, t_done - t_grace),
                900.0,
                "s",
                ctx,
                op="<=",
                note="from 60 s after the frequency's return to |ΔP| ≤ 5 % of |ΔP_ss,theo| for good",
            )
        tt = t[sel2]
        d10 = np.interp(tt - 10.0, t, dp) - dp[sel2]
        d1 = np.interp(tt - 1.0, t, dp) - dp[sel2]
        ok10 = tt - 10.0 >= t_r2
        ok1 = tt - 1.0 >= t_r2
        m10 = float(d10[ok10].max()) if ok10.any() else 0.0
        m1 = float(d1[ok1].max()) if ok1.any() else 0.0
        if ctx.document.req7_per_second:
            reqs["7"] = compare(
                "7",
                "Deactivation rate (1 s)",
                m1,
                0.025 * D,
                "MW",
                ctx,
                op="<=",
                note=f"max |P(t−1)| − |P(t)| ≤ 0.025·|ΔP_ss,theo| ({ctx.document.key} 5.2.8)",
            )
        else:
            reqs["7"] = compare(
                "7",
                "Deactivation rate (10 s window)",
                m10,
                0.025 * D * 10.0,
                "MW",
                ctx,
                op="<=",
                note="max P(t−10) − P(t) ≤ 0.025·|ΔP_ss,theo|·10",
            )
            reqs["7-step"] = compare(
                "7",
                "Deactivation step (1 s)",
                m1,
                0.2 * D,
                "MW",
                ctx,
                op="<=",
                note="max P(t−1) − P(t) ≤ 0.2·|ΔP_ss,theo|",
            )
        figs.update(deactivation_drop_10s_mw=m10, deactivation_drop_1s_mw=m1)
        start = np.flatnonzero(sel2 & (dp < dp[np.flatnonzero(sel2)[0]] - thr))
        if start.size:
            figs["t_deactivation_start_s"] = float(t[start[0]])
            if t[start[0]] < t_grace - 1e-9:
                notes.append(
                    f"deactivation started {t_grace - t[start[0]]:.1f} s before the 60 s in the normal "
                    "band had passed (TR 3.1.3: after 60 s)"
                )
        if endurance:
            reqs["12"] = _endurance("12", t, dp, t_r1, p1.t_end, D, ctx)
    return _evaluation(ctx, "fcrd-static", reqs, figs, _series(t, f, p, curves, markers, P0), notes)


# --------------------------------------------------------------------------------------------------
# Linearity step sequences (TR 3.4.2, Req. 11, Tables 8-9)


def evaluate_linearity(t, f, p, ctx: Context) -> TestEvaluation:
    """Req. 11 for every step: the 10 s moving average of ΔP over the last 60 s of each step (at least
    60 s after it) within the allowed area of Table 8 (FCR-N) or 9 (FCR-D)."""
    t, f, p = (np.asarray(x, float) for x in (t, f, p))
    found = sg.plateaus(t, f, min_s=20.0)
    fcrn = ctx.service == "Fcrn"
    f_zero = 50.0 if fcrn else (49.9 if ctx.service == "FcrdUp" else 50.1)
    full = 0.1 if fcrn else 0.4
    if len(found) < 3 or abs(found[0].level - f_zero) > sg.LEVEL_TOL_HZ:
        raise DataError(
            f"applied frequency does not follow a linearity step sequence (TR 3.4.2: from {f_zero:g} Hz in "
            f"steps); plateaus found at {_levels_text(found)} Hz"
        )
    base_pl = found[0]
    P_base = _ss(t, p, base_pl)
    D = ctx.dp_theo
    ma = sg.moving_average(t, p, 10.0) - P_base
    reqs: dict[str, RequirementResult] = {}
    figs: dict[str, float | None] = {"p_base_mw": P_base, "steps": float(len(found) - 1)}
    curves: list[Curve] = [Curve("10 s moving average", t, ma + P_base, "power", requirement="11")]
    markers: list[Marker] = []
    worst: tuple[float, RequirementResult] | None = None
    for k, x in enumerate(found[1:], 1):
        # signed target and Req. 11's bounds: upwards (under 50 Hz / FCR-D up) −5 %/+10 %, downwards
        # −10 %/+5 %; FCR-N at 50.00 Hz itself: the closure of Table 8's area, ±10 %
        if fcrn:
            target = D * (50.0 - x.level) / full if D is not None else 0.0
            if x.level < 50.0 - 1e-6:
                lo, hi = -0.05, 0.1
            elif x.level > 50.0 + 1e-6:
                lo, hi = -0.1, 0.05
            else:
                lo, hi = -0.1, 0.1
        else:
            act = max(0.0, (f_zero - x.level) * ctx.sign) / full
            target = ctx.sign * D * act if D is not None else 0.0
            lo, hi = (-0.05, 0.1) if ctx.up else (-0.1, 0.05)
        a = x.t_end - 60.0 if x.duration_s >= 120.0 else x.t_change + 60.0
        title = f"Linearity at {x.level:.3f} Hz (step {k})"
        if a >= x.t_end - 1e-9:
            reqs[f"11-{k}"] = undecided(
                "11",
                title,
                "",
                ctx,
                f"step lasts {x.duration_s:.0f} s, under the 60 s + 60 s the TR assesses",
            )
            continue
        if D is None:
            reqs[f"11-{k}"] = undecided("11", title, "", ctx, NO_DP)
            continue
        sel = (t >= a) & (t <= x.t_end)
        relative = (not fcrn) and ctx.fcrd_static and ctx.document.req11_static_relative and abs(target) > 0
        if relative:
            # Statnett 5.2.11 (static FCR-D): 0.95 ≤ |ΔP̄|/|ΔP_target| ≤ 1.1
            lo, hi = 0.95, 1.1
            vals = np.abs(ma[sel]) / abs(target)
            what = f"|ΔP̄|/|ΔP_target| ({ctx.document.key} 5.2.11)"
        else:
            vals = (ma[sel] - target) / D
            what = "(ΔP̄ − ΔP_target)/|ΔP_ss,theo|"
        vmin, vmax = float(vals.min()), float(vals.max())
        v = vmin if (vmin - lo) < (hi - vmax) else vmax
        r = within(
            "11",
            title,
            v,
            lo,
            hi,
            "",
            ctx,
            note=f"{what} over {a:.0f}-{x.t_end:.0f} s, the worst of [{vmin:.4f}, {vmax:.4f}]; "
            f"target {target:.3f} MW",
        )
        reqs[f"11-{k}"] = r
        margin = min(vmin - lo, hi - vmax)
        if worst is None or margin < worst[0]:
            worst = (margin, r)
        b1, b2 = (
            (P_base + lo * target, P_base + hi * target)
            if relative
            else (P_base + target + lo * D, P_base + target + hi * D)
        )
        curves.append(
            Curve(
                f"Req. 11 allowed (step {k})",
                np.array([a, x.t_end]),
                np.full(2, P_base + target),
                "power",
                np.full(2, min(b1, b2)),
                np.full(2, max(b1, b2)),
                "11",
            )
        )
    if worst is not None:
        states = [r.passed for r in reqs.values()]
        ok = False if False in states else (None if None in states else True)
        w = worst[1]
        reqs["11"] = RequirementResult(
            "11",
            "Linearity, all steps (the worst)",
            w.value,
            w.limit,
            "",
            ok,
            "within",
            w.note,
            document=ctx.document.key,
        )
    if D is not None:
        figs["dp_ss_theo_mw"] = D
    return _evaluation(ctx, "linearity", reqs, figs, _series(t, f, p, curves, markers, P_base))
