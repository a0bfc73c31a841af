"""Public API of fcrlive.sim: determinism, batch = single runs, realtime = simulate, sine tests, errors."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from fcrlive.errors import ConfigError
from fcrlive.plant.params import Plant
from fcrlive.sim import SIGNALS, SimConfig, simulate, simulate_batch, sine_test
from fcrlive.sim.realtime import RealtimeSimulator

PLANT = Plant()
CFG = SimConfig(duration_s=60.0, snr_db=12.0, excitation=True, meas_noise_power=0.01,
                meas_noise_freq_hz=0.002)


def _close(a: np.ndarray, b: np.ndarray, rtol: float = 1e-8) -> bool:
    return bool(np.max(np.abs(a - b)) <= rtol * (np.max(np.abs(b)) + 1e-300))


def test_deterministic_under_a_seed_and_seeds_differ():
    a, b = simulate(PLANT, replace(CFG, seed=5)), simulate(PLANT, replace(CFG, seed=5))
    c = simulate(PLANT, replace(CFG, seed=6))
    for name in SIGNALS:
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert not np.allclose(a.u, c.u)
    assert np.array_equal(a.r, c.r)  # the excitation is generated once, from its own seed
    assert np.allclose(a.epsilon, a.r - a.y)
    assert a.y.shape == (3000,) and a.t[1] == pytest.approx(0.02)


@pytest.mark.parametrize("model", ["nonlinear", "linear"])
def test_batch_equals_single_runs(model):
    cfg = replace(CFG, model=model)
    b = simulate_batch(PLANT, cfg, [3, 8])
    assert b.u.shape == (2, 3000) and b.r.shape == (2, 3000)
    for i, seed in enumerate((3, 8)):
        s = simulate(PLANT, replace(cfg, seed=seed))
        for name in SIGNALS:
            assert _close(getattr(b, name)[i], getattr(s, name)), (model, name)
        one = b.run(i)
        assert one.seed == seed and np.array_equal(one.u, b.u[i])


def test_batch_fields_restrict_memory():
    b = simulate_batch(PLANT, replace(CFG, duration_s=10.0), [1], fields=("u", "epsilon"))
    assert b.u is not None and b.epsilon is not None and b.c is None and b.pe_mw is None
    with pytest.raises(ConfigError):
        simulate_batch(PLANT, CFG, [1], fields=("nope",))


def test_realtime_reproduces_simulate():
    n = 1500
    r = 0.0007 * np.random.default_rng(1).standard_normal(n)
    rt = RealtimeSimulator(PLANT, seed=4, snr_db=None, process_noise_std=0.001, meas_noise_power=0.01,
                           meas_noise_freq_hz=0.002)
    assert rt.dt == pytest.approx(0.02)
    samples = [rt.step(r[k]) for k in range(n)]
    s = simulate(PLANT, SimConfig(duration_s=n * 0.02, snr_db=None, process_noise_std=0.001, r=r, seed=4,
                                  meas_noise_power=0.01, meas_noise_freq_hz=0.002))
    for name in ("y", "epsilon", "c", "a", "pe_mw", "grid_freq_hz", "r"):
        assert _close(np.array([getattr(q, name) for q in samples]), getattr(s, name)), name
    assert _close(np.array([q.speed_pu for q in samples]) - 1.0, s.omega)
    assert _close(np.array([q.pm_mw for q in samples]), s.pm * 300.0)
    assert samples[-1].n == n - 1 and samples[-1].t == pytest.approx((n - 1) * 0.02)
    rt.reset()
    again = rt.step(r[0])
    assert again == samples[0]


def test_realtime_default_snr_matches_simulate_noise_level():
    rt = RealtimeSimulator(PLANT, seed=0)
    s = simulate(PLANT, SimConfig(duration_s=1.0))
    assert rt.process_noise_std == pytest.approx(s.process_noise_std)
    assert rt.load_noise_std == pytest.approx(s.load_noise_std)


def test_sine_test_measures_g_req():
    """Open-loop sine, no noise: the power follows −G_req·(applied frequency) within 2 %."""
    period = 25.0
    res = sine_test(PLANT, period, config=SimConfig(snr_db=None, load_noise_std=0.0))
    assert res.n_periods == 5
    assert res.settle_s % period == 0 and res.settle_s >= 5 * 100.0  # ≥ 5 × the ~114 s governor mode
    k = res.stationary
    assert len(res.t[k]) == round(5 * period / 0.02)
    w = 2 * math.pi / period
    e = np.exp(-1j * w * res.t[k])
    f_app = np.sum((res.applied_freq_hz[k] - 50.0) / 50.0 * e)
    g = np.sum(res.u[k] * e) / f_app
    assert abs(np.sum(res.applied_freq_hz[k] - 50.0)) < 1e-6 * len(e)
    # the governor sees the applied signal: ε = −(f_app − f0)/f0
    assert np.allclose(res.epsilon, -(res.applied_freq_hz - 50.0) / 50.0)
    transfer = pytest.importorskip("fcrlive.plant.transfer")
    g_req = complex(transfer.freqresp(transfer.analytic(PLANT).G_req, w))
    assert abs(-g / g_req - 1) < 0.02
    # power amplitude = |G_p(25 s)|·(0.1/50)·300 MW with |G_p| = 1.104 (plant-model.md table)
    assert (res.pe_mw[k].max() - res.pe_mw[k].min()) / 2 == pytest.approx(1.104 * 0.002 * 300.0, rel=0.02)


def test_config_errors_are_user_errors():
    with pytest.raises(ConfigError):
        simulate(PLANT, SimConfig(duration_s=-1.0))
    with pytest.raises(ConfigError):
        simulate(PLANT, SimConfig(duration_s=10.0, r=np.zeros(3)))
    with pytest.raises(ConfigError):
        simulate(PLANT, SimConfig(duration_s=10.0, snr_db=6.0, load_noise_std=0.0))
    with pytest.raises(ConfigError):
        analogue = PLANT.with_unit(governor=replace(PLANT.unit.governor, digital=False))
        simulate(analogue, SimConfig(duration_s=1))
