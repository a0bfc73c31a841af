"""Z_cu with H: the two-rate bias check (experiments._rate_check_fit, RATE_CHECK_FACTOR).

G_jp is fitted again at half the identification's sample time; the error of a fit on block means
(c's variation inside each block, which the decimated model cannot see) shrinks with the sample time, so
the two fits' difference widens the intervals of |S|, |G_1| and |G_p| (in quadrature with the
jackknife's). What is asserted here is deterministic: the values do not
move, no interval narrows, the widening is where the fits differ and nowhere near ω = 0 (the droop), and
a log too slow for a second rate says so. Coverage over the zoo is measured in the benchmark
(docs/zoo.md).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from fcrlive.analysis import experiments as ex
from fcrlive.constants import TSO_PERIODS_S
from fcrlive.ident import FreqResp
from fcrlive.sim import logger as lg
from fcrlive.sim import zoo

PLANT = "C-pid-tustin-50Hz"  # a PID: the derivative's noise in c, the two fits 3 % apart at 10 s


@pytest.fixture(scope="module")
def fits():
    tr = zoo.truth(PLANT)
    res = zoo.simulate(PLANT, minutes=30, excitation=True, seed=0)
    sig = lg.signals(res, zoo.zoo_logger("ctl-ideal"), seed=zoo.logger_seed(0, "ctl-ideal"))
    on = ex.zcu_swing(sig, H=tr.H, kd=tr.kd)
    off = ex.zcu_swing(sig, H=tr.H, kd=tr.kd, rate_check=False)
    return sig, tr, on, off


def test_with_bias_adds_in_quadrature_along_the_response():
    w = np.array([0.1, 0.5, 1.0])
    base = FreqResp(w, np.array([1 + 1j, -2.0, 0.5j]), np.array([[0.1, 0.0], [0.0, 0.2], [0.05j, 0.05]]),
                    (("a", np.eye(2)),))
    sd_b = np.array([0.3, 0.0, 0.1])
    out = ex._with_bias(base, sd_b, "bias")
    assert np.array_equal(out.value, base.value)
    np.testing.assert_allclose(out.sd_abs, np.hypot(base.sd_abs, sd_b), rtol=1e-12)
    np.testing.assert_allclose(out.sd_phase, base.sd_phase, rtol=1e-12)
    assert [k for k, _ in out.sources] == ["a", "bias"]


def test_rate_check_widens_where_the_two_fits_differ_and_keeps_the_values(fits):
    _, _, on, off = fits
    assert any(n.startswith("two-rate bias check: G_jp also fitted at 0.12 s") for n in on.notes)
    w = np.array([2 * np.pi / p for p in TSO_PERIODS_S])
    r_on, r_off = on.responses(w), off.responses(w)
    for key in ("S", "G_1", "G_p"):
        assert np.array_equal(r_on[key].value, r_off[key].value)
        assert np.all(r_on[key].sd_abs >= r_off[key].sd_abs)
    # on this record the 0.12-s fit is several per cent off at 10 s: the interval there must grow
    assert r_on["G_p"].sd_abs[0] > 1.3 * r_off["G_p"].sd_abs[0]
    # ... and not at all at the static gain (the droop keeps its interval)
    w0 = np.array([1e-6, 1e-3])
    np.testing.assert_allclose(on.responses(w0)["G_1"].sd_abs, off.responses(w0)["G_1"].sd_abs, rtol=1e-12)


def test_a_log_at_the_identification_rate_has_no_second_rate(fits):
    sig, tr, _, _ = fits
    q = round(0.5 / float(sig.Ts))  # every 0.5 s, as a logger that slow would keep it
    keep = slice(None, None, q)
    slow = replace(sig, Ts=0.5, y=sig.y[keep], u=sig.u[keep], r=sig.r[keep], c=sig.c[keep], a=sig.a[keep],
                   epsilon=sig.epsilon[keep], t=sig.t[keep], filled=sig.filled[keep],
                   segments=((0, len(sig.y[keep])),))
    ctl = ex.controller_from_plant(zoo.zoo_plant(PLANT).plant)  # a 2 Hz log cannot show a 50 Hz controller
    res = ex.zcu_swing(slow, H=tr.H, kd=tr.kd, controller=ctl, jackknife=False)
    assert any(n.startswith("two-rate bias check not possible") for n in res.notes)
