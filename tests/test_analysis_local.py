"""Local requirements, loop margins and droop helpers of fcrlive.analysis.local."""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive.analysis import local as lc
from fcrlive.analysis import tso_checks as tc
from fcrlive.errors import ConfigError

ct = pytest.importorskip("control")


@pytest.mark.parametrize(
    "num,den",
    [
        ([4.0], [1.0, 3.0, 3.0, 1.0]),  # GM 2, PM 27.1°
        ([2.0], [0.5, 1.5, 1.0, 0.0]),  # integrator
        ([3.0, 1.0], [1.0, 2.0, 2.0, 1.0]),  # no phase crossover
    ],
)
def test_margins_match_python_control(num, den):
    sys = ct.tf(num, den)
    gm, pm, sm, wpc, wgc, wms = ct.stability_margins(sys)
    m = lc.loop_margins(tc.as_response(sys))
    assert m.gain_margin == pytest.approx(gm, rel=1e-6)
    assert m.phase_margin_deg == pytest.approx(pm, abs=1e-4)
    assert m.stability_margin == pytest.approx(sm, rel=1e-6)
    assert m.omega_gain_crossover == pytest.approx(wgc, rel=1e-6)
    if np.isfinite(gm):
        assert m.omega_phase_crossover == pytest.approx(wpc, rel=1e-6)
    assert m.omega_stability_margin == pytest.approx(wms, rel=1e-4)
    assert m.max_sensitivity == pytest.approx(1 / sm, rel=1e-6)


def test_sensitivity_check_and_peak():
    # L = G_p G_J with a first-order G_p and the paper's swing (max|S| ≈ 1.70): peak vs brute force
    Gp = tc.rational([12.5], [1.0, 1.0])
    GJ = lc.swing(3.5, 0.1)
    S = lc.sensitivity(Gp, GJ)
    w = np.logspace(-4, 1, 200_000)
    brute = np.max(np.abs(S(w)))
    chk = lc.check_sensitivity(S)
    assert chk.max_s == pytest.approx(brute, rel=1e-6)
    assert chk.passed == (brute < 1.5)
    assert lc.check_sensitivity(S, ms=brute * 0.99).passed is False
    m = lc.loop_margins(lc.local_loop(Gp, GJ))
    assert m.max_sensitivity == pytest.approx(brute, rel=1e-6)
    up = lc.check_sensitivity(S, S_sd=lambda x: 0.01 * np.ones_like(x)).max_s_upper
    assert up == pytest.approx(brute + 1.96 * 0.01, rel=1e-3)


def test_disturbance_rejection_white_and_integrated():
    Gp = tc.rational([12.5], [1.0, 1.0])
    GJ = lc.swing(3.5, 0.1)
    G1 = lc.disturbance_rejection(Gp, GJ)
    peak = lc.peak(G1).value
    chk = lc.check_disturbance_rejection(G1)
    assert chk.passed is None
    assert chk.gain_sq_shape_max == pytest.approx(peak**2, rel=1e-6)
    assert chk.sigma_req == pytest.approx(0.1 / 150)
    lam = chk.admissible_level
    assert lc.check_disturbance_rejection(G1, level=0.9 * lam).passed is True
    assert lc.check_disturbance_rejection(G1, level=1.1 * lam).passed is False
    integ = lc.check_disturbance_rejection(G1, spectrum="integrated", omega_range=(2 * np.pi / 1800, 10.0))
    assert integ.worst_omega == pytest.approx(2 * np.pi / 1800, rel=1e-3)  # the low end decides
    with pytest.raises(ConfigError):
        lc.spectrum_shape("pink")


def test_g1_static_gain_gives_droop():
    # G_1(0) = 1/(Kd + Gt(0)/ρ) for the paper's plant 1: 0.0794 → ρ_eff = 0.08
    rho, kd = 0.08, 0.1
    Gp = tc.rational([1.0 / rho], [0.5, 1.0])
    G1 = lc.disturbance_rejection(Gp, lc.swing(3.5, kd))
    g10 = G1(np.array([0.0]))[0].real
    assert g10 == pytest.approx(1 / (kd + 1 / rho))
    d = lc.effective_droop(g10, kd)
    assert d.value == pytest.approx(rho)
    assert d.reserve_pu_per_pu == pytest.approx(1 / rho)


def test_effective_droop_interval():
    g, sd, kd = 0.0794, 0.002, 0.1
    d = lc.effective_droop(g, kd, sd=sd)
    f = lc.effective_droop_from_g1
    assert d.lower == pytest.approx(f(g - 1.959963984540054 * sd, kd))
    assert d.upper == pytest.approx(f(g + 1.959963984540054 * sd, kd))
    assert d.lower < d.value < d.upper
    assert d.sd == pytest.approx(sd / (1 - kd * g) ** 2)
    d2 = lc.effective_droop(g, kd, ci=(0.08, 0.078))
    assert (d2.lower, d2.upper) == (pytest.approx(f(0.078, kd)), pytest.approx(f(0.08, kd)))
    assert f(20.0, kd) == float("inf")
    with pytest.raises(ConfigError):
        lc.effective_droop(-1.0, kd)
