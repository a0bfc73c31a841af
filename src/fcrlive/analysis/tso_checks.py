"""The Nordic TSOs' frequency-domain FCR requirements (TR v1.1 Section 3.2-3.3): Req. 8 and Req. 9.

Everything here works on frequency responses, so an analytic model, an identified model and the
points of a sine test are checked the same way.

The responses here are :data:`ResponseFunction` s: callables ``fr(omega) -> complex ndarray`` with
``omega`` in rad/s (a continuous-time model evaluated at jω, or a discrete-time model evaluated at
e^{jωTs} by the caller; python-control ``TransferFunction`` objects are accepted and converted by
:func:`as_response`), which can be evaluated anywhere a search needs them. They are not the identified
:class:`fcrlive.ident.FreqResp` (values with their uncertainty on a fixed grid of ω). Sampled points
(omega, values) become a callable with :func:`interpolate_points`.

Conventions (docs/tso-checks.md):
- ``F`` is the unit's normalised response from frequency CONTROL ERROR (f_ref − f) to power, with unit
  static gain for an ideal droop: ``F = ρ·G_p`` (G_p in pu on the machine base, ε → ΔPm, positive static
  gain), or ``F = G_p / G_p(0)``; see :func:`normalise_gp`.
- The power-system model ``G`` (TR eq. 11, Table 7) maps power in pu of the FCR volume to frequency
  in pu of the one-sided band, so ``F·G`` is dimensionless and the critical point is −1.
- Req. 8: ``|1 + F G_stab| ≥ 0.43`` (0.4085 accepted with the 5 % tolerance; FCR-N exemption 0.3225)
  AND a closed-loop stable Nyquist curve (no encirclement of −1).
- Req. 9: ``0.95·|G_perf/(1 + F G_perf)| < |1/D(jω)|``, ``D(s) = 1/(70 s + 1)``; otherwise the capacity
  reduction ``K_red,dyn`` (F replaced by F/K_red,dyn) that makes it hold; ≥ 0.9 (FCR-N) / ≥ 0.75 (FCR-D).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from fcrlive.constants import F0_HZ, Z95
from fcrlive.errors import ConfigError
from fcrlive.gridsearch import log_grid, refined_min_grid

ResponseFunction = Callable[[np.ndarray], np.ndarray]
"""A response as a function: ``fr(omega [rad/s]) -> complex ndarray`` of the same shape (module docstring)."""

KF_PU_PER_HZ = 0.01
"""Load frequency dependence K_f of the TR power-system model [pu/Hz] (Table 7)."""

STABILITY_RADIUS = 0.43
"""Req. 8: radius of the forbidden circle around −1."""
STABILITY_TOLERANCE = 0.05
"""Req. 8: 5 % margin allowed on the radius (0.43·0.95 = 0.4085 accepted)."""
FCRN_EXEMPTION_FACTOR = 0.75
"""Req. 8: an FCR-N exemption may lower the radius to 75 % (0.3225)."""
PERFORMANCE_MARGIN = 0.95
"""Req. 9: K_margin, the 5 % margin on the performance requirement."""
DISTURBANCE_TIME_CONSTANT_S = 70.0
"""Req. 9: the disturbance profile D(s) = 1/(70 s + 1) [s]."""
K_RED_DYN_MIN: dict[str, float] = {"fcrn": 0.9, "fcrd": 0.75}
"""Req. 9: smallest capacity reduction factor K_red,dyn allowed per product."""
TSO_BAND_PERIODS_S: tuple[float, float] = (10.0, 300.0)
"""The tested band of sine periods [s] (TR Table 6)."""
FREQUENCY_BAND_HZ: dict[str, float] = {"fcrn": 0.1, "fcrd": 0.4}
"""One-sided frequency band Δf_FCR-X [Hz] per product."""


# --------------------------------------------------------------------------------------------------
# Frequency responses
# --------------------------------------------------------------------------------------------------


def as_response(sys) -> ResponseFunction:
    """A :data:`ResponseFunction` from a python-control LTI system or a callable.

    Continuous systems are evaluated at jω, discrete ones at e^{jω dt}. Callables pass unchanged.
    Duck-typed so that importing this module does not import python-control.
    """
    if hasattr(sys, "isctime") and hasattr(sys, "dt"):
        if sys.isctime():
            return lambda w: np.asarray(sys(1j * np.asarray(w, float), warn_infinite=False), complex)
        dt = float(sys.dt)
        return lambda w: np.asarray(sys(np.exp(1j * np.asarray(w, float) * dt), warn_infinite=False), complex)
    if not callable(sys):
        raise ConfigError(f"not a frequency response: {type(sys).__name__}")
    return sys


def evaluate(fr, omega) -> np.ndarray:
    """``fr`` evaluated at ``omega`` [rad/s] as a complex array (broadcast scalars)."""
    w = np.asarray(omega, dtype=float)
    v = np.asarray(as_response(fr)(w), dtype=complex)
    if v.shape != w.shape:
        v = np.broadcast_to(v, w.shape).copy()
    return v


def rational(num: Sequence[float], den: Sequence[float], dt: float | None = None) -> ResponseFunction:
    """Frequency response of a rational transfer function (coefficients highest power first).

    Continuous (``dt=None``): num(jω)/den(jω). Discrete (``dt`` in s): num(z)/den(z) at z = e^{jω dt},
    coefficients in powers of z (as python-control and scipy.signal).
    """
    num = np.atleast_1d(np.asarray(num, float))
    den = np.atleast_1d(np.asarray(den, float))

    def fr(w):
        w = np.asarray(w, float)
        x = 1j * w if dt is None else np.exp(1j * w * dt)
        return np.polyval(num, x) / np.polyval(den, x)

    return fr


def delay(tau_s: float) -> ResponseFunction:
    """Pure time delay e^{−jωτ} (τ in s)."""
    return lambda w: np.exp(-1j * np.asarray(w, float) * tau_s)


def fme_response(t_fme_s: float = 1.0) -> ResponseFunction:
    """F_FME(s) = 1/(T_FME s + 1): frequency measurement equipment, default T_FME = 1 s (TR Section 4.4).

    Multiply F by it when the test signal is generated inside the controller and so bypasses the
    frequency measurement (TR text after eq. 9).
    """
    return lambda w: 1.0 / (1j * np.asarray(w, float) * t_fme_s + 1.0)


def normalise_gp(
    gp,
    *,
    droop: float | None = None,
    static_gain: float | None = None,
    t_fme_s: float | None = None,
) -> ResponseFunction:
    """F from G_p: ``F = droop·G_p`` or ``F = G_p/static_gain`` (exactly one), times F_FME if ``t_fme_s``.

    ``gp``: response from control error ε [pu of f0] to mechanical (or electrical) power [pu machine
    base], positive static gain. ``droop`` ρ [pu] gives F(0) = Gt(0) (1 for a unit-gain turbine);
    ``static_gain`` (e.g. Gt(0)/ρ or an identified G_p(0)) gives F(0) = 1 exactly.
    """
    if (droop is None) == (static_gain is None):
        raise ConfigError("give exactly one of droop or static_gain to normalise G_p")
    scale = float(droop) if droop is not None else 1.0 / float(static_gain)
    if not np.isfinite(scale) or scale <= 0:
        raise ConfigError(f"normalisation must be positive and finite, got {scale}")
    fr = as_response(gp)
    fme = fme_response(t_fme_s) if t_fme_s is not None else None

    def F(w):
        v = scale * evaluate(fr, w)
        return v * fme(w) if fme is not None else v

    return F


def interpolate_points(omega, values) -> ResponseFunction:
    """A callable through sampled points (e.g. sine tests): linear in the complex plane vs log ω.

    The TR constructs the Nyquist curve between measured points by interpolation; this does the same.
    Outside [min ω, max ω] it returns NaN: nothing is claimed beyond the tested frequencies.
    """
    w = np.asarray(omega, float)
    v = np.asarray(values, complex)
    if w.ndim != 1 or w.shape != v.shape or w.size < 1:
        raise ConfigError("omega and values must be 1-D arrays of the same length")
    if np.any(w <= 0) or not np.all(np.isfinite(v)):
        raise ConfigError("points need omega > 0 and finite values")
    order = np.argsort(w)
    lw, v = np.log(w[order]), v[order]

    def fr(x):
        x = np.asarray(x, float)
        with np.errstate(divide="ignore"):
            lx = np.log(x)
        if lw.size == 1:
            out = np.where(np.isclose(lx, lw[0]), v[0], np.nan + 0j)
        else:
            out = np.interp(lx, lw, v.real) + 1j * np.interp(lx, lw, v.imag)
            out = np.where((lx < lw[0] - 1e-12) | (lx > lw[-1] + 1e-12), np.nan + 0j, out)
        return out

    return fr


# --------------------------------------------------------------------------------------------------
# Power-system models (TR eq. 11, Table 7)
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PowerSystemModel:
    """G(s) = (ΔP_FCR/Δf_band)·(f0/Sn)·1/(2 H s + Kf·f0) [pu]: TR eq. 11 with one Table 7 set.

    Input: power in pu of the FCR volume ΔP_FCR; output: frequency in pu of the band Δf_band.
    """

    name: str
    dp_fcr_mw: float
    """FCR-X volume ΔP_FCR [MW]."""
    df_band_hz: float
    """One-sided frequency band Δf_FCR-X [Hz]."""
    sn_mw: float
    """Nominal power S_n [MW]."""
    h_s: float
    """Inertia constant H [s] on S_n."""
    f0_hz: float = F0_HZ
    kf_pu_per_hz: float = KF_PU_PER_HZ

    @property
    def gain(self) -> float:
        """Numerator (ΔP/Δf)·(f0/Sn) [1/s·s = pu]."""
        return self.dp_fcr_mw / self.df_band_hz * self.f0_hz / self.sn_mw

    @property
    def num_den(self) -> tuple[list[float], list[float]]:
        """Transfer-function coefficients (num, den), highest power of s first."""
        return [self.gain], [2.0 * self.h_s, self.kf_pu_per_hz * self.f0_hz]

    @property
    def static_gain(self) -> float:
        """G(0) [pu]."""
        return self.gain / (self.kf_pu_per_hz * self.f0_hz)

    def __call__(self, omega) -> np.ndarray:
        w = np.asarray(omega, float)
        return self.gain / (2.0 * self.h_s * 1j * w + self.kf_pu_per_hz * self.f0_hz)


FCRN_STABILITY = PowerSystemModel("FCR-N stability", 600.0, 0.1, 23_000.0, 120_000.0 / 23_000.0)
FCRN_PERFORMANCE = PowerSystemModel("FCR-N performance", 600.0, 0.1, 42_000.0, 190_000.0 / 42_000.0)
FCRD_STABILITY = PowerSystemModel("FCR-D stability", 1450.0, 0.4, 23_000.0, 120_000.0 / 23_000.0)
FCRD_PERFORMANCE = PowerSystemModel("FCR-D performance", 1450.0, 0.4, 42_000.0, 190_000.0 / 42_000.0)

PRODUCTS: dict[str, tuple[PowerSystemModel, PowerSystemModel]] = {
    "fcrn": (FCRN_STABILITY, FCRN_PERFORMANCE),
    "fcrd": (FCRD_STABILITY, FCRD_PERFORMANCE),
}
"""(stability set, performance set) per product; FCR-D up and down use the same sets."""

_PRODUCT_ALIASES = {"fcrn": "fcrn", "fcrd": "fcrd", "fcrdup": "fcrd", "fcrddo": "fcrd", "fcrddown": "fcrd"}


def product_key(product: str) -> str:
    """Canonical product key ("fcrn" or "fcrd") from e.g. "FCR-N", "FcrdUp", "fcrd_down"."""
    k = product.lower().replace("-", "").replace("_", "").replace(" ", "")
    try:
        return _PRODUCT_ALIASES[k]
    except KeyError:
        raise ConfigError(f"unknown FCR product {product!r}; use fcrn or fcrd (up/down)") from None


def disturbance_profile(omega) -> np.ndarray:
    """D(jω) = 1/(70 jω + 1) of Req. 9."""
    return 1.0 / (1j * DISTURBANCE_TIME_CONSTANT_S * np.asarray(omega, float) + 1.0)


def steady_state_response_mw(rated_mw: float, droop: float, band_hz: float, f0_hz: float = F0_HZ) -> float:
    """ΔP_ss,theo = (Δf_band/f0)·P_rated/ρ [MW] for a droop ρ [pu] on the rated power."""
    return band_hz / f0_hz * rated_mw / droop


def stability_threshold(product: str, *, tolerance: bool = True, fcrn_exemption: bool = False) -> float:
    """Smallest accepted |1 + F G_stab|: 0.43, ·0.95 with the tolerance, ·0.75 with the FCR-N exemption."""
    r = STABILITY_RADIUS
    if fcrn_exemption and product_key(product) == "fcrn":
        return r * FCRN_EXEMPTION_FACTOR
    return r * (1.0 - STABILITY_TOLERANCE) if tolerance else r


# --------------------------------------------------------------------------------------------------
# Grids and minima
# --------------------------------------------------------------------------------------------------


def band_omega(band_s: tuple[float, float] = TSO_BAND_PERIODS_S) -> tuple[float, float]:
    """(ω_lo, ω_hi) [rad/s] of a band of periods (T_min, T_max) [s]."""
    t_lo, t_hi = sorted(band_s)
    return 2 * np.pi / t_hi, 2 * np.pi / t_lo


# --------------------------------------------------------------------------------------------------
# Req. 8: distance from −1 and encirclement
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Encirclement:
    """Counter-clockwise encirclements of −1 by F·G over ω ∈ (−∞, ∞) (Nyquist criterion).

    Closed-loop stable ⇔ ``ccw == open_loop_unstable_poles``.
    """

    ccw: int
    """Counter-clockwise winding number of 1 + F G around 0 (ω from −∞ to +∞)."""
    raw: float
    """The unrounded winding number (a non-integer one means the curve passes through −1)."""
    omega_max: float
    """Upper end of the evaluated axis [rad/s]; beyond it |F G| is assumed < 1."""
    tail_loop_gain: float
    """|F G| at omega_max: must be < 1 for the closure beyond omega_max to be valid."""
    reliable: bool
    """False when the tail gain is ≥ 1, the raw number is not near an integer or L(0) is not finite."""


def encirclements(L, omega_max: float, *, n: int = 4000, max_refine: int = 14) -> Encirclement:
    """Winding of 1 + L(jω) around the origin over the whole frequency axis.

    L is assumed real (conjugate-symmetric: L(−jω) = conj L(jω)) with finite L(0); the curve for ω < 0
    is then the mirror image, so the full winding is twice the phase change of 1 + L from ω = 0 to
    ω → ∞ divided by 2π. The phase change is accumulated on a grid refined until consecutive points
    differ by < 30° in angle, then closed from omega_max to 1 + L(∞) = 1, which is valid when
    |L| < 1 beyond omega_max (a strictly proper G makes L → 0).
    """
    fr = as_response(L)
    w = np.concatenate([[0.0], np.logspace(-6, np.log10(omega_max), n)])
    v = 1.0 + evaluate(fr, w)
    reliable = True
    if not np.isfinite(v[0]):
        # An integrator in F: start just off zero; the half-winding is then not anchored on the real axis.
        reliable = False
        w, v = w[1:], v[1:]
    for _ in range(max_refine):
        d = np.abs(np.angle(v[1:] / v[:-1]))
        bad = np.nonzero(d > np.pi / 6)[0]
        if bad.size == 0 or w.size > 400_000:
            break
        lo, hi = w[bad], w[bad + 1]
        mid = np.where(lo > 0, np.sqrt(lo * np.maximum(hi, lo)), 0.5 * hi)
        vm = 1.0 + evaluate(fr, mid)
        w = np.insert(w, bad + 1, mid)
        v = np.insert(v, bad + 1, vm)
    else:
        reliable = False
    if np.any(~np.isfinite(v)):
        reliable = False
        v = v[np.isfinite(v)]
    half = float(np.sum(np.angle(v[1:] / v[:-1])) + np.angle(1.0 / v[-1]))
    raw = half / np.pi
    tail = float(abs(v[-1] - 1.0))
    if tail >= 1.0 or abs(raw - round(raw)) > 0.1:
        reliable = False
    return Encirclement(round(raw), raw, float(w[-1]), tail, reliable)


@dataclass(frozen=True)
class StabilityMargin:
    """min |1 + F G| over a band of ω, and where."""

    margin: float
    omega: float
    """ω of the minimum [rad/s]."""
    margin_lower: float | None = None
    """The margin at the lower 95 % bound of F (see assess_tso), or None."""
    margin_upper: float | None = None
    """The margin at the optimistic 95 % bound (F moved by z·sd away from −1/G), or None."""

    @property
    def period_s(self) -> float:
        return 2 * np.pi / self.omega if self.omega > 0 else float("inf")


def stability_margin(
    F, G, omega_range: tuple[float, float], *, n: int = 2000, F_sd=None, z: float = Z95
) -> StabilityMargin:
    """min over ω ∈ omega_range [rad/s] of |1 + F G| (Req. 8), refined around the grid minimum.

    ``F_sd``: optional callable of the (complex, circular) standard deviation of F; the lower bound
    moves F by z·sd towards −1/G, the worst direction: |1 + F G| − z·sd·|G|; the upper bound away from
    it: min of |1 + F G| + z·sd·|G|.
    """
    Ff, Gf = as_response(F), as_response(G)
    w = log_grid(*omega_range, n)

    def dist(x):
        return np.abs(1.0 + evaluate(Ff, x) * evaluate(Gf, x))

    m, wm = refined_min_grid(dist, w, dist(w))
    lower = upper = None
    if F_sd is not None:
        sdf = as_response(F_sd)

        def dist_lo(x, sign=-1.0):
            return dist(x) + sign * z * np.abs(evaluate(sdf, x)) * np.abs(evaluate(Gf, x))

        lower, _ = refined_min_grid(dist_lo, w, dist_lo(w))
        upper, _ = refined_min_grid(lambda x: dist_lo(x, 1.0), w, dist_lo(w, 1.0))
    return StabilityMargin(m, wm, lower, upper)


# --------------------------------------------------------------------------------------------------
# Req. 9: performance and K_red,dyn
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Performance:
    """Req. 9: worst ratio of K_margin·|G/(1 + F G)| to |1/D| (< 1 passes), and K_red,dyn."""

    ratio: float
    """max over ω of K_margin·|G_perf/(1 + F G_perf)|·|D(jω)|."""
    omega: float
    """ω of the worst ratio [rad/s]."""
    k_red_dyn: float
    """Largest K ≤ 1 for which the requirement holds with F/K (1.0 when it holds as is; 0.0 if none found)."""
    ratio_upper: float | None = None
    """The ratio at the upper 95 % bound of F's uncertainty, or None."""
    k_red_dyn_lower: float | None = None
    """K_red,dyn at the 95 % bound, or None."""
    ratio_lower: float | None = None
    """The ratio at the optimistic 95 % bound (F moved by z·sd away from −1/G), or None."""
    k_red_dyn_upper: float | None = None
    """K_red,dyn at the optimistic 95 % bound, or None."""

    @property
    def period_s(self) -> float:
        return 2 * np.pi / self.omega if self.omega > 0 else float("inf")


