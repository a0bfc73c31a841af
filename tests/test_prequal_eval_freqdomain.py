"""Frequency-domain prequalification with exact answers: sine files of a known F(jω) (Req. 8, 9, 10,
the 0.43·0.95 margin and the FCR-N 75 % exemption), and Req. 8/9 from normal operation computed from
an exactly known G_1 (the conversion G_p = 1/G_1 − (2Hs + Kd))."""

from __future__ import annotations

import numpy as np
import pytest
from test_prequal_eval_support import write

from fcrlive.analysis import tso_checks as tc
from fcrlive.constants import TSO_PERIODS_S, TSO_STATIONARY_PERIODS
from fcrlive.plant.description import unit_description_from_dict
from fcrlive.prequal import freqdomain
from fcrlive.prequal.common import Context
from fcrlive.prequal.evaluate import evaluate_logs
from fcrlive.prequal.model import document_spec
from fcrlive.tso.csvlog import read_log

P0, D = 150.0, 7.5
DT = 0.2


def F_true(w, T=2.0, tau=0.8):
    return np.exp(-1j * w * tau) / (1 + 1j * w * T)


def _unit(exemption=False):
    d = {
        "unit": {
            "rated_mw": 300.0,
            "prequal": {
                "resource": "TESTU1",
                "area": "NO5",
                "fcrn_exemption": exemption,
                "points": [{"load": "high", "droop_level": "high", "droop": 0.08}],
            },
        }
    }
    return unit_description_from_dict(d).prequal


def _sine_file(folder, period, F, *, service="Fcrn", harmonic=0.0, centre=50.0, style="id"):
    n = TSO_STATIONARY_PERIODS[period] + 1
    t = np.arange(0.0, n * period, DT)
    w = 2 * np.pi / period
    f = centre + 0.1 * np.sin(w * t)
    # control error e = −0.1 sin(ωt); ΔP = (ΔP_ss,theo/Δf_band)·F·e as a phasor
    band = 0.1 if service == "Fcrn" else 0.4
    amp = D / band * abs(F) * 0.1
    # the harmonic is a cosine from the start of the stationary window: orthogonal there to the offset,
    # the trend and the fundamental, so the fit leaves it whole in the residual
    a = t[-1] - TSO_STATIONARY_PERIODS[period] * period
    p = P0 - amp * np.sin(w * t + np.angle(F)) + harmonic * amp * np.cos(2 * w * (t - a))
    tid = {"Fcrn": "4.1", "FcrdUp": "4.2", "FcrdDo": "4.3"}[service]
    test_type = f"{tid}-{period:g}" if style == "id" else f"Sine{period:g}"
    return write(
        folder,
        service,
        test_type,
        t,
        {"InsAcPow": p, "ApplFreqSig": f, "GridFreq": np.full(t.size, 50.0)},
        period=period,
        dt=DT,
    )


def test_sine_file_gives_F_and_req10_exactly(tmp_path):
    unit = _unit()
    period = 40.0
    F = F_true(2 * np.pi / period)
    path = _sine_file(tmp_path, period, F)
    res = evaluate_logs([read_log(path, required=("InsAcPow",))], unit)
    ev = next(e for e in res.tests if e.kind == "sine")
    assert ev.test_id == "4.1" and ev.figures["period_s"] == 40.0
    (pt,) = ev.points
    assert abs(pt.F - F) < 1e-6  # the LS fit of an exact sine (6 decimals in the file)
    assert ev.requirements["10"].value == pytest.approx(0.0, abs=1e-6) and ev.requirements["10"].passed


def test_sine_harmonic_fails_req10_by_known_margin(tmp_path):
    # a second harmonic of 1.2 times the fundamental: rms(P − P_fit)/std(P_sine) = 1.2, up to the one
    # sample beyond whole periods in the stationary window (O(1/N), N = 625)
    unit = _unit()
    path = _sine_file(tmp_path, 25.0, F_true(2 * np.pi / 25.0), harmonic=1.2, style="sine")
    ev = next(
        e for e in evaluate_logs([read_log(path, required=("InsAcPow",))], unit).tests if e.kind == "sine"
    )
    r = ev.requirements["10"]
    assert r.value == pytest.approx(1.2, rel=2e-3) and r.passed is False and r.limit == 1.0


