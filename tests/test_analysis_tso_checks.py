"""Req. 8 / Req. 9 checks of fcrlive.analysis.tso_checks."""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive.analysis import tso_checks as tc
from fcrlive.errors import ConfigError


def one(w):
    return np.ones_like(np.asarray(w, float), dtype=complex)


def test_power_system_sets_match_table_7():
    g = tc.FCRN_STABILITY
    assert g.h_s == pytest.approx(5.2174, abs=1e-4)
    assert tc.FCRN_PERFORMANCE.h_s == pytest.approx(4.5238, abs=1e-4)
    # static gain (ΔP/Δf)(f0/Sn)/(Kf f0) = 6000·50/23000/0.5
    assert g.static_gain == pytest.approx(6000 * 50 / 23000 / 0.5)
    assert tc.FCRD_STABILITY.static_gain == pytest.approx(3625 * 50 / 23000 / 0.5)
    num, den = g.num_den
    w = np.array([0.1])
    assert g(w)[0] == pytest.approx(num[0] / (den[0] * 1j * 0.1 + den[1]))
    assert tc.PRODUCTS["fcrd"] == (tc.FCRD_STABILITY, tc.FCRD_PERFORMANCE)


def test_thresholds_and_aliases():
    assert tc.stability_threshold("fcrn") == pytest.approx(0.4085)
    assert tc.stability_threshold("fcrn", tolerance=False) == pytest.approx(0.43)
    assert tc.stability_threshold("fcrn", fcrn_exemption=True) == pytest.approx(0.3225)
    assert tc.stability_threshold("FcrdUp", fcrn_exemption=True) == pytest.approx(0.4085)
    assert tc.product_key("FCR-D down") == "fcrd"
    with pytest.raises(ConfigError):
        tc.product_key("afrr")


def test_ideal_droop_passes_both_products():
    v = tc.assess_tso(one)
    assert set(v) == {"fcrn", "fcrd"}
    for verdict in v.values():
        assert verdict.passed, verdict.reasons
        assert verdict.closed_loop_stable is True
        assert verdict.encirclements_ccw == 0
        assert verdict.k_red_dyn == 1.0
        assert verdict.performance_ratio < 1.0
        # |1 + G| ≥ 1 for a phase ≥ −90° loop; the minimum is at the top of the band / axis
        assert verdict.stability_margin_band > 1.0
        assert verdict.stability_margin_wide >= 1.0
    # F = 1: the ratio peaks at ω → 0: 0.95·G(0)/(1 + G(0))
    g0 = tc.FCRN_PERFORMANCE.static_gain
    assert v["fcrn"].performance_ratio == pytest.approx(0.95 * g0 / (1 + g0), rel=1e-4)


def test_slow_lag_fails_performance_and_needs_capacity_reduction():
    lag = tc.rational([1.0], [60.0, 1.0])
    v = tc.assess_tso(lag)
    n, d = v["fcrn"], v["fcrd"]
    assert n.performance_ratio > 1.0 and d.performance_ratio > 1.0
    assert n.k_red_dyn < 0.9 and not n.passed
    assert any("Req. 9" in r for r in n.reasons)
    assert 0.75 <= d.k_red_dyn < 1.0
    # K_red,dyn is the boundary: F/K passes, F/(K + δ) fails
    pk = tc.performance(lambda w: lag(w) / d.k_red_dyn, tc.FCRD_PERFORMANCE, (1e-4, 10.0))
    assert pk.ratio < 1.0 + 1e-3
    pk2 = tc.performance(lambda w: lag(w) / (d.k_red_dyn + 0.01), tc.FCRD_PERFORMANCE, (1e-4, 10.0))
    assert pk2.ratio > 1.0


