"""End to end: the paper's plant's whole prequalification test programme simulated (``fcrlive simulate
--tso-test all``, the shortest variants: 5-min steps, no endurance, 10 min of normal operation) and
evaluated with ``fcrlive prequal DIR --json``; the verdicts agree with the plant's analytic model.

Two analytic references, each with its own reading:

- The same programme answered by the analytic transfer function of the open-loop test
  (:mod:`fcrlive.plant.transfer`: control error → ΔPm, G_pm, through the unit's swing against the grid,
  K11/(2 H s² + Kd s + K11); ρ·G_req/F_aa in the paper's terms), written as noise-free files with the same
  names and evaluated by the same command: every requirement's value must agree, and so must its verdict
  wherever the analytic value is not within that agreement of its limit. The sine tests' F(jω) must be
  the analytic F = ρ·G_req (the speed filter F_aa enters as the unit's T_FME = Tf), and ΔP_ss,theo the
  droop's (Req. 1: 0.1 Hz/(50 Hz·8 %)·300 MW = 7.5 MW; the analytic step response goes there).
- The plant's analytic F (TR eq. 9: the linearised unit, its droop in the integral channel) driven by the
  logged applied frequency and read by hand (Req. 1 from the last 60 s of each step, ΔP_7.5s and E_7.5s of
  ramp 5), and tso_checks on F at the sines' periods (Req. 8/9): within the simulation's nonlinearity and
  noise.

One simulation serves both (it was two test modules of ~40 s each).
"""

from __future__ import annotations

import json
import math
import shutil

import control
import numpy as np
import pytest

from fcrlive.analysis import tso_checks as tc
from fcrlive.cli import main
from fcrlive.plant.description import load_unit_description
from fcrlive.plant.params import preset
from fcrlive.plant.transfer import analytic, freqresp, static_gain
from fcrlive.prequal.programme import points_of
from fcrlive.sim.linear import slowest_time_constant
from fcrlive.tso.csvlog import TsoLog, read_log, write_log
from fcrlive.tso.names import parse_tso_filename

PLANT = preset("paper-plant1")
RHO = PLANT.unit.governor.droop


def _pe_model(pm0: float | None = None):
    """ΔPe [pu] per control error [pu] in the open-loop test, G_pm·K11/(2 H s² + Kd s + K11), with the
    turbine linearised at ``pm0`` [pu] (default the plant's operating point)."""
    from dataclasses import replace

    from fcrlive.plant.transfer import effective_damping

    plant = PLANT if pm0 is None else PLANT.with_unit(turbine=replace(PLANT.unit.turbine, Pm0=pm0))
    tfs = analytic(plant)
    swing = control.tf([tfs.K11], [2.0 * plant.unit.swing.H, effective_damping(plant.unit), tfs.K11])
    return tfs, control.ss(tfs.G_pm * swing)


def _pm0_at(f_hz: float) -> float:
    """The operating point [pu] the droop moves the unit to at a steady applied frequency f_hz."""
    return PLANT.unit.turbine.Pm0 + (50.0 - f_hz) / 50.0 / RHO * PLANT.unit.turbine.At


def _analytic_log(log: TsoLog, model, lead_s: float) -> TsoLog:
    """The file ``log`` answered by the analytic model: the same applied frequency (held at its first
    value for ``lead_s`` before, as the simulator settles), power P0 + rated·ΔPe, no noise."""
    t = log.t_s
    dt = float(np.median(np.diff(t)))
    f = log.columns["ApplFreqSig"]
    n_lead = round(lead_s / dt)
    eps = np.concatenate([np.full(n_lead, f[0]), f])
    eps = (50.0 - eps) / 50.0
    tt = np.arange(eps.size) * dt
    _, y = control.forced_response(model, tt, eps)
    p0 = float(log.columns["CalcBaseline"][0])
    cols = dict(log.columns)
    cols["InsAcPow"] = p0 + PLANT.unit.rated_mw * np.asarray(y)[n_lead:]
    return TsoLog.from_arrays(t, cols, log.start, period_s=log.period_s)


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory):
    sim = tmp_path_factory.mktemp("sim")
    assert main(["simulate", "--tso-test", "all", "--operation-minutes", "10", "--out-dir", str(sim)]) == 0
    ana = tmp_path_factory.mktemp("analytic")
    tfs, model = _pe_model()
    lead = 8.0 * slowest_time_constant(PLANT, open_loop=True)
    for f in sorted(sim.glob("*.csv")):
        name = parse_tso_filename(f)
        if name.test_type == "Operation":
            continue  # no analytic counterpart file: the identification is checked below
        log = read_log(f)
        m = model
        if name.period_s is not None:  # a sine around 49.7 or 50.3 Hz runs the turbine at another load
            m = _pe_model(_pm0_at(float(np.median(log.columns["ApplFreqSig"]))))[1]
        write_log(ana / f.name, _analytic_log(log, m, lead))
    shutil.copy(sim / "unit.toml", ana / "unit.toml")
    return sim, ana, tfs