@pytest.mark.parametrize("exemption", [False, True])
def test_sine_set_req8_margin_tolerance_and_exemption(tmp_path, exemption):
    unit = _unit(exemption)
    paths = [_sine_file(tmp_path, T, F_true(2 * np.pi / T)) for T in TSO_PERIODS_S]
    res = evaluate_logs([read_log(p, required=("InsAcPow",)) for p in paths], unit)
    (ss,) = [e for e in res.tests if e.kind == "sine-set"]
    assert len(ss.points) == 10 and len(ss.files) == 10
    # by hand: for this F the smallest |1 + F·G_stab| is at the 10 s point itself
    w10 = 2 * np.pi / 10.0
    by_hand = abs(1 + F_true(w10) * tc.FCRN_STABILITY(w10))
    r8 = ss.requirements["8"]
    assert r8.value == pytest.approx(by_hand, abs=1e-5)
    assert 0.43 * 0.75 < by_hand < 0.43 * 0.95  # the case: between the exemption and the 95 % margin
    assert r8.passed is exemption
    assert r8.limit == pytest.approx(0.43 * (0.75 if exemption else 0.95))
    assert ss.figures["stability_limit_nominal"] == 0.43
    assert ss.figures["stability_limit_tolerance"] == pytest.approx(0.4085)
    assert ss.figures["stability_limit_exemption"] == pytest.approx(0.3225)
    assert ("exemption" in r8.note) and ("0.4085" in r8.note)
    # Req. 9 as tso_checks gives it on the exact points
    v = tc.assess_tso_points(
        2 * np.pi / np.array(TSO_PERIODS_S), F_true(2 * np.pi / np.array(TSO_PERIODS_S)), products=("fcrn",)
    )["fcrn"]
    assert ss.requirements["9"].value == pytest.approx(v.performance_ratio, rel=1e-5)
    assert ss.requirements["9"].passed is True
    assert not any("sine test" in m for m in res.verdict["Fcrn"].missing)


def test_sine_set_reports_missing_periods(tmp_path):
    unit = _unit()
    paths = [_sine_file(tmp_path, T, F_true(2 * np.pi / T)) for T in (40.0, 60.0, 90.0)]
    res = evaluate_logs([read_log(p, required=("InsAcPow",)) for p in paths], unit)
    assert any("sine test periods 10, 15, 25, 50, 70, 150, 300 s" in m for m in res.verdict["Fcrn"].missing)


# --------------------------------------------------------------------------------------------------
# Normal operation: F from G_1


class _ExactG1:
    """An identification result whose G_1 is known exactly (a first-order governor on the paper's swing
    equation), standing in for the identification so that the conversion can be checked by hand."""

    def __init__(self, H, Kd, droop, Tg, rel_sd, direct=False, not_identifiable=None):
        """``direct``: G_p fitted itself (as lowband gives it), with a report carrying
        ``not_identifiable``."""
        from types import SimpleNamespace

        self.H, self.Kd, self.droop, self.Tg, self.rel_sd = H, Kd, droop, Tg, rel_sd
        self.direct = direct

        class _A:
            pass

        self.assessment = _A()
        self.assessment.responses = self._responses
        self.assessment.droop = None
        self.report = None
        if direct:
            self.report = SimpleNamespace(method="lowband", warnings=[], identification_ts_s=None,
                                          not_identifiable=dict(not_identifiable or {}))

    def gp(self, w):
        return (1 / self.droop) / (1 + 1j * w * self.Tg)

    def g1(self, w):
        return 1.0 / (self.gp(w) + 2 * self.H * 1j * w + self.Kd)

    def _responses(self, w):
        from fcrlive.ident.freqresp import FreqResp

        w = np.asarray(w, float)
        out = {}
        for key, g in (("G_1", self.g1(w)), *((("G_p", self.gp(w)),) if self.direct else ())):
            # a FreqResp with one parameter whose unit variance gives sd = rel_sd·|G| on each axis
            jac = (self.rel_sd * (g.real + 1j * g.imag)).reshape(-1, 1)
            out[key] = FreqResp(w, g, jac, (("theta", np.eye(1)),))
        return out


def _operation_context(H: float, Kd: float, droop: float) -> Context:
    """FCR-N operation log of a 300 MW unit whose ΔP_ss,theo follows from its droop (0.1 Hz band)."""
    return Context(
        document=document_spec("nordic-2025"),
        service="Fcrn",
        test_id="Operation",
        file="op.csv",
        dp_theo=0.1 / 50.0 / droop * 300.0,
        rated_mw=300.0,
        H=H,
        Kd=Kd,
    )


def test_operation_F_from_G1_exact():
    H, Kd, droop = 3.5, 0.1, 0.08
    ident = _ExactG1(H, Kd, droop, Tg=3.0, rel_sd=1e-6)
    ctx = _operation_context(H, Kd, droop)
    t = np.arange(0, 3600.0, 0.1)
    ev = freqdomain.evaluate_operation(
        t, np.full(t.size, 50.0), np.full(t.size, P0), ctx, ident, sample_s=0.1
    )
    # F = (P_rated/f0)(Δf_band/ΔP_ss,theo)·G_p = ρ·G_p = 1/(1 + 3 s)
    w = 2 * np.pi / np.array(TSO_PERIODS_S)
    F_exact = 1 / (1 + 1j * w * 3.0)
    got = np.array([p.F for p in ev.points])
    np.testing.assert_allclose(got, F_exact, rtol=1e-9, atol=1e-9)
    v = tc.assess_tso(lambda x: 1 / (1 + 1j * x * 3.0), products=("fcrn",), omega_wide=(1e-4, 1.0))["fcrn"]
    assert ev.requirements["8"].value == pytest.approx(v.stability_margin_band, rel=1e-6)
    assert ev.requirements["9"].value == pytest.approx(v.performance_ratio, rel=1e-6)
    assert ev.requirements["8"].passed is True and ev.requirements["8"].value_interval is not None


