"""The daemon's result-quality rule: on real identification reports of short simulated windows, on
constructed reports of the real type, through the topic split, and through the worker and the store."""

from __future__ import annotations

import functools
import json
import math
import sqlite3
import time
from pathlib import Path

import numpy as np
import pytest
from tests_daemon_support import report

from fcrlive.analysis.identify import identify_signals
from fcrlive.analysis.report import IdentifyReport, PeakCI, ValueCI
from fcrlive.daemon.config import ResultQualityConfig, load_config
from fcrlive.daemon.payloads import DataQuality, ResultPayload, Window, result_topics
from fcrlive.daemon.result_quality import failed, judge
from fcrlive.daemon.store import ResultRow, SampleWriter, connect, read_results
from fcrlive.errors import ConfigError
from fcrlive.plant.params import preset
from fcrlive.sim import SimConfig, simulate
from fcrlive.tso.signals import log_from_sim, plant_signals

ROOT = Path(__file__).resolve().parents[1]
PLANT = preset("paper-plant1")
KD = 0.1
HEADLINE = {"droop", "max_abs_s", "max_abs_g1", "tso/fcrn", "tso/fcrd", "tso/fcrd_up", "tso/fcrd_down", "gp"}


@functools.cache
def _report(minutes: float, excitation: bool, seed: int) -> IdentifyReport:
    res = simulate(PLANT, SimConfig(duration_s=60 * minutes, snr_db=12.0, excitation=excitation, seed=seed))
    ps = plant_signals(log_from_sim(res), rated_mw=300.0)
    return identify_signals(ps, rated_mw=300.0, f0=50.0, kd=KD, plant=PLANT if excitation else None)


# Windows picked from a survey of 10-min windows (docs/daemon.md, "Result quality"): (minutes,
# excitation, seed)
ZCU_GOOD = (10, True, 4)
"""A good Z_cu window. (Seed 0 was, until the jackknife of G_jp widened the intervals of the peaks to what
they miss by: its max|S| interval is now 0.26× the value, above the rule's 0.25 'uncertain' limit; seed 1
until the decimation filter stopped adding its rounding noise: 0.34×.)"""
ZCU_WILD = (10, True, 3)
"""Was a wild outlier of the kind the demo showed (no droop, max|S| 5.3 in [0, 14.8]) until Z_cu took G_J
from the data sheet's H and restarted from physical denominators (issue 12); now a good window."""
ZU_WIDE = (10, False, 13)
"""Z_u: a droop with a uselessly wide interval (6.3 % in [0.7, 12.0] %). Seed 14, used before, was a wrong
basin of Z_u at 1 s (3.0 % in [0, 28] %) and is a good droop at 3 s (experiments.ZU_TS_MIN)."""
ZU_FAIR = (10, False, 4)
"""Z_u: a good droop with a wide max|G_1| (its interval holds the errors-in-variables bias bound,
analysis.quality.zu_eiv). Seed 9, used while Z_u's search landed by rounding, is now rejected: the orders
within ΔBIC 10 (experiments.ZU_ORDER_DBIC) widen its droop beyond the value."""


@pytest.fixture
def zcu_good() -> IdentifyReport:
    return _report(*ZCU_GOOD)


def _payload(result: IdentifyReport | None, verdict, error: str | None = None) -> ResultPayload:
    t = 10_000.0
    return ResultPayload(
        unit="G1", t=t, t_iso="x", window=Window.of(t - 600, t), method="auto", ok=error is None, error=error,
        duration_s=1.0, quality=DataQuality(ok_fraction=1.0, samples=1, expected=1, counts={"ok": 1}, gaps=0,
                                            gap_s=0.0),
        result=result, result_quality=verdict)


# -- real reports of short simulated windows --------------------------------------------------------

