"""The industry sine test (TR eqs. 6-9 and Req. 10; paper Section 4.1, eq. 11-13).

For one sine test of a KNOWN period T, the last n periods (TR Table 6:
``fcrlive.constants.TSO_STATIONARY_PERIODS``) are taken as stationary. A sine of period T plus an
offset and a linear trend (the baseline drift) is fitted by least squares to

- the frequency CONTROL ERROR e = f_ref − f [Hz] (f the applied frequency signal, ApplFreqSig), and
- the power P [MW],

over the whole stationary window and over each period separately. From the two fits:

- ``|F| = (A_P/A_e)·(Δf_band/ΔP_ss,theo)`` (eq. 7), ΔP_ss,theo the unit's steady-state response to the full
  band [MW] (given, or (Δf_band/f0)·P_rated/ρ — then Δf_band cancels);
- ``arg F = φ_P − φ_e`` (eq. 8), negative when power lags the control error; wrapped to (−π, π];
- ``G_req = (A_P/P_rated)/(A_e/f0)·e^{j arg F}`` in pu (paper eq. 11: electric power u [pu machine base]
  over the excitation r [pu of f0]); G_req is G_p seen through a low-pass (paper eq. 12-13);
- Req. 10: ``sqrt(Σ(P − P_fit)²)/sqrt(Σ(P_sine − mean P_sine)²) < 1`` where P_fit is the full fit
  (offset + trend + sine: the baseline is removed as the TR asks) and P_sine its sine part.

Standard errors come from the ordinary least-squares covariance σ̂²(XᵀX)⁻¹ and the delta method. They
assume white residuals; coloured power noise makes them optimistic, so the between-period scatter of the
per-period F is reported too (``F_sd_periods``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fcrlive.constants import F0_HZ, TSO_STATIONARY_PERIODS
from fcrlive.errors import DataError

__all__ = [
    "CycleResult",
    "SineFit",
    "SineTestResult",
    "evaluate_sine_test",
    "fit_sine",
    "sine_test_points",
]


@dataclass(frozen=True)
class SineFit:
    """x(t) ≈ offset + trend·(t − t_ref) + amplitude·sin(ω (t − t_ref) + phase), least squares.

    Units follow the signal (Hz or MW); phase in rad, trend per second.
    """

    period_s: float
    t_ref: float
    """Time origin of the phase [s] (start of the fitted window)."""
    amplitude: float
    amplitude_se: float
    phase_rad: float
    phase_se_rad: float
    offset: float
    trend: float
    residual_rms: float
    """sqrt(mean residual²) of the fit."""
    linearity: float
    """Req. 10 figure: sqrt(Σ residual²)/sqrt(Σ(sine part − its mean)²)."""
    n_samples: int
    cov_ab: tuple[tuple[float, float], tuple[float, float]]
    """Covariance of the (cos, sin) coefficients (a, b), a = A sin φ, b = A cos φ."""

    @property
    def omega(self) -> float:
        return 2 * np.pi / self.period_s

    @property
    def phasor(self) -> complex:
        """A·e^{jφ}: the complex amplitude (x = Im(phasor·e^{jω(t − t_ref)}) + baseline)."""
        return self.amplitude * np.exp(1j * self.phase_rad)


def fit_sine(t, x, period_s: float, *, t_ref: float | None = None) -> SineFit:
    """Least-squares fit of offset + linear trend + sine of the known period to x(t).

    ``t`` [s] strictly increasing (uniform sampling not required), ``x`` any unit. Needs > 4 samples.
    """
    t = np.asarray(t, float)
    x = np.asarray(x, float)
    if t.shape != x.shape or t.ndim != 1:
        raise DataError("t and x must be 1-D arrays of the same length")
    if t.size <= 4:
        raise DataError(f"sine fit needs more than 4 samples, got {t.size}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(x))):
        raise DataError("sine fit: non-finite samples")
    if period_s <= 0:
        raise DataError(f"period must be positive, got {period_s}")
    t0 = float(t[0]) if t_ref is None else float(t_ref)
    tau = t - t0
    w = 2 * np.pi / period_s
    tc = tau - tau.mean()
    X = np.column_stack([np.ones_like(tau), tc, np.cos(w * tau), np.sin(w * tau)])
    coef, *_ = np.linalg.lstsq(X, x, rcond=None)
    fit = X @ coef
    res = x - fit
    dof = max(t.size - 4, 1)
    s2 = float(res @ res) / dof
    XtX_inv = np.linalg.pinv(X.T @ X)
    C = s2 * XtX_inv
    c0, c1, a, b = coef
    A = float(np.hypot(a, b))
    phi = float(np.arctan2(a, b))
    Cab = C[2:, 2:]
    if A > 0:
        g_A = np.array([a / A, b / A])
        g_phi = np.array([b / A**2, -a / A**2])
        se_A = float(np.sqrt(max(g_A @ Cab @ g_A, 0.0)))
        se_phi = float(np.sqrt(max(g_phi @ Cab @ g_phi, 0.0)))
    else:
        se_A, se_phi = float(np.sqrt(np.trace(Cab) / 2)), float("inf")
    sine = X[:, 2:] @ coef[2:]
    den = float(np.sqrt(np.sum((sine - sine.mean()) ** 2)))
    lin = float(np.sqrt(res @ res) / den) if den > 0 else float("inf")
    # offset reported at t_ref (the trend column is centred for conditioning)
    offset = float(c0 - c1 * tau.mean())
    return SineFit(
        period_s=float(period_s),
        t_ref=t0,
        amplitude=A,
        amplitude_se=se_A,
        phase_rad=phi,
        phase_se_rad=se_phi,
        offset=offset,
        trend=float(c1),
        residual_rms=float(np.sqrt(np.mean(res**2))),
        linearity=lin,
        n_samples=int(t.size),
        cov_ab=((float(Cab[0, 0]), float(Cab[0, 1])), (float(Cab[1, 0]), float(Cab[1, 1]))),
    )


def _wrap(phi: float) -> float:
    """Wrap to (−π, π]."""
    return float(np.pi - np.mod(np.pi - phi, 2 * np.pi))


@dataclass(frozen=True)
class CycleResult:
    """The F estimate from one stationary period (cycle) of a sine test."""

    index: int
    """0 = first of the stationary periods used."""
    t_start: float
    F: complex
    linearity: float
    """Req. 10 figure of the power fit over this period alone."""


@dataclass(frozen=True)
class SineTestResult:
    """One sine test evaluated (TR eq. 6-9, Req. 10) over its stationary periods.

    ``F`` is normalised (F(0) = 1 for an ideal droop, eq. 7-9); ``G_req`` in pu (paper eq. 11).
    Amplitude and phase standard errors from the LS fits (white-residual assumption).
    """

    period_s: float
    n_periods: int
    """Number of stationary periods used."""
    t_start: float
    t_end: float
    control_error: SineFit
    """Fit to e = f_ref − f [Hz]."""
    power: SineFit
    """Fit to P [MW]."""
    gain: float
    """|F| (eq. 7), dimensionless."""
    gain_se: float
    phase_rad: float
    """arg F (eq. 8) [rad], negative when power lags the control error; wrapped to (−π, π]."""
    phase_se_rad: float
    F: complex
    """F(jω) (eq. 9), including F_FME if t_fme_s was given."""
    F_sd: float
    """Circular standard deviation of F: |F|·sqrt((se_|F|/|F|)² + se_φ²) (delta method)."""
    G_req: complex
    """Power [pu of rated] over control error [pu of f0]: the paper's G_req (eq. 11-12)."""
    linearity: float
    """Req. 10 figure over the stationary window (< 1 passes)."""
    linearity_max_period: float
    """Worst Req. 10 figure over the individual periods."""
    cycles: tuple[CycleResult, ...]
    F_sd_periods: float | None
    """Scatter of the per-period F: sqrt(Σ|F_k − mean|²/(n − 1))/sqrt(n) (None for n < 2)."""
    fme_applied: bool

    @property
    def omega(self) -> float:
        return 2 * np.pi / self.period_s

    @property
    def phase_deg(self) -> float:
        return float(np.degrees(self.phase_rad))

    @property
    def linearity_passed(self) -> bool:
        return self.linearity < 1.0


