"""Closed-loop identification with a measured external excitation r.

Direct prediction-error identification (``bj`` on (u, y)) is consistent in closed loop only when the
noise model is right *and* there is a delay in the loop (paper, Theorems 1-2, Condition C1/C2). Without
a loop delay, or with a wrong noise model (OE, too low nc/nd), it is biased because u is correlated
with the noise. The two methods here use r, which is uncorrelated with the noise, and are consistent
for G whatever the noise model (and with or without a loop delay), at the cost of some variance:

* two-stage (Van den Hof & Schrama 1993): stage 1 estimates the sensitivity r → u with a causal FIR
  by least squares (consistent: r is uncorrelated with the noise), stage 2 simulates the noise-free
  û_r = Ŝ r and fits OE/BJ from û_r to y.
* projection (Forssell & Ljung 2000): the same with a non-causal FIR (lags −n_lead..n_lag), which
  projects u onto r even when the controller is non-linear or time varying.

Covariance caveat: the stage-2 covariance λ̂(JᵀJ)⁻¹ treats û_r as an exact, noise-free input. It
ignores the estimation error of Ŝ (a small extra term of relative order n_fir/N) and, when the stage-2
noise model is OE or too simple, the colour of the stage-2 noise v + G(u − û_r). Use BJ in stage 2
for honest bands; with OE the sd are indicative only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from fcrlive.ident.arx import per_input
from fcrlive.ident.data import IdData
from fcrlive.ident.errors import NotExcitingError, TooFewSamplesError
from fcrlive.ident.pem import _ls, bj, oe
from fcrlive.ident.poly import PolyModel

_COV_NOTE = (
    "covariance treats the stage-1 simulated input as exact (ignores the FIR estimation error); "
    "indicative only if the stage-2 noise model is too simple"
)


def _r_matrix(data: IdData, r) -> np.ndarray:
    r = np.asarray(r, dtype=float)
    if r.ndim == 1:
        r = r[:, None]
    if r.shape[0] != data.N:
        raise ValueError(f"excitation r has {r.shape[0]} samples, the data {data.N}")
    if not np.all(np.isfinite(r)):
        raise ValueError("excitation r has NaN/inf samples (split the data and r together)")
    for j in range(r.shape[1]):
        if np.ptp(r[:, j]) == 0:
            raise NotExcitingError("excitation is constant", where=f"excitation column {j}")
    return r


def fir_projection(data: IdData, r, n_lag: int, n_lead: int = 0, *,
                   return_bic: bool = False) -> tuple[IdData, np.ndarray]:
    """Replace each input of ``data`` by its least-squares FIR projection on r (lags −n_lead..n_lag).

    Returns (data with the projected inputs û_i, FIR coefficients (nu, n_taps·nr)). The FIR is fitted
    on all experiments jointly (rows where every lag is inside the experiment) and applied from rest.
    With ``return_bic`` it returns (BIC summed over inputs, None) instead, for choosing the length.
    """
    R = _r_matrix(data, r)
    nr = R.shape[1]
    lags = np.arange(-int(n_lead), int(n_lag) + 1)
    p = lags.size * nr
    X_rows, U_rows, X_full = [], [], []
    for (a, b), (_, u) in zip(data.bounds, data.segments()):
        L = b - a
        Rs = R[a:b]
        X = np.zeros((L, p))
        for j in range(nr):
            for m, k in enumerate(lags):
                col = j * lags.size + m
                if k >= 0:
                    X[k:, col] = Rs[:L - k, j] if k < L else 0.0
                else:
                    X[:L + k, col] = Rs[-k:, j] if -k < L else 0.0
        X_full.append(X)
        lo, hi = int(max(lags.max(), 0)), int(L + min(lags.min(), 0))
        if hi > lo:
            X_rows.append(X[lo:hi])
            U_rows.append(u[lo:hi])
    if not X_rows or sum(x.shape[0] for x in X_rows) <= 2 * p:
        raise TooFewSamplesError(
            f"too few samples for a {lags.size}-tap FIR projection on {nr} excitation(s)",
            where=f"output {data.output_name!r}",
        )
    X = np.vstack(X_rows)
    U = np.vstack(U_rows)
    coef = np.column_stack([_ls(X, U[:, i]) for i in range(data.nu)])
    if return_bic:
        n = X.shape[0]
        ssr = np.sum((U - X @ coef) ** 2, axis=0)
        return float(np.sum(n * np.log(ssr / n) + p * np.log(n))), None  # type: ignore[return-value]
    u_hat = np.vstack(X_full) @ coef
    names = tuple(f"{n}_r" for n in data.input_names)
    return data._with(u=u_hat, input_names=names), coef.T


def choose_fir_length(data: IdData, r, noncausal: bool, candidates=(3, 5, 8, 12, 20, 30, 45, 60, 90, 120)
                      ) -> int:
    """FIR length (past taps; as many future taps if ``noncausal``) minimising BIC of the projection.

    A FIR longer than needed adds estimation noise to û_r, which acts as an errors-in-variables
    disturbance in stage 2 (attenuation bias of order n_fir/N·noise/signal): keep it as short as BIC
    allows. Candidates are limited to N/(20·nr·(1 + noncausal)).
    """
    R = _r_matrix(data, r)
    cap = max(3, data.N // (20 * R.shape[1] * (2 if noncausal else 1)))
    cands = [c for c in candidates if c <= cap] or [min(candidates)]
    scores = [fir_projection(data, R, n_lag=c - 1 if not noncausal else c, n_lead=c if noncausal else 0,
                             return_bic=True)[0] for c in cands]
    return int(cands[int(np.argmin(scores))])


def _stage2(data: IdData, proj: IdData, method: str, nb, nc, nd, nf, nk, kw) -> PolyModel:
    if nc == 0 and nd == 0:
        m = oe(proj, nb, nf, nk, **kw)
    else:
        m = bj(proj, nb, nc, nd, nf, nk, **kw)
    rep = replace(m.report, method=f"{method} {m.report.method}", notes=(*m.report.notes, _COV_NOTE))
    return replace(m, report=rep, input_names=data.input_names)


def two_stage(data: IdData, r, nb: int | Sequence[int], nf: int | Sequence[int],
              nk: int | Sequence[int] = 1, *, nc: int = 0, nd: int = 0, n_fir: int | None = None,
              **kw) -> PolyModel:
    """Two-stage closed-loop estimate of G_i = B_i/F_i from r (measured excitation) and (u, y).

    Args:
        data: closed-loop data (y; u_1..u_nu), the inputs correlated with the noise through feedback.
            Inputs that are themselves external (e.g. r in the paper's eq. 14) may be included: their
            projection on r is (almost) exact.
        r: excitation (N,) or (N, nr) aligned with ``data`` (same concatenated samples).
        nb, nf, nk: B/F orders and delays per input; nc, nd: stage-2 noise model (0, 0 = OE).
        n_fir: FIR length of the sensitivity estimate (default: chosen by BIC, see
            :func:`choose_fir_length`); it must cover the closed-loop settling time from r to u.
        **kw: passed to :func:`oe`/:func:`bj` (multistart, seed, ...).

    Returns:
        PolyModel (inputs named as in ``data``); see the module docstring for the covariance caveat.
    """
    R = _r_matrix(data, r)
    if n_fir is None:
        n_fir = choose_fir_length(data, R, noncausal=False)
    proj, _ = fir_projection(data, R, n_lag=int(n_fir) - 1, n_lead=0)
    per_input(nb, data.nu, "nb")
    return _stage2(data, proj, "two-stage", nb, nc, nd, nf, nk, kw)


def projection(data: IdData, r, nb: int | Sequence[int], nf: int | Sequence[int],
               nk: int | Sequence[int] = 1, *, nc: int = 0, nd: int = 0, n_lag: int | None = None,
               n_lead: int | None = None, **kw) -> PolyModel:
    """Projection method (Forssell & Ljung 2000): like :func:`two_stage` with a non-causal FIR.

    ``n_lag``/``n_lead`` default to a BIC choice (:func:`choose_fir_length`), as many future as past taps.
    """
    R = _r_matrix(data, r)
    m = choose_fir_length(data, R, noncausal=True) if n_lag is None or n_lead is None else 0
    n_lag = m if n_lag is None else int(n_lag)
    n_lead = m if n_lead is None else int(n_lead)
    proj, _ = fir_projection(data, R, n_lag=n_lag, n_lead=n_lead)
    return _stage2(data, proj, "projection", nb, nc, nd, nf, nk, kw)
