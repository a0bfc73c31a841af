"""Each plot function of fcrlive.analysis.plots writes a non-empty PNG."""

from __future__ import annotations

import numpy as np

from fcrlive.analysis import plots
from fcrlive.analysis import tso_checks as tc

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _is_png(path) -> bool:
    data = path.read_bytes()
    return len(data) > 2000 and data[:8] == PNG_MAGIC


def test_bode_png_with_band_and_points(tmp_path):
    lag = tc.rational([1.0], [5.0, 1.0])
    w = 2 * np.pi / np.array([300.0, 60.0, 10.0])
    out = plots.plot_bode(
        tmp_path / "sub" / "bode.png",
        [("F", lag), ("F·FME", tc.normalise_gp(lag, static_gain=1.0, t_fme_s=1.0))],
        sd={"F": lambda x: 0.05 * np.abs(lag(x))},
        points=[("sine tests", w, lag(w), 0.02 * np.ones(3))],
        x_axis="period",
        title="test",
    )
    assert out.exists() and _is_png(out)
    out2 = plots.plot_bode(tmp_path / "bode_w.png", [("F", lag)])
    assert _is_png(out2)


def test_nyquist_png(tmp_path):
    out = plots.plot_nyquist(
        tmp_path / "nyq.png",
        tc.delay(2.0),
        tc.FCRN_STABILITY,
        points=(np.array([0.1, 0.3]), np.exp(-2j * np.array([0.1, 0.3]))),
    )
    assert _is_png(out)


def test_performance_png(tmp_path):
    lag = tc.rational([1.0], [60.0, 1.0])
    k = tc.assess_tso(lag, products=("fcrd",))["fcrd"].k_red_dyn
    out = plots.plot_performance(tmp_path / "req9.png", lag, tc.FCRD_PERFORMANCE, k_red_dyn=k)
    assert _is_png(out)