def _ratio_fun(Fv, Gv, Dv, sdv, k, margin, z):
    den = np.abs(1.0 + Fv * Gv / k)
    if sdv is not None:
        den = np.maximum(den - z * sdv * np.abs(Gv) / k, 0.0)
    with np.errstate(divide="ignore"):
        return margin * np.abs(Gv) * np.abs(Dv) / den


def _k_red(ratio_at_k: Callable[[float], float], k_floor: float = 1e-3, tol: float = 1e-5) -> float:
    """Largest K in (0, 1] with ratio(K) < 1, by halving to find a passing K and then bisection."""
    if ratio_at_k(1.0) < 1.0:
        return 1.0
    k_fail, k_pass = 1.0, None
    k = 0.5
    while k >= k_floor:
        if ratio_at_k(k) < 1.0:
            k_pass = k
            break
        k_fail, k = k, k / 2
    if k_pass is None:
        return 0.0
    while k_fail - k_pass > tol:
        mid = 0.5 * (k_fail + k_pass)
        if ratio_at_k(mid) < 1.0:
            k_pass = mid
        else:
            k_fail = mid
    return k_pass


def performance(
    F,
    G,
    omega_range: tuple[float, float],
    *,
    n: int = 3000,
    margin: float = PERFORMANCE_MARGIN,
    F_sd=None,
    z: float = Z95,
) -> Performance:
    """Req. 9 over ω ∈ omega_range [rad/s]: worst ratio and K_red,dyn (bisection on the grid).

    The worst ratio is refined around the grid maximum; K_red,dyn is bisected on the dense grid (a
    narrow resonance between grid points could be missed: the grid has ``n`` log-spaced points).
    ``F_sd``: as in stability_margin, the upper bound uses |1 + F G/K| − z·sd·|G|/K, the lower (optimistic)
    one |1 + F G/K| + z·sd·|G|/K; K_red,dyn's bounds follow from each.
    """
    Ff, Gf = as_response(F), as_response(G)
    w = log_grid(*omega_range, n)
    Fv, Gv, Dv = evaluate(Ff, w), evaluate(Gf, w), disturbance_profile(w)
    sdv = np.abs(evaluate(as_response(F_sd), w)) if F_sd is not None else None

    def neg_ratio(x, sd=None, zz=z):
        sdx = np.abs(evaluate(as_response(F_sd), x)) if sd is not None else None
        r = _ratio_fun(evaluate(Ff, x), evaluate(Gf, x), disturbance_profile(x), sdx, 1.0, margin, zz)
        return np.where(np.isfinite(r), -r, np.nan)

    r_grid = _ratio_fun(Fv, Gv, Dv, None, 1.0, margin, z)
    neg, wm = refined_min_grid(neg_ratio, w, np.where(np.isfinite(r_grid), -r_grid, np.nan))
    ratio = -neg
    if np.isnan(ratio) and np.isinf(r_grid).any():
        ratio, wm = float("inf"), float(w[np.argmax(r_grid)])

    def worst(k, sd=None, zz=z):
        r = _ratio_fun(Fv, Gv, Dv, sd, k, margin, zz)
        return float(np.nanmax(r)) if np.isfinite(r).any() or np.isinf(r).any() else float("nan")

    # K_red,dyn: on the grid, but pass-through of the refined ratio for K = 1.
    k_red = 1.0 if ratio < 1.0 else _k_red(lambda k: worst(k) if k < 1.0 else max(worst(1.0), ratio))
    ratio_up = k_lo = ratio_lo = k_hi = None
    if sdv is not None:
        neg_u, _ = refined_min_grid(
            lambda x: neg_ratio(x, sd=True), w, -_ratio_fun(Fv, Gv, Dv, sdv, 1.0, margin, z)
        )
        ratio_up = -neg_u
        # an unknown sd (NaN) leaves the bound unknown; the bisection would read it as K = 0
        k_lo = float("nan") if np.isnan(ratio_up) else _k_red(
            lambda k: worst(k, sdv) if k < 1.0 else max(worst(1.0, sdv), ratio_up))
        # the optimistic side: F moved by z·sd away from −1/G (z → −z in the ratio's denominator)
        neg_l, _ = refined_min_grid(
            lambda x: neg_ratio(x, sd=True, zz=-z), w, -_ratio_fun(Fv, Gv, Dv, sdv, 1.0, margin, -z)
        )
        ratio_lo = -neg_l
        k_hi = float("nan") if np.isnan(ratio_lo) else _k_red(
            lambda k: worst(k, sdv, -z) if k < 1.0 else max(worst(1.0, sdv, -z), ratio_lo))
    return Performance(float(ratio), float(wm), float(k_red), ratio_up, k_lo, ratio_lo, k_hi)


