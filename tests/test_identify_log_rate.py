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
