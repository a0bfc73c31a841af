"""Z_cu without H: the swing-equation check (experiments._swing_check, SWING_CHECK_FACTOR).

Without H the swing path G_J is fitted with the loop, and its closed-loop bias reaches S, G_1 and G_p
(on the zoo's D: max|S| −4.4 … −6.2 % with ±1.7-3.7 % intervals). Z_cu is fitted once more with
G_J = 1/(2Ĥs + Kd), Ĥ read off the fitted G_J, and the intervals are made to hold that fit's interval
and twice the difference. Asserted here is what is deterministic: the values do not move, no interval
narrows, every interval of |S|, |G_1|, |G_p| above 0.01 rad/s holds the other fit's value, the droop is
untouched, and without Kd there is no check. Coverage over the zoo: the benchmark (docs/zoo.md).
"""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive.analysis import experiments as ex
from fcrlive.constants import Z95
from fcrlive.sim import logger as lg
from fcrlive.sim import zoo

PLANT = "D-stiff1pct-fwd-100Hz"


@pytest.fixture(scope="module")
def fits():
    tr = zoo.truth(PLANT)
    res = zoo.simulate(PLANT, minutes=30, excitation=True, seed=0)
    sig = lg.signals(res, zoo.zoo_logger("ctl-ideal"), seed=zoo.logger_seed(0, "ctl-ideal"))
    on = ex.zcu(sig, kd=tr.kd)
    off = ex.zcu(sig)
    return sig, tr, on, off


def test_the_check_reads_h_off_the_fit_and_says_so(fits):
    _, tr, on, off = fits
    note = next(n for n in on.notes if n.startswith("swing-equation check"))
    h_hat = float(note.split("Ĥ = ")[1].split(" s")[0])
    assert 0.5 * tr.H < h_hat < 2.0 * tr.H
    assert not any(n.startswith("swing-equation check") for n in off.notes)


def test_values_stay_and_intervals_hold_the_swing_fit(fits):
    sig, tr, on, off = fits
    note = next(n for n in on.notes if n.startswith("swing-equation check"))
    h_hat = float(note.split("Ĥ = ")[1].split(" s")[0])
    sw = ex.zcu_swing(sig, H=h_hat, kd=tr.kd, controller=on.controller, delay_check=False)
    w = np.geomspace(0.02, 1.5, 40)
    a, b, c = on.responses(w), off.responses(w), sw.responses(w)
    for key in ("S", "G_1", "G_p"):
        np.testing.assert_allclose(a[key].value, b[key].value, rtol=1e-12)
        assert np.all(a[key].sd_abs >= b[key].sd_abs * (1 - 1e-9))
        half = Z95 * a[key].sd_abs
        assert np.all(np.abs(np.abs(c[key].value) - np.abs(a[key].value)) <= half * (1 + 1e-9))
    # somewhere the check is what sets the interval (D's no-H max|S| is biased low)
    assert np.any(a["S"].sd_abs > 1.5 * b["S"].sd_abs)


def test_the_droop_keeps_its_interval(fits):
    _, _, on, off = fits
    w0 = np.array([1e-7])
    ga, gb = on.responses(w0)["G_1"], off.responses(w0)["G_1"]
    assert ga.value[0] == pytest.approx(gb.value[0], rel=1e-12)
    assert ga.sd_abs[0] == pytest.approx(gb.sd_abs[0], rel=1e-9)


# ---------------------------------------------------------------------------------------------------
# The meter-noise replicates of zcu_swing (experiments._meter_replicates)


def test_meter_noise_replicates_only_widen_and_say_so():
    # the zoo's E through a governor-side logger with 0.1 % meter noise, 15 min with excitation: the same
    # fit with and without the replicates; they may widen the intervals, never move a value or narrow one

    t = zoo.truth("E-stiff5pct-classic-demand-25Hz")
    sig = zoo.signals("E-stiff5pct-classic-demand-25Hz", "ctl-0.1pct", minutes=15.0, seed=0, excitation=True)
    with_ = ex.zcu_swing(sig, H=t.H, kd=t.kd)
    without = ex.zcu_swing(sig, H=t.H, kd=t.kd, meter_check=False)
    floor = [float(n.split("≈ ")[1].split(" %")[0]) for n in with_.notes
             if n.startswith("meter noise on u ≈")]
    assert floor and 0.09 <= floor[0] <= 0.11, with_.notes  # the logger's 0.1 % of rated
    assert not any(n.startswith("meter noise on u") for n in without.notes)
    w = np.array([0.0, 0.02, 0.1, 0.3])
    for key in ("G_1", "S", "G_p"):
        a, b = with_.responses(w)[key], without.responses(w)[key]
        np.testing.assert_array_equal(a.value, b.value)
        assert np.all(a.sd_abs >= b.sd_abs * (1 - 1e-12)), key
    # the droop's (ω = 0) interval is wider here (4×): the replicates spread more than its sandwich says
    assert with_.responses(w)["G_1"].sd_abs[0] > 1.5 * without.responses(w)["G_1"].sd_abs[0]


