"""analysis.controller: the governor's c/ε, exact from a plant description, identified from a log at the
controller rate, refused below it."""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive.analysis import controller as cm
from fcrlive.analysis.identify import identify_signals
from fcrlive.ident import FreqResp
from fcrlive.plant import transfer as tf
from fcrlive.sim import logger as lg
from fcrlive.sim import zoo

W = np.array([0.01, 0.05, 0.2, 0.5, 1.5])


def _servo(plant, w):
    num, den = tf._servo_z(plant.unit, plant.unit.governor.Tc)
    z = np.exp(1j * w * plant.unit.governor.Tc)
    return FreqResp.known(w, np.polyval(num, z) / np.polyval(den, z))


def _true_c(plant, w):
    num, den = tf._discrete_governor(plant.unit).C
    z = np.exp(1j * w * plant.unit.governor.Tc)
    return np.polyval(num, z) / np.polyval(den, z)


@pytest.mark.parametrize("name", list(zoo.plants()))
def test_plant_description_gives_the_exact_c_over_epsilon(name):
    plant = zoo.zoo_plant(name).plant
    d = cm.from_plant(plant.unit.governor)
    got = d.C(W, _servo(plant, W)).value
    np.testing.assert_allclose(got, _true_c(plant, W), rtol=1e-9)


@pytest.fixture(scope="module")
def records():
    return {p: zoo.simulate(p, minutes=6, excitation=True, seed=5)
            for p in ("B-int-beuler-10Hz", "E-stiff5pct-classic-demand-25Hz", "F-pid-classic-2pct-25Hz")}


@pytest.mark.parametrize("name", ["B-int-beuler-10Hz", "E-stiff5pct-classic-demand-25Hz",
                                  "F-pid-classic-2pct-25Hz"])
@pytest.mark.parametrize("logger", ["ctl-ideal", "ctl-0.1pct"])
def test_identified_at_the_controller_rate(records, name, logger):
    """Backward Euler, droop from the demand, a classic PID: c/ε within 0.1 % of the truth, residual at the
    columns' rounding."""
    plant = zoo.zoo_plant(name).plant
    sig = lg.signals(records[name], zoo.zoo_logger(logger), seed=1)
    a, b = sig.segments[0]
    ic = cm.identify(sig.epsilon[a:b], sig.c[a:b], sig.a[a:b], sig.Ts)
    assert ic.rel_residual < (1e-5 if logger == "ctl-ideal" else 5e-3)
    got = ic.digital.C(W, _servo(plant, W)).value
    np.testing.assert_allclose(np.abs(got / _true_c(plant, W) - 1), 0, atol=1e-3)


def test_log_below_the_controller_rate_is_refused(records):
    sig = lg.signals(records["B-int-beuler-10Hz"], zoo.zoo_logger("half-0.5pct"), seed=1)
    a, b = sig.segments[0]
    with pytest.raises(cm.ControllerFitError, match="controller model does not fit"):
        cm.identify(sig.epsilon[a:b], sig.c[a:b], sig.a[a:b], sig.Ts)


def test_auto_takes_a_refused_controller_to_lowband_with_the_reason():
    t = zoo.truth("B-int-beuler-10Hz")
    res = zoo.simulate("B-int-beuler-10Hz", minutes=12, excitation=True, seed=5)  # lowband needs 10 min
    sig = lg.signals(res, zoo.zoo_logger("half-0.5pct"), seed=1)
    rep = identify_signals(sig, rated_mw=t.rated_mw, kd=t.kd, h=t.H)
    assert rep.method == "lowband"
    assert "controller model does not fit" in rep.method_reason


def test_pid_plant_end_to_end_by_zcu_with_the_data_sheet():
    """A PID governor (it raised "could not identify a PI controller" before): auto with H and Kd from the
    data sheet runs Z_cu with the identified digital controller; droop and peaks near the truth."""
    t = zoo.truth("C-pid-tustin-50Hz")
    res = zoo.simulate("C-pid-tustin-50Hz", minutes=30, excitation=True, seed=0)
    sig = lg.signals(res, zoo.zoo_logger("ctl-ideal"), seed=zoo.logger_seed(0, "ctl-ideal"))
    rep = identify_signals(sig, rated_mw=t.rated_mw, kd=t.kd, h=t.H)
    assert rep.method == "zcu"
    assert abs(rep.droop.value - t.droop) < 0.0005  # 0.05 percentage points
    assert abs(rep.max_abs_s.value / t.max_s - 1) < 0.08
    assert abs(rep.max_abs_g1.value / t.max_g1 - 1) < 0.05


def test_exact_log_of_a_classic_pid_gives_its_true_derivative_filter(records):
    """Without noise the gate is an exact function of c and EVERY derivative filter constant fits c to
    rounding, each with its own split of the gate terms; the one whose three droop estimates agree is the
    governor's. Before, the search's minimum over a flat 1e-13 residual was a rounding coin toss (Tdf
    0.013 or 0.008 s for the true 0.2 s), and with it c/ε through the fitted servo: a record perturbed in
    the 15th digit must give the same equation."""
    name = "F-pid-classic-2pct-25Hz"
    gov = zoo.zoo_plant(name).plant.unit.governor
    sig = lg.signals(records[name], zoo.zoo_logger("ctl-ideal"), seed=1)
    a, b = sig.segments[0]
    ic = cm.identify(sig.epsilon[a:b], sig.c[a:b], sig.a[a:b], sig.Ts)
    assert ic.governor.Tdf == pytest.approx(gov.Tdf, rel=1e-3)
    assert ic.governor.droop == pytest.approx(gov.droop, rel=1e-6)
    rng = np.random.default_rng(0)
    eps = sig.epsilon[a:b] * (1.0 + 1e-15 * rng.standard_normal(b - a))
    ic2 = cm.identify(eps, sig.c[a:b], sig.a[a:b], sig.Ts)
    assert ic2.structure == ic.structure
    np.testing.assert_allclose(ic2.digital.b_x, ic.digital.b_x, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(ic2.digital.a, ic.digital.a, rtol=1e-6, atol=1e-9)
