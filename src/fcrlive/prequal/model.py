"""Result types of the prequalification evaluation (TR v1.1 Table 2): frozen dataclasses, no I/O.

One :class:`PrequalResult` per evaluated directory: every test file's :class:`TestEvaluation` (its
requirements as :class:`RequirementResult`, its figures, and the series a report plots), the
:class:`Capacity` per service and the :class:`Verdict` per service. Every result names the document
whose limits it applied (:class:`DocumentSpec`): the Nordic TR v1.1 and Statnett's 2024 support
document differ (Req. 4: 2.5 s vs 1.7 s).

Units: power MW, frequency Hz, time s, energy MW·s; K_red factors dimensionless.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Literal

import numpy as np

from fcrlive.plant.description import OperatingPoint, PrequalUnit

__all__ = [
    "DOCUMENTS",
    "Capacity",
    "Curve",
    "DocumentSpec",
    "FrequencyPoint",
    "Marker",
    "OperatingPoint",
    "PrequalResult",
    "PrequalUnit",
    "RequirementResult",
    "Series",
    "TestEvaluation",
    "Verdict",
    "document_spec",
]

Service = Literal["Fcrn", "FcrdUp", "FcrdDo"]
"""The services of the TSO file names."""

SERVICES: tuple[str, ...] = ("Fcrn", "FcrdUp", "FcrdDo")

Kind = Literal[
    "fcrn-steps",  # TR Table 3 (test IDs 1.x)
    "fcrd-ramps",  # TR Table 4, dynamic FCR-D fast ramps (2.x up, 3.x down)
    "fcrd-static",  # TR Table 5, static FCR-D ramp test
    "linearity",  # TR Section 3.4.2 step sequences (5.x, 6.x, 7.x)
    "sine",  # one sine period (4.x + period): Req. 10 and one point of F
    "sine-set",  # all sine periods of one service together: Req. 8 and 9
    "operation",  # normal operation: Req. 8 and 9 from the identification
]


# --------------------------------------------------------------------------------------------------
# Which document's limits


@dataclass(frozen=True)
class DocumentSpec:
    """The document a result was evaluated against, and the limits in which the documents differ."""

    key: str
    """``nordic-2025`` or ``statnett-2024`` (the ``--document`` option)."""
    title: str
    deactivation_limit_s: float
    """Req. 4: the deactivation energy limit in seconds times |ΔP_ss,theo| (2.5 s / 1.7 s)."""
    req1b_ramps: tuple[str, ...] = ("7", "8")
    """Req. 1b is evaluated for these ramps (TR: 6-7 and 6-8; Statnett 5.1.5: 6-8 only)."""
    req1b_fcrn_denominator: bool = False
    """Req. 1b relative to |ΔP_FCR-N| alone (Statnett) instead of the combined expected response (TR)."""
    req7_per_second: bool = False
    """Req. 7 (static FCR-D deactivation): Statnett 5.2.8 |P(t)| − |P(t+1 s)| ≤ 0.025·|ΔP_ss,theo|; TR
    10 s window ≤ 0.25·|ΔP_ss,theo| and 1 s steps ≤ 0.2·|ΔP_ss,theo|."""
    req11_static_relative: bool = False
    """Req. 11 for static FCR-D relative to each step's target (Statnett 5.2.11: 0.95 ≤ |ΔP̄|/|target| ≤ 1.1)
    instead of the TR's bounds in |ΔP_ss,theo|."""


DOCUMENTS: Mapping[str, DocumentSpec] = MappingProxyType(
    {
        "nordic-2025": DocumentSpec(
            "nordic-2025",
            "Technical Requirements for Frequency Containment Reserve Provision in the Nordic "
            "Synchronous Area, v1.1, 28 March 2025",
            2.5,
        ),
        "statnett-2024": DocumentSpec(
            "statnett-2024",
            "Statnett, Støttedokument for krav til FCR (support document), 2024-01-05",
            1.7,
            req1b_ramps=("8",),
            req1b_fcrn_denominator=True,
            req7_per_second=True,
            req11_static_relative=True,
        ),
    }
)


