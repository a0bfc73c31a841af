"""Noise sizing: the variance machinery, the ±0.1 Hz load rule and the SNR actually achieved."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from fcrlive.plant.params import Plant
from fcrlive.sim import SimConfig, linear, simulate, simulate_batch


def test_expected_sample_variance_matches_brute_force():
    rng = np.random.default_rng(0)
    A = np.array([[0.9, 0.2, 0.0], [-0.1, 0.8, 0.05], [0.0, 0.0, 1.0]])  # includes a random walk
    G = rng.standard_normal((3, 2))
    c = np.array([1.0, -0.5, 0.3])
    N = 57
    # brute force: the covariance of the stacked outputs o[0..N−1]
    n = A.shape[0]
    T = np.zeros((N, N * 2))  # o[k] = Σ_j c A^(k−1−j) G e[j]
    for k in range(N):
        for j in range(k):
            T[k, 2 * j:2 * j + 2] = c @ np.linalg.matrix_power(A, k - 1 - j) @ G
    cov = T @ T.T
    center = np.eye(N) - np.ones((N, N)) / N
    brute = np.trace(center @ cov @ center) / N
    assert linear.expected_sample_variance(A, G, c, N) == pytest.approx(brute, rel=1e-10)
    assert linear.state_covariance(A, G, N) == pytest.approx(
        sum(np.linalg.matrix_power(A, k) @ G @ G.T @ np.linalg.matrix_power(A, k).T for k in range(N)),
        rel=1e-10,
    )
    assert n == 3


@pytest.fixture(scope="module")
def load_only():
    """100 linear realisations of 1800 s with the load alone (the linear model is what sizes the noise;
    the nonlinear model is compared with it below)."""
    plant = Plant()
    cfg = SimConfig(duration_s=1800.0, snr_db=None, model="linear")
    return plant, cfg, simulate_batch(plant, cfg, range(100), fields=("u", "grid_freq_hz"))


@pytest.fixture(scope="module")
def unit_process_noise_only(load_only):
    """Mean np.var(u) of 100 realisations with process noise of unit std alone (same seeds)."""
    plant, cfg, _ = load_only
    b = simulate_batch(plant, replace(cfg, load_noise_std=0.0, process_noise_std=1.0), range(100),
                       fields=("u",))
    return float(np.mean(np.var(b.u, axis=1)))


def test_load_noise_keeps_frequency_within_band(load_only):
    """3σ of the grid frequency after 1800 s is 0.1 Hz (100 realisations: ±15 %)."""
    _, _, b = load_only
    three_sigma = 3 * np.sqrt(np.mean((b.grid_freq_hz[:, -1] - 50.0) ** 2))
    assert three_sigma == pytest.approx(0.1, rel=0.15)


@pytest.mark.parametrize(("snr_db", "excitation"), [(12.0, False), (0.0, True)])
def test_snr_achieved_within_1_db(load_only, unit_process_noise_only, snr_db, excitation):
    """Each source alone, same seeds: 10 log10(var u (load + r) / var u (process noise)) ≈ request."""
    plant, base, b = load_only
    short = replace(base, duration_s=1.0, snr_db=snr_db, excitation=excitation)
    sigma_v = simulate(plant, short).process_noise_std
    signal = np.mean(np.var(b.u, axis=1))
    if excitation:
        r_only = simulate(plant, replace(base, load_noise_std=0.0, excitation=True))
        signal += np.var(r_only.u)  # deterministic: r is generated once
    noise = unit_process_noise_only * sigma_v**2  # the linear model: exactly proportional
    assert 10 * math.log10(signal / noise) == pytest.approx(snr_db, abs=1.0)


def test_snr_holds_for_the_nonlinear_model():
    """Per-source u variances of the nonlinear model equal the linear ones (same seeds) within 3 %."""
    plant = Plant()
    cfg = SimConfig(duration_s=1800.0, snr_db=6.0, seed=11)
    for only in ({"process_noise_std": 0.0, "snr_db": None}, {"load_noise_std": 0.0, "snr_db": None,
                                                             "process_noise_std": 0.0013}):
        c = replace(cfg, **only)
        v_nl = np.var(simulate(plant, c).u)
        v_li = np.var(simulate(plant, replace(c, model="linear")).u)
        assert v_nl == pytest.approx(v_li, rel=0.03)


def test_snr_levels_scale_the_process_noise():
    plant = Plant()
    s = {db: simulate(plant, SimConfig(duration_s=1.0, snr_db=db)).process_noise_std for db in (12, 6, 0)}
    assert s[6] / s[12] == pytest.approx(10 ** (6 / 20))
    assert s[0] / s[12] == pytest.approx(10 ** (12 / 20))