# --------------------------------------------------------------------------------------------------
# Verdict per product
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TsoVerdict:
    """The Req. 8 and Req. 9 verdict for one product, with the margins behind it.

    Frequencies in rad/s, periods in s. ``None`` marks what could not be established (e.g. the wide
    band and closed-loop stability from sine-test points only).
    """

    product: str
    """"fcrn" or "fcrd" (FCR-D up and down share the Table 7 sets)."""
    stability_threshold: float
    """The accepted minimum of |1 + F G_stab| used for the verdict."""
    stability_margin_band: float
    """min |1 + F G_stab| inside the tested band (10-300 s by default)."""
    omega_stability_band: float
    stability_margin_wide: float | None
    """min |1 + F G_stab| over the wide band (e.g. 1e-4 rad/s to omega_max)."""
    omega_stability_wide: float | None
    closed_loop_stable: bool | None
    """Nyquist criterion with ``open_loop_unstable_poles`` (None when not established)."""
    encirclements_ccw: int | None
    performance_ratio: float
    """Req. 9 worst ratio over the performance range (< 1 passes)."""
    omega_performance: float
    k_red_dyn: float
    """Capacity reduction factor for Req. 9 (1.0 when not needed)."""
    k_red_dyn_min: float
    """Smallest K_red,dyn allowed (0.9 FCR-N, 0.75 FCR-D)."""
    stability_margin_wide_at_k_red: float | None
    """min |1 + (F/K_red,dyn) G_stab| over the wide band, reported when K_red,dyn < 1."""
    passed: bool
    reasons: tuple[str, ...] = ()
    """Why it failed (empty when passed)."""
    notes: tuple[str, ...] = ()
    """Things to know that did not decide the verdict."""
    # Uncertainty (None when no F_sd / F_samples were given)
    stability_margin_band_lower: float | None = None
    stability_margin_wide_lower: float | None = None
    performance_ratio_upper: float | None = None
    k_red_dyn_lower: float | None = None
    closed_loop_stable_fraction: float | None = None
    """Fraction of F samples with a closed-loop stable Nyquist curve (samples only)."""
    passed_at_bound: bool | None = None
    """The verdict with the 95 % bounds in place of the point values."""
    # The optimistic 95 % bounds (F moved away from −1/G; samples: the other quantile)
    stability_margin_band_upper: float | None = None
    stability_margin_wide_upper: float | None = None
    performance_ratio_lower: float | None = None
    k_red_dyn_upper: float | None = None
    decision: str = "undecided"
    """"pass", "fail" or "undecided": the verdict with its uncertainty (:func:`decide`); ``passed`` is
    the point verdict."""
    extras: dict = field(default_factory=dict, compare=False, hash=False)
    """Per-sample arrays when F_samples were given: keys margin_band, margin_wide, ratio, k_red_dyn."""

    @property
    def period_stability_band_s(self) -> float:
        return 2 * np.pi / self.omega_stability_band

    @property
    def period_stability_wide_s(self) -> float | None:
        return None if self.omega_stability_wide is None else 2 * np.pi / self.omega_stability_wide

    @property
    def period_performance_s(self) -> float:
        return 2 * np.pi / self.omega_performance


