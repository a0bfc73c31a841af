"""Model validation like the toolbox: ``resid``, ``compare``, AIC/BIC/FPE and order search.

Correlations are computed per experiment and summed (no products across a gap), then normalised:

    r_ε(k)    = R_ε(k)/R_ε(0),                       R_ε(k) = (1/N) Σ ε(t) ε(t−k)
    r_εu(τ)   = R_εu(τ)/sqrt(R_ε(0) R_u(0)),         R_εu(τ) = (1/N) Σ ε(t) u(t−τ)

τ > 0 means ε now vs u in the past: a significant r_εu(τ ≥ nk) says the dynamics from u are not fully
modelled. τ < 0 (u now vs ε in the past) is correlation through feedback and is expected in closed
loop; it is reported but not part of the pass/fail decision (nor are lags τ < nk, see ``resid``).

Pass/fail uses portmanteau statistics rather than "every lag inside its band" (with 25 lags at 99 %
that rule alone rejects a correct model ~22 % of the time):
  whiteness:      Q = N Σ_{k=1..M} r_ε(k)²  ~ χ²(M − nc − nd)
  independence:   S = N r̂ᵀ P⁻¹ r̂ over τ = nk_i..M ~ χ²(M + 1 − nk_i), P_{τ1τ2} = Σ_k r_ε(k) r_u(k+τ2−τ1)
                  (the covariance of the cross-correlations when ε and u are independent; P is the
                  input's Toeplitz matrix when ε is white, as in the toolbox's band sqrt(P/N)).
The per-lag bands (±z/√N, z for the chosen confidence) are returned for plots as in ``resid``.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.stats as stats

from fcrlive.ident.data import IdData
from fcrlive.ident.poly import PolyModel


def _xcorr_sum(a_segs, b_segs, lags: np.ndarray) -> np.ndarray:
    """Σ over experiments of Σ_t a(t) b(t−τ) for each τ in lags (zero outside each experiment)."""
    out = np.zeros(lags.size)
    for a, b in zip(a_segs, b_segs):
        L = a.shape[0]
        for j, tau in enumerate(lags):
            if tau >= 0 and tau < L:
                out[j] += a[tau:] @ b[:L - tau]
            elif tau < 0 and -tau < L:
                out[j] += a[:L + tau] @ b[-tau:]
    return out


def _independence(e_segs, u_segs, re: np.ndarray, r_e: np.ndarray, M: int, k0: int, n: int
                  ) -> tuple[np.ndarray, float]:
    """r_εu(τ), τ = −M..M, and the p-value of the portmanteau independence test over τ = k0..M."""
    kk = np.arange(-M, M + 1)
    taper = 1.0 - np.abs(kk) / (M + 1)  # Bartlett weights keep the covariance estimate positive
    re_sym = r_e[np.abs(kk)] * taper
    ru = _xcorr_sum(u_segs, u_segs, np.arange(3 * M + 2)) / n
    reu = _xcorr_sum(e_segs, u_segs, kk) / n
    xc = reu / np.sqrt(re[0] * ru[0])
    r_u = ru / ru[0]
    taus = np.arange(k0, M + 1)
    pos = xc[M + taus]
    # Cov of √N r̂_εu(τ1), √N r̂_εu(τ2) for ε independent of u: Σ_k r_ε(k) r_u(k + τ2 − τ1)
    diff = taus[None, :] - taus[:, None]
    P = np.zeros((taus.size, taus.size))
    for k, w in zip(kk, re_sym):
        P += w * r_u[np.abs(k + diff)]
    try:
        s = n * float(pos @ np.linalg.solve(P, pos))
    except np.linalg.LinAlgError:
        s = n * float(pos @ np.linalg.lstsq(P, pos, rcond=None)[0])
    return xc, float(stats.chi2.sf(s, taus.size))


@dataclass(frozen=True)
class ResidResult:
    """Residual analysis.

    Attributes:
        lags: 0..M for the autocorrelation.
        autocorr: r_ε(k), k = 0..M (r_ε(0) = 1).
        xlags: −M..M for the cross-correlations.
        xcorr: r_εu_i(τ), shape (nu, 2M+1).
        band99, band95: per-lag ± bands of the normalised correlations (1/√N scale).
        whiteness_p: p-value of the whiteness portmanteau test.
        independence_p: p-value of the independence test (τ = 0..M) per input.
        confidence: level of the pass/fail decisions.
        white, independent: test results; ``passed`` = both.
        n_outside: lags outside the band at ``confidence`` (autocorr k ≥ 1; xcorr τ ≥ 0 per input).
    """

    lags: np.ndarray
    autocorr: np.ndarray
    xlags: np.ndarray
    xcorr: np.ndarray
    band99: float
    band95: float
    whiteness_p: float
    independence_p: tuple[float, ...]
    confidence: float
    white: bool
    independent: tuple[bool, ...]
    n_outside: tuple[int, ...]

    @property
    def passed(self) -> bool:
        return self.white and all(self.independent)


def resid(model: PolyModel, data: IdData, max_lag: int = 25, confidence: float = 0.99) -> ResidResult:
    """Residual whiteness and residual/input independence tests (the toolbox's ``resid``)."""
    data.require_finite()
    eps = model.residuals(data)
    e_segs = data.split_signal(eps)
    n = eps.size
    M = int(max_lag)
    lags = np.arange(M + 1)
    re = _xcorr_sum(e_segs, e_segs, lags) / n
    r_e = re / re[0]
    xl = np.arange(-M, M + 1)
    xc = np.zeros((data.nu, xl.size))
    ind_p, ind_ok, outside = [], [], []
    z = stats.norm.ppf(0.5 + confidence / 2)
    band = z / np.sqrt(n)
    dof_w = max(M - model.nc - model.nd, 1)
    q = n * float(np.sum(r_e[1:] ** 2))
    white_p = float(stats.chi2.sf(q, dof_w))
    outside.append(int(np.sum(np.abs(r_e[1:]) > band)))
    for i in range(data.nu):
        u_segs = [u[:, i] for _, u in data.segments()]
        # lags τ ≥ nk_i: below the delay the model has no term, and in closed loop with a direct
        # feed-through controller ε(t) and u(t) are correlated through the feedback anyway
        k0 = model.nk[i] if i < model.nu else 0
        xc[i], p = _independence(e_segs, u_segs, re, r_e, M, k0, n)
        ind_p.append(p)
        ind_ok.append(p > 1 - confidence)
        outside.append(int(np.sum(np.abs(xc[i, M + k0:]) > band)))
    return ResidResult(
        lags=lags, autocorr=r_e, xlags=xl, xcorr=xc,
        band99=float(stats.norm.ppf(0.995) / np.sqrt(n)), band95=float(stats.norm.ppf(0.975) / np.sqrt(n)),
        whiteness_p=white_p, independence_p=tuple(ind_p), confidence=confidence,
        white=white_p > 1 - confidence, independent=tuple(ind_ok), n_outside=tuple(outside),
    )


@dataclass(frozen=True)
class XResidResult:
    """Independence of residuals from an external signal (:func:`xresid`).

    Attributes:
        xlags: −M..M.
        xcorr: r_εx(τ) over ``xlags``.
        band99: per-lag ±99 % band (1/√N scale).
        p: p-value of the portmanteau test over τ = 0..M (ε's colour accounted for).
        independent: p > 1 − confidence.
    """

    xlags: np.ndarray
    xcorr: np.ndarray
    band99: float
    p: float
    independent: bool


def xresid(eps_segs: Sequence[np.ndarray], x_segs: Sequence[np.ndarray], max_lag: int = 20,
           confidence: float = 0.99) -> XResidResult:
    """Are residuals ε independent of a signal x that is NOT a model input (per experiment, summed)?

    The closed-loop use: x an external excitation r, which the process noise cannot reach, so a model
    whose residual still carries r at any lag τ ≥ 0 has dynamics missing, whatever the residual's colour.
    An input inside the loop (c, u) is a function of past noise, and an output-error model's coloured
    residual is correlated with it at τ > 0 even when the model is exact."""
    e_segs = [np.asarray(e, float) - np.mean(e) for e in eps_segs]
    x_segs = [np.asarray(x, float) - np.mean(x) for x in x_segs]
    n = sum(e.size for e in e_segs)
    M = int(max_lag)
    re = _xcorr_sum(e_segs, e_segs, np.arange(M + 1)) / n
    if not (re[0] > 0 and sum(float(x @ x) for x in x_segs) > 0):
        raise ValueError("xresid needs residuals and a signal that are not identically zero")
    xc, p = _independence(e_segs, x_segs, re, re / re[0], M, 0, n)
    return XResidResult(np.arange(-M, M + 1), xc, float(stats.norm.ppf(0.995) / np.sqrt(n)), p,
                        p > 1 - confidence)


@dataclass(frozen=True)
class CompareResult:
    """``compare``: NRMSE fit [%] = 100 (1 − ‖y − ŷ‖/‖y − ȳ‖) and the model output ŷ."""

    fit_percent: float
    y_model: np.ndarray
    horizon: str


def compare(model: PolyModel, data: IdData, horizon: str | int = "sim") -> CompareResult:
    """Fit of the simulated (``horizon="sim"``) or one-step predicted (``horizon=1``) output.

    Zero initial conditions per experiment; ȳ is the mean of each experiment.
    """
    if horizon == "sim":
        yh = model.simulate(data)
    elif horizon == 1:
        yh = model.predict(data)
    else:
        raise ValueError(f"horizon must be 'sim' or 1, got {horizon!r}")
    num = float(np.sum((data.y - yh) ** 2))
    den = sum(float(np.sum((y - y.mean()) ** 2)) for y, _ in data.segments())
    fit = 100.0 * (1.0 - np.sqrt(num / den)) if den > 0 else -np.inf
    return CompareResult(fit, yh, str(horizon))


def _loss_n_p(model: PolyModel) -> tuple[float, int, int]:
    if model.report is None:
        raise ValueError("model has no estimation report (loss and N unknown)")
    return model.report.loss, model.report.n_samples, model.n_params


def aic(model: PolyModel) -> float:
    """Akaike's criterion N·log V + 2p (V = mean squared prediction error on the estimation data)."""
    v, n, p = _loss_n_p(model)
    return float(n * np.log(v) + 2 * p)


def bic(model: PolyModel) -> float:
    """Bayesian (Rissanen MDL) criterion N·log V + p·log N."""
    v, n, p = _loss_n_p(model)
    return float(n * np.log(v) + p * np.log(n))


def fpe(model: PolyModel) -> float:
    """Akaike's final prediction error V (1 + p/N)/(1 − p/N)."""
    v, n, p = _loss_n_p(model)
    return float(v * (1 + p / n) / (1 - p / n))


_CRITERIA = {"aic": aic, "bic": bic, "fpe": fpe}


@dataclass(frozen=True)
class OrderSearchResult:
    """Order search: every structure tried with its score; ``best`` has the lowest score."""

    orders: tuple[tuple, ...]
    scores: np.ndarray
    models: tuple[PolyModel, ...]
    criterion: str

    @property
    def best_index(self) -> int:
        return int(np.argmin(self.scores))

    @property
    def best(self) -> PolyModel:
        return self.models[self.best_index]

    @property
    def best_orders(self) -> tuple:
        return self.orders[self.best_index]


def bj_order_search(data: IdData, grid: Iterable[Sequence[int]], nk: int | Sequence[int] = 1,
                    criterion: str = "aic", val: IdData | None = None) -> OrderSearchResult:
    """Fit BJ(nb, nc, nd, nf) for each (nb, nc, nd, nf) in ``grid`` and score it.

    ``criterion``: "aic", "bic", "fpe" on the estimation data, or "val" for the mean squared one-step
    prediction error on ``val``. A small grid is meant (each fit is a nonlinear search).
    """
    from fcrlive.ident.pem import bj  # avoid an import cycle at module load

    orders, scores, models = [], [], []
    for o in grid:
        nb, nc, nd, nf = (int(x) for x in o)
        m = bj(data, nb, nc, nd, nf, nk)
        if criterion == "val":
            if val is None:
                raise ValueError("criterion 'val' needs validation data")
            s = float(np.mean(m.residuals(val) ** 2))
        else:
            s = _CRITERIA[criterion](m)
        orders.append((nb, nc, nd, nf))
        scores.append(s)
        models.append(m)
    return OrderSearchResult(tuple(orders), np.array(scores), tuple(models), criterion)


def arx_order_search(data: IdData, na_range: Iterable[int], nb_range: Iterable[int],
                     nk: int | Sequence[int] = 1, criterion: str = "aic",
                     val: IdData | None = None) -> OrderSearchResult:
    """Fit ARX(na, nb, nk) (same nb for every input) over the ranges and score it like bj_order_search."""
    from fcrlive.ident.arx import arx

    orders, scores, models = [], [], []
    for na in na_range:
        for nb in nb_range:
            m = arx(data, na, nb, nk)
            if criterion == "val":
                if val is None:
                    raise ValueError("criterion 'val' needs validation data")
                s = float(np.mean(m.residuals(val) ** 2))
            else:
                s = _CRITERIA[criterion](m)
            orders.append((int(na), int(nb)))
            scores.append(s)
            models.append(m)
    return OrderSearchResult(tuple(orders), np.array(scores), tuple(models), criterion)
