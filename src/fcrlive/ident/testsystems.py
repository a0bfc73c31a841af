"""Known systems to test identification on: open- and closed-loop Box-Jenkins data, seeded.

Closed loop (the plant y = G u + H e with G = B/F, H = C/D; controller u = K (r − y), K = Kn/Kd):

    y = G K S r + S H e,     u = K S r − K S H e,     S = 1/(1 + G K) = F Kd / (F Kd + B Kn)

simulated exactly with lfilter on the closed-loop polynomials (from rest). A delay in the loop
(nk ≥ 1 in B, or in K) keeps direct prediction-error identification consistent (paper, Theorem 2).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.signal as sps

from fcrlive.ident.data import IdData
from fcrlive.ident.poly import PolyModel


@dataclass(frozen=True)
class ClosedLoopData:
    """Simulated closed-loop experiment: ``data`` holds (y; u), ``r`` the reference, ``e`` the noise."""

    data: IdData
    r: np.ndarray
    e: np.ndarray
    u_r: np.ndarray
    """Noise-free part of u (the part driven by r): what the two-stage method estimates."""


def bj_model(b, c, d, f, nk: int, Ts: float = 1.0, noise_variance: float = 1.0) -> PolyModel:
    """SISO BJ PolyModel from coefficient lists (b without the nk zeros, c, d, f with leading 1).

    A true system is known exactly: its covariance is zero (a model without covariance has an unknown,
    NaN, uncertainty)."""
    m = PolyModel(a=[1.0], b=(np.concatenate((np.zeros(nk), b)),), c=c, d=d, f=(f,), nk=(nk,), Ts=Ts,
                  noise_variance=noise_variance)
    return replace(m, covariance=np.zeros((m.n_params, m.n_params)))


def simulate_open_loop(model: PolyModel, u: np.ndarray, rng: np.random.Generator, sigma_e: float) -> IdData:
    """y = Σ B_i/F_i u_i + C/D e (A = 1 models; A is applied as 1/A on both terms otherwise)."""
    u = np.asarray(u, dtype=float)
    if u.ndim == 1:
        u = u[:, None]
    e = sigma_e * rng.standard_normal(u.shape[0])
    y = model.simulate(u) + sps.lfilter(model.c, np.convolve(model.a, model.d), e)
    return IdData(y, u, model.Ts, input_names=model.input_names)


def simulate_closed_loop(model: PolyModel, r: np.ndarray, kn, kd, rng: np.random.Generator,
                         sigma_e: float) -> ClosedLoopData:
    """SISO closed loop u = K (r − y), K = Kn/Kd in z⁻¹, plant ``model`` (A = 1, one input)."""
    B, F, C, D = model.b[0], model.f[0], model.c, model.d
    kn = np.atleast_1d(np.asarray(kn, float))
    kd = np.atleast_1d(np.asarray(kd, float))
    e = sigma_e * rng.standard_normal(r.shape[0])
    fk = np.convolve(F, kd)
    bk = np.convolve(B, kn)
    n = max(fk.size, bk.size)
    char = np.pad(fk, (0, n - fk.size)) + np.pad(bk, (0, n - bk.size))  # F Kd + B Kn
    # u = Kn F / char · r − Kn F C / (char D) · e
    u_r = sps.lfilter(np.convolve(kn, F), char, r)
    u_e = -sps.lfilter(np.convolve(np.convolve(kn, F), C), np.convolve(char, D), e)
    u = u_r + u_e
    y = sps.lfilter(B, F, u) + sps.lfilter(C, D, e)
    data = IdData(y, u, model.Ts, input_names=("u",))
    return ClosedLoopData(data, r, e, u_r)