def test_good_short_zcu_window_is_ok_and_fully_published(zcu_good):
    r = zcu_good.to_json_dict()
    assert r["method"] == "zcu" and abs(r["droop"]["value"] - 0.08) < 0.002
    v = judge(zcu_good)
    assert v.level == "ok" and v.reasons == []
    assert set(v.quantities) == {"droop", "max_abs_s", "max_abs_g1"}
    topics = result_topics(_payload(zcu_good, v))
    assert {"droop", "max_abs_s", "max_abs_g1", "tso/fcrn", "gp", "result_quality"} <= set(topics)
    assert topics["droop"].quality.level == "ok" and topics["droop"].value == pytest.approx(8.0, abs=0.2)
    assert topics["result_quality"].level == "ok"


def test_rejected_short_window_keeps_the_headline_topics(zcu_good):
    # the demo's wild Z_cu window (no droop, max|S| 5.3 in [0, 14.8]) is a good one with the estimators of
    # issue 12; what it gave is rebuilt on the report type to check the rule and the topic split
    wild = _report(*ZCU_WILD)
    assert judge(wild).level in ("ok", "uncertain") and abs(wild.droop.value - 0.08) < 0.002
    rep = _with(zcu_good, droop=None, max_abs_s=PeakCI(value=5.3, omega=0.2, ci95=(0.0, 14.8)))
    v = judge(rep)
    assert v.level == "rejected"
    assert "droop: no finite value (not identifiable)" in v.reasons
    assert any(x.startswith("max_abs_s: 95 % interval") and "wide" in x for x in v.reasons)
    topics = result_topics(_payload(rep, v))
    assert not HEADLINE & set(topics)
    assert set(topics) == {"result/latest", "quality", "result_quality"}
    assert topics["result_quality"].level == "rejected" and topics["result_quality"].window_end == 10_000.0
    assert json.loads(topics["result/latest"].model_dump_json())["result_quality"]["level"] == "rejected"


def test_short_zu_window_with_a_useless_droop_interval_is_rejected():
    # the identification withholds a droop whose interval is wider than itself (analysis.quality: here
    # 6.3 % in [0.7, 12.0] %): null with the reason, and the rule rejects a run without a droop, saying why
    rep = _report(*ZU_WIDE)
    r = rep.to_json_dict()
    assert r["method"] == "zu" and r["droop"]["value"] is None and r["droop"]["ci95"] == [None, None]
    assert "wider than the value" in r["droop"]["reason"]
    assert r["not_identifiable"]["droop"] == r["droop"]["reason"]
    v = judge(rep)
    assert v.level == "rejected" and v.quantities["droop"].level == "rejected"
    assert "max_abs_s" not in v.quantities  # Z_u cannot give S: not judged, not a reason
    assert v.quantities["droop"].reasons[0].startswith("droop: no finite value (not identifiable): ")
    assert r["droop"]["reason"] in v.quantities["droop"].reasons[0]
    topics = result_topics(_payload(rep, v))
    assert not HEADLINE & set(topics)


def test_short_zu_window_with_a_wide_peak_is_uncertain_and_published_marked():
    r = _report(*ZU_FAIR)
    v = judge(r)
    assert v.level == "uncertain"
    assert v.quantities["droop"].level == "ok" and v.quantities["max_abs_g1"].level == "uncertain"
    topics = result_topics(_payload(r, v))
    assert topics["droop"].quality.level == "ok"
    assert topics["max_abs_g1"].quality.level == "uncertain"
    assert "uncertain above 0.25x" in topics["max_abs_g1"].quality.reasons[0]


@functools.cache
def _lowband_report() -> IdentifyReport:
    """20 min of normal operation identified with H known (what the daemon does with a [unit] plant):
    lowband, whose max|S| and G_p/TSO points are coherence-gated on this window."""
    res = simulate(PLANT, SimConfig(duration_s=60 * 20, snr_db=12.0, excitation=False, seed=4))
    ps = plant_signals(log_from_sim(res), rated_mw=300.0)
    return identify_signals(ps, rated_mw=300.0, f0=50.0, kd=KD, h=PLANT.unit.swing.H)


