"""Z_cu with the data sheet's swing equation (experiments.zcu_swing): the jackknife of G_jp widens the
intervals of S, G_1 and G_p (never narrows them, leaves the droop alone), and the delay check withholds
max|S|, G_p and the TSO checks, with the reason, where the answer depends on the assumed input delay."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from fcrlive.analysis import experiments as ex
from fcrlive.analysis.assess import assess
from fcrlive.analysis.identify import identify_signals
from fcrlive.ident import FreqResp
from fcrlive.sim import logger as lg
from fcrlive.sim import zoo

W = np.geomspace(1e-3, 1.5, 300)


@functools.cache
def _signals(plant: str, seed: int, logger: str = "ctl-ideal"):
    res = zoo.simulate(plant, minutes=30.0, excitation=True, seed=seed)
    return lg.signals(res, zoo.zoo_logger(logger), seed=zoo.logger_seed(seed, logger)), zoo.truth(plant)


@functools.cache
def _pair(plant: str, seed: int, logger: str = "ctl-ideal"):
    # the jackknife alone: the meter-noise replicates (their own tests in test_zcu_swing_check.py) off
    sig, tr = _signals(plant, seed, logger)
    return tuple(ex.zcu_swing(sig, H=tr.H, kd=tr.kd, jackknife=j, meter_check=False) for j in (False, True))


def test_widened_never_narrows_and_reaches_the_floor():
    rng = np.random.default_rng(0)
    w = np.linspace(0.1, 1.0, 5)
    jac = rng.normal(size=(5, 3)) + 1j * rng.normal(size=(5, 3))
    fr = FreqResp(w, np.full(5, 1.0 + 0.5j), jac, (("m", np.eye(3) * 1e-4),))
    floor = fr.sd_abs * np.array([0.5, 1.0, 2.0, 3.0, 0.0])
    wide = ex._widened(fr, floor)
    np.testing.assert_allclose(wide.value, fr.value)
    np.testing.assert_allclose(wide.sd_abs, np.maximum(fr.sd_abs, floor), rtol=1e-12)


def test_jackknife_widens_the_loop_quantities_and_leaves_the_droop():
    cov, jk = _pair("A-classic-tustin-20Hz", 5, "ctl-0.1pct")
    rc, rj = cov.responses(W), jk.responses(W)
    for key in ("S", "G_1", "G_p"):
        np.testing.assert_array_equal(rj[key].value, rc[key].value)
        assert np.all(rj[key].sd_abs >= rc[key].sd_abs * (1 - 1e-12)), key
        low = ex.JACKKNIFE_FADE[0] > W
        np.testing.assert_array_equal(rj[key].sd_abs[low], rc[key].sd_abs[low])
    tr = zoo.truth("A-classic-tustin-20Hz")
    ac, aj = assess(cov, kd=tr.kd), assess(jk, kd=tr.kd)
    assert aj.droop == ac.droop and aj.g1_static == ac.g1_static
    # on this log the covariance's interval of max|S| missed the truth; the jackknife's (2.2x) covers it
    assert aj.max_s.value == ac.max_s.value and aj.max_s.sd > 1.3 * ac.max_s.sd
    lo, hi = aj.max_s.ci95
    assert lo <= tr.max_s <= hi


def test_delay_check_withholds_max_s_gp_and_tso_with_the_reason(monkeypatch):
    # the classic PID with the droop around the controller (zoo F) through the Chebyshev decimator at 0.5 s
    # (Z_cu's data before the block means of experiments.ZCU_TS_ID; with them no zoo record triggers the
    # check): max|S| +14 % with the delay of one sample, about −10 % with two, both far outside the
    # interval of the other. The delay check on its own: the two-rate bias check widens this record's
    # intervals to hold both and then shows them
    monkeypatch.setattr(ex, "RATE_CHECK_FACTOR", 0.0)
    prepare = ex.prepare
    monkeypatch.setattr(ex, "prepare", lambda *a, **k: prepare(*a, **{**k, "decimator": "chebyshev"}))
    sig, tr = _signals("F-pid-classic-2pct-25Hz", 0)
    rep = identify_signals(sig, rated_mw=tr.rated_mw, kd=tr.kd, h=tr.H, ts_id=0.5)
    assert rep.method == "zcu"
    why = rep.not_identifiable["max_abs_s"]
    assert "assumed input delay" in why and why.startswith("not identifiable")
    assert rep.max_abs_s.value is None and rep.max_abs_s.reason == why
    assert rep.not_identifiable["gp"] == why and rep.not_identifiable["tso"] == why
    assert rep.gp is None and rep.f is None and rep.tso is None
    assert rep.local is None or rep.local.sensitivity_pass is None
    # the droop does not depend on it and stays
    assert rep.droop.value == pytest.approx(tr.droop, abs=5e-4)
    # max|G_1| comes from the same loop: its refit (0.715) is outside its interval ([0.763, 0.819], the
    # truth 0.748), a move of only 10 %, withheld because max|S| is
    why_g1 = rep.not_identifiable["max_abs_g1"]
    assert "max|G_1| depends on the assumed input delay" in why_g1 and rep.max_abs_g1.value is None


def test_a_log_where_the_delay_does_not_matter_keeps_everything():
    _, jk = _pair("A-classic-tustin-20Hz", 0)
    assert jk.not_identifiable == {}
    a = assess(jk, kd=zoo.truth("A-classic-tustin-20Hz").kd)
    assert a.not_identifiable == {} and a.tso is not None and a.sensitivity is not None


def _peaked(w: np.ndarray, gain: float, rel_sd: float = 0.02) -> FreqResp:
    """gain × a second-order peak (ζ = 0.3 at 0.3 rad/s), with a relative sd ``rel_sd``."""
    w = np.atleast_1d(np.asarray(w, float))
    v = gain * 0.09 / (0.09 - w**2 + 2j * 0.3 * 0.3 * w)
    return FreqResp(w, v, (v * rel_sd)[:, None].astype(complex), (("test", np.eye(1)),))


def test_delay_check_withholds_max_g1_and_eq10_on_their_own_reason():
    # the delay check's rule (experiments._delay_compare): max|G_1| moved by 20 % with one more sample of
    # delay, outside its ±4 % interval, while max|S| stays: only max|G_1| is withheld. (With G_jp's swing
    # pole fitted the zoo's G, seed 4, ideal log, was such a record: max|G_1| 1.25 with one sample of
    # delay, 1.03 with two; with the pole held it is 1.07 with both and nothing is withheld.)
    def responses(w):
        return {"S": _peaked(w, 1.0), "G_1": _peaked(w, 0.5)}

    def loop2(w):
        return {"S": _peaked(w, 1.0).value, "G_1": _peaked(w, 0.6).value}

    ni, seen = ex._delay_compare(responses, loop2, 1, 0.5, 2.0, ex.DELAY_CHECK_SHIFT)
    assert set(ni) == {"max_abs_g1"} and len(seen) == 2
    assert ni["max_abs_g1"].startswith("not identifiable") and "max|G_1| depends on the assumed input delay" \
        in ni["max_abs_g1"]
    # a move inside the interval, or a small one, withholds nothing
    assert ex._delay_compare(responses, lambda w: {"S": _peaked(w, 1.0).value, "G_1": _peaked(w, 0.51).value},
                             1, 0.5, 2.0, ex.DELAY_CHECK_SHIFT)[0] == {}
    # its consequences in the assessment: eq. 10 comes from G_1 and is dropped; eq. 9 and the margins come
    # from S and the loop and are kept
    _, jk = _pair("G-classic-fwd-40Hz-poor", 4)
    from dataclasses import replace

    a = assess(replace(jk, not_identifiable=dict(ni)), kd=zoo.truth("G-classic-fwd-40Hz-poor").kd)
    assert a.not_identifiable == ni
    assert a.disturbance is None
    assert a.sensitivity is not None and a.margins is not None and a.max_s is not None


def test_plain_zcu_jackknife_widens_every_loop_quantity_including_the_droop():
    # Z_cu without H (the paper's method): the jackknife of the two-input loop model applies at every ω,
    # the droop's G_1(0) included (bench identify: coverage of the droop 17 → 20 of 20, max|S| 13 → 17)
    from fcrlive.plant.params import preset
    from fcrlive.sim import SimConfig, simulate
    from fcrlive.tso.signals import log_from_sim, plant_signals

    res = simulate(preset("paper-plant1"), SimConfig(duration_s=1800, snr_db=12.0, excitation=True, seed=0))
    sig = plant_signals(log_from_sim(res), rated_mw=300.0)
    cov, jk = (ex.zcu(sig, jackknife=j) for j in (False, True))
    w = np.concatenate(([1e-5], W))
    rc, rj = cov.responses(w), jk.responses(w)
    for key in ("S", "G_1", "G_p"):
        np.testing.assert_array_equal(rj[key].value, rc[key].value)
        assert np.all(rj[key].sd_abs >= rc[key].sd_abs * (1 - 1e-12)), key
    # on this record the jackknife of G_1(0) is 3.9x the covariance's (S: the covariance's is the larger)
    assert rj["G_1"].sd_abs[0] > 2 * rc["G_1"].sd_abs[0]
    ac, aj = assess(cov, kd=0.1), assess(jk, kd=0.1)
    assert aj.droop.value == ac.droop.value and aj.droop.hi - aj.droop.lo > ac.droop.hi - ac.droop.lo
    assert any("jackknife" in n for n in jk.notes) and not any("jackknife" in n for n in cov.notes)