@dataclass(frozen=True)
class _ProductChecks:
    """Req. 8 and Req. 9 of one product on the point estimate of F."""

    key: str
    threshold: float
    k_min: float
    band: StabilityMargin
    wide: StabilityMargin | None
    enc: Encirclement | None
    perf: Performance
    wide_at_k_red: float | None
    """min |1 + (F/K_red,dyn) G_stab| over the wide band, when K_red,dyn < 1."""
    stable: bool | None


@dataclass(frozen=True)
class _Bounds:
    """The 95 % bounds of the margins, the ratio and K_red,dyn (None: not asked for)."""

    margin_band: float | None = None
    margin_wide: float | None = None
    ratio: float | None = None
    k_red_dyn: float | None = None
    stable_fraction: float | None = None
    extras: dict = field(default_factory=dict)
    # the optimistic side
    margin_band_upper: float | None = None
    margin_wide_upper: float | None = None
    ratio_lower: float | None = None
    k_red_dyn_upper: float | None = None


@dataclass(frozen=True)
class _Setup:
    """What every product's checks share: F, the frequency ranges and the options of assess_tso."""

    F: ResponseFunction
    w_band: tuple[float, float]
    omega_wide: tuple[float, float] | None
    perf_range: tuple[float, float]
    margin_scope: str
    check_encirclement: bool
    open_loop_unstable_poles: int
    z: float


