"""resid, compare, AIC/BIC/FPE and order search."""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive.ident import (
    IdData,
    aic,
    arx,
    arx_order_search,
    bic,
    bj,
    bj_order_search,
    compare,
    fpe,
    oe,
    resid,
)
from fcrlive.ident.testsystems import bj_model, simulate_closed_loop, simulate_open_loop

TRUE = bj_model([0.5, 0.3], [1, 0.6], [1, -0.9], [1, -1.5, 0.7], nk=1)


def _open(n, seed, sigma=0.3):
    rng = np.random.default_rng(seed)
    return simulate_open_loop(TRUE, rng.standard_normal(n), rng, sigma)


def test_resid_passes_true_structure_and_detects_wrong_orders():
    d = _open(4000, 1)
    good = resid(bj(d, 2, 1, 1, 2, 1), d)
    assert good.passed, (good.whiteness_p, good.independence_p)
    assert good.autocorr[0] == pytest.approx(1.0) and good.xcorr.shape == (1, 51)
    assert good.band99 > good.band95 > 0
    # too low an order for the dynamics: residuals correlated with the input
    low_g = resid(bj(d, 1, 1, 1, 1, 1), d)
    assert not all(low_g.independent)
    # output-error model on coloured noise: residuals not white (but independent of u in open loop)
    low_h = resid(oe(d, 2, 2, 1), d)
    assert not low_h.white and all(low_h.independent)
    assert low_h.n_outside[0] > 5


def test_resid_in_closed_loop_ignores_negative_lags():
    rng = np.random.default_rng(2)
    cl = simulate_closed_loop(TRUE, rng.standard_normal(4000), [0.3], [1.0], rng, 0.3)
    res = resid(bj(cl.data, 2, 1, 1, 2, 1), cl.data)
    assert res.passed
    # feedback makes u correlated with past residuals (negative lags) — reported, not a failure
    assert np.max(np.abs(res.xcorr[0, :25])) > 3 * res.band99


def test_compare_fit_percent():
    d = _open(3000, 3, sigma=0.05)
    m = bj(d, 2, 1, 1, 2, 1)
    c = compare(m, d)
    noise = d.y - TRUE.simulate(d)
    expected = 100 * (1 - np.linalg.norm(noise) / np.linalg.norm(d.y - d.y.mean()))
    assert c.fit_percent == pytest.approx(expected, abs=0.5)
    assert compare(m, d, horizon=1).fit_percent > c.fit_percent
    assert compare(arx(d, 1, 1, 1), d).fit_percent < c.fit_percent


def test_information_criteria_formulas_and_order_search():
    d = _open(3000, 4)
    m = arx(d, 3, 3, 1)
    v, n, p = m.report.loss, m.report.n_samples, m.n_params
    assert aic(m) == pytest.approx(n * np.log(v) + 2 * p)
    assert bic(m) == pytest.approx(n * np.log(v) + p * np.log(n))
    assert fpe(m) == pytest.approx(v * (1 + p / n) / (1 - p / n))
    grid = [(1, 1, 1, 1), (2, 1, 1, 2), (2, 0, 0, 2), (2, 2, 2, 2)]
    res = bj_order_search(d, grid, nk=1, criterion="bic")
    assert res.best_orders == (2, 1, 1, 2)
    val = _open(3000, 5)
    assert bj_order_search(d, grid[:3], 1, "val", val=val).best_orders == (2, 1, 1, 2)
    ar = arx_order_search(d, range(1, 8), range(1, 8), 1, criterion="bic")
    assert ar.scores.shape == (49,) and ar.best.n_params == sum(ar.best_orders)


def test_resid_multi_experiment_does_not_correlate_across_gaps():
    a, b = _open(1500, 6), _open(1500, 7)
    d = IdData.merge(a, b)
    res = resid(bj(d, 2, 1, 1, 2, 1), d)
    assert res.passed
