"""Noise-free identification of paper-plant1 (process noise off): the methods must nail deterministic
data before noise is considered. Compared with the analytic truth on three seeds."""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive.analysis import experiments as ex
from fcrlive.ident import oe
from fcrlive.plant import transfer as tr
from fcrlive.plant.params import preset
from fcrlive.sim import SimConfig, simulate
from fcrlive.tso.signals import log_from_sim, plant_signals

PLANT = preset("paper-plant1")
SEEDS = (0, 1, 2)
W = np.concatenate([[1e-4], np.linspace(0.01, 1.5, 600)])


@pytest.fixture(scope="module")
def truth():
    T = tr.analytic(PLANT)
    return {"g0": tr.static_gain(T.G_1), "max_g1": tr.peak(T.G_1).value, "max_s": tr.peak(T.S).value}


def _signals(seed, excitation, duration_s):
    cfg = SimConfig(
        duration_s=duration_s, snr_db=None, process_noise_std=0.0, excitation=excitation, seed=seed
    )
    return plant_signals(log_from_sim(simulate(PLANT, cfg)), rated_mw=300.0)


@pytest.mark.parametrize("seed", SEEDS)
def test_oe_eps_from_u_r_noise_free(seed, truth):
    # ε = G_1 u + S r exactly; OE(4) with estimated initial states (the records do not start at rest and
    # the slow poles make the free response dominate a from-rest simulation error)
    d = ex.prepare(_signals(seed, True, 1800.0)).iddata("epsilon", ("u", "r"))
    m = oe(d, [4, 4], [4, 4], [0, 0], ic="estimate")
    assert m.static_gain("u")[0] == pytest.approx(truth["g0"], rel=0.01)
    assert m.freqresp(W, "u").max_abs().value == pytest.approx(truth["max_g1"], rel=0.01)
    assert m.freqresp(W, "r").max_abs().value == pytest.approx(truth["max_s"], rel=0.01)


@pytest.mark.parametrize("seed", SEEDS)
def test_zu_noise_free_static_gain(seed, truth):
    # Z_u without excitation on 15 min: the static gain is an extrapolation, noise-free it must hold
    e = ex.zu(_signals(seed, False, 900.0))
    g0 = e.responses(W)["G_1"].value[0].real
    droop, droop_true = 1 / (1 / g0 - 0.1), 1 / (1 / truth["g0"] - 0.1)
    assert abs(droop - droop_true) <= 0.003