def _check_product(su: _Setup, key: str, thr: float, F_sd) -> _ProductChecks:
    """Req. 8 (band and wide margins, encirclements) and Req. 9 (ratio, K_red,dyn) for one product;
    with ``F_sd`` also their bounds moved by z·sd (StabilityMargin.margin_lower, Performance.*)."""
    g_stab, g_perf = PRODUCTS[key]
    Ff, wide = su.F, su.omega_wide
    mb = stability_margin(Ff, g_stab, su.w_band, F_sd=F_sd, z=su.z)
    mw = stability_margin(Ff, g_stab, wide, F_sd=F_sd, z=su.z) if wide else None
    enc = None
    if wide and su.check_encirclement:
        enc = encirclements(lambda x, g=g_stab: evaluate(Ff, x) * g(x), wide[1])
    perf = performance(Ff, g_perf, su.perf_range, F_sd=F_sd, z=su.z)
    m_k = None
    if perf.k_red_dyn < 1.0 and perf.k_red_dyn > 0 and wide:
        k = perf.k_red_dyn
        m_k = stability_margin(lambda x, k=k: evaluate(Ff, x) / k, g_stab, wide).margin
    stable = None if enc is None else enc.ccw == su.open_loop_unstable_poles
    return _ProductChecks(key, thr, K_RED_DYN_MIN[key], mb, mw, enc, perf, m_k, stable)


