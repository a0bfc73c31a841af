"""IdData: construction, gaps, merging, detrending, decimation and the data errors."""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive.errors import DataError
from fcrlive.ident import IdData, NonFiniteDataError, NotExcitingError, TooFewSamplesError


def _data(n=200, nu=2, seed=0):
    rng = np.random.default_rng(seed)
    return IdData(rng.standard_normal(n), rng.standard_normal((n, nu)), Ts=0.1)


def test_shapes_names_and_readonly():
    d = _data()
    assert d.N == 200 and d.nu == 2 and d.input_names == ("u1", "u2") and d.n_experiments == 1
    with pytest.raises(ValueError):
        d.y[0] = 1.0
    one = IdData(np.zeros(5), np.arange(5.0), Ts=1.0)
    assert one.u.shape == (5, 1)
    with pytest.raises(ValueError, match="shape"):
        IdData(np.zeros(5), np.zeros((4, 1)), Ts=1.0)
    with pytest.raises(ValueError, match="Ts"):
        IdData(np.zeros(5), np.zeros(5), Ts=0.0)


def test_split_at_nan_runs_and_mask():
    d = _data(100)
    y = d.y.copy()
    y[10:13] = np.nan
    u = d.u.copy()
    u[50, 1] = np.inf
    valid = np.ones(100, bool)
    valid[80:82] = False
    s = IdData(y, u, 0.1).split(valid=valid, min_length=5)
    assert s.lengths == (10, 37, 29, 18)
    assert np.all(np.isfinite(s.y)) and np.all(np.isfinite(s.u))
    # the samples kept are the original ones, in order
    np.testing.assert_array_equal(s.experiment(1).y, d.y[13:50])
    # a run shorter than min_length is dropped
    assert IdData(y, u, 0.1).split(min_length=11).lengths == (37, 49)


def test_merge_keeps_experiments_and_checks_compatibility():
    a, b = _data(50, seed=1), _data(70, seed=2)
    m = IdData.merge(a, b)
    assert m.starts == (0, 50) and m.N == 120
    mm = IdData.merge(m, a)
    assert mm.starts == (0, 50, 120)
    with pytest.raises(ValueError, match="Ts"):
        IdData.merge(a, IdData(b.y, b.u, Ts=0.2))


def test_detrend_per_experiment():
    t = np.arange(100.0)
    y = np.concatenate((3 + 0.5 * t[:50], -2 + 0.1 * t[:50]))
    d = IdData(y, np.column_stack((y, y)), 1.0, starts=(0, 50))
    lin = d.detrend("linear")
    assert np.max(np.abs(lin.y)) < 1e-10
    mean = d.detrend("mean")
    for yy, _ in mean.segments():
        assert abs(yy.mean()) < 1e-12


def test_decimate_keeps_slow_tone_and_removes_fast_one():
    Ts, q = 0.1, 5
    t = np.arange(3000) * Ts
    slow = np.sin(2 * np.pi * 0.05 * t)
    fast = np.sin(2 * np.pi * 1.7 * t)  # above the new Nyquist frequency (1 Hz): must not alias
    d = IdData(slow + fast, np.column_stack((slow, fast)), Ts).decimate(q)
    assert d.Ts == pytest.approx(Ts * q) and d.N == 600
    core = slice(50, -50)
    # zero phase: the slow tone is kept without delay (the Chebyshev pass band ripples by ~1 % after
    # the forward-backward pass), the zero crossings stay where they were
    np.testing.assert_allclose(d.u[core, 0], slow[::q][core], atol=0.015)
    assert abs(d.u[20, 0]) < 1e-3  # sin(2π·0.05·10 s) = 0
    assert np.max(np.abs(d.u[core, 1])) < 0.02
    with pytest.raises(TooFewSamplesError, match="experiment 0"):
        IdData(np.ones(20), np.ones(20), 1.0).decimate(4)


def test_data_errors_name_the_signal():
    d = _data()
    y = d.y.copy()
    y[7] = np.nan
    with pytest.raises(NonFiniteDataError, match=r"'y'.*index 7"):
        IdData(y, d.u, 0.1).require_finite()
    u = d.u.copy()
    u[:, 1] = 3.0
    with pytest.raises(NotExcitingError, match="'u2'") as info:
        IdData(d.y, u, 0.1).require_exciting()
    assert isinstance(info.value, DataError) and isinstance(info.value, ValueError)
