"""The numerical kernels of ident.pem against their plain definitions: the initial-condition projection
(QR with a rank check vs the SVD) and the sandwich covariance's lag sum (FFT vs the direct sum)."""

from __future__ import annotations

import numpy as np

from fcrlive.ident.pem import _hac_lag, _hac_sum, _IcProjection, _sandwich, _Struct, fixed_b_factor


def _svd_basis(Phi: np.ndarray) -> np.ndarray:
    """The definition: left singular vectors of the singular values above RTOL × the largest."""
    U, sv, _ = np.linalg.svd(Phi, full_matrices=False)
    return U[:, sv > sv[0] * _IcProjection.RTOL]


def test_ic_projection_qr_equals_svd_projector():
    # a BJ basis with the slow poles of a governor loop (nearly collinear delayed impulse responses)
    st = _Struct(nb=(2, 1), nc=2, nd=2, nf=(2, 1), nk=(1, 1), ic=True)
    F = [np.array([1.0, -1.97, 0.9702]), np.array([1.0, -0.995])]
    C, D = np.array([1.0, -0.9, 0.2]), np.array([1.0, -1.2, 0.4])
    Phi = _IcProjection.basis(st, F, C, D, 2000)
    Q = _IcProjection(st, F, C, D, 2000).Q
    U = _svd_basis(Phi)
    assert Q.shape == U.shape == Phi.shape  # full rank: the QR's basis
    X = np.random.default_rng(0).standard_normal((2000, 5))
    np.testing.assert_allclose(Q @ (Q.T @ X), U @ (U.T @ X), atol=1e-12)
    np.testing.assert_allclose(Q.T @ Q, np.eye(Q.shape[1]), atol=1e-13)


def test_ic_projection_rank_deficient_basis_falls_back_to_svd():
    rng = np.random.default_rng(1)
    A = rng.standard_normal((500, 4))
    Phi = np.asfortranarray(np.column_stack([A, A[:, 0] - 2 * A[:, 3], A[:, 1]]))
    Q = _IcProjection.orthonormal(Phi)
    U = _svd_basis(Phi)
    assert Q.shape == (500, 4) == U.shape
    X = rng.standard_normal((500, 3))
    np.testing.assert_allclose(Q @ (Q.T @ X), U @ (U.T @ X), atol=1e-12)


def _lag_sum_direct(h: np.ndarray, bounds, M: int) -> np.ndarray:
    """The definition: Σ_{|τ|≤M} (1 − |τ|/(M + 1)) Σ_n h[n] h[n−τ]ᵀ within each experiment."""
    Om = np.zeros((h.shape[1], h.shape[1]))
    for a, b in bounds:
        hs = h[a:b]
        Om += hs.T @ hs
        for tau in range(1, min(M, b - a - 1) + 1):
            G = hs[tau:].T @ hs[:-tau]
            Om += (1.0 - tau / (M + 1.0)) * (G + G.T)
    return Om


def test_hac_lag_sum_by_fft_equals_the_direct_sum():
    rng = np.random.default_rng(2)
    # correlated scores, three experiments, one shorter than the lag window
    h = _ar1(rng.standard_normal((1500, 4)), 0.9)
    bounds = [(0, 900), (900, 1470), (1470, 1500)]
    for M in (10, 57, 200):
        direct = _lag_sum_direct(h, bounds, M)
        fft = _hac_sum(h, bounds, M)
        np.testing.assert_allclose(fft, direct, rtol=1e-11, atol=1e-11 * np.abs(direct).max())
        assert np.linalg.eigvalsh(fft).min() > -1e-12 * np.abs(fft).max()  # PSD


def _ar1(x: np.ndarray, a: float) -> np.ndarray:
    y = np.empty_like(x)
    y[0] = x[0]
    for n in range(1, x.shape[0]):
        y[n] = a * y[n - 1] + x[n]
    return y


def test_sandwich_equals_its_definition():
    rng = np.random.default_rng(3)
    n = 2000
    J = rng.standard_normal((n, 5)) @ np.diag([1.0, 10.0, 0.1, 3.0, 1e3])
    eps = _ar1(rng.standard_normal((n, 1)), 0.7)[:, 0]
    bounds = [(0, 1200), (1200, n)]
    M = _hac_lag(eps, bounds)
    Hi = np.linalg.inv(J.T @ J)
    # the Newey-West sandwich with the fixed-b critical value of its lag (pem.fixed_b_factor)
    P_def = Hi @ _lag_sum_direct(J * eps[:, None], bounds, M) @ Hi * fixed_b_factor(M, n) ** 2
    np.testing.assert_allclose(_sandwich(J, eps, bounds), P_def, rtol=1e-9, atol=1e-12 * np.abs(P_def).max())


def test_sandwich_rank_deficient_jacobian_uses_the_identifiable_subspace():
    rng = np.random.default_rng(4)
    n = 1000
    A = rng.standard_normal((n, 3))
    J = np.column_stack([A, A[:, 0] + 2 * A[:, 1]])  # the last parameter is not identifiable alone
    eps = rng.standard_normal(n)
    P = _sandwich(J, eps, [(0, n)])
    # the pseudo-inverse of the column-scaled problem (pem._cov_factor)
    s = np.sqrt((J**2).sum(axis=0))
    Hp = np.linalg.pinv((J / s).T @ (J / s)) / np.outer(s, s)
    M = _hac_lag(eps, [(0, n)])
    P_def = Hp @ _lag_sum_direct(J * eps[:, None], [(0, n)], M) @ Hp * fixed_b_factor(M, n) ** 2
    np.testing.assert_allclose(P, P_def, rtol=1e-8, atol=1e-10 * np.abs(P_def).max())
    assert np.linalg.eigvalsh(P).min() > -1e-15 * np.abs(P).max()
