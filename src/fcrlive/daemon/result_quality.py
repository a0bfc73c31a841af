"""The quality rule: is an identification result fit for a dashboard? ``ok`` / ``uncertain`` / ``rejected``.

Short windows (10 min, or a window with little usable data) occasionally give a droop far from the
truth whose 95 % interval is not finite or spans the whole plausible range; published as a headline
number it would be read as a measurement. The rule judges the numbers of the identification report
exactly as they are published (:func:`fcrlive.daemon.payloads.headline_scalars`: ``droop`` in %,
``max_abs_s``, ``max_abs_g1``), each on its own, and the run takes the worst level:

``rejected``
    - ``droop`` has no finite value (not identifiable);
    - a number's 95 % interval is unknown (null: a NaN or infinite bound) or inverted (upper < lower),
      or does not contain the number;
    - the interval is wider than ``reject_ci_rel_width`` times |value|;
    - the droop is outside ``[droop_min_pct, droop_max_pct]`` (a governor droop is a few per cent).
``uncertain``
    - the interval is wider than ``uncertain_ci_rel_width`` times |value|;
    - the interval has zero width (a point estimate: nothing says how far to trust it).
``ok``
    otherwise.

``max_abs_s`` / ``max_abs_g1`` that the method cannot give (null: Z_u has no S) or that the
identification says this window cannot give (null with a reason, e.g. lowband's coherence gate; listed in
``not_identifiable``) are not judged and never published as numbers. Nor are the TSO verdicts:
``undecided`` (a margin's 95 % interval reaches over its limit) is an honest result, published on
``tso/<product>``, not a reason to reject the run. The
interval is the report's [lower, upper] as it is (the droop's is not symmetric). Thresholds:
``[identification.result_quality]`` (docs/config.md). The built-in identification has already nulled,
with the reason, every number whose interval is missing, of zero width or wider than the value
(:mod:`fcrlive.analysis.quality`): this rule can be stricter than that, not looser; it judges a
plug-in's report as it comes.
"""

from __future__ import annotations

import math

from fcrlive.analysis.report import IdentifyReport
from fcrlive.daemon.config import ResultQualityConfig
from fcrlive.daemon.payloads import (
    HEADLINE_SCALARS,
    QuantityQuality,
    ResultQuality,
    ScalarPayload,
    headline_scalars,
    not_identifiable,
)

_ORDER = {"ok": 0, "uncertain": 1, "rejected": 2}


def _fmt(x: float) -> str:
    return f"{x:.4g}"


def judge_quantity(key: str, p: ScalarPayload | None, rule: ResultQualityConfig) -> QuantityQuality:
    """The verdict on one published number (``p``: as published; None when the report has none)."""
    unit = " %" if key == "droop" else ""
    v = None if p is None else p.value
    if v is None:
        why = f": {p.reason}" if p is not None and p.reason else ""
        return QuantityQuality(level="rejected", reasons=[f"{key}: no finite value (not identifiable){why}"])
    rejected: list[str] = []
    uncertain: list[str] = []
    if key == "droop" and not rule.droop_min_pct <= v <= rule.droop_max_pct:
        rejected.append(f"droop: {_fmt(v)} % outside the plausible {_fmt(rule.droop_min_pct)}-"
                        f"{_fmt(rule.droop_max_pct)} %")
    lo, hi = p.ci95
    if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):  # unknown: never ok
        rejected.append(f"{key}: no finite 95 % interval")
        return QuantityQuality(level="rejected", reasons=rejected)
    span = f"[{_fmt(lo)}, {_fmt(hi)}]{unit}"
    tol = 1e-9 * abs(v)
    if hi < lo:
        rejected.append(f"{key}: 95 % interval {span} inverted")
    elif hi == lo:  # a point estimate: nothing says how far to trust it
        uncertain.append(f"{key}: 95 % interval {span} has zero width (no uncertainty estimate)")
    elif not lo - tol <= v <= hi + tol:
        rejected.append(f"{key}: {_fmt(v)}{unit} outside its own 95 % interval {span}")
    else:
        rel = (hi - lo) / abs(v) if v != 0 else math.inf
        if rel > rule.reject_ci_rel_width:
            rejected.append(f"{key}: 95 % interval {span} is {rel:.3g}x the value wide "
                            f"(rejected above {_fmt(rule.reject_ci_rel_width)}x)")
        elif rel > rule.uncertain_ci_rel_width:
            uncertain.append(f"{key}: 95 % interval {span} is {rel:.3g}x the value wide "
                             f"(uncertain above {_fmt(rule.uncertain_ci_rel_width)}x)")
    if rejected:
        return QuantityQuality(level="rejected", reasons=rejected + uncertain)
    return QuantityQuality(level="uncertain" if uncertain else "ok", reasons=uncertain)


def judge(report: IdentifyReport, rule: ResultQualityConfig | None = None) -> ResultQuality:
    """The verdict on an identification report: each headline number judged by :func:`judge_quantity`
    (the droop always: a report without one is rejected), the run at the worst level."""
    rule = rule or ResultQualityConfig()
    scalars = headline_scalars(report)
    quantities: dict[str, QuantityQuality] = {}
    for key in HEADLINE_SCALARS:
        if key in scalars or key == "droop":
            quantities[key] = judge_quantity(key, scalars.get(key), rule)
    level = max((q.level for q in quantities.values()), key=_ORDER.__getitem__, default="ok")
    return ResultQuality(level=level, reasons=[x for q in quantities.values() for x in q.reasons],
                         quantities=quantities, not_identifiable=not_identifiable(report))


def failed(error: str) -> ResultQuality:
    """The verdict of a run that gave no result (skipped or failed): rejected, the error as reason."""
    return ResultQuality(level="rejected", reasons=[error])
