"""The TR test profiles (fcrlive.prequal.profiles) and the simulated test programme
(``fcrlive simulate --tso-test NAME --out-dir DIR``): the profiles' levels and timings against the TR
tables, the files' names and columns, the unit description, and the simulated response against the
plant's analytic transfer function."""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive.cli import main
from fcrlive.plant.description import load_unit_description
from fcrlive.plant.params import preset
from fcrlive.prequal import profiles as pf
from fcrlive.prequal import programme as pg
from fcrlive.tso.csvlog import read_log
from fcrlive.tso.names import parse_tso_filename

# ---------------------------------------------------------------------------------------------- profiles


def levels_at(p: pf.Profile, times) -> list[float]:
    return [round(float(x), 6) for x in p.frequency(np.asarray(times, dtype=float))]


def test_fcrn_steps_follow_table_3():
    p = pf.fcrn_steps()
    # mid-points of each step of Table 3 (start times in minutes: 0, 0.5, 1, 6, 11, 16; end 21)
    assert levels_at(p, [15, 45, 200, 500, 800, 1100]) == [50.0, 49.95, 50.0, 49.9, 50.1, 50.0]
    # the steps are steps: the new level from its start time on
    assert levels_at(p, [29.99, 30.0, 359.99, 360.0, 660.0, 960.0]) == [50.0, 49.95, 50.0, 49.9, 50.1, 50.0]
    assert p.duration_s == 21 * 60 and p.service == "Fcrn" and p.kind == "fcrn-steps"
    e = pf.fcrn_steps(endurance=True)  # steps 1 and 2 held 15 min: 2 at 21 min, 3 at 36, end 41
    assert levels_at(e, [21 * 60 - 1, 21 * 60, 36 * 60 - 1, 36 * 60]) == [49.9, 50.1, 50.1, 50.0]
    assert e.duration_s == 41 * 60 and e.variant == "endurance"


def ramp_rates(p: pf.Profile) -> list[float]:
    t, f = np.array(p.knots_t), np.array(p.knots_f)
    dt, df = np.diff(t), np.diff(f)
    return [round(abs(b) / a, 9) for a, b in zip(dt, df) if a > 0 and b != 0]


def test_fcrd_ramps_follow_table_4_and_mirror_down():
    up = pf.fcrd_ramps("FcrdUp", combination=True)
    # levels after each ramp of Table 4 (up): 49.45, 49.9, 49.5, 49.9, 49.0, 50.0, 49.7, 49.89
    assert levels_at(up, [10, 34, 60, 300, 600, 740, 1000, 1300, 1600]) == [
        49.9,
        49.45,
        49.9,
        49.5,
        49.9,
        49.0,
        50.0,
        49.7,
        49.89,
    ]
    # ramp speeds 0.14, 0.09, then 0.24 Hz/s
    assert ramp_rates(up) == [0.14, 0.09, 0.24, 0.24, 0.24, 0.24, 0.24, 0.24]
    starts = [e.t_s for e in up.events]
    assert starts == [30.0, 34.9, 90.0, 390.0, 690.0, 750.0, 1050.0, 1350.0]
    assert up.duration_s == 1650.0
    # ramp 1 ends when 0.14 Hz/s reaches 49.45 Hz (3.214 s), not at the table's 33.1 s
    assert levels_at(up, [30 + 0.45 / 0.14]) == [49.45] and levels_at(up, [33.1])[0] > 49.45
    down = pf.fcrd_ramps("FcrdDo", combination=True)
    t = np.linspace(0, 1650, 3301)
    np.testing.assert_allclose(down.frequency(t), 100.0 - up.frequency(t), atol=1e-9)
    # without the combination ramps the test ends at 1050 s; endurance: 900 s after ramp 3
    assert pf.fcrd_ramps("FcrdUp").duration_s == 1050.0
    e = pf.fcrd_ramps("FcrdUp", endurance=True)
    assert [ev.t_s for ev in e.events][3:] == [990.0, 1290.0, 1350.0] and e.duration_s == 1650.0
    assert levels_at(e, [985]) == [49.5]


