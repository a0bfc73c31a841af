"""lowband on excited logs: the excitation r stays in the input ε only where the log is known to be at the
controller rate (lowband.lowband, "Excitation on logs below the controller rate").

Instantaneous samples at 1/5 of the controller rate fold the white excitation above the log's Nyquist
frequency into the band, as input noise of the z ← ε fit: on the zoo's excited 2-Hz logs the droop was
covered 118/129; with ε − r 151/154 (docs/zoo.md). Asserted here: what the rule does (deterministic) and
the coverage of one cell over seeds.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fcrlive.analysis import lowband as lb
from fcrlive.analysis.identify import identify_signals
from fcrlive.sim import zoo

PLANT = "E-stiff5pct-classic-demand-25Hz"


def test_without_excitation_the_rule_changes_nothing():
    t = zoo.truth(PLANT)
    sig = zoo.signals(PLANT, "fifth-0.2pct", minutes=15.0, seed=0, excitation=False)
    a = lb.lowband(sig, H=t.H, kd=t.kd, excitation_in_input=True)
    b = lb.lowband(sig, H=t.H, kd=t.kd, excitation_in_input=False)
    w = np.array([0.0, 0.01, 0.1])
    assert np.array_equal(a.responses(w)["G_p"].value, b.responses(w)["G_p"].value)
    assert a.notes == b.notes


def test_a_log_not_known_to_be_at_the_controller_rate_leaves_r_out_of_the_input():
    t = zoo.truth(PLANT)
    sig = zoo.signals(PLANT, "fifth-0.2pct", minutes=15.0, seed=0, excitation=True)
    rep = identify_signals(sig, rated_mw=t.rated_mw, kd=t.kd, h=t.H)
    assert rep.method == "lowband"
    assert any(n.startswith("excitation left out of the input") for n in rep.notes)
    # the same droop as lowband on the grid frequency alone
    grid = replace(sig, epsilon=np.asarray(sig.epsilon) - np.asarray(sig.r), r=np.zeros(len(sig.r)))
    ref = identify_signals(grid, rated_mw=t.rated_mw, kd=t.kd, h=t.H, method="lowband")
    assert (rep.droop.value, rep.droop.ci95) == (ref.droop.value, ref.droop.ci95)
    # with the plant description the log is known to be at 1/5 of its controller rate: still left out;
    # at the controller rate r stays in
    rep_p = identify_signals(sig, rated_mw=t.rated_mw, kd=t.kd, h=t.H, plant=t.plant, method="lowband")
    assert any(n.startswith("excitation left out of the input") for n in rep_p.notes)
    ctl = zoo.signals(PLANT, "ctl-0.1pct", minutes=15.0, seed=0, excitation=True)
    rep_c = identify_signals(ctl, rated_mw=t.rated_mw, kd=t.kd, h=t.H, plant=t.plant, method="lowband")
    assert not any(n.startswith("excitation left out of the input") for n in rep_c.notes)


def test_excited_logs_at_a_fifth_of_the_controller_rate_droop_covered_over_seeds():
    # E's 25 Hz governor logged at 5 Hz, 15 min: with r in the input 2 of 3 shown were covered (seeds 0-9);
    # without it 10 of 10 shown and covered
    t = zoo.truth(PLANT)
    shown = covered = 0
    for seed in range(8):
        sig = zoo.signals(PLANT, "fifth-0.2pct", minutes=15.0, seed=seed, excitation=True)
        rep = identify_signals(sig, rated_mw=t.rated_mw, kd=t.kd, h=t.H)
        if rep.droop is None or rep.droop.value is None:
            continue
        shown += 1
        covered += rep.droop.ci95[0] <= t.droop <= rep.droop.ci95[1]
    assert shown >= 6 and covered >= shown - 1, (shown, covered)
