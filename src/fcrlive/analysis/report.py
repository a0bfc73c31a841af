"""The identification report: a pydantic model (the JSON of ``fcrlive identify --json``, and the typed
result that the daemon's worker returns, stores and publishes) and a readable text summary. Schema
documented in docs/identify.md.

Units: droop and G_1 as fractions/pu (0.04 for 4 %), ω in rad/s, periods in s, transfer functions in pu on
the machine base with positive static gains (G_p from the control error to power).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

if TYPE_CHECKING:  # the model alone stays light: the daemon's publisher imports it, not the numerics
    from fcrlive.analysis.assess import Assessment, PeriodPoint

SCHEMA_VERSION = 1


def _f(x) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


Bounds = tuple[float | None, float | None]
"""A 95 % interval [lower, upper]; an end is None (JSON null) where it is unknown."""


class ValueCI(BaseModel):
    value: float | None
    ci95: Bounds = Field(description="[lower, upper], 95 % interval (null where unknown)")
    reason: str | None = Field(default=None, description="why value is null (not identifiable from this log)")
    method: str | None = Field(
        default=None,
        description="the method that gave this value when it is not the report's own (e.g. lowband for the "
        "droop of a Z_cu report whose own droop is not identifiable)",
    )


class PeakCI(ValueCI):
    omega: float | None = Field(description="ω of the maximum [rad/s]")


class PeriodValue(BaseModel):
    """A response at one TSO period; null (re, im, abs, phase_deg and abs_ci95 null) with ``reason`` where
    it is not identifiable from the log (analysis.quality: its interval is too wide, key ``gp_<T>s`` in
    ``not_identifiable``)."""

    period_s: float
    re: float | None
    im: float | None
    abs: float | None
    phase_deg: float | None
    abs_ci95: Bounds
    reason: str | None = Field(default=None, description="why the value is null (not identifiable)")


class TsoProduct(BaseModel):
    stability_threshold: float | None
    stability_margin_band: float | None
    stability_margin_band_lower: float | None = None
    stability_margin_wide: float | None
    stability_margin_wide_lower: float | None = None
    closed_loop_stable: bool | None
    performance_ratio: float | None
    performance_ratio_upper: float | None = None
    k_red_dyn: float | None
    k_red_dyn_lower: float | None = None
    k_red_dyn_min: float | None
    passed: bool = Field(alias="pass", description="the point verdict (the point estimate of F)")
    passed_at_bound: bool | None = None
    reasons: list[str] = []
    notes: list[str] = []
    # the verdict with its uncertainty (tso_checks.decide; docs/tso-checks.md) and the optimistic bounds
    decision: Literal["pass", "fail", "undecided"] | None = Field(
        default=None, description="pass/fail only when the 95 % interval is clear of the limit")
    stability_margin_band_upper: float | None = None
    stability_margin_wide_upper: float | None = None
    performance_ratio_lower: float | None = None
    k_red_dyn_upper: float | None = None

    @property
    def verdict(self) -> str:
        """The decision; reports stored before it existed: the point verdict."""
        return self.decision or ("pass" if self.passed else "fail")

    # one spelling on the wire, "pass", in every dump; Python code says .passed
    model_config = ConfigDict(validate_by_name=True, validate_by_alias=True, serialize_by_alias=True)


class LocalChecks(BaseModel):
    max_s_bound: float | None = None
    sensitivity_pass: bool | None = None
    max_s_upper95: float | None = None
    gain_margin: float | None = None
    phase_margin_deg: float | None = None
    stability_margin: float | None = None
    omega_gain_crossover: float | None = None
    omega_phase_crossover: float | None = None
    g1_disturbance_worst_omega: float | None = None
    g1_admissible_white_level: float | None = None


class ControllerOut(BaseModel):
    kp: float
    ti_s: float
    droop: float
    placement: str
    signal: str
    source: str
    rel_residual: float | None = None


class IdentifyReport(BaseModel):
    """``fcrlive identify --json`` (one document) and the daemon's identification payload."""

    schema_version: int = SCHEMA_VERSION
    method: str
    method_reason: str
    sources: list[str] = []
    samples: int
    duration_s: float
    identification_ts_s: float | None = None
    sample_interval_s: float | None = Field(
        default=None, description="sample interval of the data before decimation [s] (null: sine)")
    segments: int | None = Field(default=None, description="gap-free segments of that data (null: sine)")
    rated_mw: float
    f0_hz: float
    kd: float
    droop: ValueCI | None
    g1_static: ValueCI | None
    max_abs_g1: PeakCI | None
    max_abs_s: PeakCI | None
    peak_band_rad_s: list[float] | None = Field(
        default=None,
        description="[ω_min, ω_max] rad/s in which max_abs_g1, max_abs_s and eq. 9-10 are searched",
    )
    gp_kind: str
    gp: list[PeriodValue] | None
    f: list[PeriodValue] | None
    tso: dict[str, TsoProduct] | None
    local: LocalChecks | None
    controller: ControllerOut | None = None
    not_identifiable: dict[str, str] = Field(
        default={}, description="quantity -> why it is null (e.g. coherence at its frequency, log rate)"
    )
    data_quality: dict | None = Field(
        default=None, description="measured from the log: u's meter-noise floor, SNR and coherence per band"
    )
    warnings: list[str] = []
    notes: list[str] = []

    def to_json_dict(self) -> dict:
        """The JSON form as a dict (what ``identify --json`` prints and the daemon stores)."""
        return self.model_dump(mode="json")