def test_static_fcrd_follows_table_5():
    for svc, sign in (("FcrdUp", 1), ("FcrdDo", -1)):
        p = pf.fcrd_static(svc)
        base, full = 50 - sign * 0.1, 50 - sign * 0.5
        assert levels_at(p, [179.9, 180 + 0.4 / 0.24, 239.9, 240 + 0.4 / 0.24, 1439]) == [
            base,
            full,
            full,
            base,
            base,
        ]
        assert ramp_rates(p) == [0.24, 0.24] and p.duration_s == 1440.0
    assert pf.fcrd_static("FcrdUp", endurance=True).duration_s == 2280.0
    assert pf.fcrd_static("FcrdUp", ler=True).duration_s == 3180.0


def test_linearity_sequences():
    n = pf.linearity("Fcrn")
    lv = levels_at(n, np.arange(21) * 120 + 60)
    assert lv[0] == 50.0 and min(lv) == 49.9 and max(lv) == 50.1 and lv[-1] == 50.0
    assert set(np.round(np.abs(np.diff(lv)), 6)) == {0.02} and n.duration_s == 21 * 120
    up = levels_at(pf.linearity("FcrdUp"), np.arange(9) * 120 + 60)
    assert up == [49.9, 49.8, 49.7, 49.6, 49.5, 49.6, 49.7, 49.8, 49.91]
    down = levels_at(pf.linearity("FcrdDo"), np.arange(9) * 120 + 60)
    assert down == [50.1, 50.2, 50.3, 50.4, 50.5, 50.4, 50.3, 50.2, 50.09]
    with pytest.raises(ValueError, match="120-300"):
        pf.linearity("Fcrn", step_s=60)


def test_sine_profiles():
    for svc, centre in (("Fcrn", 50.0), ("FcrdUp", 49.7), ("FcrdDo", 50.3)):
        p = pf.sine(svc, 40.0, lead_in_s=100.0)
        t = np.arange(0, p.duration_s, 0.1)
        f = p.frequency(t)
        assert np.all(f[t < 100] == centre)
        np.testing.assert_allclose(f.max() - centre, 0.1, atol=1e-6)
        np.testing.assert_allclose(centre - f.min(), 0.1, atol=1e-6)
        assert p.sine.n_periods == 7 and p.duration_s == 100 + 7 * 40  # Table 6: 5 (7)
        assert pf.tso_test_type(p) == "Sine40" and pf.tso_test_id(p) == pf.SINE_TEST_ID[svc]
    with pytest.raises(ValueError, match="at least 2 periods"):
        pf.sine("Fcrn", 300.0, n_periods=1)
    assert len(pf.sine_profiles("Fcrn")) == 10 and len(pf.sine_profiles("FcrdUp")) == 7


def test_test_ids_of_table_21():
    assert pf.tso_test_type(pf.fcrn_steps(), 3) == "1.3"
    assert pf.tso_test_type(pf.fcrd_ramps("FcrdDo"), 2) == "3.2"
    assert pf.tso_test_type(pf.linearity("FcrdUp"), 1) == "6.1"
    assert pf.tso_test_type(pf.fcrd_static("FcrdUp"), 1) == "2.1"  # the ramp test's ID (no own one)
    with pytest.raises(ValueError, match="unknown test profile"):
        pf.profile("fcrn-stepz")


def test_plan_at_four_corners():
    """With four described points the tests go where TR Table 2b / Table 21 put them."""
    mk = lambda load, lvl: pg.SimPoint(load, lvl, 200.0, 0.08, 0.08, (), {})  # noqa: E731
    pts = (mk("high", "high"), mk("high", "low"), mk("low", "high"), mk("low", "low"))
    ids = [t.test_id for t in pg.plan(pg.expand_names(["all"]), pts, sine_periods=(40.0,))]
    assert ids == [
        "1.1",
        "1.2",
        "1.3",
        "1.4",
        "2.1",
        "2.2",
        "2.3",
        "2.4",
        "3.1",
        "3.2",
        "3.3",
        "3.4",
        "4.1",
        "4.2",
        "4.3",
        "5.1",
        "5.2",
        "6.1",
        "6.2",
        "7.1",
        "7.2",
        "Operation",
    ]
    tests = pg.plan(("fcrd-up-ramps",), pts, endurance=True)
    # ramps 7-8 (FCR-N/FCR-D combination) at the high droop; endurance at high load, low droop
    assert [t.profile.variant for t in tests] == ["combination", "endurance", "combination", ""]
    with pytest.raises(ValueError, match="unknown test"):
        pg.expand_names(["fcrn"])