def document_spec(key: str) -> DocumentSpec:
    """The :class:`DocumentSpec` for ``key``; ValueError naming the known keys otherwise."""
    try:
        return DOCUMENTS[key]
    except KeyError:
        raise ValueError(f"unknown document {key!r}: one of {', '.join(DOCUMENTS)}") from None


# --------------------------------------------------------------------------------------------------
# One requirement


Comparison = Literal[">=", "<=", ">", "<", "within", "info"]


@dataclass(frozen=True)
class RequirementResult:
    """One requirement evaluated on one test.

    ``value`` is compared with ``limit`` as ``comparison`` says: ``">="`` (value ≥ limit), ``"<="``,
    ``">"``, ``"<"``, or ``"within"`` (``limit`` is the closed interval (lo, hi)). ``passed`` is None
    when the data cannot decide: the requirement could not be evaluated (``value`` None, ``note``
    says why) or, for an estimate with an uncertainty, its interval ``value_interval`` straddles
    the limit ('undecided').
    """

    number: str
    """The requirement's number in the TR: "1", "1b", "2", "5a", "8" ..."""
    title: str
    value: float | None
    limit: float | tuple[float, float] | None
    unit: str
    """Unit of ``value`` and ``limit``: "MW", "MWs", "pu", "" (a ratio) ..."""
    passed: bool | None
    comparison: Comparison = ">="
    note: str = ""
    value_interval: tuple[float, float] | None = None
    """A 95 % interval of ``value`` when it is an estimate (identification from operation)."""
    document: str = ""
    """The document key whose limit was applied (e.g. ``nordic-2025``)."""
    k_red: float | None = None
    """For a requirement the TR lets a capacity reduction cure (Req. 1, 2, 3, 9): the largest factor
    K ≤ 1 with which it is met (1.0 when met as is); None when no factor cures it or none applies."""

    @property
    def status(self) -> str:
        """``pass``, ``fail`` or ``undecided`` (not evaluable or uncertain across the limit)."""
        return "undecided" if self.passed is None else ("pass" if self.passed else "fail")


# --------------------------------------------------------------------------------------------------
# What a report plots


@dataclass(frozen=True, eq=False)
class Curve:
    """A reference curve drawn with a test's series: a limit, an allowed band, a theoretical response.

    ``axis`` says which series it belongs with (``power`` in MW, ``frequency`` in Hz, or ``energy``
    in MW·s). ``lower``/``upper``, when given, make it a band (``value`` then the centre line or
    NaN).
    """

    label: str
    t_s: np.ndarray
    value: np.ndarray
    axis: Literal["power", "frequency", "energy"] = "power"
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None
    requirement: str = ""
    """The requirement number it illustrates ("2", "4" ...), "" when none."""


@dataclass(frozen=True)
class Marker:
    """A point drawn on a test's plot: where a requirement was read (e.g. ΔP at 7.5 s)."""

    label: str
    t_s: float
    value: float
    axis: Literal["power", "frequency", "energy"] = "power"
    requirement: str = ""


@dataclass(frozen=True, eq=False)
class Series:
    """The time series of one test for plotting: t from the start of the file [s]."""

    t_s: np.ndarray
    applied_freq_hz: np.ndarray
    """The applied frequency (ApplFreqSig; GridFreq in operation) [Hz]."""
    power_mw: np.ndarray
    """Active power (InsAcPow) [MW]."""
    curves: tuple[Curve, ...] = ()
    markers: tuple[Marker, ...] = ()
    power_baseline_mw: float = float("nan")
    """The power the response ΔP is counted from [MW] (P before the activation)."""


@dataclass(frozen=True)
class FrequencyPoint:
    """One point of F(jω) (normalised FCR response) from a sine test or the identification."""

    period_s: float
    F: complex
    F_sd: float = float("nan")
    """Standard deviation of F (circular: sqrt(E|F − F̂|²)); NaN when unknown."""
    linearity: float = float("nan")
    """Req. 10 ratio of that period (sine tests); NaN otherwise."""


# --------------------------------------------------------------------------------------------------
# One test


