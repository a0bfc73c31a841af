"""A TSO verdict with its uncertainty (tso_checks.decide) from the report to the published topics, the
text summary and the demo: ``undecided`` is published as such and does not reject the run."""

from __future__ import annotations

import json

from tests_daemon_support import report

from fcrlive.analysis.report import TsoProduct, text_summary
from fcrlive.commands.demo import result_line, summary_lines
from fcrlive.daemon.payloads import DataQuality, ResultPayload, TsoVerdictPayload, Window, result_topics
from fcrlive.daemon.result_quality import judge


def _tso(decision: str | None, passed: bool = True) -> TsoProduct:
    # FCR-D band margin 0.457 [0.258, 0.656] against 0.4085: straddles the limit
    return TsoProduct(stability_threshold=0.4085, stability_margin_band=0.457,
                      stability_margin_band_lower=0.258,
                      stability_margin_band_upper=0.656, stability_margin_wide=0.3, closed_loop_stable=True,
                      performance_ratio=0.85, performance_ratio_upper=1.03, performance_ratio_lower=0.72,
                      k_red_dyn=1.0, k_red_dyn_lower=0.29, k_red_dyn_upper=1.0, k_red_dyn_min=0.75,
                      passed=passed, passed_at_bound=False, decision=decision)


def _payload(r) -> ResultPayload:
    t = 10_000.0
    return ResultPayload(
        unit="G1", t=t, t_iso="x", window=Window.of(t - 600, t), method="auto", ok=True, error=None,
        duration_s=1.0, quality=DataQuality(ok_fraction=1.0, samples=1, expected=1, counts={"ok": 1}, gaps=0,
                                            gap_s=0.0),
        result=r, result_quality=judge(r))


def test_undecided_verdict_is_published_and_not_a_reason_to_reject():
    r = report(tso={"fcrd": _tso("undecided")})
    assert judge(r).level == "ok"
    topics = result_topics(_payload(r))
    p = topics["tso/fcrd"]
    assert isinstance(p, TsoVerdictPayload) and p.verdict == "undecided"
    assert p.details["decision"] == "undecided" and "pass" not in p.details
    assert p.details["stability_margin_band_upper"] == 0.656
    assert json.loads(p.model_dump_json())["verdict"] == "undecided"


def test_decision_wins_over_the_point_verdict_and_old_reports_keep_it():
    topics = result_topics(_payload(report(tso={"fcrd": _tso("fail", passed=False)})))
    assert topics["tso/fcrd"].verdict == "fail"
    # a report stored before the decision existed: the point verdict
    topics = result_topics(_payload(report(tso={"fcrd": _tso(None, passed=True)})))
    assert topics["tso/fcrd"].verdict == "pass"
    old = report().to_json_dict()
    assert old["tso"]["fcrn"]["decision"] is None and old["tso"]["fcrn"]["pass"] is True


def test_text_summary_and_demo_show_undecided_with_the_margin_interval():
    r = report(tso={"fcrd": _tso("undecided")})
    s = text_summary(r)
    line = next(x for x in s.splitlines() if x.strip().startswith("FCRD"))
    assert "UNDECIDED" in line and "0.457 [0.258, 0.656]" in line and "K_red,dyn 1.000 [0.290, 1.000]" in line
    assert "reaches over its limit" in s
    msg = _payload(r).model_dump(mode="json")
    assert "FCR-D UNDECIDED (min|1+FG| 0.46 [0.26, 0.66])" in result_line(1, msg, 1.0)
    msgs = [_payload(report(tso={"fcrd": _tso(d, passed=d != "fail")})).model_dump(mode="json")
            for d in ("pass", "undecided", "pass")]
    lines = summary_lines(msgs, {"droop": 0.04}, 0.0, 1.0, 1.0)
    assert any(x.strip().startswith("FCR-D") and "PASS, UNDECIDED, PASS" in x for x in lines)


def test_a_droop_from_another_method_says_so_on_every_surface():
    # a Z_cu report whose droop came from lowband (analysis.identify._droop_from_lowband)
    from fcrlive.analysis.report import ValueCI

    r = report(method="zcu").model_copy(
        update={"droop": ValueCI(value=0.045, ci95=(0.043, 0.047), method="lowband")})
    msg = _payload(r).model_dump(mode="json")
    assert "droop 4.50 [4.30, 4.70] % (from lowband)" in result_line(1, msg, 1.0)
    assert result_topics(_payload(r))["droop"].method == "lowband"
    line = next(x for x in text_summary(r).splitlines() if x.startswith("effective droop"))
    assert "(from lowband)" in line
    plain = _payload(report(method="zcu")).model_dump(mode="json")
    assert "from " not in result_line(1, plain, 1.0)