def _reasons_and_notes(c: _ProductChecks, su: _Setup) -> tuple[list[str], list[str]]:
    """Why the product fails (the verdict) and what else is worth knowing (does not decide it)."""
    thr, mb, mw, enc, perf = c.threshold, c.band, c.wide, c.enc, c.perf
    reasons: list[str] = []
    notes: list[str] = []
    used = mb if su.margin_scope == "band" else mw
    if not used.margin >= thr:
        reasons.append(
            f"Req. 8: min |1+FG| = {used.margin:.3f} < {thr:.4f} ({su.margin_scope}) at T = "
            f"{2 * np.pi / used.omega:.1f} s"
        )
    if c.stable is False:
        reasons.append(
            f"Req. 8: Nyquist curve encircles −1 ({enc.ccw} ccw encirclements, "
            f"{su.open_loop_unstable_poles} open-loop unstable poles): closed loop unstable"
        )
    if enc is not None and not enc.reliable:
        notes.append(
            f"encirclement count may be unreliable (|FG| = {enc.tail_loop_gain:.2f} at "
            f"ω = {enc.omega_max:.3g} rad/s, winding {enc.raw:.2f})"
        )
    if enc is None:
        notes.append("closed-loop stability not established (no wide-band model)")
    if mw is not None and su.margin_scope == "band" and mw.margin < min(thr, mb.margin - 1e-9):
        notes.append(f"outside the tested band min |1+FG| = {mw.margin:.3f} at T = {mw.period_s:.2f} s")
    if perf.k_red_dyn < c.k_min:
        reasons.append(
            f"Req. 9: ratio {perf.ratio:.3f} at T = {perf.period_s:.1f} s; K_red,dyn = "
            f"{perf.k_red_dyn:.3f} < {c.k_min}"
        )
    elif perf.k_red_dyn < 1.0:
        notes.append(f"Req. 9 met with capacity reduction K_red,dyn = {perf.k_red_dyn:.3f}")
    if c.wide_at_k_red is not None and c.wide_at_k_red < thr:
        notes.append(f"with F/K_red,dyn the wide-band min |1+FG| is {c.wide_at_k_red:.3f} < {thr:.4f}")
    return reasons, notes


def _bounds_from_sd(c: _ProductChecks) -> _Bounds:
    """The bounds the sd of F gave the checks (None where no F_sd was given)."""
    return _Bounds(c.band.margin_lower, None if c.wide is None else c.wide.margin_lower,
                   c.perf.ratio_upper, c.perf.k_red_dyn_lower,
                   margin_band_upper=c.band.margin_upper,
                   margin_wide_upper=None if c.wide is None else c.wide.margin_upper,
                   ratio_lower=c.perf.ratio_lower, k_red_dyn_upper=c.perf.k_red_dyn_upper)


