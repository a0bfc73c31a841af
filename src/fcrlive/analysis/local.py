"""Local requirements of the paper (Section 3, eq. 7-10) and loop margins of L = G_p G_J.

Transfer functions are frequency-response callables ``fr(omega [rad/s]) -> complex`` (see
fcrlive.analysis.tso_checks.as_response). All quantities per unit on the machine base, speed in pu of f0.

- Eq. (9), local stability: max_Ω |S(jΩ)| < M_s with S = 1/(1 + G_p G_J). Default M_s = 1.5: robustness
  textbooks (Åström & Murray, *Feedback Systems*) call 1.2-2 reasonable; 1.5 guarantees a gain margin
  ≥ M_s/(M_s − 1) = 3 and a phase margin ≥ 2·arcsin(1/(2 M_s)) = 38.9°. The paper's plant 1 has 1.29.
- Eq. (10), local performance: |G_1(jΩ)|² φ_Pr(Ω) < σ²_ωreq for all Ω, G_1 = G_J S. Default
  σ_ωreq = 0.1/(50·3) pu: the frequency kept within ±0.1 Hz with 99.7 % probability, the same reasoning
  as the paper's Section 7.1. The disturbance spectrum's SHAPE is white (default) or integrated white
  noise (the simulation's stochastic load, ∝ 1/Ω²) or a callable; its LEVEL is rarely known, so the
  check reports the largest admissible level and passes/fails only when a level is given.
- Margins from a dense frequency grid (python-control's stability_margins needs a system object, not a
  callable): gain and phase crossovers refined by root finding, gain margin, phase margin and the
  stability margin min |1 + L| = 1/max|S|, with python-control's conventions.
- Droop: ρ_eff = 1/(1/G_1(0) − K_d), since G_1(0) = 1/(K_d + G_t(0)/ρ); intervals by the monotone map.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from fcrlive.analysis.tso_checks import as_response, evaluate
from fcrlive.constants import PAPER_EXCITATION_STD_PU, Z95
from fcrlive.errors import ConfigError
from fcrlive.gridsearch import log_grid, refined_min_grid

DEFAULT_MS = 1.5
"""Default bound M_s on max|S| (eq. 9); see the module docstring."""
DEFAULT_SIGMA_OMEGA_REQ_PU = PAPER_EXCITATION_STD_PU
"""Default σ_ωreq [pu of f0] (eq. 10): 0.1 Hz / (50 Hz · 3)."""
DEFAULT_OMEGA_RANGE = (1e-4, 10.0)
"""Default frequency range [rad/s] for peaks and margins of continuous-time models."""


def sensitivity(Gp, GJ) -> Callable[[np.ndarray], np.ndarray]:
    """S = 1/(1 + G_p G_J) (eq. 7) as a frequency-response callable."""
    a, b = as_response(Gp), as_response(GJ)
    return lambda w: 1.0 / (1.0 + evaluate(a, w) * evaluate(b, w))


def disturbance_rejection(Gp, GJ) -> Callable[[np.ndarray], np.ndarray]:
    """G_1 = G_J S = G_J/(1 + G_p G_J) (eq. 8) as a frequency-response callable."""
    a, b = as_response(Gp), as_response(GJ)
    return lambda w: evaluate(b, w) / (1.0 + evaluate(a, w) * evaluate(b, w))


def swing(H: float, Kd: float) -> Callable[[np.ndarray], np.ndarray]:
    """G_J(jω) = 1/(2 H jω + K_d) (eq. 1), H [s], K_d [pu]."""
    return lambda w: 1.0 / (2.0 * H * 1j * np.asarray(w, float) + Kd)


@dataclass(frozen=True)
class Peak:
    """max_ω |X(jω)| and where."""

    value: float
    omega: float
    """[rad/s]"""

    @property
    def period_s(self) -> float:
        return 2 * np.pi / self.omega if self.omega > 0 else float("inf")


def peak(fr, omega_range: tuple[float, float] = DEFAULT_OMEGA_RANGE, *, n: int = 3000) -> Peak:
    """max |fr(jω)| over omega_range [rad/s], refined around the grid maximum on nested grids
    (:func:`fcrlive.gridsearch.refined_min_grid`): an identified model's response costs more per call
    than per point, and Brent's 10-25 one-point calls were a fifth of an assessment's time."""
    f = as_response(fr)
    v, w = refined_min_grid(lambda x: -np.abs(evaluate(f, x)), log_grid(*omega_range, n))
    return Peak(-v, w)


@dataclass(frozen=True)
class SensitivityCheck:
    """Eq. (9): max|S| < M_s."""

    max_s: float
    omega: float
    """ω of the peak [rad/s]."""
    ms: float
    passed: bool
    max_s_upper: float | None = None
    """Peak at the upper 95 % bound (from S_sd), or None."""


def check_sensitivity(
    S,
    *,
    ms: float = DEFAULT_MS,
    omega_range: tuple[float, float] = DEFAULT_OMEGA_RANGE,
    S_sd=None,
    z: float = Z95,
) -> SensitivityCheck:
    """Eq. (9) on a response S (use :func:`sensitivity` to build it from G_p and G_J).

    ``S_sd``: optional callable of the standard deviation of S; the bound is max(|S| + z·sd).
    """
    p = peak(S, omega_range)
    up = None
    if S_sd is not None:
        sf, sd = as_response(S), as_response(S_sd)
        up = peak(lambda w: np.abs(evaluate(sf, w)) + z * np.abs(evaluate(sd, w)), omega_range).value
    return SensitivityCheck(p.value, p.omega, ms, bool(p.value < ms), up)


@dataclass(frozen=True)
class DisturbanceCheck:
    """Eq. (10): |G_1(jΩ)|²·φ(Ω) < σ²_ωreq for all Ω in the range."""

    worst_omega: float
    """Ω where |G_1|²·shape(Ω) is largest [rad/s]."""
    gain_sq_shape_max: float
    """max_Ω |G_1(jΩ)|²·shape(Ω) [pu²/pu² × shape units]."""
    sigma_req: float
    """σ_ωreq [pu of f0]."""
    admissible_level: float
    """Largest spectrum level λ (φ = λ·shape) that meets eq. (10): σ²/max(|G_1|² shape)."""
    level: float | None
    ratio: float | None
    """max |G_1|² φ / σ² (< 1 passes), None without a level."""
    passed: bool | None
    speed_variance: float | None
    """(1/π)∫|G_1|² φ dΩ over the range: the speed variance [pu²] if φ is a two-sided density per rad/s."""


def spectrum_shape(kind) -> Callable[[np.ndarray], np.ndarray]:
    """Disturbance spectrum shape: "white" (1), "integrated" (1/Ω², integrated white noise) or a callable."""
    if callable(kind):
        return kind
    if kind == "white":
        return lambda w: np.ones_like(np.asarray(w, float))
    if kind == "integrated":
        return lambda w: 1.0 / np.asarray(w, float) ** 2
    raise ConfigError(f"unknown disturbance spectrum {kind!r}: use 'white', 'integrated' or a callable")


def check_disturbance_rejection(
    G1,
    *,
    spectrum="white",
    level: float | None = None,
    sigma_req: float = DEFAULT_SIGMA_OMEGA_REQ_PU,
    omega_range: tuple[float, float] = DEFAULT_OMEGA_RANGE,
) -> DisturbanceCheck:
    """Eq. (10) with φ(Ω) = level·shape(Ω).

    Checking the peak of G_1 is only sufficient for a white disturbance (paper Section 7.4); for the
    integrated load the low end of ``omega_range`` decides, so choose it deliberately (e.g. 2π/1800 s
    for a 30-min record).
    """
    g, sh = as_response(G1), spectrum_shape(spectrum)
    w = log_grid(*omega_range, 3000)

    def neg(x):
        return -(np.abs(evaluate(g, x)) ** 2) * np.asarray(sh(x), float)

    v, wm = refined_min_grid(neg, w, neg(w))
    m = -v
    adm = sigma_req**2 / m if m > 0 else float("inf")
    ratio = passed = var = None
    if level is not None:
        ratio = level * m / sigma_req**2
        passed = bool(ratio < 1.0)
        y = np.abs(evaluate(g, w)) ** 2 * np.asarray(sh(w), float) * level
        var = float(np.trapezoid(y, w) / np.pi)
    return DisturbanceCheck(wm, m, sigma_req, adm, level, ratio, passed, var)


# --------------------------------------------------------------------------------------------------
# Loop margins
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LoopMargins:
    """Margins of a loop L (python-control conventions of stability_margins).

    gain_margin: 1/|L| at the phase crossover (arg L = −180°) whose margin is closest to 1 in log
    (inf without a crossover). phase_margin [deg]: (arg L mod 360) − 180 at the gain crossover
    (|L| = 1) with the smallest |PM| (inf without one). stability_margin: min |1 + L| = 1/max|S|.
    """

    gain_margin: float
    phase_margin_deg: float
    stability_margin: float
    omega_phase_crossover: float
    """[rad/s], nan without one."""
    omega_gain_crossover: float
    omega_stability_margin: float
    all_gain_margins: tuple[float, ...]
    all_phase_margins_deg: tuple[float, ...]
    phase_crossovers: tuple[float, ...]
    gain_crossovers: tuple[float, ...]

    @property
    def max_sensitivity(self) -> float:
        return 1.0 / self.stability_margin


def _roots(fun, w: np.ndarray, vals: np.ndarray) -> list[float]:
    ok = np.isfinite(vals)
    idx = np.nonzero(ok[:-1] & ok[1:] & (np.sign(vals[:-1]) != np.sign(vals[1:])))[0]
    out = []
    for i in idx:
        a, b = np.log(w[i]), np.log(w[i + 1])
        out.append(float(np.exp(brentq(lambda lx: float(fun(np.array([np.exp(lx)]))[0]), a, b, xtol=1e-12))))
    return out


def loop_margins(
    L, omega_range: tuple[float, float] = DEFAULT_OMEGA_RANGE, *, n: int = 20_000
) -> LoopMargins:
    """Gain, phase and stability margins of L(jω) from a dense log grid over omega_range [rad/s].

    Phase crossovers: sign changes of Im L with Re L < 0 (the negative real axis), refined by brentq.
    Gain crossovers: sign changes of |L| − 1. Crossings between grid points closer than the grid
    resolution may be missed: ``n`` log-spaced points (default 20 000 over the range).
    """
    f = as_response(L)
    w = log_grid(*omega_range, n)
    Lw = evaluate(f, w)

    def im(x):
        return np.imag(evaluate(f, x))

    def mag1(x):
        return np.abs(evaluate(f, x)) - 1.0

    pcs = [x for x in _roots(im, w, Lw.imag) if np.real(evaluate(f, np.array([x]))[0]) < 0]
    gcs = _roots(mag1, w, np.abs(Lw) - 1.0)
    gms = [1.0 / abs(evaluate(f, np.array([x]))[0]) for x in pcs]
    pms = [float(np.remainder(np.angle(evaluate(f, np.array([x]))[0], deg=True), 360.0) - 180.0) for x in gcs]

    def dist(x):
        return np.abs(1.0 + evaluate(f, x))

    sm, wsm = refined_min_grid(dist, w, np.abs(1.0 + Lw))
    if gms:
        i = int(np.argmin(np.abs(np.log(gms))))
        gm, wpc = gms[i], pcs[i]
    else:
        gm, wpc = float("inf"), float("nan")
    if pms:
        j = int(np.argmin(np.abs(pms)))
        pm, wgc = pms[j], gcs[j]
    else:
        pm, wgc = float("inf"), float("nan")
    return LoopMargins(
        gain_margin=float(gm),
        phase_margin_deg=float(pm),
        stability_margin=float(sm),
        omega_phase_crossover=float(wpc),
        omega_gain_crossover=float(wgc),
        omega_stability_margin=float(wsm),
        all_gain_margins=tuple(float(x) for x in gms),
        all_phase_margins_deg=tuple(pms),
        phase_crossovers=tuple(pcs),
        gain_crossovers=tuple(gcs),
    )


def local_loop(Gp, GJ) -> Callable[[np.ndarray], np.ndarray]:
    """L = G_p G_J, the local loop whose sensitivity is S (eq. 7)."""
    a, b = as_response(Gp), as_response(GJ)
    return lambda w: evaluate(a, w) * evaluate(b, w)


# --------------------------------------------------------------------------------------------------
# Droop
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DroopEstimate:
    """Effective droop ρ_eff = 1/(1/G_1(0) − K_d) [pu] with a confidence interval.

    For a turbine of static gain G_t(0), ρ_eff = ρ/G_t(0): the droop the grid sees.
    """

    value: float
    lower: float
    upper: float
    """CI ends: the monotone map of the CI ends of G_1(0) (inf when 1/G_1 − K_d ≤ 0; NaN when unknown)."""
    sd: float | None
    """Delta-method standard deviation, when an sd of G_1(0) was given."""
    g1_static: float
    kd: float

    @property
    def reserve_pu_per_pu(self) -> float:
        """Steady-state power per frequency deviation, 1/ρ_eff [pu power / pu frequency]."""
        return 1.0 / self.value


def effective_droop_from_g1(g1_static: float, kd: float) -> float:
    """ρ_eff = 1/(1/G_1(0) − K_d) = G_1(0)/(1 − K_d G_1(0)) [pu]; inf if K_d G_1(0) ≥ 1, NaN for NaN."""
    g = float(g1_static)
    d = 1.0 - kd * g
    if np.isnan(d):
        return float("nan")
    return g / d if d > 0 else float("inf")


def effective_droop(
    g1_static: float,
    kd: float,
    *,
    sd: float | None = None,
    ci: tuple[float, float] | None = None,
    z: float = Z95,
) -> DroopEstimate:
    """ρ_eff with an interval from (G_1(0), sd) (CI g ± z·sd) or an explicit CI of G_1(0); with neither
    (or a NaN sd) the interval is NaN: unknown, not the zero-width interval of an exact value.

    The map g ↦ g/(1 − K_d g) is increasing for g < 1/K_d, so the CI ends map to CI ends exactly;
    the sd is the delta method, dρ/dg = 1/(1 − K_d g)². Example (paper plant 1): G_1(0) = 0.0794,
    K_d = 0.1 → ρ_eff = 0.08.
    """
    if g1_static <= 0:
        raise ConfigError(f"G_1(0) must be positive, got {g1_static}")
    val = effective_droop_from_g1(g1_static, kd)
    if ci is not None:
        lo, hi = sorted(ci)
    elif sd is not None:
        lo, hi = g1_static - z * sd, g1_static + z * sd
    else:
        lo = hi = float("nan")
    lo_r = effective_droop_from_g1(lo, kd) if not lo <= 0 else 0.0
    hi_r = effective_droop_from_g1(hi, kd)
    dsd = None
    if sd is not None:
        d = 1.0 - kd * g1_static
        dsd = float(sd / d**2) if d > 0 else float("inf")
    return DroopEstimate(float(val), float(lo_r), float(hi_r), dsd, float(g1_static), float(kd))