@pytest.fixture(scope="module")
def docs(evaluated):
    # capsys is function-scoped: run the command with a module-level capture of stdout instead
    import contextlib
    import io

    sim, ana, tfs = evaluated
    out = {}
    for key, d in (("sim", sim), ("ana", ana)):
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            assert main(["prequal", str(d), "--json"]) == 0
        out[key] = json.loads(buf.getvalue())
    return out["sim"], out["ana"], tfs


def _tests(doc: dict) -> dict:
    return {(t["file"], t["kind"]): t for t in doc["tests"]}


# Agreement expected between the simulated (noisy, nonlinear, discrete) plant and its analytic model,
# by the unit of the requirement's value: a ratio to ΔP_ss,theo, MW, MW·s, the F-based margins.
TOL = {"": 0.02, "MW": 0.3, "MWs": 3.0, "pu": 0.03}


def test_the_programme_is_complete(docs):
    doc, _, _ = docs
    kinds = {(t["service"], t["kind"]) for t in doc["tests"]}
    for svc in ("Fcrn", "FcrdUp", "FcrdDo"):
        assert (svc, "sine-set") in kinds and (svc, "linearity") in kinds
    assert (
        ("Fcrn", "fcrn-steps") in kinds
        and ("FcrdUp", "fcrd-ramps") in kinds
        and ("FcrdDo", "fcrd-ramps") in kinds
    )
    assert ("Fcrn", "operation") in kinds
    assert set(doc["verdict"]) == {"Fcrn", "FcrdUp", "FcrdDo"}
    ids = {t["test_id"] for t in doc["tests"]}
    assert {"1.1", "2.1", "3.1", "4.1", "4.2", "4.3", "5.1", "6.1", "7.1", "Operation"} <= ids


def test_requirements_agree_with_the_analytic_plant(docs):
    doc, ana, _ = docs
    a_tests = _tests(ana)
    compared = decided = 0
    bases: set[str] = set()
    for key, t in _tests(doc).items():
        if t["kind"] == "operation":
            continue
        a = a_tests[key]
        for num, r in t["requirements"].items():
            ra = a["requirements"][num]
            if r["value"] is None or ra["value"] is None or r["comparison"] == "info":
                continue
            if num == "10":  # the fit residual over the fit: noise by definition, 0 without noise
                assert r["pass"] == ra["pass"], (t["file"], r["value"])
                continue
            if num == "11":  # the worst step: the largest |deviation|, whose sign noise may flip
                assert abs(abs(r["value"]) - abs(ra["value"])) < TOL[""] and r["pass"] == ra["pass"]
                continue
            tol = TOL.get(r["unit"], 0.02)
            assert math.isclose(r["value"], ra["value"], abs_tol=tol), (
                t["file"],
                num,
                r["value"],
                ra["value"],
            )
            compared += 1
            bases.add(num.split("-")[0])
            lim = ra["limit"]
            edges = lim if isinstance(lim, list) else [lim]
            if all(abs(ra["value"] - e) > tol for e in edges if e is not None):
                assert r["pass"] == ra["pass"], (t["file"], num, r, ra)
                decided += 1
    assert compared > 50 and decided > 45, (compared, decided)
    assert {"1", "1b", "2", "3", "4", "8", "9", "11"} <= bases, bases
    # and so the verdicts per service
    assert {s: v["status"] for s, v in doc["verdict"].items()} == {
        s: v["status"] for s, v in ana["verdict"].items()
    }


