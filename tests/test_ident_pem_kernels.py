"""The numerical kernels of ident.pem against their plain definitions: the initial-condition projection
(QR with a rank check vs the SVD) and the sandwich covariance's lag sum (FFT vs the direct sum)."""

from __future__ import annotations

import numpy as np

from fcrlive.ident.pem import _IcProjection, _Struct


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
