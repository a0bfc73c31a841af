"""Which numbers of an identification may be shown: a value with a usable 95 % interval, or null with the
reason (issue 12, "an honest result per quantity").

One place for the rules, applied by :func:`fcrlive.analysis.identify.identify_full` to every report, so
``fcrlive identify``, the daemon (its result-quality rule and MQTT topics) and ``fcrlive prequal`` give
the same verdicts. A withheld quantity is null (``value`` and ``ci95`` None) with its ``reason``, the
same reason is in ``IdentifyReport.not_identifiable`` under the quantity's key (the mechanism lowband's
coherence gate already uses, :func:`fcrlive.analysis.report.build_report`), and a warning says it once.

The rules, per scalar quantity (droop, G_1(0), max|G_1|, max|S|; :data:`QUANTITIES`):

- :func:`withhold_wide`: its 95 % interval is missing or not finite (a model without a covariance: the
  uncertainty is unknown, never zero), of zero width, inverted, does not contain the value, or is wider
  than |value|. An interval wider than its value says the log cannot tell the value from zero or from
  twice itself: no number one can use.
- :func:`zur_not_converged`: the Z_ur prediction-error search stopped without converging
  (:data:`ZUR_NOT_CONVERGED`): every quantity of Z_ur (all come from that one fit) is withheld, with the
  search's own stop reason.
- the droop of a sine-test evaluation is the plant description's setting, not a measurement
  (:data:`SINE_DROOP`).

Pure: no I/O. Units as in the report (droop a fraction, shown in % in the reasons).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from fcrlive.analysis.report import IdentifyReport, PeakCI, ValueCI

NOT_IDENTIFIABLE = "not identifiable from this log"
"""How every reason of the width rule begins (lowband's coherence gate says the same)."""

WIDE_HINT = "too little movement of frequency and power in the log for it"
"""Why an interval is wide, in words a plant owner can act on."""

QUANTITIES: tuple[tuple[str, str, float, str], ...] = (
    ("droop", "the droop", 100.0, " %"),
    ("g1_static", "G_1(0)", 1.0, ""),
    ("max_abs_g1", "max|G_1|", 1.0, ""),
    ("max_abs_s", "max|S|", 1.0, ""),
)
"""(report key, label, display scale, unit) of the scalar quantities the rules judge."""

ZUR_NOT_CONVERGED = "Z_ur search did not converge: {stop}; no quantity of Z_ur is identifiable from this log"
"""Reason of every Z_ur quantity when its Box-Jenkins search did not converge (``{stop}``: the search's
stop reason, e.g. "maximum number of iterations (78) reached")."""

SINE_DROOP = (
    "not measured by the sine tests: {droop:.3g} % is the droop setting of the plant description, used "
    "only to normalise F"
)
"""Reason of the droop of a sine-test evaluation: it is the setting, not an estimate (no interval)."""

ZUR_QUANTITIES = ("droop", "g1_static", "max_abs_g1", "max_abs_s", "gp", "tso")
"""Everything Z_ur reports (G_1, S and G_p = (1 − S)/G_1 all come from its one fit)."""


def _g(x: float) -> str:
    return f"{x:.3g}"


def withhold_wide(
    value: float | None,
    ci95: tuple[float | None, float | None],
    *,
    label: str = "the value",
    scale: float = 1.0,
    unit: str = "",
) -> str | None:
    """The reason to withhold one quantity (module docstring), or None when it may be shown.

    ``value`` and ``ci95`` in the report's units; ``scale`` and ``unit`` only format the reason (100 and
    " %" for the droop). A null value (None) is not judged: it is already withheld or not given."""
    if value is None:
        return None
    if not math.isfinite(value):
        return f"{NOT_IDENTIFIABLE}: {label} came out {value}, not a number"
    v = scale * value
    lo, hi = ci95
    if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
        return (f"{NOT_IDENTIFIABLE}: {label} {_g(v)}{unit} has no 95 % interval (the model gives no "
                "covariance: its uncertainty is unknown)")
    lo_s, hi_s = scale * lo, scale * hi
    span = f"[{_g(lo_s)}, {_g(hi_s)}]{unit}"
    if hi < lo:
        return f"{NOT_IDENTIFIABLE}: the 95 % interval {span} of {label} is inverted"
    if hi == lo:
        return (f"{NOT_IDENTIFIABLE}: the 95 % interval {span} of {label} has zero width (no uncertainty "
                "estimate, not an exact value)")
    tol = 1e-9 * abs(value)
    if not lo - tol <= value <= hi + tol:
        return f"{NOT_IDENTIFIABLE}: {label} {_g(v)}{unit} lies outside its own 95 % interval {span}"
    if hi - lo > abs(value):
        return (f"{NOT_IDENTIFIABLE}: {label} {_g(v)}{unit} with a 95 % interval {span} wider than the "
                f"value ({WIDE_HINT})")
    return None


def zur_not_converged(converged: bool, stop_reason: str) -> dict[str, str]:
    """``not_identifiable`` entries for a Z_ur fit: every Z_ur quantity when its search did not converge
    (:data:`ZUR_NOT_CONVERGED`), else none."""
    if converged:
        return {}
    why = ZUR_NOT_CONVERGED.format(stop=stop_reason or "no stop reason given")
    return dict.fromkeys(ZUR_QUANTITIES, why)


def _null(key: str, reason: str) -> ValueCI:
    if key.startswith("max_abs"):
        return PeakCI(value=None, ci95=(None, None), omega=None, reason=reason)
    return ValueCI(value=None, ci95=(None, None), reason=reason)


def withhold(report: IdentifyReport, not_identifiable: Mapping[str, str] | None = None) -> IdentifyReport:
    """The report with every rule applied (module docstring): the quantities in ``not_identifiable``
    (key -> reason, e.g. :func:`zur_not_converged`; they override the report's) and those the width rule
    rejects null with their reason, listed in the report's ``not_identifiable``, each reason once in the
    warnings. ``gp`` in ``not_identifiable`` nulls G_p, F and the TSO checks, ``tso`` the TSO checks,
    ``max_abs_s`` also the local checks (eq. 9-10, margins: the same S and loop). The report itself when
    nothing is withheld."""
    given = dict(not_identifiable or {})
    ni = {**report.not_identifiable, **given}
    update: dict = {}
    warnings = list(report.warnings)

    def warn(why: str) -> None:
        if why not in warnings:
            warnings.append(why)

    for key, label, scale, unit in QUANTITIES:
        v = getattr(report, key)
        if key in given:
            update[key] = _null(key, given[key])
            warn(given[key])
            continue
        if v is None or v.value is None:
            continue
        why = withhold_wide(v.value, v.ci95, label=label, scale=scale, unit=unit)
        if why is not None:
            update[key] = _null(key, why)
            ni[key] = why
            warn(why)
    if "gp" in given:  # the TSO checks are made from G_p
        update.update(gp=None, f=None, tso=None)
    if "tso" in given:
        update["tso"] = None
    if "max_abs_s" in given:  # eq. 9-10 and the loop margins come from the same S and L
        update["local"] = None
    if not update:
        return report
    update.update(not_identifiable=ni, warnings=warnings)
    return report.model_copy(update=update)
