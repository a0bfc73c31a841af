"""Sine-test evaluation (TR eq. 6-9, Req. 10) of fcrlive.analysis.sine_fit."""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive.analysis import sine_fit as sf
from fcrlive.analysis import tso_checks as tc
from fcrlive.errors import DataError

RATED, DROOP, BAND = 300.0, 0.08, 0.1
DP_THEO = BAND / 50.0 * RATED / DROOP  # 7.5 MW for the full 0.1 Hz band


def synth(T, F, *, noise_mw=0.0, dt=0.2, n_periods=7, seed=0, f_amp=0.1, drift=0.01):
    """Applied frequency 50 + a·sin, power = baseline + drift + response to the control error 50 − f."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, n_periods * T, dt) + 1000.0  # not starting at zero on purpose
    w = 2 * np.pi / T
    f = 50.0 + f_amp * np.sin(w * t)
    # e = 50 − f = f_amp·sin(wt + π); P responds with |F|·DP_THEO/BAND per Hz and phase arg F
    A_p = abs(F) * DP_THEO / BAND * f_amp
    p = 200.0 + drift * (t - t[0]) + A_p * np.sin(w * t + np.pi + np.angle(F))
    p = p + rng.normal(0.0, noise_mw, t.size)
    return t, f, p


def test_fit_sine_recovers_amplitude_and_phase_within_se():
    rng = np.random.default_rng(7)
    T, A, phi = 25.0, 2.0, 0.7
    t = np.arange(0, 5 * T, 0.1)
    x = 3.0 - 0.02 * t + A * np.sin(2 * np.pi / T * t + phi) + rng.normal(0, 0.5, t.size)
    fit = sf.fit_sine(t, x, T)
    assert abs(fit.amplitude - A) < 3 * fit.amplitude_se
    assert abs(fit.phase_rad - phi) < 3 * fit.phase_se_rad
    # the standard errors are about right: σ·sqrt(2/N)
    assert fit.amplitude_se == pytest.approx(0.5 * np.sqrt(2 / t.size), rel=0.15)
    assert fit.trend == pytest.approx(-0.02, abs=0.005)
    assert fit.offset == pytest.approx(3.0, abs=0.3)


def test_fit_sine_se_calibrated_over_repeats():
    T, A, phi = 15.0, 1.0, -1.2
    t = np.arange(0, 5 * T, 0.2)
    z = []
    for seed in range(200):
        x = A * np.sin(2 * np.pi / T * t + phi) + np.random.default_rng(seed).normal(0, 0.4, t.size)
        fit = sf.fit_sine(t, x, T)
        z.append((fit.amplitude - A) / fit.amplitude_se)
    z = np.array(z)
    assert abs(z.mean()) < 0.3
    assert 0.8 < z.std() < 1.2


def test_sine_test_recovers_F_and_reports_pu_G_req():
    F_true = 0.8 * np.exp(-1j * 0.6)
    t, f, p = synth(40.0, F_true, noise_mw=0.3)
    r = sf.evaluate_sine_test(t, f, p, 40.0, rated_mw=RATED, droop=DROOP)
    assert r.n_periods == 5  # TR Table 6
    assert abs(r.gain - abs(F_true)) < 3 * r.gain_se
    assert abs(r.phase_rad - np.angle(F_true)) < 3 * r.phase_se_rad
    assert r.phase_rad < 0  # power lags the control error
    # same F with the explicit ΔP_ss,theo normalisation
    r2 = sf.evaluate_sine_test(t, f, p, 40.0, dp_ss_theo_mw=DP_THEO, band_hz=BAND)
    assert pytest.approx(r.F) == r2.F
    # G_req in pu: F = ρ·G_req when ΔP_ss,theo comes from the droop
    assert DROOP * r.G_req == pytest.approx(r.F, rel=1e-9)
    assert len(r.cycles) == 5
    assert all(abs(c.F - F_true) < 0.05 for c in r.cycles)
    assert r.F_sd_periods is not None and r.F_sd_periods < 0.02
    assert r.linearity < 0.2 and r.linearity_passed


def test_stationary_window_is_the_last_periods():
    # a transient in the first periods must not affect the result
    T = 50.0
    F_true = 0.9 * np.exp(-1j * 0.4)
    t, f, p = synth(T, F_true, n_periods=8)
    p = p + 30.0 * np.exp(-(t - t[0]) / 20.0)
    r = sf.evaluate_sine_test(t, f, p, T, rated_mw=RATED, droop=DROOP)
    assert r.t_start == pytest.approx(t[-1] - 5 * T)
    assert abs(r.F - F_true) < 2e-3
    with pytest.raises(DataError):
        sf.evaluate_sine_test(t[-100:], f[-100:], p[-100:], T, rated_mw=RATED, droop=DROOP)


def test_linearity_small_for_clean_sine_large_for_noise():
    F_true = 0.5 * np.exp(-1j * 1.0)
    t, f, p = synth(15.0, F_true, noise_mw=0.0)
    clean = sf.evaluate_sine_test(t, f, p, 15.0, rated_mw=RATED, droop=DROOP)
    assert clean.linearity < 1e-6
    t, f, p = synth(15.0, F_true, noise_mw=5.0, seed=3)  # noise ≫ the 1.9 MW sine
    noisy = sf.evaluate_sine_test(t, f, p, 15.0, rated_mw=RATED, droop=DROOP)
    assert noisy.linearity > 1.0 and not noisy.linearity_passed
    assert noisy.linearity_max_period > 1.0


def test_fme_multiplies_F():
    F_true = 0.7 * np.exp(-1j * 0.3)
    t, f, p = synth(10.0, F_true)
    r0 = sf.evaluate_sine_test(t, f, p, 10.0, rated_mw=RATED, droop=DROOP)
    r1 = sf.evaluate_sine_test(t, f, p, 10.0, rated_mw=RATED, droop=DROOP, t_fme_s=1.0)
    assert pytest.approx(r0.F / (1j * 2 * np.pi / 10.0 + 1)) == r1.F
    assert r1.fme_applied


def test_points_feed_the_tso_checks():
    lag = tc.rational([1.0], [2.0, 1.0])
    res = []
    for T in (300.0, 150.0, 90.0, 60.0, 40.0, 25.0, 15.0, 10.0):
        w = 2 * np.pi / T
        t, f, p = synth(T, complex(lag(np.array([w]))[0]), noise_mw=0.05, dt=0.5, n_periods=6, seed=int(T))
        res.append(sf.evaluate_sine_test(t, f, p, T, rated_mw=RATED, droop=DROOP))
    w, F, sd = sf.sine_test_points(res)
    assert np.all(np.diff(w) > 0)
    assert np.allclose(F, lag(w), atol=0.01)
    v = tc.assess_tso_points(w, F, F_sd_values=sd, products=("fcrn",))["fcrn"]
    vm = tc.assess_tso(lag, products=("fcrn",))["fcrn"]
    assert v.stability_margin_band == pytest.approx(vm.stability_margin_band, rel=0.05)
    assert v.stability_margin_band_lower <= v.stability_margin_band
