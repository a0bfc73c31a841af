"""The validation zoo (fcrlive.sim.zoo) and the logger model (fcrlive.sim.logger).

Truth against simulation: a lock-in at a few frequencies (near the peaks of G_1 and S and at 60 s) on
the simulator's noise-free response to a load sine (G_1 = ε/u) and to an excitation sine
(S = (ε − G_1 u)/r, u reacts to r through the grid), against the analytic sampled-data truth.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from fcrlive.errors import ConfigError
from fcrlive.plant import transfer as tr
from fcrlive.sim import SimConfig, simulate, zoo
from fcrlive.sim import linear as lin
from fcrlive.sim import logger as lg
from fcrlive.tso.csvlog import write_log

ZOO = [n for n in zoo.plants() if not n.startswith("ref-")]


def _lockin(zp: zoo.ZooPlant, w: float, kind: str, periods: int = 4, settle_s: float = 400.0):
    """Complex amplitudes of ε, u, r at ω from a noise-free run driven by a load or an r sine.

    A constant, a ramp and a slow exponential are fitted along with the sine: the slowest closed-loop
    modes (up to 2600 s) have not died out after the settling time."""
    p = zp.plant
    Tc = p.unit.governor.Tc
    T = 2 * math.pi / w
    N = round((settle_s + periods * T) / Tc)
    t = np.arange(N + 1) * Tc
    kw = dict(duration_s=N * Tc, snr_db=None, process_noise_std=0.0, load_noise_std=0.0, model=zp.model)
    if kind == "load":
        kw["load_pu"] = 1e-3 * np.sin(w * t)
    else:
        kw["r"] = 1e-4 * np.sin(w * t[:N])
    res = simulate(p, SimConfig(**kw))
    M = round(periods * T / Tc)
    ts = res.t[N - M:]
    tc = ts - ts.mean()
    A = np.vstack([np.ones_like(tc), tc / tc.max(), np.exp(-(ts - ts[0]) / 2000.0), np.cos(w * ts),
                   np.sin(w * ts)]).T

    def amp(x):
        c = np.linalg.lstsq(A, x[N - M:], rcond=None)[0]
        return c[3] - 1j * c[4]

    return amp(res.epsilon), amp(res.u), amp(res.r)


HELD_OUT = ("held-out-0", "held-out-3", "held-out-4")  # a PI; a PID with its S peak at 1.5 rad/s; Kd = 0


@pytest.mark.parametrize("name", [*ZOO, *HELD_OUT])
def test_truth_matches_the_simulated_plant(name):
    zp = zoo.zoo_plant(name)
    t = zoo.truth(name)
    for w in (t.omega_max_g1, t.omega_max_s, 2 * math.pi / 60.0):
        e1, u1, _ = _lockin(zp, w, "load")
        e2, u2, r2 = _lockin(zp, w, "r")
        G = e1 / u1
        S = (e2 - G * u2) / r2
        assert abs(G / t.response("G_1", w) - 1) < 0.005, (name, w)
        assert abs(S / t.response("S", w) - 1) < 0.005, (name, w)


@pytest.mark.parametrize("name", ZOO)
def test_analytic_model_matches_the_exact_discretisation(name):
    # The analytic blocks (transfer.py, u linear between samples) against the simulator's closed-loop
    # matrices (linear.py): two independent derivations of the same digital loop, for every controller
    # variant in the zoo. They differ only by u's course between samples: at most 0.13 % up to
    # 0.6 rad/s (the 10 Hz plant; 0.006 % at 20-100 Hz).
    p = zoo.plants()[name].plant
    t = zoo.truth(name)
    w = np.geomspace(0.01, 0.6, 9)
    g = lin.frequency_response(p, w, "load", "epsilon") / lin.frequency_response(p, w, "load", "u")
    s = lin.frequency_response(p, w, "r", "epsilon") - g * lin.frequency_response(p, w, "r", "u")
    np.testing.assert_allclose(t.response("G_1", w), g, rtol=1e-9)
    np.testing.assert_allclose(t.response("S", w), s, rtol=1e-9)
    tol = 1.5e-3 if t.Tc >= 0.1 else 1e-4
    assert np.max(np.abs(g / t.analytic_response("G_1", w) - 1)) < tol
    assert np.max(np.abs(s / t.analytic_response("S", w) - 1)) < tol


def test_zoo_spans_what_the_issue_asks():
    ps = [zp.plant for zp in zoo.plants().values() if not zp.name.startswith("ref-")]
    gov = [p.unit.governor for p in ps]
    assert {g.droop_placement for g in gov} == {"integral", "classic"}
    assert {g.integral_method for g in gov} == {"forward", "backward", "tustin"}
    assert any(g.Td > 0 for g in gov) and any(g.Td == 0 for g in gov)
    rates = sorted(1 / g.Tc for g in gov)
    assert rates[0] == pytest.approx(10) and rates[-1] == pytest.approx(100)
    share = [p.unit.rated_mw / p.grid.s_base_mw for p in ps]
    assert min(share) <= 0.011 and any(0.04 <= s <= 0.051 for s in share)
    assert any(p.grid.other.rated_mw == 3000 and p.unit.rated_mw == 300 for p in ps)
    H = [p.unit.swing.H for p in ps]
    Kd = [p.unit.swing.Kd for p in ps]
    Tw = [p.unit.turbine.Tw for p in ps]
    At = [p.unit.turbine.At for p in ps]
    droops = [g.droop for g in gov]
    assert min(H) == 3.0 and max(H) == 6.0 and min(Kd) == 0.0 and max(Kd) == 1.0
    assert min(Tw) == 0.6 and max(Tw) == 2.0 and any(a != 1.0 for a in At)
    assert min(droops) == 0.02 and max(droops) == 0.10


def test_truth_quantities_are_consistent():
    for name in zoo.plants():
        t = zoo.truth(name)
        assert t.droop == pytest.approx(1.0 / (1.0 / t.g1_static - t.kd), rel=1e-9)
        # the droop seen from the power: ρ/G_t(0)
        gain = tr.turbine_linear(t.plant.unit.turbine).gain
        assert t.droop == pytest.approx(t.droop_setting / gain, rel=1e-6)
        # G_1 at a very low frequency tends to G_1(0)
        assert abs(t.response("G_1", 1e-6)) == pytest.approx(t.g1_static, rel=1e-4)
        assert abs(t.response("S", t.omega_max_s)) == pytest.approx(t.max_s, rel=1e-9)
        assert abs(t.response("G_1", t.omega_max_g1)) == pytest.approx(t.max_g1, rel=1e-9)
        w = np.geomspace(*t.peak_band, 500)
        assert np.max(np.abs(t.response("S", w))) <= t.max_s * (1 + 1e-9)
        assert np.max(np.abs(t.response("G_1", w))) <= t.max_g1 * (1 + 1e-9)
        for (p, f), (q, g) in zip(t.f, t.gp, strict=True):
            assert p == q
            assert f == pytest.approx(g * t.droop, rel=1e-12)  # F = G_p/G_p(0), G_p(0) = 1/droop
            assert g == pytest.approx(t.response("G_p", 2 * math.pi / p), rel=1e-9)


def test_unknown_names_are_config_errors():
    with pytest.raises(ConfigError, match="known"):
        zoo.truth("no-such-plant")
    with pytest.raises(ConfigError, match="known"):
        zoo.zoo_logger("no-such-logger")


def test_held_out_plants_are_drawn_by_their_number_alone():
    # 24: held-out-21's first unit has no governor in the band, and is redrawn (zoo.held_out)
    first = [zoo.held_out(k) for k in range(24)]
    zoo.held_out.cache_clear()
    again = [zoo.zoo_plant(f"held-out-{k}") for k in range(24)]
    assert first == again  # the same plant from its number, in any process
    assert len({zp.plant for zp in first}) == 24
    for zp in first:
        g, u, t = zp.plant.unit.governor, zp.plant.unit, zoo.truth(zp.name)
        assert 10.0 <= 1.0 / g.Tc <= 100.0 and 0.02 <= g.droop <= 0.10
        assert 3.0 <= u.swing.H <= 6.0 and 0.0 <= u.swing.Kd <= 1.0 and 0.6 <= u.turbine.Tw <= 2.0
        assert 0.01 <= u.rated_mw / zp.plant.grid.s_base_mw <= 0.09 and 6.0 <= zp.snr_db <= 20.0
        assert zp.model == ("linear" if g.Td > 0 else "nonlinear")
        assert zoo.HELD_OUT_MAX_S[0] <= t.max_s <= zoo.HELD_OUT_MAX_S[1]
        poles = np.linalg.eigvals(lin.closed_loop(zp.plant).Phi)
        assert np.max(np.abs(poles)) < 1.0
    # the draws cover what the named plants do, not one corner of it
    govs = [zp.plant.unit.governor for zp in first]
    assert {g.droop_placement for g in govs} == {"integral", "classic"}
    assert {g.integral_method for g in govs} == {"forward", "backward", "tustin"}
    assert any(g.Td > 0 for g in govs) and any(zp.plant.unit.swing.Kd == 0 for zp in first)
    for bad in ("held-out-x", "held-out--1", "held-out-"):
        with pytest.raises(ConfigError, match="held-out-K"):
            zoo.zoo_plant(bad)


def test_derivative_action_needs_the_linear_model():
    p = zoo.plants()["C-pid-tustin-50Hz"].plant
    with pytest.raises(ConfigError, match="linear"):
        simulate(p, SimConfig(duration_s=10.0))


# ---------------------------------------------------------------------------------------------------
# The logger


@pytest.fixture(scope="module")
def record():
    """A 10-min record of zoo plant B (10 Hz controller) with excitation."""
    return zoo.simulate("B-int-beuler-10Hz", minutes=10.0, excitation=True, seed=4)


@pytest.mark.parametrize("every", [1, 2, 5, 10])
def test_instantaneous_samples_are_every_kth_controller_sample(record, every):
    log = lg.log(record, lg.Logger(every=every, round_columns=False, columns="governor"))
    assert log.sample_s == pytest.approx(every * record.Tc)
    assert len(log) == math.ceil(record.n / every)
    np.testing.assert_array_equal(log.columns["InsAcPow"], record.pe_mw[::every])
    np.testing.assert_array_equal(log.columns["GuideVane"], 100 * record.a[::every])
    np.testing.assert_allclose(log.columns["ApplFreqSig"] - log.columns["GridFreq"],
                               -record.f0 * record.r[::every], atol=1e-12)


def test_block_averages_are_means_of_whole_blocks(record):
    log = lg.log(record, lg.Logger(block_s=1.0, round_columns=False))
    n = round(1.0 / record.Tc)
    assert log.sample_s == pytest.approx(1.0)
    assert len(log) == record.n // n
    assert log.columns["InsAcPow"][3] == pytest.approx(np.mean(record.pe_mw[3 * n:4 * n]), rel=1e-14)
    assert log.columns["GridFreq"][7] == pytest.approx(record.f0 * (1 + np.mean(record.y[7 * n:8 * n])),
                                                       rel=1e-14)
    assert set(log.columns) == {"GridFreq", "ApplFreqSig", "InsAcPow"}


def test_frequency_resolution_quantises_grid_frequency(record):
    for step_mhz in (1.0, 10.0):
        log = lg.log(record, lg.Logger(freq_resolution_mhz=step_mhz, round_columns=False))
        f = log.columns["GridFreq"]
        k = f / (step_mhz * 1e-3)
        np.testing.assert_allclose(k, np.round(k), atol=1e-6)
        assert np.max(np.abs(f - record.f0 * (1 + record.y))) <= step_mhz * 1e-3 / 2 + 1e-9
        # the governor's applied frequency keeps its own precision
        assert np.any(np.abs(log.columns["ApplFreqSig"] * 1e3 - np.round(log.columns["ApplFreqSig"] * 1e3))
                      > 1e-3)


def test_column_rounding_as_tso_logs(record, tmp_path):
    log = lg.log(record, lg.Logger(columns="governor"))
    for name, dec in lg.COLUMN_DECIMALS.items():
        v = log.columns[name]
        np.testing.assert_allclose(v, np.round(v, dec), rtol=0, atol=1e-9)
    # written with the same decimals, a file holds exactly these numbers
    path = write_log(tmp_path / "x.csv", log, decimals=lg.COLUMN_DECIMALS)
    assert path.exists()


@pytest.mark.parametrize("noise_at", ["log", "meter"])
def test_meter_noise_std(record, noise_at):
    pct = 0.5
    clean = lg.log(record, lg.Logger(block_s=1.0, round_columns=False))
    lgr = lg.Logger(block_s=1.0, meter_noise_pct=pct, noise_at=noise_at, round_columns=False)
    noisy = lg.log(record, lgr, seed=11)
    d = noisy.columns["InsAcPow"] - clean.columns["InsAcPow"]
    n = round(1.0 / record.Tc)
    want = pct / 100 * record.rated_mw * (1.0 if noise_at == "log" else 1.0 / math.sqrt(n))
    # 600 samples: the sample std is within 4 standard errors (1/sqrt(2·600) = 2.9 %) of its value
    assert abs(np.std(d) / want - 1) < 4 / math.sqrt(2 * len(d))
    assert abs(np.mean(d)) < 4 * want / math.sqrt(len(d))
    # the other columns are untouched
    np.testing.assert_array_equal(noisy.columns["GridFreq"], clean.columns["GridFreq"])


def test_logger_is_deterministic_in_its_seed(record):
    lgr = zoo.loggers()["tenth-1pct"]
    a, b, c = lg.log(record, lgr, seed=1), lg.log(record, lgr, seed=1), lg.log(record, lgr, seed=2)
    for k in a.columns:
        np.testing.assert_array_equal(a.columns[k], b.columns[k])
    assert not np.array_equal(a.columns["InsAcPow"], c.columns["InsAcPow"])


def test_jitter_moves_samples_by_at_most_the_jitter(record):
    ideal = lg.log(record, lg.Logger(every=2, round_columns=False))
    jit = lg.log(record, lg.Logger(every=2, jitter_ms=20.0, round_columns=False), seed=3)
    # a sample taken δ late is the record linear between controller samples: it moves by at most
    # |δ|/Tc of the largest step between neighbouring controller samples
    p = record.pe_mw
    d = jit.columns["InsAcPow"] - ideal.columns["InsAcPow"]
    span = np.max(np.abs(np.diff(p)))
    assert np.max(np.abs(d)) <= span * 20.0 / (1e3 * record.Tc) + 1e-9
    assert np.count_nonzero(d) > 0.9 * len(d)
    np.testing.assert_array_equal(jit.t_s, ideal.t_s)  # time stamps stay nominal


def test_bad_logger_fields_are_config_errors(record):
    for bad in (dict(every=0), dict(block_s=-1.0), dict(meter_noise_pct=-0.1), dict(block_s=1.0, every=2),
                dict(block_s=1.0, jitter_ms=1.0), dict(block_s=0.15)):
        with pytest.raises(ConfigError):
            lg.log(record, replace(lg.Logger(), **bad))


def test_zoo_signals_cell_is_deterministic():
    a = zoo.signals("A-classic-tustin-20Hz", "hist-1s", minutes=3.0, seed=5)
    b = zoo.signals("A-classic-tustin-20Hz", "hist-1s", minutes=3.0, seed=5)
    np.testing.assert_array_equal(a.u, b.u)
    np.testing.assert_array_equal(a.epsilon, b.epsilon)
    assert a.Ts == 1.0 and len(a) == 180 and a.c is None


# ---------------------------------------------------------------------------------------------------
# The droop from normal operation (lowband, H and Kd from the data sheet) on zoo cells
#
# Over seeds rather than one seed in its interval: a 95 % interval misses on one record in twenty, so a
# single-seed coverage assertion fails for no fault of the estimator. Seeds 0-7 are deterministic, and
# the thresholds are what issue 12 asks of the whole population (median error ≤ 0.2 pp on 60-min logs;
# coverage 90-98 %, of which ≥ 6/8 is the binomial lower end: P(≤ 5 of 8 | 95 %) = 0.6 %).

NORMAL_SEEDS = range(8)


@pytest.mark.parametrize("logger", ["hist-1s", "half-0.5pct"])
@pytest.mark.parametrize("plant", ["A-classic-tustin-20Hz", "E-stiff5pct-classic-demand-25Hz"])
def test_droop_from_normal_operation_over_seeds(plant, logger):
    from fcrlive.analysis.identify import identify_signals

    t = zoo.truth(plant)
    errs, covered = [], 0
    for seed in NORMAL_SEEDS:
        sig = zoo.signals(plant, logger, minutes=60.0, seed=seed)
        rep = identify_signals(sig, rated_mw=t.rated_mw, kd=t.kd, h=t.H)
        assert rep.method == "lowband"
        lo, hi = rep.droop.ci95
        assert math.isfinite(lo) and math.isfinite(hi) and hi > lo  # never a zero-width interval
        errs.append(100.0 * abs(rep.droop.value - t.droop))
        covered += lo <= t.droop <= hi
    assert covered >= 6, (covered, errs)
    assert float(np.median(errs)) <= 0.2, errs


def test_peaks_from_normal_operation_at_low_snr_are_not_identifiable():
    # plant F (PID, flat peaks at 0.1-0.23 rad/s) through a historian with 0.5 % meter noise: u's swings
    # near the peaks are buried in the meter noise (coherence ≈ 0.02); the answer must be a null with the
    # measured reason, never a number
    from fcrlive.analysis.identify import identify_signals

    plant = "F-pid-classic-2pct-25Hz"
    t = zoo.truth(plant)
    rep = identify_signals(zoo.signals(plant, "hist-1s", minutes=60.0, seed=0), rated_mw=t.rated_mw,
                           kd=t.kd, h=t.H)
    assert rep.method == "lowband"
    for key in ("max_abs_g1", "max_abs_s"):
        q = getattr(rep, key)
        assert q.value is None and tuple(q.ci95) == (None, None)
        assert q.reason.startswith("not identifiable from this log: "), q.reason
        assert "coherence" in q.reason or "edge of the band" in q.reason, q.reason
        assert rep.not_identifiable[key] == q.reason
    # the droop is still reported, with an interval
    assert rep.droop.value is not None and math.isfinite(rep.droop.ci95[0])


def test_droop_of_a_log_folded_by_slow_instantaneous_samples_is_not_narrow_and_wrong():
    # plant B (10 Hz governor) logged instantaneously at 2 Hz: the content above 1 Hz folds into the fit
    # band and puts the 15-min droop 0.4-2 pp low. Before the two-rate bias check (lowband docstring) 2 of
    # the 3 droops shown for seeds 0-7 had intervals that missed (−1.5 and −1.7 pp with ±1.3 pp); over 30
    # seeds 5 of 14. Now the interval holds the difference of the 5-s and 10-s fits: a droop is either
    # covered or withheld as not identifiable (measured: 5 shown of 30, all covered).
    from fcrlive.analysis.identify import identify_signals

    plant = "B-int-beuler-10Hz"
    t = zoo.truth(plant)
    shown = missed = 0
    for seed in NORMAL_SEEDS:
        rep = identify_signals(zoo.signals(plant, "fifth-0.2pct", minutes=15.0, seed=seed),
                               rated_mw=t.rated_mw, kd=t.kd, h=t.H)
        assert rep.method == "lowband"
        if rep.droop.value is None:
            assert rep.droop.reason.startswith("not identifiable from this log"), rep.droop.reason
            continue
        shown += 1
        lo, hi = rep.droop.ci95
        missed += not lo <= t.droop <= hi
    assert missed <= 1, (shown, missed)


def test_a_flat_low_band_fit_is_no_resonance():
    # plant B logged at 2 Hz, 60 min, seed 14: the lowband fit's |G_1| is flat up to the top of its band and
    # its maximum (0.0424 at 0.158 rad/s, inside the band, coherence passing) was published with
    # [0.036, 0.048] against a true max|G_1| of 0.677 at 0.30 rad/s. A maximum less than PEAK_MIN_RISE × the
    # value at the band's low end is not a resonance: withheld with that reason
    from fcrlive.analysis.identify import PEAK_MIN_RISE, identify_signals

    plant = "B-int-beuler-10Hz"
    t = zoo.truth(plant)
    rep = identify_signals(zoo.signals(plant, "fifth-0.2pct", minutes=60.0, seed=14), rated_mw=t.rated_mw,
                           kd=t.kd, h=t.H)
    assert rep.method == "lowband"
    q = rep.max_abs_g1
    assert q.value is None and tuple(q.ci95) == (None, None)
    assert "has no resonance" in q.reason and f"less than {PEAK_MIN_RISE:g}×" in q.reason, q.reason
    assert rep.droop.value is not None  # the droop stays


def test_peak_of_a_governor_the_lag_lead_does_not_describe_is_covered_or_withheld():
    # plant C (PID, water time 2 s) in normal operation at the controller rate, 60 min: lowband's lag-lead
    # put max|G_1| +2.5 … +4 % high on every log, with ±1-4 % intervals that missed on seeds 2 and 3 of
    # 0-4 (4 of 10 covered over seeds 0-9). The order check (a pole and a zero more, 2 × the difference in
    # the interval; lowband docstring) covers it: measured 10/10 over seeds 0-9, all still shown
    from fcrlive.analysis.identify import identify_signals

    plant = "C-pid-tustin-50Hz"
    t = zoo.truth(plant)
    shown = missed = 0
    for seed in range(5):
        rep = identify_signals(zoo.signals(plant, "ctl-ideal", minutes=60.0, seed=seed), rated_mw=t.rated_mw,
                               kd=t.kd, h=t.H)
        assert rep.method == "lowband"
        assert any(n.startswith("order check: G_p also fitted") for n in rep.notes), rep.notes
        q = rep.max_abs_g1
        if q.value is None:
            continue
        shown += 1
        missed += not q.ci95[0] <= t.max_g1 <= q.ci95[1]
    assert missed <= 1, (shown, missed)
