"""Mapping TSO logs to the paper's pu signals, and simulation results to TSO logs."""

from __future__ import annotations

import types
from datetime import datetime

import numpy as np
import pytest

from fcrlive.errors import DataError
from fcrlive.tso.csvlog import TsoLog, read_log, write_log
from fcrlive.tso.signals import log_from_sim, log_from_sine, plant_signals

START = datetime(2026, 11, 1)
F0 = 50.0
RATED = 300.0


def _fake_sim(n=3000, Tc=0.02, excitation=True, seed=1):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * Tc
    y = np.cumsum(rng.normal(scale=2e-6, size=n))
    y -= y.mean()
    r = rng.normal(scale=6.7e-4, size=n) if excitation else np.zeros(n)
    u = rng.normal(scale=3e-3, size=n)
    return types.SimpleNamespace(
        t=t,
        y=y,
        r=r,
        epsilon=r - y,
        u=u,
        c=0.85 + 0.01 * rng.normal(size=n),
        a=0.85 + 0.01 * rng.normal(size=n),
        pe_mw=225.0 + RATED * u,
        grid_freq_hz=F0 * (1 + y + 1e-5),
        f0=F0,
        rated_mw=RATED,
        p0_mw=225.0,
        Tc=Tc,
    )


def test_signals_recover_r_and_epsilon_exactly_from_a_synthetic_log():
    n = 1000
    t = np.arange(n) * 0.1
    rng = np.random.default_rng(3)
    grid = F0 + 0.02 * rng.normal(size=n)
    r_true = 0.1 / F0 * np.sin(2 * np.pi * t / 25.0)  # the applied frequency is the grid minus f0·r
    applied = grid - F0 * r_true
    log = TsoLog.from_arrays(
        t,
        {
            "InsAcPow": 200.0 + 3 * rng.normal(size=n),
            "GridFreq": grid,
            "ApplFreqSig": applied,
            "ContOutSig": np.full(n, 80.0),
            "GuideVane": np.full(n, 82.0),
        },
        START,
    )
    s = plant_signals(log, RATED)
    np.testing.assert_allclose(s.r, r_true, rtol=0, atol=1e-14)
    np.testing.assert_allclose(s.epsilon, (F0 - applied) / F0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.epsilon, s.r - s.y, rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.y, (grid - F0) / F0, atol=1e-15)
    assert s.p0_mw == pytest.approx(np.mean(log.columns["InsAcPow"]))
    assert abs(np.mean(s.u)) < 1e-12
    np.testing.assert_allclose(s.u * RATED + s.p0_mw, log.columns["InsAcPow"])
    assert s.has_excitation
    assert s.c is not None and s.c[0] == pytest.approx(0.80)
    assert s.a is not None and s.a[0] == pytest.approx(0.82)
    assert s.Ts == pytest.approx(0.1) and s.segments == ((0, n),) and s.valid.all()


def test_no_applied_frequency_means_no_excitation_and_given_p0():
    n = 200
    t = np.arange(n) * 0.1
    log = TsoLog.from_arrays(t, {"InsAcPow": np.full(n, 210.0), "GridFreq": np.full(n, 50.05)}, START)
    s = plant_signals(log, RATED, p0_mw=180.0)
    assert not s.has_excitation
    assert (s.r == 0).all()
    np.testing.assert_allclose(s.epsilon, -s.y)
    assert s.y[0] == pytest.approx(0.001)
    assert s.u[0] == pytest.approx(0.1)
    assert s.c is None and s.a is None
    assert any("no ApplFreqSig" in n for n in s.notes)
    # the applied signal logged but identical to the grid: still no excitation
    same = TsoLog.from_arrays(t, {**log.columns, "ApplFreqSig": log.columns["GridFreq"]}, START)
    assert not plant_signals(same, RATED).has_excitation


def test_signals_refuse_bad_rating_and_text_columns():
    n = 50
    log = TsoLog.from_arrays(
        np.arange(n) * 0.1, {"InsAcPow": np.ones(n), "GridFreq": np.array(["x"] * n)}, START
    )
    with pytest.raises(DataError, match="not numeric"):
        plant_signals(log, RATED)
    with pytest.raises(DataError, match="rated power"):
        plant_signals(log, 0.0)