def _period_values(pts: tuple[PeriodPoint, ...] | None) -> list[PeriodValue] | None:
    if pts is None:
        return None
    return [
        PeriodValue(
            period_s=p.period_s,
            re=p.value.real,
            im=p.value.imag,
            abs=abs(p.value),
            phase_deg=float(np.degrees(np.angle(p.value))),
            abs_ci95=(_f(p.abs_lo), _f(p.abs_hi)),
        )
        for p in sorted(pts, key=lambda p: p.period_s)
    ]


def build_report(
    a: Assessment,
    *,
    method_reason: str,
    samples: int,
    duration_s: float,
    rated_mw: float,
    f0: float,
    sources=(),
    ts_id: float | None = None,
    sample_interval_s: float | None = None,
    segments: int | None = None,
    controller=None,
    extra_warnings=(),
    notes=(),
    not_identifiable: dict[str, str] | None = None,
    data_quality: dict | None = None,
) -> IdentifyReport:
    """The report of an assessment; ``not_identifiable`` (quantity -> reason) nulls those quantities."""
    ni = {**getattr(a, "not_identifiable", {}), **(not_identifiable or {})}
    droop = g1s = mg1 = ms = None
    if a.droop is not None:
        droop = ValueCI(value=_f(a.droop.value), ci95=(_f(a.droop.lo), _f(a.droop.hi)))
    if a.g1_static is not None:
        g1s = ValueCI(value=_f(a.g1_static.value), ci95=(_f(a.g1_static.lo), _f(a.g1_static.hi)))
    if a.max_g1 is not None:
        lo, hi = a.max_g1.ci95
        mg1 = PeakCI(value=_f(a.max_g1.value), omega=_f(a.max_g1.omega), ci95=(_f(lo), _f(hi)))
    if a.max_s is not None:
        lo, hi = a.max_s.ci95
        ms = PeakCI(value=_f(a.max_s.value), omega=_f(a.max_s.omega), ci95=(_f(lo), _f(hi)))
    tso = None
    if a.tso is not None:
        tso = {
            k: TsoProduct(
                stability_threshold=_f(v.stability_threshold),
                stability_margin_band=_f(v.stability_margin_band),
                stability_margin_band_lower=_f(v.stability_margin_band_lower),
                stability_margin_wide=_f(v.stability_margin_wide),
                stability_margin_wide_lower=_f(v.stability_margin_wide_lower),
                closed_loop_stable=v.closed_loop_stable,
                performance_ratio=_f(v.performance_ratio),
                performance_ratio_upper=_f(v.performance_ratio_upper),
                k_red_dyn=_f(v.k_red_dyn),
                k_red_dyn_lower=_f(v.k_red_dyn_lower),
                k_red_dyn_min=_f(v.k_red_dyn_min),
                passed=v.passed,
                passed_at_bound=v.passed_at_bound,
                decision=v.decision,
                stability_margin_band_upper=_f(v.stability_margin_band_upper),
                stability_margin_wide_upper=_f(v.stability_margin_wide_upper),
                performance_ratio_lower=_f(v.performance_ratio_lower),
                k_red_dyn_upper=_f(v.k_red_dyn_upper),
                reasons=list(v.reasons),
                notes=list(v.notes),
            )
            for k, v in a.tso.items()
        }
    loc = None
    if a.sensitivity is not None or a.margins is not None or a.disturbance is not None:
        loc = LocalChecks()
        if a.sensitivity is not None:
            loc.max_s_bound = a.sensitivity.ms
            loc.sensitivity_pass = a.sensitivity.passed
            loc.max_s_upper95 = _f(a.sensitivity.max_s_upper)
        if a.margins is not None:
            m = a.margins
            loc.gain_margin = _f(m.gain_margin)
            loc.phase_margin_deg = _f(m.phase_margin_deg)
            loc.stability_margin = _f(m.stability_margin)
            loc.omega_gain_crossover = _f(m.omega_gain_crossover)
            loc.omega_phase_crossover = _f(m.omega_phase_crossover)
        if a.disturbance is not None:
            loc.g1_disturbance_worst_omega = _f(a.disturbance.worst_omega)
            loc.g1_admissible_white_level = _f(a.disturbance.admissible_level)
    ctl = None
    if controller is not None:
        ctl = ControllerOut(
            kp=controller.Kp,
            ti_s=controller.Ti,
            droop=controller.droop,
            placement=controller.placement,
            signal=controller.signal,
            source=controller.source,
            rel_residual=_f(controller.rel_residual) if controller.source == "identified" else None,
        )
    rep = IdentifyReport(
        method=a.method,
        method_reason=method_reason,
        sources=list(sources),
        samples=int(samples),
        duration_s=float(duration_s),
        identification_ts_s=ts_id,
        sample_interval_s=sample_interval_s,
        segments=segments,
        rated_mw=float(rated_mw),
        f0_hz=float(f0),
        kd=float(a.kd),
        droop=droop,
        g1_static=g1s,
        max_abs_g1=mg1,
        max_abs_s=ms,
        peak_band_rad_s=None if a.peak_band is None else [_f(a.peak_band[0]), _f(a.peak_band[1])],
        gp_kind=a.gp_kind,
        gp=_period_values(a.gp),
        f=_period_values(a.f),
        tso=tso,
        local=loc,
        controller=ctl,
        not_identifiable=ni,
        data_quality=data_quality,
        warnings=[*a.warnings, *extra_warnings],
        notes=list(notes),
    )
    if "droop" in ni:
        rep.droop = ValueCI(value=None, ci95=(None, None), reason=ni["droop"])
        rep.g1_static = None
    if "max_abs_g1" in ni:
        rep.max_abs_g1 = PeakCI(value=None, ci95=(None, None), omega=None, reason=ni["max_abs_g1"])
    if "max_abs_s" in ni:
        rep.max_abs_s = PeakCI(value=None, ci95=(None, None), omega=None, reason=ni["max_abs_s"])
    if "gp" in ni:
        rep.gp = rep.f = None
    if "tso" in ni:
        rep.tso = None
    return rep


