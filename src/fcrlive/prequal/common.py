"""What every evaluation of one test needs: the context (document, service, ΔP_ss,theo) and small
builders of :class:`~fcrlive.prequal.model.RequirementResult`. Pure."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fcrlive.prequal.model import DocumentSpec, RequirementResult

K_RED_MIN: dict[str, float] = {"Fcrn": 0.9, "FcrdUp": 0.75, "FcrdDo": 0.75}
"""Smallest capacity reduction factor the TR allows (eq. 3: FCR-N 0.9; 3.1.2 and 3.3: FCR-D 0.75)."""
K_RED_DYN_MIN_STATIC = 0.84
"""Static FCR-D: K_red,dyn for Req. 2 and 3 between 0.84 and 1 (TR 3.1.3)."""

BAND_HZ: dict[str, float] = {"Fcrn": 0.1, "FcrdUp": 0.4, "FcrdDo": 0.4}


@dataclass(frozen=True)
class Context:
    """One test's evaluation context. ``dp_theo`` is |ΔP_ss,theo| [MW] for the test's service at its
    operating point (None when unknown: the requirements that need it are then undecided)."""

    document: DocumentSpec
    service: str
    test_id: str
    file: str
    dp_theo: float | None
    dp_theo_source: str = ""
    dp_theo_fcrn: float | None = None
    """|ΔP_ss,theo| of FCR-N at the same point [MW] (Req. 1b)."""
    operating_point: str = ""
    mode_shifting: bool = False
    fcrd_static: bool = False
    """The unit provides static FCR-D (TR 3.1.3)."""
    rated_mw: float | None = None
    t_fme_s: float | None = None
    fcrn_exemption: bool = False
    H: float | None = None
    Kd: float | None = None
    f0_hz: float = 50.0

    @property
    def sign(self) -> float:
        """+1 where the response is an increase of power (FCR-N upwards, FCR-D up), −1 for FCR-D down."""
        return -1.0 if self.service == "FcrdDo" else 1.0

    @property
    def up(self) -> bool:
        return self.service != "FcrdDo"


NO_DP = "ΔP_ss,theo unknown: give it in the unit description ([unit.prequal] points) or log RegStr_<service>"


def _f(x) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def within(number, title, value, lo, hi, unit, ctx: Context, note="", k_red=None) -> RequirementResult:
    """lo ≤ value ≤ hi."""
    v = _f(value)
    passed = None if v is None else bool(lo <= v <= hi)
    return RequirementResult(
        number,
        title,
        v,
        (float(lo), float(hi)),
        unit,
        passed,
        "within",
        note,
        document=ctx.document.key,
        k_red=k_red,
    )


_POINT = object()
"""compare()'s default: decide by the point value."""


def compare(
    number,
    title,
    value,
    limit,
    unit,
    ctx: Context,
    op=">=",
    note="",
    interval=None,
    k_red=None,
    passed=_POINT,
) -> RequirementResult:
    """value op limit; ``passed`` (True/False/None) overrides the point comparison (e.g. an uncertain
    estimate: None for undecided)."""
    v = _f(value)
    if passed is _POINT:
        passed = (
            None
            if v is None
            else bool({">=": v >= limit, "<=": v <= limit, ">": v > limit, "<": v < limit}[op])
        )
    return RequirementResult(
        number, title, v, float(limit), unit, passed, op, note, interval, ctx.document.key, k_red
    )


def undecided(number, title, unit, ctx: Context, note, limit=None, op=">=") -> RequirementResult:
    return RequirementResult(number, title, None, limit, unit, None, op, note, document=ctx.document.key)


def k_red_ss(responses: list[float], dp_theo: float, under: float, over: float) -> float | None:
    """The steady-state reduction factor (TR 3.1.1-3.1.2 'Requirement 1 with reduction factor'):
    the largest K ≤ 1 with −under ≤ d/(K·ΔP) − 1 ≤ over for every oriented response d. None when no
    K > 0 works (over-delivery cannot be cured by a smaller K)."""
    if dp_theo <= 0 or not responses:
        return None
    hi = min([1.0] + [d / ((1 - under) * dp_theo) for d in responses])
    lo = max(d / ((1 + over) * dp_theo) for d in responses)
    if hi <= 0 or hi < lo - 1e-12:
        return None
    return float(hi)


def ss_window(p_t_change: float, p_t_end: float, width_s: float = 60.0) -> tuple[float, float]:
    """The window a plateau's steady-state power is averaged over: its last ``width_s`` seconds, or its
    second half when it is shorter than 2·width_s."""
    dur = p_t_end - p_t_change
    w = min(width_s, 0.5 * dur)
    return p_t_end - w, p_t_end


def finite(x) -> bool:
    return x is not None and bool(np.isfinite(x))
