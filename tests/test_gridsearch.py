"""The one grid-plus-refinement search behind every peak and frequency-minimum of fcrlive."""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive.gridsearch import log_grid, peak, refined_min, uncertain_peak
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