def _scale(
    dp_ss_theo_mw: float | None,
    band_hz: float | None,
    rated_mw: float | None,
    droop: float | None,
    f0_hz: float,
) -> float:
    """Δf_band/ΔP_ss,theo [Hz/MW]."""
    if dp_ss_theo_mw is not None:
        if band_hz is None:
            raise DataError("dp_ss_theo_mw needs band_hz (0.1 Hz FCR-N, 0.4 Hz FCR-D)")
        return abs(band_hz) / abs(dp_ss_theo_mw)
    if rated_mw is None or droop is None:
        raise DataError("give dp_ss_theo_mw and band_hz, or rated_mw and droop")
    # ΔP_ss,theo = (Δf_band/f0)·P_rated/ρ, so Δf_band/ΔP_ss,theo = f0·ρ/P_rated whatever the band.
    return f0_hz * droop / rated_mw


def evaluate_sine_test(
    t,
    freq_hz,
    power_mw,
    period_s: float,
    *,
    n_periods: int | None = None,
    f_ref_hz: float = F0_HZ,
    dp_ss_theo_mw: float | None = None,
    band_hz: float | None = None,
    rated_mw: float | None = None,
    droop: float | None = None,
    f0_hz: float = F0_HZ,
    t_fme_s: float | None = None,
    is_control_error: bool = False,
) -> SineTestResult:
    """Evaluate one sine test from plain arrays.

    Parameters
    ----------
    t: time [s], increasing; the stationary window is the LAST ``n_periods``·T seconds.
    freq_hz: the applied frequency signal f [Hz] (e.g. ApplFreqSig); the control error is f_ref − f.
    power_mw: active power [MW] (baseline included: offset + trend are fitted away).
    period_s: the known sine period T [s].
    n_periods: stationary periods to use; default TR Table 6 (5 up to 90 s, 3 at 150 s, 2 at 300 s;
        3 for periods not in the table).
    dp_ss_theo_mw, band_hz: normalisation of eq. 7; or ``rated_mw`` and ``droop`` ρ [pu] (then
        ΔP_ss,theo = (Δf_band/f0)·P_rated/ρ). ``rated_mw`` is also needed for G_req.
    t_fme_s: multiply F by 1/(jω T_FME + 1) (test signal generated inside the controller; TR: 1 s).
    is_control_error: ``freq_hz`` already is the control error e = f_ref − f [Hz] (f_ref then unused).
    """
    t = np.asarray(t, float)
    f = np.asarray(freq_hz, float)
    p = np.asarray(power_mw, float)
    if not (t.shape == f.shape == p.shape) or t.ndim != 1:
        raise DataError("t, frequency and power must be 1-D arrays of the same length")
    if np.any(np.diff(t) <= 0):
        raise DataError("time must be strictly increasing")
    T = float(period_s)
    n = int(n_periods) if n_periods is not None else TSO_STATIONARY_PERIODS.get(T, 3)
    if n < 1:
        raise DataError(f"need at least one stationary period, got {n}")
    t_end = float(t[-1])
    t_start = t_end - n * T
    if t_start < t[0] - 1e-9 * max(1.0, abs(t[0])):
        raise DataError(
            f"sine test T = {T:g} s: {n} stationary periods need {n * T:g} s, "
            f"the data cover {t_end - t[0]:g} s"
        )
    sel = t >= t_start
    e = f if is_control_error else f_ref_hz - f
    fe = fit_sine(t[sel], e[sel], T, t_ref=t_start)
    fp = fit_sine(t[sel], p[sel], T, t_ref=t_start)
    if fe.amplitude <= 0:
        raise DataError(f"sine test T = {T:g} s: no sine in the control error")
    scale = _scale(dp_ss_theo_mw, band_hz, rated_mw, droop, f0_hz)
    w = 2 * np.pi / T
    fme = 1.0 / (1j * w * t_fme_s + 1.0) if t_fme_s is not None else 1.0

    gain = fp.amplitude / fe.amplitude * scale
    rel = np.hypot(
        fp.amplitude_se / fp.amplitude if fp.amplitude > 0 else np.inf, fe.amplitude_se / fe.amplitude
    )
    phase = _wrap(fp.phase_rad - fe.phase_rad)
    phase_se = float(np.hypot(fp.phase_se_rad, fe.phase_se_rad))
    F = complex(gain * np.exp(1j * phase) * fme)
    F_sd = float(abs(F) * np.hypot(rel, phase_se))
    G_req = complex((fp.amplitude / (rated_mw or np.nan)) / (fe.amplitude / f0_hz) * np.exp(1j * phase))

    cycles = []
    for k in range(n):
        a, b = t_start + k * T, t_start + (k + 1) * T
        s = (t >= a) & ((t < b) if k < n - 1 else (t <= b))
        if s.sum() <= 4:
            raise DataError(f"sine test T = {T:g} s: too few samples in period {k}")
        ce = fit_sine(t[s], e[s], T, t_ref=t_start)
        cp = fit_sine(t[s], p[s], T, t_ref=t_start)
        Fk = cp.amplitude / ce.amplitude * scale * np.exp(1j * _wrap(cp.phase_rad - ce.phase_rad)) * fme
        cycles.append(CycleResult(k, a, complex(Fk), cp.linearity))
    Fs = np.array([c.F for c in cycles])
    sd_periods = float(np.sqrt(np.sum(np.abs(Fs - Fs.mean()) ** 2) / (n - 1)) / np.sqrt(n)) if n > 1 else None
    return SineTestResult(
        period_s=T,
        n_periods=n,
        t_start=t_start,
        t_end=t_end,
        control_error=fe,
        power=fp,
        gain=float(abs(F)),
        gain_se=float(abs(F) * rel),
        phase_rad=float(np.angle(F)),
        phase_se_rad=phase_se,
        F=F,
        F_sd=F_sd,
        G_req=G_req,
        linearity=fp.linearity,
        linearity_max_period=float(max(c.linearity for c in cycles)),
        cycles=tuple(cycles),
        F_sd_periods=sd_periods,
        fme_applied=t_fme_s is not None,
    )


def sine_test_points(results: Sequence[SineTestResult]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ω [rad/s], F, F_sd) sorted by ω, ready for tso_checks.assess_tso_points."""
    rs = sorted(results, key=lambda r: r.omega)
    return (
        np.array([r.omega for r in rs]),
        np.array([r.F for r in rs], complex),
        np.array([r.F_sd for r in rs]),
    )