def test_not_identifiable_quantities_are_never_published_as_numbers():
    rep = _lowband_report()
    assert rep.method == "lowband" and {"max_abs_s", "gp", "tso"} <= set(rep.not_identifiable)
    assert rep.max_abs_s.value is None and rep.max_abs_s.reason == rep.not_identifiable["max_abs_s"]
    v = judge(rep)
    # not judged (the window cannot give it, as Z_u cannot give S), said why; the droop decides the run
    assert "max_abs_s" not in v.quantities and v.not_identifiable == rep.not_identifiable
    assert v.level != "rejected" and v.quantities["droop"].level == "ok"
    topics = result_topics(_payload(rep, v))
    assert "max_abs_s" not in topics and "gp" not in topics
    assert topics["droop"].value == pytest.approx(8.0, abs=0.3) and topics["droop"].reason is None
    assert topics["result_quality"].not_identifiable["max_abs_s"].startswith("not identifiable")
    for k in ("fcrn", "fcrd"):
        assert topics[f"tso/{k}"].verdict == "unknown"
        assert topics[f"tso/{k}"].details["reason"] == rep.not_identifiable["tso"]
    # a reason on the quantity alone is enough to keep it off its topic
    rep2 = _with(rep, not_identifiable={k: x for k, x in rep.not_identifiable.items() if k != "max_abs_s"})
    assert "max_abs_s" not in result_topics(_payload(rep2, judge(rep2)))
    # a null droop with a reason: rejected, and the reason is in the verdict
    why = "droop not identifiable: the test says why"
    v3 = judge(_with(rep, droop=ValueCI(value=None, ci95=(None, None), reason=why)))
    assert v3.level == "rejected" and any(why in x for x in v3.reasons)


def test_thresholds_come_from_the_configuration():
    r = _report(*ZU_FAIR)
    assert judge(r, ResultQualityConfig(uncertain_ci_rel_width=1.0)).level == "ok"
    assert judge(r, ResultQualityConfig(droop_min_pct=9.0, droop_max_pct=20.0)).level == "rejected"
    # a report of the real type with a droop 2.8x as wide as itself (what Z_u gave on ZU_WIDE before the
    # identification withheld such numbers itself; a plug-in's report is judged as it comes)
    wide = _with(r, droop=ValueCI(value=0.06, ci95=(0.0, 0.168)))
    assert judge(wide).level == "rejected"
    assert judge(wide, ResultQualityConfig(reject_ci_rel_width=10.0)).level == "uncertain"


# -- constructed reports of the real type -----------------------------------------------------------

def _with(rep: IdentifyReport, **kw) -> IdentifyReport:
    return rep.model_copy(update=kw)


@pytest.mark.parametrize(("droop", "level", "reason"), [
    (ValueCI(value=0.08, ci95=[0.079, 0.081]), "ok", None),
    (ValueCI(value=0.31, ci95=[None, None]), "rejected", "droop: no finite 95 % interval"),  # NaN → null
    (ValueCI(value=0.25, ci95=[0.249, 0.251]), "rejected", "droop: 25 % outside the plausible 1-20 %"),
    (ValueCI(value=0.004, ci95=[0.0039, 0.0041]), "rejected", "droop: 0.4 % outside the plausible 1-20 %"),
    (ValueCI(value=0.08, ci95=[0.081, 0.079]), "rejected", "droop: 95 % interval [8.1, 7.9] % inverted"),
    (ValueCI(value=0.08, ci95=[0.09, 0.1]), "rejected", "droop: 8 % outside its own 95 % interval"),
    (ValueCI(value=0.08, ci95=[0.07, 0.095]), "uncertain", "droop: 95 % interval [7, 9.5] % is 0.312x"),
    (ValueCI(value=0.08, ci95=[0.08, 0.08]), "uncertain", "has zero width"),
    (ValueCI(value=None, ci95=[None, None]), "rejected", "droop: no finite value"),
])
def test_droop_cases_on_constructed_reports(zcu_good, droop, level, reason):
    v = judge(_with(zcu_good, droop=droop))
    assert v.quantities["droop"].level == level and v.level == level
    if reason:
        assert any(reason in x for x in v.reasons), v.reasons


