"""Logs slower than the controller rate: Z_cu keeps the droop but its peaks are biased, and says so.

The process noise on the governor's speed signal reaches the controller output unfiltered; a logger that
samples it below the controller rate aliases it into the band as input noise (errors in variables).
"""

from __future__ import annotations

import pytest

from fcrlive.analysis.identify import identify_signals
from fcrlive.plant.params import preset
from fcrlive.sim import SimConfig, simulate
from fcrlive.tso.signals import log_from_sim, plant_signals

PLANT = preset("paper-plant1")
TRUE_DROOP = PLANT.unit.governor.droop


@pytest.fixture(scope="module")
def sim():
    return simulate(PLANT, SimConfig(duration_s=900.0, snr_db=12.0, excitation=True, seed=3))


def _identify(sim, sample_s):
    sig = plant_signals(log_from_sim(sim, sample_s=sample_s), rated_mw=PLANT.unit.rated_mw)
    # method given: with the plant description (H known) auto takes a log slower than the controller to
    # lowband
    rep = identify_signals(sig, rated_mw=PLANT.unit.rated_mw, kd=PLANT.unit.swing.Kd, plant=PLANT,
                           method="zcu")
    assert rep.method == "zcu"
    return rep, any("slower than a governor's controller rate" in w for w in rep.warnings)


def test_controller_rate_log_is_not_flagged_and_accurate(sim):
    rep, warned = _identify(sim, 0.02)
    assert not warned
    assert abs(rep.droop.value - TRUE_DROOP) < 0.002  # ±0.2 percentage points


def test_10_hz_log_is_flagged_and_its_droop_interval_still_holds_the_truth(sim):
    rep, warned = _identify(sim, 0.1)
    assert warned
    lo, hi = rep.droop.ci95
    assert lo <= TRUE_DROOP <= hi


def test_a_log_at_the_controller_rate_of_a_10_hz_governor_is_not_flagged_without_a_plant():
    # the zoo's B runs its controller at 10 Hz; its governor-side log is at 10 Hz too. Without a plant
    # description the controller Z_cu fits from the log (to the columns' rounding) says the log is at the
    # controller rate: no "slower than a governor's controller rate" warning. Z_ur, which fits no
    # controller, keeps it (it cannot know).
    from fcrlive.sim import zoo

    t = zoo.truth("B-int-beuler-10Hz")
    sig = zoo.signals("B-int-beuler-10Hz", "ctl-0.1pct", minutes=15.0, seed=2, excitation=True)
    assert sig.Ts == pytest.approx(0.1)
    rep = identify_signals(sig, rated_mw=t.rated_mw, kd=t.kd, h=t.H, method="zcu")
    assert rep.method == "zcu" and rep.controller is not None
    assert not any("slower than a governor's controller rate" in w for w in rep.warnings), rep.warnings
    rep_ur = identify_signals(sig, rated_mw=t.rated_mw, kd=t.kd, method="zur")
    assert any("slower than a governor's controller rate" in w for w in rep_ur.warnings)