# ---------------------------------------------------------------------------------------------- simulated


@pytest.fixture(scope="module")
def programme(tmp_path_factory):
    out = tmp_path_factory.mktemp("tso")
    rc = main(
        [
            "simulate",
            "--tso-test",
            "fcrn-steps",
            "--tso-test",
            "sines-fcrn",
            "--sine-periods",
            "40",
            "--tso-test",
            "fcrd-down-ramps",
            "--out-dir",
            str(out),
        ]
    )
    assert rc == 0
    return out


def test_files_have_tso_names_and_profiles(programme):
    files = sorted(programme.glob("*.csv"))
    names = {(n.service, n.test_type): n for n in map(parse_tso_filename, files)}
    assert set(names) == {("Fcrn", "1.1"), ("Fcrn", "Sine40"), ("FcrdDo", "3.1")}
    assert all(n.resource == "FCPSIM1" and n.area == "NO5" and n.sample_s == 0.1 for n in names.values())
    for f in files:
        log = read_log(f)
        n = parse_tso_filename(f)
        for col in ("InsAcPow", "GridFreq", "ApplFreqSig", "CalcBaseline", f"ContMode_{n.service}"):
            assert col in log.columns, (f.name, col)
        if n.test_type == "1.1":
            expect = pf.fcrn_steps().frequency(log.t_s)
        elif n.test_type == "3.1":
            expect = pf.fcrd_ramps("FcrdDo", combination=True).frequency(log.t_s)
        else:
            assert log.period_s == 40.0
            f0 = log.columns["ApplFreqSig"]
            np.testing.assert_allclose([f0.max(), f0.min()], [50.1, 49.9], atol=1e-6)
            continue
        np.testing.assert_allclose(log.columns["ApplFreqSig"], expect, atol=1e-6)
        assert log.duration_s == pytest.approx(
            pf.fcrn_steps().duration_s - 0.1 if n.test_type == "1.1" else 1650.0 - 0.1
        )


def test_unit_description_of_the_simulated_plant(programme):
    d = load_unit_description(programme / "unit.toml")
    plant = preset("paper-plant1")
    assert d.plant == plant
    pq = d.prequal
    assert pq.resource == "FCPSIM1" and pq.area == "NO5" and pq.rated_mw == 300.0
    assert pq.dp_ss_theo("Fcrn", "1.1") == pytest.approx(0.1 / (50 * 0.08) * 300)  # 7.5 MW
    assert pq.dp_ss_theo("FcrdUp", "2.1") == pytest.approx(30.0)
    assert pq.t_fme_s == plant.unit.governor.Tf and pq.H == 3.5 and pq.Kd == 0.1


def test_step_response_matches_the_analytic_model(programme):
    """The open-loop test mode: the logged power follows the plant's analytic G_pm (control error →
    ΔPm) driven by the logged applied frequency, to within the meter noise, over the whole FCR-N step
    sequence; at the end of the 5-min step the slow droop loop (τ = 114 s) has not finished."""
    import control

    from fcrlive.plant.transfer import analytic

    log = read_log(next(programme.glob("*_Fcrn_1.1_*.csv")))
    t, p, f = log.t_s, log.columns["InsAcPow"], log.columns["ApplFreqSig"]
    tfs = analytic(preset("paper-plant1"))
    _, y = control.forced_response(tfs.G_pm, t, -(f - 50.0) / 50.0)  # control error [pu] → ΔPm [pu]
    model = 225.0 + 300.0 * np.asarray(y)
    # 60-s means: the meter noise (0.3 MW std at 10 Hz) averages to 0.012 MW; the model's own error
    # (nonlinear turbine, discrete governor) is below 0.01 MW
    err = (p - model)[: t.size // 600 * 600].reshape(-1, 600).mean(axis=1)
    assert np.max(np.abs(err)) < 0.06, err
    end = p[(t > 600) & (t < 660)].mean() - p[(t > 300) & (t < 360)].mean()
    assert 6.5 < end < 7.2  # of the 7.5 MW the droop asks for


def test_bad_input_is_one_line(tmp_path, capsys):
    assert main(["simulate", "--tso-test", "fcrn-stepz", "--out-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "unknown test 'fcrn-stepz'" in err and err.count("\n") == 1
    assert main(["simulate", "--tso-test", "fcrn-steps"]) == 2
    assert "--out-dir" in capsys.readouterr().err