def _bounds_from_samples(su: _Setup, key: str, F_samples: Sequence) -> _Bounds:
    """The checks repeated on each F sample: 2.5 % quantiles of the margins and K_red,dyn, the 97.5 %
    quantile of the ratio (and the other quantile of each as the optimistic bound), the fraction of
    closed-loop stable samples; the per-sample arrays as extras."""
    g_stab, g_perf = PRODUCTS[key]
    wide = su.omega_wide
    s_mb, s_mw, s_r, s_k, s_st = [], [], [], [], []
    for Fi in F_samples:
        Fi = as_response(Fi)
        s_mb.append(stability_margin(Fi, g_stab, su.w_band, n=600).margin)
        if wide:
            s_mw.append(stability_margin(Fi, g_stab, wide, n=1000).margin)
            if su.check_encirclement:
                e = encirclements(lambda x, Fi=Fi, g=g_stab: evaluate(Fi, x) * g(x), wide[1], n=1500)
                s_st.append(e.ccw == su.open_loop_unstable_poles)
        p = performance(Fi, g_perf, su.perf_range, n=1000)
        s_r.append(p.ratio)
        s_k.append(p.k_red_dyn)
    return _Bounds(
        margin_band=float(np.quantile(s_mb, 0.025)),
        margin_wide=float(np.quantile(s_mw, 0.025)) if s_mw else None,
        ratio=float(np.quantile(s_r, 0.975)),
        k_red_dyn=float(np.quantile(s_k, 0.025)),
        stable_fraction=float(np.mean(s_st)) if s_st else None,
        extras={"margin_band": np.array(s_mb), "margin_wide": np.array(s_mw), "ratio": np.array(s_r),
                "k_red_dyn": np.array(s_k)},
        margin_band_upper=float(np.quantile(s_mb, 0.975)),
        margin_wide_upper=float(np.quantile(s_mw, 0.975)) if s_mw else None,
        ratio_lower=float(np.quantile(s_r, 0.025)),
        k_red_dyn_upper=float(np.quantile(s_k, 0.975)),
    )


def _passed_at_bound(c: _ProductChecks, b: _Bounds, margin_scope: str) -> bool | None:
    """The verdict with the 95 % bounds in place of the point values; None when they are unknown."""
    used_lo = b.margin_band if margin_scope == "band" else b.margin_wide
    if used_lo is None or np.isnan(used_lo) or (b.k_red_dyn is not None and np.isnan(b.k_red_dyn)):
        return None
    return bool(
        used_lo >= c.threshold
        and (b.k_red_dyn is None or b.k_red_dyn >= c.k_min)
        and c.stable is not False
        and (b.stable_fraction is None or b.stable_fraction >= 0.975)
    )


def _known(x: float | None) -> bool:
    return x is not None and not np.isnan(x)


def decide(c: _ProductChecks, b: _Bounds, margin_scope: str, *, exact: bool) -> str:
    """"pass", "fail" or "undecided": the verdict with its uncertainty (docs/tso-checks.md, "Decision").

    - ``exact`` (an F given without F_sd or F_samples, e.g. an analytic model): the point verdict.
    - pass: the verdict holds at the pessimistic 95 % bounds (``passed_at_bound`` True).
    - fail: a requirement fails even at its optimistic 95 % bound: the Req. 8 margin's upper bound
      < the threshold, or K_red,dyn's upper bound < its minimum; or the point estimate's Nyquist curve
      encircles −1 (closed loop unstable) and that cannot change within the uncertainty: no F sample
      is closed-loop stable, or (F_sd) the pessimistic wide-band margin is > 0 (no F within z·sd
      reaches −1, so none changes the winding) on a reliable encirclement count.
    - undecided: otherwise, including every case where a bound it needs is unknown (None/NaN), and
      where the bounds (sample quantiles) disagree with the point verdict: a decision is never the
      opposite of ``passed``.
    """
    point = _passed_point(c, margin_scope)
    if exact:
        return "pass" if point else "fail"
    if point:
        return "pass" if _passed_at_bound(c, b, margin_scope) else "undecided"
    # the point fails: fail only if it also fails on the optimistic side
    m_hi = b.margin_band_upper if margin_scope == "band" else b.margin_wide_upper
    if _known(m_hi) and m_hi < c.threshold:
        return "fail"
    if _known(b.k_red_dyn_upper) and b.k_red_dyn_upper < c.k_min:
        return "fail"
    if c.stable is False:
        if b.stable_fraction is not None:
            if b.stable_fraction == 0.0:
                return "fail"
        elif c.enc is not None and c.enc.reliable and _known(b.margin_wide) and b.margin_wide > 0:
            return "fail"
    return "undecided"


def _passed_point(c: _ProductChecks, margin_scope: str) -> bool:
    """The point verdict (what ``TsoVerdict.passed`` says): Req. 8 margin, closed loop, Req. 9 K_red,dyn."""
    used = c.band if margin_scope == "band" else c.wide
    return bool(used.margin >= c.threshold and c.stable is not False and c.perf.k_red_dyn >= c.k_min)


def _verdict(c: _ProductChecks, b: _Bounds, su: _Setup, exact: bool = False) -> TsoVerdict:
    reasons, notes = _reasons_and_notes(c, su)
    mw = c.wide
    return TsoVerdict(
        product=c.key,
        stability_threshold=c.threshold,
        stability_margin_band=c.band.margin,
        omega_stability_band=c.band.omega,
        stability_margin_wide=None if mw is None else mw.margin,
        omega_stability_wide=None if mw is None else mw.omega,
        closed_loop_stable=c.stable,
        encirclements_ccw=None if c.enc is None else c.enc.ccw,
        performance_ratio=c.perf.ratio,
        omega_performance=c.perf.omega,
        k_red_dyn=c.perf.k_red_dyn,
        k_red_dyn_min=c.k_min,
        stability_margin_wide_at_k_red=c.wide_at_k_red,
        passed=not reasons,
        reasons=tuple(reasons),
        notes=tuple(notes),
        stability_margin_band_lower=b.margin_band,
        stability_margin_wide_lower=b.margin_wide,
        performance_ratio_upper=b.ratio,
        k_red_dyn_lower=b.k_red_dyn,
        closed_loop_stable_fraction=b.stable_fraction,
        passed_at_bound=_passed_at_bound(c, b, su.margin_scope),
        stability_margin_band_upper=b.margin_band_upper,
        stability_margin_wide_upper=b.margin_wide_upper,
        performance_ratio_lower=b.ratio_lower,
        k_red_dyn_upper=b.k_red_dyn_upper,
        decision=decide(c, b, su.margin_scope, exact=exact),
        extras=b.extras,
    )


