"""The power measurement chain: a transducer's lag and dead time on InsAcPow (the zoo's loggers), Z_cu
with H taking a known chain off the power (fcrlive.signals.PowerChain), and its check for one nobody gave
(fcrlive.analysis.experiments.power_chain_profile)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from fcrlive.analysis.experiments import power_chain_profile
from fcrlive.analysis.identify import identify_signals
from fcrlive.cli import main
from fcrlive.errors import ConfigError
from fcrlive.signals import PowerChain, transducer
from fcrlive.sim import logger as lg
from fcrlive.sim import zoo


@pytest.fixture(scope="module")
def record():
    """A 15-min excited record of zoo plant A (20 Hz controller)."""
    return zoo.simulate("A-classic-tustin-20Hz", minutes=15.0, excitation=True, seed=3)


def test_transducer_is_a_unit_gain_first_order_lag_and_a_dead_time():
    Ts, T = 0.02, 0.2
    x = np.r_[np.ones(10), 2.0 * np.ones(300)]
    y = transducer(x, Ts, T, 0.0)
    np.testing.assert_array_equal(y[:10], 1.0)  # from rest at the first value
    # the sampled step response of 1/(Ts + 1): 1 − e^(−(k+1)Ts/T) of the step after k samples
    k = np.arange(300)
    np.testing.assert_allclose(y[10:], 2.0 - np.exp(-(k + 1) * Ts / T), rtol=0, atol=1e-12)
    d = transducer(x, Ts, 0.0, 0.1)  # 0.1 s = 5 samples
    np.testing.assert_array_equal(d[:15], 1.0)
    np.testing.assert_array_equal(d[15:], 2.0)


def test_restored_inverts_the_transducer_but_for_the_dead_time_at_the_end():
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.standard_normal(2000))
    ch = PowerChain(0.5, 0.2)
    Ts = 0.04
    back = ch.restored(transducer(x, Ts, ch.lag_s, ch.delay_s), Ts, ((0, len(x)),))
    k = round(ch.delay_s / Ts)
    np.testing.assert_allclose(back[: len(x) - k], x[: len(x) - k], rtol=0, atol=1e-9 * np.abs(x).max())
    assert np.all(back[len(x) - k:] == back[len(x) - k - 1])
    # segments are restored separately: nothing crosses a gap
    two = ch.restored(np.r_[x[:1000], x[1000:]], Ts, ((0, 1000), (1000, 2000)))
    np.testing.assert_array_equal(two[1000:], ch.restored(x[1000:], Ts, ((0, 1000),)))


def test_the_logger_puts_the_chain_on_insacpow_only(record):
    plain = lg.log(record, lg.Logger(columns="governor", round_columns=False))
    chained = lg.log(record, lg.Logger(columns="governor", round_columns=False, power_lag_s=0.3,
                                       power_delay_s=0.1))
    np.testing.assert_allclose(chained.columns["InsAcPow"], transducer(record.pe_mw, record.Tc, 0.3, 0.1),
                               rtol=1e-14)
    assert not np.allclose(chained.columns["InsAcPow"], plain.columns["InsAcPow"])
    for name in ("GridFreq", "ApplFreqSig", "ContOutSig", "GuideVane"):
        np.testing.assert_array_equal(chained.columns[name], plain.columns[name])


def test_bad_chains_are_config_errors(record):
    for bad in (dict(power_lag_s=-0.1), dict(power_delay_s=math.nan)):
        with pytest.raises(ConfigError, match="power_"):
            lg.log(record, replace(lg.Logger(), **bad))
    with pytest.raises(ConfigError, match="lag_s"):
        PowerChain(-1.0, 0.0)


def test_zcu_with_the_chain_given_answers_as_on_the_aligned_log(record):
    """On a log without noise the only difference between the two loggers is the chain: given, Z_cu
    with H must give the aligned log's numbers; not given, the peaks move far beyond their intervals'
    worth (the bias the chain makes: docs/zoo.md)."""
    tr = zoo.truth("A-classic-tustin-20Hz")
    ideal = zoo.zoo_logger("ctl-ideal")
    slow = replace(ideal, name="slow", power_lag_s=0.5, power_delay_s=0.2)
    kw = dict(rated_mw=tr.rated_mw, kd=tr.kd, h=tr.H)
    ref = identify_signals(lg.signals(record, ideal, seed=1), **kw)
    s = lg.signals(record, slow, seed=1)
    given = identify_signals(s, power_chain=PowerChain(0.5, 0.2), **kw)
    logged = identify_signals(s, **kw)
    assert ref.method == given.method == logged.method == "zcu"
    for key in ("max_abs_s", "max_abs_g1"):
        a, b, c = getattr(ref, key), getattr(given, key), getattr(logged, key)
        assert b.value == pytest.approx(a.value, rel=5e-3)
        assert b.ci95[0] == pytest.approx(a.ci95[0], rel=2e-2)
        assert b.ci95[1] == pytest.approx(a.ci95[1], rel=2e-2)
        assert abs(c.value / a.value - 1) > 0.1
        # not given, the profile finds the chain: the value stays the logged power's, its interval holds it
        assert c.ci95[0] < a.value < c.ci95[1]
        assert c.ci95[1] - c.ci95[0] > 2.0 * abs(c.value - a.value)
    assert given.droop.value == pytest.approx(ref.droop.value, rel=1e-3)
    assert any("power restored" in n for n in given.notes)
    assert any("restored through a power transducer lag 0.5 s, dead time 0.2 s" in n for n in logged.notes)
    assert any("points to none" in n for n in ref.notes)


@pytest.mark.parametrize(("lag", "delay", "lags"), [(0.5, 0.2, (0.5,)), (0.3, 0.0, (0.2, 0.35)),
                                                     (0.0, 0.1, (0.0,)), (0.0, 0.0, (0.0,))])
def test_the_profile_finds_a_chain_on_the_log_and_none_on_the_aligned_log(record, lag, delay, lags):
    """The profile's grid holds 0.2 and 0.35 s, not 0.3 s: it names a neighbour; on the aligned log
    nothing beats (0, 0)."""
    tr = zoo.truth("A-classic-tustin-20Hz")
    ideal = zoo.zoo_logger("ctl-ideal")
    s = lg.signals(record, replace(ideal, name="x", power_lag_s=lag, power_delay_s=delay), seed=1)
    p = power_chain_profile(s, tr.H, tr.kd)
    assert p.best.lag_s in lags
    assert p.best.delay_s == pytest.approx(delay, abs=1e-9)
    assert p.found == (lag > 0 or delay > 0)
    assert not p.at_edge
    if not p.found:
        assert p.lr == 0.0


def test_an_aligned_power_given_skips_the_profile_and_changes_nothing_else(record):
    tr = zoo.truth("A-classic-tustin-20Hz")
    s = lg.signals(record, zoo.zoo_logger("ctl-ideal"), seed=1)
    kw = dict(rated_mw=tr.rated_mw, kd=tr.kd, h=tr.H)
    given = identify_signals(s, power_chain=PowerChain(), **kw)
    checked = identify_signals(s, **kw)
    assert any("aligned with the frequency columns, as given" in n for n in given.notes)
    assert not any("profile" in n for n in given.notes)
    for key in ("max_abs_s", "max_abs_g1", "droop"):
        assert getattr(given, key).value == getattr(checked, key).value
        assert getattr(given, key).ci95 == getattr(checked, key).ci95


def test_identify_refuses_a_negative_power_lag_in_one_line(tmp_path, capsys):
    log = tmp_path / "x.csv"
    log.write_text("DateTime,InsAcPow,GridFreq\n")
    rc = main(["identify", str(log), "--rated-mw", "100", "--power-lag-s", "-0.2"])
    err = capsys.readouterr().err
    assert rc == 2
    assert "--power-lag-s" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_the_daemon_plug_in_passes_the_configured_chain(record, tmp_path):
    """The daemon's window of a governor whose power point lags: the plug-in given the unit's power_lag_s
    and power_delay_s restores the power (Z_cu says so and its peaks move); without them it does not."""
    from fcrlive.daemon.identify_plugin import identify_window
    from fcrlive.plant.description import plant_to_toml

    zp = zoo.zoo_plant("A-classic-tustin-20Hz")
    toml = tmp_path / "a.toml"
    toml.write_text(plant_to_toml(zp.plant))
    p = transducer(record.pe_mw, record.Tc, 0.5, 0.2)
    n = len(record.t)
    window = {"t": np.asarray(record.t, float), "ok": np.ones(n), "power": p,
              "grid_freq": record.f0 * (1.0 + np.asarray(record.y)),
              "excitation_applied": record.f0 * np.asarray(record.r),
              "controller_output": 100.0 * np.asarray(record.c), "guide_vane": 100.0 * np.asarray(record.a)}
    kw = dict(rated_mw=record.rated_mw, f0=record.f0, plant=str(toml), kd=zoo.truth(zp.name).kd)
    given = identify_window(window, power_lag_s=0.5, power_delay_s=0.2, **kw)
    logged = identify_window(window, **kw)
    assert given.method == "zcu" and any("power restored" in x for x in given.notes)
    assert not any("power restored" in x for x in logged.notes)
    # without them the plug-in's Z_cu finds the chain itself and says so
    assert any("InsAcPow restored through a power transducer lag 0.5 s" in x for x in logged.notes)
    assert given.max_abs_g1.value != pytest.approx(logged.max_abs_g1.value, rel=0.05)


def test_a_chain_the_method_does_not_use_is_said_so(record):
    tr = zoo.truth("A-classic-tustin-20Hz")
    s = lg.signals(record, zoo.zoo_logger("ctl-ideal"), seed=1)
    rep = identify_signals(s, rated_mw=tr.rated_mw, kd=tr.kd, h=tr.H, method="lowband",
                           power_chain=PowerChain(0.3, 0.0))
    assert any("given but not used" in n for n in rep.notes)
    assert not any("given but not used" in n for n in identify_signals(
        s, rated_mw=tr.rated_mw, kd=tr.kd, h=tr.H, method="lowband").notes)