def test_pure_delay_keeps_distance_in_band_but_encircles():
    tau = 2.0
    F = tc.delay(tau)
    G = tc.FCRN_STABILITY
    v = tc.assess_tso(F, products=("fcrn",))["fcrn"]
    assert v.stability_margin_band >= 0.43
    assert v.stability_margin_wide >= 0.43  # even over the wide band: only the winding number tells
    assert v.closed_loop_stable is False
    assert v.encirclements_ccw == -2
    assert not v.passed
    assert any("encircles" in r for r in v.reasons)
    # the crossing of the negative real axis left of −1 happens above 2π/10 rad/s
    w = np.linspace(2 * np.pi / 10, 10, 200_001)
    L = F(w) * G(w)
    cross = np.nonzero((np.sign(L.imag[:-1]) != np.sign(L.imag[1:])) & (L.real[:-1] < -1))[0]
    assert cross.size >= 1 and w[cross[0]] > 2 * np.pi / 10
    # and for ω below the band nothing comes near −1
    wl = np.logspace(-5, np.log10(2 * np.pi / 10), 20_000)
    assert np.all(np.abs(1 + F(wl) * G(wl)) >= 0.43)


def test_pure_delay_instability_confirmed_by_pade_closed_loop_poles():
    ct = pytest.importorskip("control")
    G = tc.FCRN_STABILITY
    num, den = G.num_den
    pn, pd = ct.pade(2.0, 12)
    loop = ct.tf(pn, pd) * ct.tf(num, den)
    cl = ct.feedback(loop, 1)
    assert np.max(np.real(ct.poles(cl))) > 0
    # short delay: stable both ways
    pn, pd = ct.pade(0.5, 8)
    cl = ct.feedback(ct.tf(pn, pd) * ct.tf(num, den), 1)
    assert np.max(np.real(ct.poles(cl))) < 0
    assert tc.assess_tso(tc.delay(0.5), products=("fcrn",))["fcrn"].closed_loop_stable is True


def test_encirclement_counts_open_loop_unstable_pole():
    # L = k/(s − 1): one unstable open-loop pole; closed loop stable for k > 1 (1 ccw encirclement)
    e = tc.encirclements(tc.rational([2.0], [1.0, -1.0]), 100.0)
    assert e.ccw == 1 and e.reliable
    e = tc.encirclements(tc.rational([0.5], [1.0, -1.0]), 100.0)
    assert e.ccw == 0


def test_margin_matches_closed_form():
    # F = 1: |1 + G(jω)| is smallest at the top of the band, where it has a closed form
    G = tc.FCRN_STABILITY
    w_hi = 2 * np.pi / 10
    m = tc.stability_margin(one, G, tc.band_omega())
    assert m.omega == pytest.approx(w_hi, rel=1e-6)
    assert m.margin == pytest.approx(abs(1 + G(np.array([w_hi]))[0]), rel=1e-9)
    assert m.period_s == pytest.approx(10.0, rel=1e-6)


def test_uncertainty_bounds_sd_and_samples():
    lag = tc.rational([1.0], [10.0, 1.0])
    sd = lambda w: 0.05 * np.abs(lag(w))  # noqa: E731
    v = tc.assess_tso(lag, products=("fcrn",), F_sd=sd)["fcrn"]
    assert v.stability_margin_band_lower < v.stability_margin_band
    assert v.performance_ratio_upper > v.performance_ratio
    assert v.passed_at_bound is not None
    rng = np.random.default_rng(3)
    samples = [tc.rational([g], [T, 1.0]) for g, T in zip(rng.normal(1, 0.03, 12), rng.normal(10, 0.5, 12))]
    vs = tc.assess_tso(lag, products=("fcrn",), F_samples=samples)["fcrn"]
    assert vs.closed_loop_stable_fraction == 1.0
    assert vs.extras["ratio"].shape == (12,)
    assert vs.stability_margin_band_lower <= np.max(vs.extras["margin_band"])


def test_normalise_gp_and_fme():
    gp = tc.rational([1.0 / 0.08], [2.0, 1.0])  # G_p(0) = 1/ρ
    F = tc.normalise_gp(gp, droop=0.08)
    assert F(np.array([0.0]))[0] == pytest.approx(1.0)
    F2 = tc.normalise_gp(gp, static_gain=12.5, t_fme_s=1.0)
    assert F2(np.array([1.0]))[0] == pytest.approx(F(np.array([1.0]))[0] / (1j + 1))
    with pytest.raises(ConfigError):
        tc.normalise_gp(gp, droop=0.08, static_gain=12.5)


