"""ident.oe's drift column (``drift_pole``): an output that integrates a constant offset the model cannot
see, e.g. a unit without damping whose speed ramps with a constant power mismatch
(experiments.zcu_swing). Seeded records; the assertions are on deterministic fits."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as sps

from fcrlive.ident import IdData, oe
from fcrlive.ident.pem import _IcProjection, _Struct

B_TRUE = np.array([0.0, 0.5, 0.3])
F_TRUE = np.array([1.0, -1.2, 0.5])


def _record(drift: np.ndarray, seed: int = 0) -> IdData:
    rng = np.random.default_rng(seed)
    n = drift.shape[0]
    u = rng.standard_normal(n)
    y = sps.lfilter(B_TRUE, F_TRUE, u) + drift + 0.7 + 0.05 * rng.standard_normal(n)
    return IdData(y, u[:, None], Ts=0.5).detrend("mean")


def _error(m) -> float:
    return float(max(np.max(np.abs(m.b[0] - B_TRUE)), np.max(np.abs(m.f[0] - F_TRUE))))


def test_drift_column_is_the_step_response_of_the_pole():
    st = _Struct(nb=(2,), nc=0, nd=0, nf=(2,), nk=(1,), ic=True, drift_pole=1.0)
    Phi = _IcProjection.basis(st, [F_TRUE], np.ones(1), np.ones(1), 400)
    np.testing.assert_array_equal(Phi[:, -1], np.arange(1.0, 401.0))  # p = 1: a linear trend
    st = _Struct(nb=(2,), nc=0, nd=0, nf=(2,), nk=(1,), ic=True, drift_pole=0.9)
    Phi = _IcProjection.basis(st, [F_TRUE], np.ones(1), np.ones(1), 400)
    np.testing.assert_allclose(Phi[:, -1], (1.0 - 0.9 ** np.arange(1, 401)) / 0.1, rtol=1e-12)
    without = _IcProjection.basis(_Struct(nb=(2,), nc=0, nd=0, nf=(2,), nk=(1,), ic=True), [F_TRUE],
                                  np.ones(1), np.ones(1), 400)
    assert Phi.shape[1] == without.shape[1] + 1
    np.testing.assert_array_equal(Phi[:, :-1], without)  # the other columns where kaufman reads them


def test_a_linear_trend_does_not_bias_the_model():
    n = 3000
    d = _record(0.004 * np.arange(n))
    with_drift = oe(d, 2, 2, 1, ic="estimate", drift_pole=1.0)
    plain = oe(d, 2, 2, 1, ic="estimate")
    assert with_drift.report.converged
    assert _error(with_drift) < 0.01
    # the same record without the column: the slow drift pulls the model (or the search stalls)
    assert _error(plain) > 5 * _error(with_drift)


def test_without_a_drift_the_column_costs_little():
    d = _record(np.zeros(3000), seed=1)
    with_drift = oe(d, 2, 2, 1, ic="estimate", drift_pole=1.0)
    plain = oe(d, 2, 2, 1, ic="estimate")
    assert _error(with_drift) < 0.01 and _error(plain) < 0.01
    assert abs(with_drift.report.loss / plain.report.loss - 1.0) < 2e-3  # one column of 3000 samples


def test_drift_pole_needs_the_estimated_initial_state():
    d = _record(np.zeros(500))
    with pytest.raises(ValueError, match="drift_pole needs ic='estimate'"):
        oe(d, 2, 2, 1, drift_pole=1.0)
    with pytest.raises(ValueError, match="must be in"):
        oe(d, 2, 2, 1, ic="estimate", drift_pole=1.5)