@dataclass(frozen=True, eq=False)
class TestEvaluation:
    """One evaluated test: a TSO file (or, for ``sine-set``, the sine files of one service)."""

    __test__ = False  # not a pytest test class

    file: str
    """The file name (for ``sine-set``: the files joined with ', ')."""
    service: str
    """``Fcrn``, ``FcrdUp`` or ``FcrdDo``."""
    test_id: str
    """Test ID of TR Appendix 2 Table 21 ("1.1", "2.3", "4.1" ...), or ``Operation``."""
    kind: str
    """One of :data:`Kind`."""
    requirements: Mapping[str, RequirementResult]
    """Keyed by requirement number as a string; a requirement evaluated twice in one test is keyed
    "1-up"/"1-down" (FCR-N steps), "1b-7"/"1b-8" (ramps 7 and 8), "11-1" ... (linearity steps)."""
    figures: Mapping[str, float]
    """Named figures: ``dp_ss_mw``, ``dp_ss_theo_mw``, ``dp_7p5s_mw``, ``e_7p5s_mws``,
    ``deactivation_mws``, ``k_red_ss``, ``k_red_dyn``, ``p_ss_0_mw`` ... (MW, MW·s, s, 1)."""
    checks: Mapping[str, RequirementResult] = field(default_factory=dict)
    """Measurement-chain checks (TR Section 4): ``sampling``, ``power_resolution``,
    ``frequency_resolution``, ``accuracy`` (stated)."""
    series: Series | None = None
    points: tuple[FrequencyPoint, ...] = ()
    """F(jω) points (sine tests, sine set, operation)."""
    operating_point: str = ""
    """The operating point of the test ID ("high load, high droop"), "" when not known."""
    files: tuple[str, ...] = ()
    """Every file the evaluation used (one, or the sine files of a ``sine-set``)."""
    notes: tuple[str, ...] = ()

    @property
    def passed(self) -> bool | None:
        """False if any requirement failed, None if any is undecided, else True."""
        states = [r.passed for r in self.requirements.values()]
        if any(s is False for s in states):
            return False
        if any(s is None for s in states):
            return None
        return True


# --------------------------------------------------------------------------------------------------
# Per service


@dataclass(frozen=True)
class Capacity:
    """Reduction factors and capacity of one service: C = min(K_red,ss, K_red,dyn)·|ΔP_ss,theo| (eqs. 3, 5).

    One reduction factor for all operating points (the TR allows that or one per point): the smallest
    found over the tests. A factor is None when no test determined it (then it counts as 1 in C only if
    the other one is known; ``capacity_mw`` is None when neither is).
    """

    service: str
    k_red_ss: float | None
    k_red_dyn: float | None
    capacity_mw: float | None
    dp_ss_theo_mw: float | None
    """|ΔP_ss,theo| the capacity is computed from [MW] (the largest over the tested points)."""
    k_min: float
    """The smallest factor the TR allows: 0.9 (FCR-N), 0.75 (FCR-D)."""
    from_tests: tuple[str, ...] = ()
    """Files that determined the factors."""
    note: str = ""


@dataclass(frozen=True)
class Verdict:
    """Whether a service prequalifies from the evaluated files."""

    service: str
    status: Literal["pass", "fail", "incomplete"]
    missing: tuple[str, ...] = ()
    """What is needed but not there (a test type, an operating point, a requirement undecided)."""
    failed: tuple[str, ...] = ()
    """Requirements that failed, as "Req. N (file)"."""


@dataclass(frozen=True, eq=False)
class PrequalResult:
    """The evaluation of one application directory."""

    document: DocumentSpec
    unit: PrequalUnit | None
    tests: tuple[TestEvaluation, ...]
    capacity: Mapping[str, Capacity]
    verdict: Mapping[str, Verdict]
    notes: tuple[str, ...] = ()
    unit_name: str = ""
    """The [unit] name of the description, "" without one."""
    checks: Mapping[str, RequirementResult] = field(default_factory=dict)
    """Application-level checks: the stated measurement accuracy (TR 4.1) against Table 15."""


def requirement_status(passed: bool | None) -> str:
    """``pass``/``fail``/``undecided`` for a RequirementResult.passed value."""
    return "undecided" if passed is None else ("pass" if passed else "fail")


