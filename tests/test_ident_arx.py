"""ARX: agreement with an independent least-squares solution, calibration, structure selection, errors."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as sps

from fcrlive.ident import (
    IdData,
    NonFiniteDataError,
    NotExcitingError,
    OrderError,
    TooFewSamplesError,
    arx,
    arxstruc,
    selstruc,
)
from fcrlive.ident.arx import arx_regression

A_TRUE = np.array([1.0, -1.5, 0.7])
B1_TRUE = np.array([0.0, 1.0, 0.5])  # nk = 1, nb = 2
B2_TRUE = np.array([0.0, 0.0, -0.4])  # nk = 2, nb = 1
THETA_TRUE = np.array([-1.5, 0.7, 1.0, 0.5, -0.4])


def _miso_arx(n, seed, sigma=0.5):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 2))
    e = sigma * rng.standard_normal(n)
    y = sps.lfilter(B1_TRUE, A_TRUE, u[:, 0]) + sps.lfilter(B2_TRUE, A_TRUE, u[:, 1]) + sps.lfilter(
        [1.0], A_TRUE, e)
    return IdData(y, u, Ts=0.2, input_names=("u", "r"))


@pytest.mark.parametrize("solver", ["qr", "cholqr2"])
def test_arx_agrees_with_independent_least_squares(solver):
    d = IdData.merge(_miso_arx(700, 1), _miso_arx(500, 2))
    m = arx(d, 2, [2, 1], [1, 2], solver=solver)
    assert m.report.algorithm == solver
    # independent reference: regressor built by hand, np.linalg.lstsq and the normal equations
    rows, ys = [], []
    for y, u in d.segments():
        for t in range(2, y.size):
            rows.append([-y[t - 1], -y[t - 2], u[t - 1, 0], u[t - 2, 0], u[t - 2, 1]])
            ys.append(y[t])
    X, Y = np.array(rows), np.array(ys)
    ref = np.linalg.lstsq(X, Y, rcond=None)[0]
    np.testing.assert_allclose(m.theta, ref, rtol=0, atol=1e-8)
    np.testing.assert_allclose(m.theta, np.linalg.solve(X.T @ X, X.T @ Y), rtol=0, atol=1e-8)
    lam = np.sum((Y - X @ ref) ** 2) / (Y.size - 5)
    np.testing.assert_allclose(m.noise_variance, lam, rtol=1e-10)
    np.testing.assert_allclose(m.covariance, lam * np.linalg.inv(X.T @ X), rtol=1e-7)
    Phi, yy = arx_regression(d, 2, [2, 1], [1, 2])
    np.testing.assert_allclose(Phi, X) and np.testing.assert_allclose(yy, Y)


def test_arx_high_order_cholqr2_matches_householder():
    rng = np.random.default_rng(5)
    d = IdData(rng.standard_normal(3000), rng.standard_normal((3000, 3)), 1.0)
    a = arx(d, 10, 10, 0, solver="qr")
    b = arx(d, 10, 10, 0, solver="cholqr2")
    np.testing.assert_allclose(a.theta, b.theta, atol=1e-10)
    np.testing.assert_allclose(a.covariance, b.covariance, rtol=1e-8, atol=1e-14)


def test_arx_estimates_within_three_sd_and_sd_calibrated():
    m = arx(_miso_arx(4000, 3), 2, [2, 1], [1, 2])
    z = (m.theta - THETA_TRUE) / m.sd
    assert np.all(np.abs(z) < 3), z
    assert m.b[1][:2].tolist() == [0.0, 0.0] and m.nk == (1, 2) and m.nb == (2, 1)
    # sd against the spread over independent data sets (small Monte Carlo: 40 runs)
    est = np.array([arx(_miso_arx(1000, 100 + k), 2, [2, 1], [1, 2]).theta for k in range(40)])
    sd_mc = est.std(axis=0, ddof=1)
    sd_hat = arx(_miso_arx(1000, 99), 2, [2, 1], [1, 2]).sd
    assert np.all(np.abs(sd_hat / sd_mc - 1) < 0.35), sd_hat / sd_mc


def test_arxstruc_selstruc_find_the_true_orders():
    d = _miso_arx(3000, 4)
    v = _miso_arx(3000, 5)
    orders = [[na, nb1, nb2, 1, 2] for na in (1, 2, 3, 4) for nb1 in (1, 2, 3) for nb2 in (1, 2)]
    table = arxstruc(d, v, orders)
    best, _ = selstruc(table, "bic")
    assert best.tolist() == [2, 2, 1, 1, 2]
    assert table.loss.shape == (len(orders),) and table.validated


def test_arx_errors():
    d = _miso_arx(300, 6)
    y = d.y.copy()
    y[17] = np.inf
    with pytest.raises(NonFiniteDataError, match="'y'"):
        arx(IdData(y, d.u, 0.2), 2, 2, 1)
    u = d.u.copy()
    u[:, 1] = 0.0
    with pytest.raises(NotExcitingError, match="'r'"):
        arx(IdData(d.y, u, 0.2, input_names=("u", "r")), 2, 2, 1)
    with pytest.raises(TooFewSamplesError, match=r"rows.*parameters"):
        arx(IdData(d.y[:20], d.u[:20], 0.2), 10, 5, 1)
    with pytest.raises(OrderError, match="nb"):
        arx(d, 2, [2, 2, 2], 1)
    with pytest.raises(OrderError):
        arx(d, -1, 2, 1)
    # a sine is persistently exciting of order 2 only: ARX with nb = 6 is rank deficient
    t = np.arange(400)
    s = IdData(np.random.default_rng(0).standard_normal(400), np.sin(0.3 * t), 1.0)
    with pytest.raises(NotExcitingError, match="rank deficient"):
        arx(s, 0, 6, 0)