def test_sim_to_file_to_signals_gives_back_the_simulated_signals(tmp_path):
    sim = _fake_sim()
    log = log_from_sim(sim)
    assert list(log.columns) == ["InsAcPow", "GridFreq", "ApplFreqSig", "ContOutSig", "GuideVane"]
    back = read_log(write_log(tmp_path / "sim.csv", log))
    s = plant_signals(back, RATED, p0_mw=225.0)
    assert s.has_excitation
    # 6 decimals: 0.5e-6 Hz / 50 Hz = 1e-8 pu on frequencies, 0.5e-6 MW / 300 MW on power
    np.testing.assert_allclose(s.y, sim.y, atol=1.1e-8, rtol=0)
    np.testing.assert_allclose(s.r, sim.r, atol=2.1e-8, rtol=0)
    np.testing.assert_allclose(s.epsilon, sim.epsilon, atol=1.1e-8, rtol=0)
    np.testing.assert_allclose(s.u, sim.u, atol=2e-9, rtol=0)
    np.testing.assert_allclose(s.c, sim.c, atol=1e-8, rtol=0)
    np.testing.assert_allclose(s.a, sim.a, atol=1e-8, rtol=0)
    assert s.Ts == pytest.approx(0.02)


def test_sim_log_decimation_and_no_excitation():
    sim = _fake_sim(excitation=False)
    log = log_from_sim(sim, sample_s=0.1)
    assert "ApplFreqSig" not in log.columns
    assert len(log) == 600 and log.sample_s == pytest.approx(0.1)
    np.testing.assert_allclose(log.columns["GridFreq"], F0 * (1 + sim.y[::5]))
    with pytest.raises(ValueError, match="whole multiple"):
        log_from_sim(sim, sample_s=0.03)


def test_sine_result_to_period_suffixed_log(tmp_path):
    n = 4000
    t = np.arange(n) * 0.02
    applied = F0 + 0.1 * np.sin(2 * np.pi * t / 40.0)
    res = types.SimpleNamespace(
        period_s=40.0,
        t=t,
        applied_freq_hz=applied,
        grid_freq_hz=np.full(n, F0),
        pe_mw=np.full(n, 225.0),
        u=np.zeros(n),
        c=np.full(n, 0.85),
        a=np.full(n, 0.85),
        epsilon=(F0 - applied) / F0,
    )
    path = write_log(tmp_path / "sine.csv", log_from_sine(res, sample_s=0.1))
    assert path.read_bytes().startswith(b"DateTime40,InsAcPow40,GridFreq40,ApplFreqSig40,")
    s = plant_signals(read_log(path), RATED)
    assert s.period_s == 40.0 and s.has_excitation
    np.testing.assert_allclose(s.epsilon, res.epsilon[::5], atol=1.1e-8)


def test_real_simulation_through_a_file_gives_the_governors_signals(tmp_path):
    from fcrlive.plant.params import preset
    from fcrlive.sim import SimConfig, simulate

    sim = simulate(preset("paper-plant1"), SimConfig(duration_s=60.0, excitation=True, seed=2))
    back = read_log(write_log(tmp_path / "sim.csv", log_from_sim(sim)))
    s = plant_signals(back, sim.rated_mw, f0=sim.f0, p0_mw=sim.p0_mw)
    assert s.has_excitation and len(s) == sim.n
    np.testing.assert_allclose(s.y, sim.y, atol=1.1e-8, rtol=0)
    np.testing.assert_allclose(s.r, sim.r, atol=2.1e-8, rtol=0)
    np.testing.assert_allclose(s.epsilon, sim.epsilon, atol=1.1e-8, rtol=0)
    np.testing.assert_allclose(s.u, sim.u, atol=2e-9, rtol=0)
    np.testing.assert_allclose(s.c, sim.c, atol=1e-8, rtol=0)
    np.testing.assert_allclose(s.a, sim.a, atol=1e-8, rtol=0)
