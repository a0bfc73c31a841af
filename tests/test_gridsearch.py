"""The one grid-plus-refinement search behind every peak and frequency-minimum of fcrlive."""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive.gridsearch import log_grid, peak, refined_min, refined_min_grid, uncertain_peak
from fcrlive.ident import FreqResp

ZETA, W0 = 1e-3, 0.7071  # a resonance far narrower than the grid spacing


def _h(w):
    x = np.asarray(w, float) / W0
    return 1.0 / (1.0 - x**2 + 2j * ZETA * x)


TRUE_MAX = 1.0 / (2 * ZETA * np.sqrt(1 - ZETA**2))
TRUE_W = W0 * np.sqrt(1 - 2 * ZETA**2)


def test_a_resonance_between_grid_points_is_found():
    w = log_grid(1e-2, 10.0, 200)
    assert np.abs(_h(w)).max() < 0.8 * TRUE_MAX  # the grid alone misses it
    v, wm = peak(lambda x: np.abs(_h(x)), 1e-2, 10.0, 200, xatol=1e-10)
    assert v == pytest.approx(TRUE_MAX, rel=1e-6) and wm == pytest.approx(TRUE_W, rel=1e-7)


def test_refined_min_ignores_non_finite_values():
    w = log_grid(0.1, 10.0, 50)

    def fun(x):
        return np.where(x < 0.5, np.nan, (np.log(x) - np.log(2.0)) ** 2)

    v, wm = refined_min(fun, w)
    assert v == pytest.approx(0.0, abs=1e-12) and wm == pytest.approx(2.0, rel=1e-6)
    assert all(np.isnan(refined_min(lambda x: np.full(x.shape, np.nan), w)))


def test_uncertain_peak_takes_value_and_sd_at_the_refined_point():
    pk = uncertain_peak(lambda w: FreqResp.known(w, _h(w)), 1e-2, 10.0, 300)
    assert pk.omega == pytest.approx(TRUE_W, rel=1e-6)
    assert pk.value == pytest.approx(abs(_h(pk.omega)), rel=1e-12)
    assert pk.value == pytest.approx(TRUE_MAX, rel=1e-6) and pk.sd == 0.0


def test_refined_min_grid_finds_a_resonance_between_grid_points():
    w = log_grid(1e-2, 10.0, 2000)
    calls = []

    def neg(x):
        calls.append(x.size)
        return -np.abs(_h(x))

    v, wm = refined_min_grid(neg, w)
    assert -v == pytest.approx(TRUE_MAX, rel=1e-9) and wm == pytest.approx(TRUE_W, rel=1e-7)
    assert calls == [2000, 63, 63, 63]  # the grid, then three vectorised rounds


def test_refined_min_grid_agrees_with_brent_and_ignores_non_finite_values():
    w = log_grid(0.1, 10.0, 50)

    def fun(x):
        return np.where(x < 0.5, np.nan, (np.log(x) - np.log(2.0)) ** 2 + np.cos(3 * np.log(x)) * 1e-3)

    vb, wb = refined_min(fun, w)
    vg, wg = refined_min_grid(fun, w)
    # a coarse grid (0.09 in log ω): three rounds end 6e-6 wide in log ω, the value ~1e-11 off the minimum
    assert vg == pytest.approx(vb, abs=1e-10) and wg == pytest.approx(wb, rel=1e-5)
    assert all(np.isnan(refined_min_grid(lambda x: np.full(x.shape, np.nan), w)))
    # the best point at the grid's end: the refinement stays inside the grid
    v, wm = refined_min_grid(lambda x: x, w)
    assert (v, wm) == (pytest.approx(0.1), pytest.approx(0.1))