# ---------------------------------------------------------------------------------------------------
# Text summary


def _ci(v: ValueCI | None, fmt: str = "{:.4f}", scale: float = 1.0, unit: str = "") -> str:
    if v is None or v.value is None:
        why = v.reason if v is not None else None
        if why and why.startswith("not "):  # "not identifiable from this log: ..." says it already
            return why
        return "not identifiable" + (f": {why}" if why else "")
    lo, hi = v.ci95
    s = fmt.format(v.value * scale)
    if lo is not None and hi is not None:
        s += f"  [{fmt.format(lo * scale)}, {fmt.format(hi * scale)}]"
    else:
        s += "  [interval unknown]"
    return s + (f" {unit}" if unit else "") + (f"  (from {v.method})" if v.method else "")


def _iv(lo: float | None, hi: float | None) -> str:
    """" [lo, hi]" of a verdict's 95 % bounds ("?" where unknown); "" for an exact F (no bounds)."""
    if lo is None and hi is None:
        return ""
    return " [" + ", ".join("?" if x is None else f"{x:.3f}" for x in (lo, hi)) + "]"


def _num(x, fmt: str) -> str:
    return "inf" if x is None else fmt.format(x)


def text_summary(r: IdentifyReport) -> str:
    lines = [
        f"method: {r.method} ({r.method_reason})",
        f"data: {r.samples} samples at the identification rate, {r.duration_s:.0f} s usable"
        + (f", Ts = {r.identification_ts_s:g} s" if r.identification_ts_s else ""),
        "",
        f"{'quantity':<28}{'value  [95 % interval]':<40}",
        f"{'effective droop':<28}{_ci(r.droop, '{:.3f}', 100.0, '%')}"
        + (f"  (Kd = {r.kd:g})" if r.kd else ""),
        f"{'G_1(0) [pu/pu]':<28}{_ci(r.g1_static)}",
    ]
    for name, pk in (("max|G_1| [pu/pu]", r.max_abs_g1), ("max|S|", r.max_abs_s)):
        s = _ci(pk, "{:.3f}")
        if pk is not None and pk.omega:
            s += f"  at ω = {pk.omega:.3f} rad/s (T = {2 * math.pi / pk.omega:.1f} s)"
        lines.append(f"{name:<28}{s}")
    if r.peak_band_rad_s is not None and r.max_abs_g1 is not None:
        lo, hi = r.peak_band_rad_s
        lines.append(
            f"{'peak band':<28}{lo:.3g}-{hi:.3g} rad/s "
            f"(periods {2 * math.pi / hi:.1f}-{2 * math.pi / lo:.0f} s)"
        )
    if r.controller is not None:
        c = r.controller
        lines.append(
            f"{'controller':<28}Kp = {c.kp:.4g}, Ti = {c.ti_s:.4g} s, droop {100 * c.droop:.3g} % "
            f"({c.placement}/{c.signal}, {c.source})"
        )
    if r.local is not None and r.local.stability_margin is not None:
        lo = r.local
        lines.append(
            f"{'local loop L = G_p G_J':<28}GM = {_num(lo.gain_margin, '{:.3g}')}, "
            f"PM = {_num(lo.phase_margin_deg, '{:.3g}')}°, "
            f"min|1+L| = {lo.stability_margin:.3f}"
            + (
                f"; eq. 9 {'pass' if lo.sensitivity_pass else 'FAIL'} (M_s {lo.max_s_bound:g})"
                if lo.sensitivity_pass is not None
                else ""
            )
        )
    if r.gp:
        lines += [
            "",
            f"{r.gp_kind} at the TSO periods (and F = normalised):",
            f"{'T [s]':>7} {'|' + r.gp_kind + '|':>10} {'arg [deg]':>10} {'|F|':>8} "
            f"{'95 % |' + r.gp_kind + '|':>22}",
        ]
        fmap = {p.period_s: p for p in (r.f or [])}
        for p in r.gp:
            fp = fmap.get(p.period_s)
            if p.abs is None:
                lines.append(f"{p.period_s:7.0f} {'-':>10} {'-':>10} {'-':>8} {'not identifiable':>22}")
                continue
            lo, hi = p.abs_ci95
            band = "unknown" if lo is None or hi is None else f"[{lo:.3f}, {hi:.3f}]"
            f_abs = fp.abs if fp is not None and fp.abs is not None else float("nan")
            lines.append(
                f"{p.period_s:7.0f} {p.abs:10.3f} {p.phase_deg:10.1f} {f_abs:8.3f} {band:>22}"
            )
        nulled = [p for p in r.gp if p.abs is None]
        if nulled:
            lines.append(f"        T = {', '.join(f'{p.period_s:g}' for p in nulled)} s: {nulled[0].reason}"
                         if len({p.reason for p in nulled}) == 1 else
                         "        " + "; ".join(f"T = {p.period_s:g} s: {p.reason}" for p in nulled))
    if r.tso:
        lines += ["", "TSO requirements (Req. 8 stability, Req. 9 performance):"]
        for k, v in r.tso.items():
            if v.stability_margin_band is None or v.performance_ratio is None:
                lines.append(f"  {k.upper():<5} {v.verdict.upper()}")
                continue
            wide = "n/a" if v.stability_margin_wide is None else f"{v.stability_margin_wide:.3f}"
            stab = (
                "n/a" if v.closed_loop_stable is None else ("stable" if v.closed_loop_stable else "UNSTABLE")
            )
            lines.append(
                f"  {k.upper():<5} {v.verdict.upper()}: "
                f"min|1+FG| band {v.stability_margin_band:.3f}"
                f"{_iv(v.stability_margin_band_lower, v.stability_margin_band_upper)}"
                f" (≥ {v.stability_threshold:.4f}), wide {wide}, closed loop {stab}; Req. 9 ratio "
                f"{v.performance_ratio:.3f}, K_red,dyn {v.k_red_dyn:.3f}"
                f"{_iv(v.k_red_dyn_lower, v.k_red_dyn_upper)} (≥ {v.k_red_dyn_min:g})"
            )
            if v.verdict == "undecided":
                lines.append("        undecided: a margin's 95 % interval reaches over its limit or is "
                             "unknown" + ("" if v.passed else " (the point estimate fails)"))
            for reason in v.reasons:
                lines.append(f"        {reason}")
    elif r.gp is None:
        why = r.not_identifiable.get("tso") or r.not_identifiable.get("gp")
        lines += ["", "TSO requirements: not checked (G_p not identifiable from this data"
                  + (f": {why})" if why else ")")]
    if r.warnings:
        lines += ["", "warnings:"] + [f"  - {w}" for w in r.warnings]
    if r.notes:
        lines += ["", "notes:"] + [f"  - {n}" for n in r.notes]
    return "\n".join(lines)