def test_sine_tests_measure_the_analytic_f(docs):
    """F(jω) of the sine sets (with F_FME = F_aa, T_FME = Tf) is the plant's ρ·G_req at the load the
    sine's centre frequency sets: within 4 of the evaluation's own standard deviations plus 2 % for
    the linearisation."""
    doc, _, _ = docs
    centre = {"Fcrn": 50.0, "FcrdUp": 49.7, "FcrdDo": 50.3}
    n = 0
    for t in doc["tests"]:
        if t["kind"] != "sine-set":
            continue
        tfs, _ = _pe_model(_pm0_at(centre[t["service"]]))
        for p in t["F"]:
            w = 2 * np.pi / p["period_s"]
            Fa = RHO * freqresp(tfs.G_req, [w])[0] / static_gain(tfs.G_t)
            F = complex(p["re"], p["im"])
            assert p["sd"] is not None and p["sd"] > 0
            assert abs(F - Fa) < 4.0 * p["sd"] + 0.02 * abs(Fa), (t["service"], p["period_s"], F, Fa, p["sd"])
            n += 1
    assert n == 3 * 10


def test_droop_and_the_steady_state(evaluated, docs):
    """Req. 1 reads ΔP_ss,theo from the droop (unit.toml), which is the analytic static response; the
    5-min FCR-N step does not reach it (the slow droop loop), the analytic step response says the same."""
    doc, _, tfs = docs
    (pt,) = points_of(PLANT)
    assert pt.dp_ss_theo_mw == {"Fcrn": 7.5, "FcrdUp": 30.0, "FcrdDo": 30.0}
    assert static_gain(tfs.G_pm) * 0.1 / 50.0 * 300.0 == pytest.approx(7.5, rel=1e-9)
    steps = next(t for t in doc["tests"] if t["kind"] == "fcrn-steps")
    assert steps["figures"]["dp_ss_theo_mw"] == pytest.approx(7.5)
    # the analytic step response after the TR's 5 min: 0.002 pu error → MW
    _, y = control.step_response(tfs.G_pm, np.linspace(0, 300, 3001))
    at_5min = 0.1 / 50.0 * 300.0 * float(y[-1])
    assert 6.8 < at_5min < 7.2
    assert steps["figures"]["dp_ss_1_mw"] == pytest.approx(at_5min, abs=0.3)
    assert steps["requirements"]["1-up"]["pass"] is (at_5min / 7.5 - 1.0 >= -0.05)


def test_operation_is_evaluated(docs):
    """Req. 8/9 from 10 min of normal operation: evaluated, and where the data decide, the decision is
    the analytic F's (from the sine sets' analytic counterpart)."""
    doc, ana, _ = docs
    op = next(t for t in doc["tests"] if t["kind"] == "operation")
    ref = next(t for t in ana["tests"] if t["kind"] == "sine-set" and t["service"] == "Fcrn")
    for num in ("8", "9"):
        assert num in op["requirements"]
        if op["requirements"][num]["pass"] is not None:
            assert op["requirements"][num]["pass"] == ref["requirements"][num]["pass"]
        else:  # undecided says why (10 min is too short for lowband: the identification's own message)
            assert op["requirements"][num]["note"], op["requirements"][num]


def _response(F, log, scale_mw):
    """The analytic power response [MW] to the logged applied frequency: scale·F∗((50 − f)/0.1)."""
    _, y = control.forced_response(F, log.t_s, (50.0 - log.columns["ApplFreqSig"]) / 0.1)
    return scale_mw * y