def test_a_bad_peak_rejects_the_whole_run(zcu_good):
    bad = PeakCI(value=1.3, omega=0.29, ci95=[None, None])
    v = judge(_with(zcu_good, max_abs_s=bad))
    assert v.level == "rejected" and v.quantities["droop"].level == "ok"
    assert v.reasons == ["max_abs_s: no finite 95 % interval"]
    assert not HEADLINE & set(result_topics(_payload(_with(zcu_good, max_abs_s=bad), v)))


def test_plugin_reports_and_nan_intervals():
    """A plug-in returns the report type (nothing else crosses the worker); a NaN (unknown) interval
    is never ok."""
    from fcrlive.daemon.worker import run_job

    assert judge(report()).level == "ok"  # 4 % in [3.61, 4.39] %
    v = judge(report(droop_ci95=(math.nan, math.nan)))
    assert v.level == "rejected" and v.reasons == ["droop: no finite 95 % interval"]
    v = judge(report(droop_ci95=(0.0204, 0.0596)))  # ±1.96 of 4: 0.98x wide
    assert v.level == "uncertain"
    assert judge(report(droop=0.35, droop_ci95=(0.349, 0.351))).level == "rejected"  # range
    assert failed("too little good data").model_dump() == {
        "level": "rejected", "reasons": ["too little good data"], "quantities": {}, "not_identifiable": {}}
    sig = {"t": np.arange(3.0), "ok": np.ones(3)}
    with pytest.raises(TypeError, match="returned dict, expected an IdentifyReport"):
        run_job(_dict_plugin, sig, 100.0, 50.0, None, "auto")


def _dict_plugin(signals, rated_mw, f0, **_):
    return {"droop": {"value": 4.0, "std": 0.2, "unit": "%"}}


def test_unjudged_results_publish_as_before():
    topics = result_topics(_payload(report(), None))
    assert "result_quality" not in topics and topics["droop"].quality is None


def test_configuration_checks_the_thresholds(tmp_path):
    base = {"source": {"kind": "modbus", "modbus": {"register_map": str(ROOT / "sim_device/registers.toml")}}}
    cfg = load_config(ROOT / "deploy" / "fcrlive.toml")
    assert cfg.identification.result_quality == ResultQualityConfig()
    with pytest.raises(ConfigError, match="droop_min_pct must be below droop_max_pct"):
        load_config(None, unit={"name": "G1", "rated_mw": 100.0}, **base,
                    identification={"result_quality": {"droop_min_pct": 20.0, "droop_max_pct": 5.0}})
    with pytest.raises(ConfigError, match=r"identification\.result_quality\.bogus"):
        load_config(None, unit={"name": "G1", "rated_mw": 100.0}, **base,
                    identification={"result_quality": {"bogus": 1}})


# -- the store ----------------------------------------------------------------------------------------

def test_store_keeps_the_verdict_and_upgrades_an_old_store(tmp_path):
    db = tmp_path / "old.sqlite"
    con = sqlite3.connect(db)  # a store written before the rule existed
    con.execute("CREATE TABLE results(id INTEGER PRIMARY KEY, t REAL NOT NULL, t1 REAL NOT NULL,"
                " t2 REAL NOT NULL, method TEXT, ok_fraction REAL, quality TEXT, result TEXT,"
                " duration_s REAL, error TEXT)")
    con.execute("INSERT INTO results(t, t1, t2, quality) VALUES (1, 0, 1, '{}')")
    con.commit()
    con.close()
    assert read_results(connect(db, readonly=True))[0].result_quality is None
    verdict = judge(report(droop=0.35, droop_ci95=(0.349, 0.351)))
    with SampleWriter(db, ("power",)) as w:
        w.add_result(ResultRow(t=2.0, t1=1.0, t2=2.0, method="auto", ok_fraction=1.0, quality={},
                               result={"droop": 35.0}, duration_s=0.1, result_quality=verdict.model_dump()))
        assert w.flush()
    new, old = read_results(connect(db, readonly=True))
    assert old.result_quality is None
    assert new.result == {"droop": 35.0} and new.result_quality["level"] == "rejected"
    assert new.result_quality["reasons"] == ["droop: 35 % outside the plausible 1-20 %"]


