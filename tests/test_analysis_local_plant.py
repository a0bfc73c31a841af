"""The analysis checks on the paper's plant 1 (fcrlive.plant.transfer): the reference numbers.

plant-model.md targets (Section 7.4 of the paper): G_1(0) = 0.0794, max|G_1| = 1.01, max|S| = 1.29.
"""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive.analysis import local as lc
from fcrlive.analysis import tso_checks as tc

transfer = pytest.importorskip("fcrlive.plant.transfer")
params = pytest.importorskip("fcrlive.plant.params")


@pytest.fixture(scope="module")
def plant1():
    return transfer.analytic(params.preset("paper-plant1"))


def test_local_requirements_reproduce_paper_numbers(plant1):
    S = tc.as_response(plant1.S)
    G1 = tc.as_response(plant1.G_1)
    chk = lc.check_sensitivity(S)
    assert chk.max_s == pytest.approx(1.287, abs=1e-3)
    assert chk.passed  # 1.29 < 1.5
    assert lc.peak(G1).value == pytest.approx(1.011, abs=1e-3)
    # the local loop's stability margin is 1/max|S|
    m = lc.loop_margins(lc.local_loop(plant1.G_p, plant1.G_J))
    assert m.max_sensitivity == pytest.approx(chk.max_s, rel=1e-6)
    assert m.phase_margin_deg > 0 and m.gain_margin > 1
    g10 = float(np.real(G1(np.array([0.0]))[0]))
    assert g10 == pytest.approx(0.0794, abs=1e-4)
    assert lc.effective_droop(g10, 0.1).value == pytest.approx(0.08, rel=1e-9)


def test_tso_verdict_continuous_and_digital_agree(plant1):
    vc = tc.assess_tso(plant1.F)
    Tc = plant1.discrete.Tc
    Fd = tc.normalise_gp(plant1.discrete.G_p, droop=plant1.droop)
    vd = tc.assess_tso(Fd, omega_wide=(1e-4, np.pi / Tc))
    for k in ("fcrn", "fcrd"):
        assert vc[k].closed_loop_stable and vd[k].closed_loop_stable
        assert vd[k].stability_margin_band == pytest.approx(vc[k].stability_margin_band, rel=0.01)
        assert vd[k].k_red_dyn == pytest.approx(vc[k].k_red_dyn, abs=0.01)
        assert vd[k].passed == vc[k].passed
