"""Closed loop: two-stage and projection are consistent where direct OE (wrong noise model) is biased."""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive.ident import IdData, choose_fir_length, fir_projection, oe, projection, two_stage
from fcrlive.ident.testsystems import bj_model, simulate_closed_loop

# plant 0.5 q⁻¹/(1 − 0.8 q⁻¹), noise 1/(1 − 0.9 q⁻¹), P controller 0.8: strong coloured noise feedback
PLANT = bj_model([0.5], [1.0], [1, -0.9], [1, -0.8], nk=1)
G_TRUE = np.array([0.5, -0.8])


def _loop(seed, n=8000, sigma=0.5):
    rng = np.random.default_rng(seed)
    r = rng.standard_normal(n)
    return simulate_closed_loop(PLANT, r, [0.8], [1.0], rng, sigma)


def test_two_stage_consistent_where_direct_oe_is_biased():
    cl = _loop(0)
    direct = oe(cl.data, 1, 1, 1)
    z_direct = (direct.theta - G_TRUE) / direct.sd
    assert abs(z_direct[0]) > 10, z_direct  # the bias is many standard deviations
    # stage-2 noise S·H = (1 − 0.8q⁻¹)/((1 − 0.4q⁻¹)(1 − 0.9q⁻¹)): BJ with nc = 1, nd = 2
    ts = two_stage(cl.data, cl.r, 1, 1, 1, nc=1, nd=2)
    z = (ts.theta[[0, -1]] - G_TRUE) / ts.sd[[0, -1]]
    assert np.all(np.abs(z) < 3), z
    assert ts.report.method == "two-stage bj" and any("stage-1" in n for n in ts.report.notes)
    assert ts.input_names == cl.data.input_names
    pj = projection(cl.data, cl.r, 1, 1, 1, nc=1, nd=2)
    zp = (pj.theta[[0, -1]] - G_TRUE) / pj.sd[[0, -1]]
    assert np.all(np.abs(zp) < 3), zp
    # the biased estimate is far from the consistent ones in the consistent estimate's sd
    assert abs(direct.theta[0] - ts.theta[0]) > 10 * ts.sd[0]


def test_two_stage_oe_consistent_on_average():
    """With an OE stage 2 the estimate is still consistent (only its sd is indicative)."""
    est = np.array([two_stage(_loop(10 + k, n=4000).data, _loop(10 + k, n=4000).r, 1, 1, 1).theta
                    for k in range(6)])
    direct = np.array([oe(_loop(10 + k, n=4000).data, 1, 1, 1).theta for k in range(3)])
    assert np.all(np.abs(est.mean(axis=0) - G_TRUE) < 0.06), est.mean(axis=0)
    assert np.all(np.abs(direct[:, 0] - G_TRUE[0]) > 0.4)


def test_fir_projection_recovers_sensitivity_output():
    cl = _loop(1)
    n_fir = choose_fir_length(cl.data, cl.r, noncausal=False)
    assert 5 <= n_fir <= 30  # S = (1 − 0.8q⁻¹)/(1 − 0.4q⁻¹) decays fast
    proj, coef = fir_projection(cl.data, cl.r, n_lag=n_fir - 1)
    err = proj.u[:, 0] - cl.u_r
    assert np.std(err) < 0.1 * np.std(cl.u_r)
    assert coef.shape == (1, n_fir) and coef[0, 0] == pytest.approx(0.8, abs=0.05)


def test_multi_experiment_and_bad_excitation():
    a, b = _loop(2, n=3000), _loop(3, n=3000)
    d = IdData.merge(a.data, b.data)
    r = np.concatenate((a.r, b.r))
    m = two_stage(d, r, 1, 1, 1, nc=1, nd=2)
    assert np.all(np.abs((m.theta[[0, -1]] - G_TRUE) / m.sd[[0, -1]]) < 3)
    with pytest.raises(ValueError, match="samples"):
        two_stage(d, r[:-1], 1, 1, 1)
    with pytest.raises(ValueError, match="constant"):
        two_stage(d, np.ones_like(r), 1, 1, 1)