def assess_tso(
    F,
    *,
    products: Sequence[str] = ("fcrn", "fcrd"),
    band: tuple[float, float] = TSO_BAND_PERIODS_S,
    omega_wide: tuple[float, float] | None = (1e-4, 10.0),
    margin_scope: str = "band",
    tolerance: bool = True,
    fcrn_exemption: bool = False,
    open_loop_unstable_poles: int = 0,
    check_encirclement: bool = True,
    performance_range: tuple[float, float] | None = None,
    F_sd=None,
    F_samples: Sequence | None = None,
    z: float = Z95,
) -> dict[str, TsoVerdict]:
    """Req. 8 and Req. 9 for each product, from a normalised response F (see normalise_gp).

    Parameters
    ----------
    F: callable ω [rad/s] → F(jω) (or python-control system). Assumed real-coefficient.
    products: keys or aliases ("fcrn", "fcrd", "FcrdUp", ...); FCR-D up/down give the same verdict.
    band: tested periods (T_min, T_max) [s]; the in-band margin is the TR requirement.
    omega_wide: (ω_lo, ω_hi) [rad/s] for the wide-band margin and the encirclement check; ω_hi is
        also where the Nyquist curve is closed (|F G| must be < 1 beyond it). For a discrete-time F
        pass ω_hi = π/Ts. ``None`` for sampled points: no wide band, no encirclement.
    margin_scope: "band" (TR) or "wide": which margin decides Req. 8.
    tolerance: accept 0.43·0.95 = 0.4085; ``fcrn_exemption``: accept 0.3225 for FCR-N.
    open_loop_unstable_poles: P of F·G (F and G stable ⇒ 0); closed-loop stable ⇔ ccw encirclements = P.
    performance_range: ω range for Req. 9 [rad/s]; default omega_wide, or the band without it.
    F_sd: callable ω → standard deviation of F (complex, circular: sqrt(E|F − F̂|²)); the bounds move
        F by z·sd in the worst direction (towards −1/G): conservative and simple.
    F_samples: F responses drawn from the estimate's distribution; the bounds are then the 2.5 %
        quantile of the margins / K_red,dyn and the 97.5 % quantile of the ratio, and
        closed_loop_stable_fraction is reported. If both are given, the samples win.

    Each verdict's ``passed`` is the point verdict; ``decision`` ("pass" / "fail" / "undecided", see
    :func:`decide`) is the one to publish: pass only when it holds at the pessimistic 95 % bounds, fail
    only when it fails even at the optimistic ones, undecided in between or when a bound is unknown.
    An F given without F_sd or F_samples is taken as exact: decision = the point verdict.
    """
    if margin_scope not in ("band", "wide"):
        raise ConfigError(f"margin_scope must be 'band' or 'wide', got {margin_scope!r}")
    if margin_scope == "wide" and omega_wide is None:
        raise ConfigError("margin_scope='wide' needs omega_wide")
    w_band = band_omega(band)
    su = _Setup(as_response(F), w_band, omega_wide, performance_range or omega_wide or w_band, margin_scope,
                check_encirclement, open_loop_unstable_poles, z)
    out: dict[str, TsoVerdict] = {}
    for prod in products:
        key = product_key(prod)
        if key in out:
            continue
        thr = stability_threshold(key, tolerance=tolerance, fcrn_exemption=fcrn_exemption)
        checks = _check_product(su, key, thr, F_sd if F_samples is None else None)
        bounds = _bounds_from_sd(checks) if F_samples is None else _bounds_from_samples(su, key, F_samples)
        out[key] = _verdict(checks, bounds, su, exact=F_sd is None and F_samples is None)
    return out


def assess_tso_points(
    omega,
    F_values,
    *,
    F_sd_values=None,
    products: Sequence[str] = ("fcrn", "fcrd"),
    band: tuple[float, float] = TSO_BAND_PERIODS_S,
    tolerance: bool = True,
    fcrn_exemption: bool = False,
) -> dict[str, TsoVerdict]:
    """Req. 8 and Req. 9 from sampled F (sine tests): the TR's interpolated Nyquist curve.

    F is interpolated linearly in the complex plane between the points (vs log ω), and the checks
    run over the tested range only (the band clipped to the points). Closed-loop stability and the
    wide band are not established (None), since nothing is known between or beyond the points
    except by interpolation: a model is needed for that.
    """
    w = np.asarray(omega, float)
    Fi = interpolate_points(w, F_values)
    sdi = interpolate_points(w, np.abs(np.asarray(F_sd_values, float))) if F_sd_values is not None else None
    lo, hi = band_omega(band)
    rng = (max(lo, w.min()), min(hi, w.max()))
    if rng[0] > rng[1]:
        raise ConfigError("no sine-test points inside the tested band")
    # the band margin is evaluated on the clipped range: pass it as the band in periods
    band_clip = (2 * np.pi / rng[1], 2 * np.pi / rng[0])
    return assess_tso(
        Fi,
        products=products,
        band=band_clip,
        omega_wide=None,
        performance_range=rng,
        tolerance=tolerance,
        fcrn_exemption=fcrn_exemption,
        F_sd=sdi,
    )
