"""Z_cu without H: its peaks, G_p and TSO checks are withheld where meter noise on u biases the fitted
swing path (analysis.quality.zcu_meter_noise); the droop stays.

On the zoo's 30-min excited logs with 0.1 % meter noise and no H, Z_cu put max|S| 16-28 % off (A: −16 …
−20 %) with intervals that missed; u's SNR in 0.15-0.4 rad/s was 3-20 dB there, 24-54 dB on ideal logs.
"""

from __future__ import annotations

import pytest

from fcrlive.analysis import quality
from fcrlive.analysis.lowband import BandInfo


def bands(*snr_db: float) -> tuple[BandInfo, ...]:
    edges = ((0.002, 0.02), (0.02, 0.06), (0.06, 0.15), (0.15, 0.4))
    return tuple(BandInfo(lo, hi, s, 0.9) for (lo, hi), s in zip(edges, snr_db))


def test_rule_withholds_the_peaks_when_a_peak_band_is_noisy():
    out = quality.zcu_meter_noise(bands(60, 50, 30, 12), 0.1)
    assert set(out) == {"max_abs_g1", "max_abs_s", "gp", "tso"}
    assert "12 dB at ω = 0.15-0.4 rad/s" in out["max_abs_s"] and "give H" in out["max_abs_s"]
    # the low bands (the droop's) do not count; a clean peak band passes
    assert quality.zcu_meter_noise(bands(5, 5, 25, 21), 0.01) == {}
    assert quality.zcu_meter_noise(bands(60, 50, 30, float("nan")), 0.01) == {}


@pytest.mark.parametrize("logger, withheld", [("ctl-0.1pct", True), ("ctl-ideal", False)])
def test_zoo_a_without_h(logger, withheld):
    from fcrlive.analysis.identify import identify_signals
    from fcrlive.sim import zoo

    name = "A-classic-tustin-20Hz"
    t = zoo.truth(name)
    sig = zoo.signals(name, logger, minutes=30, excitation=True, seed=0)
    rep = identify_signals(sig, rated_mw=zoo.plants()[name].plant.unit.rated_mw, kd=t.kd)
    assert rep.method == "zcu"
    assert rep.droop.value is not None  # the droop is not the swing path's
    assert (rep.max_abs_s.value is None) is withheld
    assert ("max_abs_s" in rep.not_identifiable) is withheld
    if withheld:
        assert "errors in variables" in rep.not_identifiable["max_abs_s"]
        assert not rep.gp or all(p.abs is None for p in rep.gp)
        assert "tso" in rep.not_identifiable
