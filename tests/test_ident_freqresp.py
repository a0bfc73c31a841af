"""Uncertain frequency responses: gradients, Gauss-approximation sd, and the algebra of eqs. 15 and 19."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as sps

from fcrlive.ident import FreqResp, IdData, PolyModel, arx
from fcrlive.ident.testsystems import bj_model

W = np.array([0.0, 0.05, 0.2, 0.6, 1.5, 3.0])  # rad/s, Ts = 1 s


def _model_with_cov(seed: int, scale: float = 1e-4) -> PolyModel:
    rng = np.random.default_rng(seed)
    m = PolyModel(a=[1, -0.5], b=([0, 1.0, 0.4], [0.3]), c=[1, 0.3], d=[1, -0.6], f=([1, -0.7], [1, 0.2]),
                  nk=(1, 0), Ts=1.0)
    p = m.n_params
    L = rng.standard_normal((p, p))
    return m.with_theta(m.theta + 0.01 * rng.standard_normal(p), covariance=scale * (L @ L.T) / p)


def _num_jac(fun, theta, h=1e-7):
    return np.column_stack([(fun(theta + h * e) - fun(theta - h * e)) / (2 * h) for e in np.eye(theta.size)])


@pytest.mark.parametrize("inp", [0, 1, "noise"])
def test_freqresp_gradient_matches_finite_differences(inp):
    m = _model_with_cov(0)
    g = m.freqresp(W, input=inp)
    Jn = _num_jac(lambda th: m.with_theta(th).freqresp(W, input=inp).value, m.theta)
    np.testing.assert_allclose(g.jacobian, Jn, atol=1e-7)
    num, den = m.tf(inp)
    _, h = sps.freqz(num, den, worN=W)
    np.testing.assert_allclose(g.value, h, rtol=1e-12)


def test_sd_abs_and_phase_match_monte_carlo_of_parameters():
    m = _model_with_cov(1, scale=1e-6)
    g = m.freqresp(W, input=0)
    rng = np.random.default_rng(2)
    draws = rng.multivariate_normal(m.theta, m.covariance, size=4000)
    vals = np.array([m.with_theta(th).freqresp(W, input=0).value for th in draws])
    np.testing.assert_allclose(g.sd_abs, np.abs(vals).std(axis=0), rtol=0.08)
    np.testing.assert_allclose(g.sd_phase, np.angle(vals / g.value).std(axis=0), rtol=0.08)
    lo, hi = g.ci95_abs()
    inside = (np.abs(vals) >= lo) & (np.abs(vals) <= hi)
    assert np.all(np.abs(inside.mean(axis=0) - 0.95) < 0.02)


def test_static_gain_and_peak():
    m = _model_with_cov(3)
    val, sd = m.static_gain(input=0)
    np.testing.assert_allclose(val, np.sum(m.b[0]) / (np.sum(m.a) * np.sum(m.f[0])))
    grad = _num_jac(lambda th: np.atleast_1d(m.with_theta(th).static_gain(0)[0]), m.theta)[0]
    assert sd == pytest.approx(np.sqrt(grad @ m.covariance @ grad), rel=1e-6)
    pk = m.peak_gain(input=0)
    w = np.linspace(1e-4, np.pi, 20001)
    assert pk.value == pytest.approx(np.max(m.freqresp(w, 0).abs), rel=1e-5)
    assert pk.sd > 0 and pk.ci95()[0] < pk.value < pk.ci95()[1]


def test_product_quotient_inverse_propagation_matches_numerical_jacobian():
    m1, m2 = _model_with_cov(4), _model_with_cov(5)
    w = W[1:]
    Gc = 0.8 + 0.5 / (1 - np.exp(-1j * w))  # a known PI controller
    rho = 2.0

    def combo(t1, t2):
        a = m1.with_theta(t1).freqresp(w, 0)
        b = m1.with_theta(t1).freqresp(w, 1)
        c = m2.with_theta(t2).freqresp(w, 0)
        return (a * Gc / (b * (1 + rho * Gc * c))).value + (1 - a).inv().value - 3.0 * c.value / a.value

    G = m1.freqresp(w, 0) * Gc / (m1.freqresp(w, 1) * (1 + rho * Gc * m2.freqresp(w, 0)))
    G = G + (1 - m1.freqresp(w, 0)).inv() - 3.0 * m2.freqresp(w, 0) / m1.freqresp(w, 0)
    np.testing.assert_allclose(G.value, combo(m1.theta, m2.theta), rtol=1e-12)
    # two independent sources, stacked block-diagonally; the shared model m1 occupies one block
    assert [k for k, _ in G.sources] == [m1.uid, m2.uid] and G.n_params == m1.n_params + m2.n_params
    J1 = _num_jac(lambda t: combo(t, m2.theta), m1.theta)
    J2 = _num_jac(lambda t: combo(m1.theta, t), m2.theta)
    np.testing.assert_allclose(G.jacobian, np.hstack((J1, J2)), rtol=1e-5, atol=1e-7)
    cov = np.block([[m1.covariance, np.zeros((m1.n_params, m2.n_params))],
                    [np.zeros((m2.n_params, m1.n_params)), m2.covariance]])
    ga = np.real(np.conj(G.value)[:, None] * np.hstack((J1, J2))) / G.abs[:, None]
    np.testing.assert_allclose(G.sd_abs, np.sqrt(np.einsum("ij,jk,ik->i", ga, cov, ga)), rtol=1e-5)


def test_eq15_shared_model_keeps_correlation():
    """G_p = (1 − S)/G_1 with S and G_1 from one MISO fit: correlation of S and G_1 must be kept."""
    rng = np.random.default_rng(6)
    n = 3000
    u, r = rng.standard_normal(n), rng.standard_normal(n)
    y = sps.lfilter([0.4, 0.2], [1, -0.6], u) + sps.lfilter([1, -0.9], [1, -0.6], r) + sps.lfilter(
        [1], [1, -0.6], 0.3 * rng.standard_normal(n))
    m = arx(IdData(y, np.column_stack((u, r)), 1.0, input_names=("u", "r")), 1, 2, 0)
    w = W[1:]
    G1, S = m.freqresp(w, "u"), m.freqresp(w, "r")
    Gp = (1 - S) / G1
    assert Gp.n_params == m.n_params  # same source: no stacking

    def gp(th):
        mm = m.with_theta(th)
        return ((1 - mm.freqresp(w, "r")) / mm.freqresp(w, "u")).value

    Jn = _num_jac(gp, m.theta)
    np.testing.assert_allclose(Gp.jacobian, Jn, rtol=1e-5, atol=1e-8)
    ga = np.real(np.conj(Gp.value)[:, None] * Jn) / Gp.abs[:, None]
    np.testing.assert_allclose(Gp.sd_abs, np.sqrt(np.einsum("ij,jk,ik->i", ga, m.covariance, ga)), rtol=1e-5)
    # treating S and G_1 as independent would give a different (wrong) sd
    S_indep = FreqResp(S.omega, S.value, S.jacobian, (("other", m.covariance),))
    assert not np.allclose(((1 - S_indep) / G1).sd_abs, Gp.sd_abs, rtol=1e-3)


def test_known_response_has_no_uncertainty_and_grids_must_match():
    k = FreqResp.known(W, 2.0)
    assert np.all(k.sd_abs == 0) and k.n_params == 0
    g = bj_model([0.5], [1.0], [1.0], [1, -0.5], 1).freqresp(W)
    # a model without covariance has an unknown sd (NaN), never a zero one (no zero-width interval)
    assert np.all(np.isnan((g * k).sd_abs)) and np.all(np.isnan(g.sd_real))
    with pytest.raises(ValueError, match="grid"):
        g + g[1:].__class__.known(W[1:] * 2, 1.0)
    assert len(g[2:4]) == 2 and g[2:4].omega.tolist() == W[2:4].tolist()


def test_sd_abs_matches_monte_carlo_of_estimates():
    """Estimated sd of |G| from one fit vs the spread of |Ĝ| over 80 independent data sets (ARX)."""
    def fit(seed):
        rng = np.random.default_rng(seed)
        u = rng.standard_normal(800)
        y = sps.lfilter([0, 0.5, 0.3], [1, -1.2, 0.5], u) + sps.lfilter([1], [1, -1.2, 0.5],
                                                                          0.5 * rng.standard_normal(800))
        return arx(IdData(y, u, 1.0), 2, 2, 1).freqresp(W, 0)

    gs = [fit(100 + k) for k in range(80)]
    emp = np.std([g.abs for g in gs], axis=0, ddof=1)
    est = np.mean([g.sd_abs for g in gs], axis=0)
    np.testing.assert_allclose(est, emp, rtol=0.3)