# -- through the worker process, the store and the publisher --------------------------------------------

SIG = ("device_time", "speed", "power", "controller_output", "guide_vane")


class _Recorder:
    def __init__(self):
        self.sent: list[tuple[str, object]] = []

    def publish(self, topic, payload):
        self.sent.append((topic, payload))


async def test_worker_path_stores_and_publishes_a_rejected_short_window(tmp_path):
    """10 simulated minutes without excitation (Z_u, ZU_WIDE) in the store, identified by the default
    plug-in in the worker process: stored with its verdict, headline topics not published."""
    from fcrlive.daemon.sample import Quality, Sample
    from fcrlive.daemon.service import Service
    from fcrlive.daemon.worker import IdentificationWorker

    res = simulate(PLANT, SimConfig(duration_s=600, snr_db=12.0, excitation=False, seed=ZU_WIDE[2]))
    t0 = time.time() - 620
    db = tmp_path / "s.sqlite"

    def service(rule: dict) -> Service:
        cfg = load_config(
            None, unit={"name": "G1", "rated_mw": res.rated_mw, "f0": res.f0, "kd": KD},
            source={"kind": "modbus", "modbus": {"register_map": str(ROOT / "sim_device/registers.toml")}},
            store={"path": str(db)}, mqtt={"enabled": False}, metrics={"enabled": False},
            identification={"window_min": 11.0, "min_ok_fraction": 0.0, "result_quality": rule})
        svc = Service(cfg)
        svc.signals = SIG  # the store holds only the signals the plug-in needs
        svc.publisher = _Recorder()
        return svc

    strict, relaxed = service({}), service({"reject_ci_rel_width": 10.0})
    writer = SampleWriter(db, SIG).open()
    for i, (t, y, p, c, a) in enumerate(zip(res.t, res.y, res.pe_mw, res.c, res.a)):
        values = {"device_time": float(t), "speed": 1.0 + float(y), "power": float(p),
                  "controller_output": 100.0 * float(c), "guide_vane": 100.0 * float(a)}
        writer.add(Sample(t0 + float(t), float(t), i, values, Quality.OK))
    assert writer.flush(30)
    strict.writer = relaxed.writer = writer
    try:
        async with IdentificationWorker(strict.identify, timeout_s=120) as worker:
            out = await strict.identify_once(worker)
            out2 = await relaxed.identify_once(worker)
        assert writer.flush(10)
    finally:
        writer.close()

    assert out.ok and out.result.method == "zu"
    assert out.result_quality.level == "rejected"
    assert out.result_quality.quantities["droop"].level == "rejected"
    sent = dict(strict.publisher.sent)
    assert set(sent) == {"result/latest", "quality", "result_quality"}
    assert sent["result_quality"].reasons == out.result_quality.reasons
    assert strict.metrics.result_levels.labels("rejected")._value.get() == 1
    assert strict.metrics.last_result_time._value.get() == 0  # no accepted result yet

    # a rule that would tolerate a wider interval cannot bring the droop back: the identification itself
    # withheld it (analysis.quality: 3.0 % in [0, 28] %), so the run is rejected under either rule, saying why
    assert out.result.droop.value is None and "wider than the value" in out.result.droop.reason
    assert out2.result_quality.level == "rejected"
    assert out2.result_quality.reasons == out.result_quality.reasons
    assert not HEADLINE & set(dict(relaxed.publisher.sent))

    stored = read_results(connect(db, readonly=True))
    assert [r.result_quality["level"] for r in stored] == ["rejected", "rejected"]
    assert stored[1].result["droop"] == out.result.droop.model_dump(mode="json")  # null with its reason
    assert stored[1].result_quality["reasons"] == out.result_quality.reasons