def test_programme_agrees_with_analytic_F(evaluated, docs):
    """Req. 1, 2, 3 against F driven by the logged applied frequency, read the evaluator's way by hand;
    Req. 8/9 and F(jω) of the FCR-N sines against tso_checks on F at the same periods."""
    sim, _, _ = evaluated
    doc, _, _ = docs
    desc = load_unit_description(sim / "unit.toml")
    F = analytic(desc.plant).F
    dn = desc.prequal.dp_ss_theo("Fcrn", "1.1")
    assert dn == pytest.approx(0.1 / 50.0 / desc.plant.unit.governor.droop * desc.plant.unit.rated_mw)

    # Req. 1 (FCR-N steps): the analytic response read the same way (last 60 s of each step)
    steps = next(t for t in doc["tests"] if t["kind"] == "fcrn-steps")
    log = read_log(next(sim.glob("*_Fcrn_1.1_*.csv")))
    y = _response(F, log, dn)
    t = log.t_s
    f = log.columns["ApplFreqSig"]
    # the plateau ends: where the applied frequency next changes
    change = np.flatnonzero(np.abs(np.diff(f)) > 0.004)
    last = [t[i] for i in change[2:]] + [t[-1]]  # ends of the 50.0, 49.9, 50.1, 50.0 Hz steps
    ss = [y[(t > e - 60.0) & (t <= e)].mean() for e in last[:4]]
    base = 0.5 * (ss[0] + ss[3])
    req = steps["requirements"]
    assert req["1-up"]["value"] == pytest.approx((ss[1] - base - dn) / dn, abs=0.01)
    assert req["1-down"]["value"] == pytest.approx((ss[2] - base + dn) / dn, abs=0.01)

    # Req. 2 and 3 (FCR-D up, ramp 5): the analytic ΔP_7.5s and E_7.5s from the same baseline window
    ramps = next(t for t in doc["tests"] if t["kind"] == "fcrd-ramps" and t["service"] == "FcrdUp")
    log = read_log(next(sim.glob("*_FcrdUp_2.1_*.csv")))
    y = _response(F, log, dn)  # one droop for FCR-N and FCR-D in the simulated governor
    t = log.t_s
    fig = ramps["figures"]
    t5 = fig["t_ramp5_s"]
    base = y[(t > t5 - 60.0) & (t <= t5)].mean()
    dp75 = float(np.interp(t5 + 7.5, t, y) - base)
    tt = np.linspace(t5, t5 + 7.5, 3001)
    e75 = np.trapezoid(np.interp(tt, t, y) - base, tt)
    assert fig["dp_7p5s_mw"] == pytest.approx(dp75, rel=0.05)
    assert fig["e_7p5s_mws"] == pytest.approx(e75, rel=0.05)
    assert ramps["requirements"]["2"]["pass"] is bool(float(dp75) >= 0.86 * fig["dp_ss_theo_mw"])

    # Req. 8 and 9 (sines): tso_checks on the analytic F at the same periods
    sset = next(t for t in doc["tests"] if t["kind"] == "sine-set" and t["service"] == "Fcrn")
    periods = np.array([p["period_s"] for p in sset["F"]])
    w = 2 * np.pi / periods
    v = tc.assess_tso_points(w, freqresp(F, w), products=("fcrn",))["fcrn"]
    req = sset["requirements"]
    assert req["8"]["value"] == pytest.approx(v.stability_margin_band, rel=0.03)
    assert req["9"]["value"] == pytest.approx(v.performance_ratio, rel=0.03)
    assert req["8"]["pass"] is bool(v.stability_margin_band >= 0.4085)
    assert req["9"]["pass"] is bool(v.performance_ratio < 1)
    for p in sset["F"]:
        Fa = freqresp(F, np.array([2 * np.pi / p["period_s"]]))[0]
        assert abs(complex(p["re"], p["im"]) - Fa) < 0.03, (p["period_s"], p, Fa)


def test_endurance_variant_keeps_its_activation(tmp_path):
    """The paper's plant in the endurance variants (15-min FCR-N steps, 900 s after FCR-D ramp 3): its
    response only rises on the long levels (slowly: the 0.2 Hz FCR-N step is at ~0.8·ΔP_ss,theo after the
    TR's 5 min), so Req. 12 ('stays activated') passes with no fall to speak of."""
    assert main(["simulate", "--tso-test", "fcrn-steps", "--tso-test", "fcrd-up-ramps", "--endurance",
                 "--out-dir", str(tmp_path)]) == 0
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["prequal", str(tmp_path), "--json"]) == 0
    doc = json.loads(buf.getvalue())
    r12 = {
        (t["kind"], k): r
        for t in doc["tests"]
        if t["figures"].get("endurance_variant") == 1.0
        for k, r in t["requirements"].items()
        if k.split("-")[0] == "12"
    }
    assert set(r12) == {  # FCR-N's plain "12" is the worse direction
        ("fcrn-steps", "12-up"),
        ("fcrn-steps", "12-down"),
        ("fcrn-steps", "12"),
        ("fcrd-ramps", "12"),
    }
    for key, r in r12.items():
        assert r["pass"] is True and -0.01 < r["value"] <= 0.0, (key, r)
    assert not any("endurance" in m for v in doc["verdict"].values() for m in v["missing"])