def test_python_control_system_accepted():
    ct = pytest.importorskip("control")
    sys = ct.tf([1.0], [5.0, 1.0])
    fr = tc.as_response(sys)
    assert fr(np.array([0.2]))[0] == pytest.approx(1 / (1j + 1))
    sysd = ct.c2d(sys, 0.1)
    frd = tc.as_response(sysd)
    assert abs(frd(np.array([0.2]))[0] - 1 / (1j + 1)) < 1e-2


def test_points_assessment_matches_model_on_dense_points():
    lag = tc.rational([1.0], [3.0, 1.0])
    w = 2 * np.pi / np.array([300, 150, 90, 70, 60, 50, 40, 25, 15, 10.0])
    vp = tc.assess_tso_points(w, lag(w), products=("fcrn",))["fcrn"]
    vm = tc.assess_tso(lag, products=("fcrn",))["fcrn"]
    assert vp.closed_loop_stable is None and vp.stability_margin_wide is None
    assert vp.stability_margin_band == pytest.approx(vm.stability_margin_band, rel=0.05)
    assert vp.passed == vm.passed


def test_wide_band_margin_reported_and_selectable():
    # a 1 s delay: stable, fine in 10-300 s, but close to −1 at T ≈ 4 s (outside the tested band)
    v = tc.assess_tso(tc.delay(1.0), products=("fcrn",))["fcrn"]
    assert v.closed_loop_stable is True
    assert v.stability_margin_band > 1.0
    assert v.stability_margin_wide < 0.3
    assert v.period_stability_wide_s < 10.0
    assert v.passed  # the TR judges the tested band
    assert any("outside the tested band" in n for n in v.notes)
    vw = tc.assess_tso(tc.delay(1.0), products=("fcrn",), margin_scope="wide")["fcrn"]
    assert not vw.passed and any("Req. 8" in r for r in vw.reasons)


# --------------------------------------------------------------------------------------------------
# decision: pass / fail / undecided with the uncertainty of F


def _delayed_lag(tau: float, T: float):
    return lambda w: tc.delay(tau)(w) * tc.rational([1.0], [T, 1.0])(w)


def _rel_sd(F, s: float):
    return lambda w: s * np.abs(F(w))


def test_decision_undecided_when_the_margin_interval_straddles_the_limit():
    F = _delayed_lag(1.0, 1.0)  # FCR-D band margin 0.457 against 0.4085
    v = tc.assess_tso(F, products=("fcrd",), F_sd=_rel_sd(F, 0.1))["fcrd"]
    lo, m, hi = v.stability_margin_band_lower, v.stability_margin_band, v.stability_margin_band_upper
    assert lo < v.stability_threshold <= m < hi
    assert v.passed and v.passed_at_bound is False
    assert v.decision == "undecided"
    # the optimistic bounds sit on the other side of the point values
    assert v.performance_ratio_lower < v.performance_ratio < v.performance_ratio_upper
    assert v.k_red_dyn_lower <= v.k_red_dyn <= v.k_red_dyn_upper


def test_decision_pass_and_fail_when_the_interval_is_clear_of_the_limit():
    F = _delayed_lag(1.0, 1.0)
    v = tc.assess_tso(F, products=("fcrd",), F_sd=_rel_sd(F, 0.02))["fcrd"]
    assert v.stability_margin_band_lower >= v.stability_threshold
    assert v.decision == "pass" and v.passed_at_bound is True
    F = _delayed_lag(1.0, 3.0)  # band margin 0.234: fails
    v = tc.assess_tso(F, products=("fcrd",), F_sd=_rel_sd(F, 0.1))["fcrd"]
    assert v.stability_margin_band_upper < v.stability_threshold
    assert not v.passed and v.decision == "fail"
    # a wider interval reaching over the limit: no longer a sure fail
    v = tc.assess_tso(F, products=("fcrd",), F_sd=_rel_sd(F, 0.3))["fcrd"]
    assert v.stability_margin_band_upper >= v.stability_threshold
    assert not v.passed and v.decision == "undecided"


