"""Z_cu without H: max|S| (with G_p, the TSO checks) and max|G_1| are withheld where they follow the
assumed input delay of G_jp (experiments._loop_delay_check).

paper-plant1, 30-min excited logs at the controller rate: at 12 dB one more sample of delay moves max|S|
by 7-14 % and the fit is right within 0.5 %; at 6 dB (process noise twice as large) by 18-20 % on seeds
0-2, where max|S| came out +11 … +12 % with intervals that missed it. Since the swing-equation check
(experiments._swing_check) those intervals are ±20 % and hold the refit on seeds 0, 1 and 3 (shown,
covering the truth 1.287) and not on seed 2 (withheld): the test asserts the rule, not one outcome.
"""

from __future__ import annotations

import re

import pytest

from fcrlive.analysis.identify import identify_full
from fcrlive.plant.params import preset
from fcrlive.sim import SimConfig, simulate
from fcrlive.tso.signals import log_from_sim, plant_signals

PLANT = preset("paper-plant1")


def _report(snr_db: float, seed: int):
    res = simulate(PLANT, SimConfig(duration_s=1800, snr_db=snr_db, excitation=True, seed=seed))
    return identify_full(plant_signals(log_from_sim(res), rated_mw=300.0), rated_mw=300.0, kd=0.1).report


@pytest.mark.parametrize("snr_db, seed", [(12.0, 0), (6.0, 0), (6.0, 2)])
def test_max_s_is_withheld_where_it_follows_the_assumed_delay(snr_db, seed):
    rep = _report(snr_db, seed)
    assert rep.method == "zcu"
    note = next(n for n in rep.notes if n.startswith("delay check (G_jp refitted with 2 samples"))
    v, lo, hi, moved = (float(x) for x in re.search(
        r"max\|S\| ([\d.]+) \[([\d.]+), ([\d.]+)\] → ([\d.]+)", note).groups())
    withheld = abs(moved / v - 1.0) > 0.15 and not lo <= moved <= hi
    if snr_db == 12.0:
        assert not withheld  # at 12 dB the fit does not hang on the delay
    assert (rep.max_abs_s.value is None) is withheld
    if withheld:
        why = rep.not_identifiable["max_abs_s"]
        assert "model structure" in why and "input delay" in why
        assert rep.not_identifiable["tso"] == why
    assert rep.droop.value is not None  # the static gain does not hang on the delay