def test_meter_noise_at_15_minutes_the_droop_is_covered_over_seeds():
    # 15-min excited logs at the controller rate with 0.1 % meter noise, plants E and G, seeds 0-7: before
    # the replicates the droop's interval missed on E seed 3 and G seed 6 (−0.1 and +0.04 pp with ±0.03 and
    # ±0.01 pp); over 7 plants × 20 seeds 104/128 → 120/128 (docs/zoo.md). G (Kd = 0) withholds most of
    # its droops since METER_MATERIAL_PCT (its replicate refits do not converge): 8 of 16 shown here
    from fcrlive.analysis.identify import identify_signals

    shown = missed = 0
    for plant in ("E-stiff5pct-classic-demand-25Hz", "G-classic-fwd-40Hz-poor"):
        t = zoo.truth(plant)
        for seed in range(8):
            sig = zoo.signals(plant, "ctl-0.1pct", minutes=15.0, seed=seed, excitation=True)
            rep = identify_signals(sig, rated_mw=t.rated_mw, kd=t.kd, h=t.H)
            if rep.droop is None or rep.droop.value is None:
                continue
            shown += 1
            missed += not rep.droop.ci95[0] <= t.droop <= rep.droop.ci95[1]
    assert shown >= 6 and missed <= 1, (shown, missed)


def test_meter_noise_whose_effect_cannot_be_measured_withholds_the_droop():
    # the Kd = 0 unit B at 15 min with excitation, seed 5: at 0.1 % meter noise the replicate refits do not
    # converge (the noise a random walk in y + G_J u, which the turbine path's fit then follows with a
    # pole-zero pair at z = 1), so Z_cu's droop is withheld with the reason (with the swing pole fitted,
    # seed 2 was such a record and its droop had been published +0.032 pp off with ±0.027 pp). The ideal
    # log of the same record (floor ≈ 0.04 %, u's own content) keeps its droop.
    from fcrlive.analysis.identify import identify_signals

    t = zoo.truth("B-int-beuler-10Hz")
    noisy = zoo.signals("B-int-beuler-10Hz", "ctl-0.1pct", minutes=15.0, seed=5, excitation=True)
    rep = identify_signals(noisy, rated_mw=t.rated_mw, kd=t.kd, h=t.H, method="zcu")
    assert rep.method == "zcu"
    assert rep.droop is not None and rep.droop.value is None and rep.g1_static is None
    assert "meter's noise" in rep.droop.reason and "could not be measured" in rep.droop.reason
    assert "Kd = 0" in rep.droop.reason
    # the peaks are not withheld by this rule (here they are by the turbine path's own, experiments.
    # TURBINE_TAU_MAX_S: the held-pole fit follows the same noise)
    assert "could not be measured" not in (rep.max_abs_s.reason or "") + (rep.max_abs_g1.reason or "")
    ideal = zoo.signals("B-int-beuler-10Hz", "ctl-ideal", minutes=15.0, seed=5, excitation=True)
    rep_i = identify_signals(ideal, rated_mw=t.rated_mw, kd=t.kd, h=t.H)
    assert rep_i.droop is not None and rep_i.droop.value is not None and rep_i.droop.method is None
    assert rep_i.droop.ci95[0] <= t.droop <= rep_i.droop.ci95[1]

    # method auto gives the droop and G_1(0) of lowband on the same log instead, marked as such, with Z_cu's
    # reason in a note; the peaks and G_p stay Z_cu's
    auto = identify_signals(noisy, rated_mw=t.rated_mw, kd=t.kd, h=t.H)
    # (with the plant description lowband knows the log is at the controller rate: r stays in its input)
    low = identify_signals(noisy, rated_mw=t.rated_mw, kd=t.kd, h=t.H, method="lowband", plant=t.plant)
    assert auto.method == "zcu" and auto.droop.method == "lowband" and auto.g1_static.method == "lowband"
    assert (auto.droop.value, auto.droop.ci95) == (low.droop.value, low.droop.ci95)
    assert auto.droop.ci95[0] <= t.droop <= auto.droop.ci95[1]
    assert "droop" not in auto.not_identifiable
    assert not any("meter's noise" in w for w in auto.warnings)
    assert any(n.startswith("droop and G_1(0) from lowband") and "meter's noise" in n for n in auto.notes)
    assert auto.max_abs_s == rep.max_abs_s and auto.gp == rep.gp and auto.max_abs_g1 == rep.max_abs_g1
    # and says so wherever it is shown: the text summary and the published droop
    from fcrlive.analysis.report import text_summary
    from fcrlive.daemon.payloads import headline_scalars

    line = next(x for x in text_summary(auto).splitlines() if x.startswith("effective droop"))
    assert line.endswith("(from lowband)")
    assert headline_scalars(auto)["droop"].method == "lowband"
    assert headline_scalars(rep_i)["droop"].method is None