def test_decision_encirclement_fails_only_when_no_f_in_the_interval_reaches_minus_one():
    F = _delayed_lag(3.0, 1.0)  # band margin fine, but the Nyquist curve encircles −1
    v = tc.assess_tso(F, products=("fcrd",), F_sd=_rel_sd(F, 0.1))["fcrd"]
    # the band margin alone would leave it undecided: the encirclement decides
    assert v.closed_loop_stable is False
    assert v.stability_margin_band_lower < v.stability_threshold < v.stability_margin_band_upper
    assert v.stability_margin_wide_lower > 0
    assert v.decision == "fail"
    v = tc.assess_tso(F, products=("fcrd",), F_sd=_rel_sd(F, 0.3))["fcrd"]
    assert v.stability_margin_wide_lower < 0 and v.decision == "undecided"
    # samples: fail when every sample is unstable, undecided when some are stable
    unstable = [_delayed_lag(t, 1.0) for t in (2.9, 3.0, 3.1)]
    v = tc.assess_tso(F, products=("fcrd",), F_samples=unstable)["fcrd"]
    assert v.closed_loop_stable_fraction == 0.0 and v.decision == "fail"
    mixed = [*unstable, _delayed_lag(0.5, 1.0)]
    v = tc.assess_tso(F, products=("fcrd",), F_samples=mixed)["fcrd"]
    assert 0 < v.closed_loop_stable_fraction < 1 and v.decision == "undecided"


def test_decision_undecided_when_the_bounds_are_unknown():
    F = _delayed_lag(1.0, 1.0)
    v = tc.assess_tso(F, products=("fcrd",), F_sd=lambda w: np.full(np.shape(w), np.nan))["fcrd"]
    assert v.passed and v.passed_at_bound is None and v.decision == "undecided"


def test_decision_of_an_exact_f_is_the_point_verdict():
    v = tc.assess_tso(one)
    assert all(x.decision == "pass" and x.passed_at_bound is None for x in v.values())
    v = tc.assess_tso(_delayed_lag(1.0, 3.0), products=("fcrd",))["fcrd"]
    assert not v.passed and v.decision == "fail" and v.stability_margin_band_upper is None
    v = tc.assess_tso(_delayed_lag(3.0, 1.0), products=("fcrd",))["fcrd"]
    assert v.closed_loop_stable is False and v.decision == "fail"


@pytest.mark.parametrize("plant", ["paper-plant1", "G-classic-fwd-40Hz-poor"])
def test_margin_and_ratio_refinement_agree_with_brent(plant):
    """The nested-grid refinement (gridsearch.refined_min_grid) finds the minima Brent's search finds."""
    from fcrlive.gridsearch import log_grid, refined_min
    from fcrlive.plant import transfer as tr
    from fcrlive.plant.params import preset
    from fcrlive.sim import zoo

    pl = preset(plant) if plant.startswith("paper") else zoo.plants()[plant].plant
    F = tc.as_response(tr.analytic(pl).F)
    g_stab, g_perf = tc.PRODUCTS["fcrn"]
    for rng in (tc.band_omega(), (1e-4, 10.0)):
        m = tc.stability_margin(F, g_stab, rng)
        ref, w_ref = refined_min(lambda x: np.abs(1.0 + F(x) * g_stab(x)), log_grid(*rng, 2000))
        assert m.margin == pytest.approx(ref, rel=1e-10) and m.omega == pytest.approx(w_ref, rel=1e-6)
    p = tc.performance(F, g_perf, (1e-4, 10.0))
    neg, w_ref = refined_min(
        lambda x: -tc._ratio_fun(F(x), g_perf(x), tc.disturbance_profile(x), None, 1.0, tc.PERFORMANCE_MARGIN,
                                 0.0), log_grid(1e-4, 10.0, 3000))
    assert p.ratio == pytest.approx(-neg, rel=1e-10) and p.omega == pytest.approx(w_ref, rel=1e-6)