def test_operation_uncertain_verdict_is_undecided_and_slow_log_withheld():
    H, Kd, droop = 3.5, 0.1, 0.08
    ctx = _operation_context(H, Kd, droop)
    t = np.arange(0, 600.0, 1.0)
    # a sd of G_1 large enough that the 95 % interval of the Req. 9 ratio straddles 1 … (3 s governor: 0.5)
    wide = _ExactG1(H, Kd, droop, Tg=3.0, rel_sd=0.5)
    ev = freqdomain.evaluate_operation(t, np.full(t.size, 50.0), np.full(t.size, P0), ctx, wide, sample_s=0.1)
    r8 = ev.requirements["8"]
    lo, hi = r8.value_interval
    assert lo < r8.limit < hi and r8.passed is None and "undecided" in r8.note
    # … and a precise one from a 1 s log: figures kept, verdict withheld
    sharp = _ExactG1(H, Kd, droop, Tg=3.0, rel_sd=1e-6)
    ev2 = freqdomain.evaluate_operation(
        t, np.full(t.size, 50.0), np.full(t.size, P0), ctx, sharp, sample_s=1.0
    )
    assert ev2.requirements["8"].passed is None and "aliased" in ev2.requirements["8"].note
    assert ev2.requirements["8"].value == pytest.approx(ev.requirements["8"].value, rel=1e-9)
    # a G_p the identification fitted itself (lowband: 1-s block means and an anti-aliasing filter before
    # its fit) is read directly and not withheld for the log's rate; uncertain, it is undecided all the same
    wide_gp = _ExactG1(H, Kd, droop, Tg=3.0, rel_sd=0.5, direct=True)
    ev3 = freqdomain.evaluate_operation(
        t, np.full(t.size, 50.0), np.full(t.size, P0), ctx, wide_gp, sample_s=1.0
    )
    r8 = ev3.requirements["8"]
    lo, hi = r8.value_interval
    assert lo < r8.limit < hi and r8.passed is None and "undecided" in r8.note and "aliased" not in r8.note
    sharp_gp = _ExactG1(H, Kd, droop, Tg=3.0, rel_sd=1e-6, direct=True)
    ev4 = freqdomain.evaluate_operation(
        t, np.full(t.size, 50.0), np.full(t.size, P0), ctx, sharp_gp, sample_s=1.0
    )
    assert ev4.requirements["8"].passed is True and ev4.requirements["9"].passed is not None
    assert ev4.requirements["8"].value == pytest.approx(ev.requirements["8"].value, rel=1e-6)
    # G_p the identification says the log cannot give (coherence-gated): undecided with its reason, no number
    why = "not identifiable from this log: u-ε coherence 0.21 at ω = 0.1 rad/s (needs ≥ 0.6)"
    gated = _ExactG1(H, Kd, droop, Tg=3.0, rel_sd=1e-6, direct=True, not_identifiable={"gp": why, "tso": why})
    ev5 = freqdomain.evaluate_operation(
        t, np.full(t.size, 50.0), np.full(t.size, P0), ctx, gated, sample_s=0.1
    )
    for k in ("8", "9"):
        r = ev5.requirements[k]
        assert r.passed is None and r.value is None and why in r.note and "lowband" in r.note
    assert ev5.points == ()


def test_fcrd_sine_set_periods_and_shared_direction(tmp_path):
    # FCR-D without mode shifting needs 10-70 s (TR Table 6 **); one FCR-D sine set answers both
    # directions (Table 2 *)
    unit = _unit()
    periods = [p for p in TSO_PERIODS_S if p <= 70.0]
    paths = [_sine_file(tmp_path, T, F_true(2 * np.pi / T), service="FcrdUp", centre=49.7) for T in periods]
    res = evaluate_logs([read_log(p, required=("InsAcPow",)) for p in paths], unit)
    (ss,) = [e for e in res.tests if e.kind == "sine-set"]
    assert ss.service == "FcrdUp" and ss.test_id == "4.2"
    for s in ("FcrdUp", "FcrdDo"):
        assert not any("sine" in m for m in res.verdict[s].missing), res.verdict[s].missing
    assert res.capacity["FcrdDo"].k_red_dyn == pytest.approx(ss.figures["k_red_dyn"])
