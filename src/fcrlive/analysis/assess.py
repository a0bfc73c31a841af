"""Assessment of an identified experiment: droop, peaks, local requirements, margins, TSO checks.

Input: an :class:`fcrlive.analysis.experiments.ExperimentResult` (closed-loop methods) or a
:class:`~fcrlive.analysis.experiments.SineExperiment`. Output: a frozen :class:`Assessment`.

- Droop: effective droop ρ_eff = 1/(1/G_1(0) − K_d) (K_d = 0 unless given) from G_1(1) of the discrete
  model, the interval by the monotone map of the 95 % interval of G_1(1) (analysis.local).
- max|G_1| and max|S| over the PEAK BAND (1e-3 rad/s, ω_peak) with their ω and the first-order sd of the
  maximum (PeakGain); eq. (9) and (10) by analysis.local over the same band; gain/phase/stability margins
  of L = G_p G_J up to the Nyquist frequency of the identification rate. ω_peak = min(2π/T_min,
  ``PEAK_PASSBAND_FRACTION`` × the anti-aliasing passband edge 0.8·π/Ts), T_min = ``peak_min_period_s``
  (default :data:`PEAK_MIN_PERIOD_S` = 4 s, ω ≤ 1.57 rad/s): above it the decimated data carry little
  information (filter roll-off, a few samples per period) and a fitted model's gain there is an
  artefact of its structure, not a measurement. The FCR band of interest is 10-300 s and the peaks of
  G_1 and S sit at 0.14-0.3 rad/s (periods 20-45 s). On Z_u (no excitation) the unrestricted search
  found "peaks" at the Nyquist frequency 6.28 rad/s, +135 … +760 % above the true maximum.
- TSO: F = G_p/G_p(0) (unit static gain; the TSO's normalisation with ΔP_ss,theo from the identified
  droop), optionally times F_FME; Req. 8 in the 10-300 s band and over (1e-4 rad/s, Nyquist) with the
  encirclement count, Req. 9 with K_red,dyn (analysis.tso_checks), both with the 95 % bounds from the
  sd of F.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fcrlive.analysis import local
from fcrlive.analysis.experiments import ExperimentResult, SineExperiment
from fcrlive.analysis.quality import WARN_G1_0, WARN_GP0, WARN_MAX_S
from fcrlive.analysis.tso_checks import TsoVerdict, assess_tso, assess_tso_points, fme_response
from fcrlive.constants import TSO_PERIODS_S, Z95
from fcrlive.gridsearch import uncertain_peak
from fcrlive.ident import FreqResp, PeakGain

OMEGA_MIN = 1e-3
"""Lower end [rad/s] of the grid for peaks and margins (a 6000 s period)."""
PEAK_MIN_PERIOD_S = 4.0
"""Default shortest period [s] of the peak band for max|G_1|, max|S| and eq. 9-10 (module docstring)."""
PEAK_PASSBAND_FRACTION = 0.5
"""The peak band also ends at this fraction of the anti-aliasing passband edge 0.8·π/Ts."""


def peak_band(ts_id: float, peak_min_period_s: float = PEAK_MIN_PERIOD_S) -> tuple[float, float]:
    """(ω_min, ω_max) [rad/s] in which max|G_1| and max|S| are searched (module docstring)."""
    if not peak_min_period_s > 0:
        raise ValueError(f"peak_min_period_s must be positive, got {peak_min_period_s}")
    nyq = np.pi / float(ts_id)
    hi = min(2 * np.pi / peak_min_period_s, PEAK_PASSBAND_FRACTION * 0.8 * nyq, 0.999 * nyq)
    return OMEGA_MIN, float(max(hi, 2 * OMEGA_MIN))


@dataclass(frozen=True)
class Interval:
    """A value with its 95 % interval [lo, hi]; lo and hi are NaN when the uncertainty is unknown."""

    value: float
    lo: float
    hi: float


@dataclass(frozen=True)
class PeakEstimate:
    value: float
    omega: float
    sd: float

    @property
    def ci95(self) -> tuple[float, float]:
        return (max(self.value - Z95 * self.sd, 0.0), self.value + Z95 * self.sd)


@dataclass(frozen=True)
class PeriodPoint:
    """A response at one TSO period, with the 95 % interval of its magnitude."""

    period_s: float
    value: complex
    abs_lo: float
    abs_hi: float


@dataclass(frozen=True, eq=False)
class Assessment:
    method: str
    kd: float
    g1_static: Interval | None
    droop: Interval | None
    max_g1: PeakEstimate | None
    max_s: PeakEstimate | None
    gp_kind: str
    """"G_p" for the closed-loop methods, "G_req" for sine tests."""
    gp: tuple[PeriodPoint, ...] | None
    f: tuple[PeriodPoint, ...] | None
    tso: dict[str, TsoVerdict] | None
    sensitivity: local.SensitivityCheck | None
    disturbance: local.DisturbanceCheck | None
    margins: local.LoopMargins | None
    warnings: tuple[str, ...] = ()
    peak_band: tuple[float, float] | None = None
    """(ω_min, ω_max) [rad/s] of the search for max|G_1|, max|S| and eq. 9-10 (None for sine tests)."""
    responses: object = field(default=None, compare=False)
    """ω → dict of FreqResp (closed-loop methods), for plots."""
    F_callable: object = field(default=None, compare=False)
    F_sd_callable: object = field(default=None, compare=False)
    not_identifiable: dict[str, str] = field(default_factory=dict)
    """Report key → reason, from the experiment (ExperimentResult.not_identifiable): null in the report."""


def _peak(fr_fun, key: str, omega_max: float) -> PeakEstimate:
    pk: PeakGain = uncertain_peak(lambda w: fr_fun(w)[key], OMEGA_MIN, omega_max, 1000)
    return PeakEstimate(pk.value, pk.omega, pk.sd)


def _memo(fr_fun, size: int = 256):
    """fr_fun with its last ``size`` results kept by ω (the TSO checks ask value and sd at the same ω)."""
    cache: dict[bytes, dict] = {}

    def f(w):
        w = np.atleast_1d(np.asarray(w, float))
        k = w.tobytes()
        hit = cache.get(k)
        if hit is None:
            if len(cache) >= size:
                cache.pop(next(iter(cache)))
            hit = cache[k] = fr_fun(w)
        return hit

    return f


def _callable(fr_fun, key: str, scale: float = 1.0, what: str = "value"):
    def f(w):
        w = np.asarray(w, float)
        g = fr_fun(np.maximum(w.ravel(), 1e-9))[key]
        v = g.value if what == "value" else np.hypot(g.sd_real, g.sd_imag)
        return (v * scale).reshape(w.shape)

    return f


def _period_points(fr: FreqResp, scale: float = 1.0) -> tuple[PeriodPoint, ...]:
    lo, hi = fr.ci95_abs()
    return tuple(
        PeriodPoint(float(2 * np.pi / w), complex(v * scale), float(a * scale), float(b * scale))
        for w, v, a, b in zip(fr.omega, fr.value, lo, hi)
    )


def assess(
    result: ExperimentResult | SineExperiment,
    *,
    kd: float = 0.0,
    t_fme_s: float | None = None,
    products=("fcrn", "fcrd"),
    peak_min_period_s: float = PEAK_MIN_PERIOD_S,
) -> Assessment:
    """Everything the report shows, from one experiment (module docstring).

    ``peak_min_period_s``: shortest period of the band in which max|G_1|, max|S| and eq. 9-10 are
    evaluated (:func:`peak_band`).
    """
    if isinstance(result, SineExperiment):
        return _assess_sine(result, t_fme_s=t_fme_s, products=products)
    warns = list(result.warnings)
    ni = dict(result.not_identifiable)
    fr = _memo(result.responses)
    wmax = result.omega_max * 0.999
    band = peak_band(result.Ts, peak_min_period_s)
    wpk = band[1]
    g1_0 = fr(np.array([1e-7]))["G_1"]
    g = float(g1_0.value.real[0])
    sd = float(g1_0.sd_real[0])
    g1_static = Interval(g, g - Z95 * sd, g + Z95 * sd)
    droop = None
    if g > 0:
        d = local.effective_droop(g, kd, sd=sd)
        droop = Interval(d.value, d.lower, d.upper)
    elif "g1_static" not in ni:  # a withheld fit (ExperimentResult.not_identifiable) quotes no numbers
        warns.append(f"{WARN_G1_0}{g:.3g} is not positive: no droop")
    max_g1 = _peak(fr, "G_1", wpk)
    G1c = _callable(fr, "G_1")
    # eq. 10 comes from the same G_1 as max|G_1|
    dist = None if "max_abs_g1" in ni else local.check_disturbance_rejection(G1c, omega_range=band)
    max_s = sens = margins = None
    gp = f = tso = None
    F = F_sd = None
    if "S" in result.identifiable:
        max_s = _peak(fr, "S", wpk)
        sens = local.check_sensitivity(
            _callable(fr, "S"), omega_range=band, S_sd=_callable(fr, "S", what="sd")
        )
        R = fr(np.array([1e-7]))
        L = lambda w: _callable(fr, "G_p")(w) * _callable(fr, "G_J")(w)  # noqa: E731
        margins = local.loop_margins(L, (OMEGA_MIN, wmax), n=4000)
        gp0 = float(R["G_p"].value.real[0])
        w_t = 2 * np.pi / np.array(TSO_PERIODS_S)
        Gp_t = fr(w_t)["G_p"]
        gp = _period_points(Gp_t)
        if gp0 > 0:
            f = _period_points(Gp_t, 1.0 / gp0)
            F = _callable(fr, "G_p", 1.0 / gp0)
            F_sd = _callable(fr, "G_p", 1.0 / gp0, what="sd")
            if t_fme_s is not None:
                fme = fme_response(t_fme_s)
                F0, Fs0 = F, F_sd
                F = lambda w: F0(w) * fme(w)  # noqa: E731
                F_sd = lambda w: Fs0(w) * np.abs(fme(w))  # noqa: E731
            tso = assess_tso(F, products=products, omega_wide=(1e-4, wmax), F_sd=F_sd)
        elif "g1_static" not in ni:
            warns.append(f"{WARN_GP0}{gp0:.3g} is not positive: TSO checks skipped")
        if "max_abs_s" in ni:  # eq. 9 and the margins come from the same S and loop
            sens = margins = None
        elif not sens.passed:
            warns.append(f"{WARN_MAX_S}{sens.max_s:.3f} ≥ M_s = {sens.ms:g}")
    return Assessment(
        result.method,
        kd,
        g1_static,
        droop,
        max_g1,
        max_s,
        "G_p",
        gp,
        f,
        tso,
        sens,
        dist,
        margins,
        tuple(warns),
        band,
        fr,
        F,
        F_sd,
        ni,
    )


def _assess_sine(result: SineExperiment, *, t_fme_s, products) -> Assessment:
    warns = list(result.warnings)
    w = result.omega
    Greq = result.G_req
    sd = result.G_req_sd
    gp = tuple(
        PeriodPoint(
            float(2 * np.pi / wi), complex(v), float(max(abs(v) - Z95 * s, 0.0)), float(abs(v) + Z95 * s)
        )
        for wi, v, s in zip(w, Greq, sd)
    )
    warns.append(
        "sine tests: G_req (G_p through the grid's low-pass, paper eq. 12-13) at the tested periods "
        "only; no G_1, S, droop interval or closed-loop stability from them"
    )
    if not np.isfinite(result.droop):
        return Assessment(
            "sine", 0.0, None, None, None, None, "G_req", gp, None, None, None, None, None, tuple(warns)
        )
    Fv = result.F
    if t_fme_s is not None:
        Fv = Fv * fme_response(t_fme_s)(w)
    f = tuple(
        PeriodPoint(
            float(2 * np.pi / wi), complex(v), float(max(abs(v) - Z95 * s, 0.0)), float(abs(v) + Z95 * s)
        )
        for wi, v, s in zip(w, Fv, result.F_sd)
    )
    tso = assess_tso_points(w, Fv, F_sd_values=result.F_sd, products=products)
    # the droop setting used to normalise F, not a measurement: its interval is unknown (NaN), not zero
    droop = Interval(result.droop, float("nan"), float("nan"))
    return Assessment(
        "sine", 0.0, None, droop, None, None, "G_req", gp, f, tso, None, None, None, tuple(warns)
    )
