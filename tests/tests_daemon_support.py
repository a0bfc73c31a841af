"""Helpers for the daemon tests: a toy plant for sim_device.SimGovernor (dynamics are not under test)."""

from __future__ import annotations

import math
from types import SimpleNamespace


class ToySimulator:
    """``dt``/``step(r)``/``reset()`` as SimGovernor expects: a 0.02 s controller with sine signals."""

    dt = 0.02

    def __init__(self):
        self.n = 0

    def reset(self):
        self.n = 0

    def step(self, r):
        self.n += 1
        t = self.n * self.dt
        f = 50.0 + 0.05 * math.sin(2 * math.pi * t / 10.0)
        return SimpleNamespace(speed_pu=f / 50.0, grid_freq_hz=f, pe_mw=80.0 - 400.0 * (f - 50.0) / 50.0,
                               pm_mw=80.0, c=0.5, a=0.5, epsilon=r)


def report(droop: float = 0.04, droop_ci95=(0.03608, 0.04392), max_abs_s: float = 1.25,
           fcrn_pass: bool = True, **fields):
    """A small IdentifyReport of the real type: droop 4 % ± 0.39 pp, max|S| 1.25 [1.2, 1.3], FCR-N."""
    from fcrlive.analysis.report import IdentifyReport, PeakCI, TsoProduct, ValueCI

    base = dict(
        method="auto", method_reason="test plug-in", samples=0, duration_s=0.0, rated_mw=100.0, f0_hz=50.0,
        kd=0.0, droop=ValueCI(value=droop, ci95=droop_ci95), g1_static=None, max_abs_g1=None,
        max_abs_s=PeakCI(value=max_abs_s, omega=0.29, ci95=(max_abs_s - 0.05, max_abs_s + 0.05)),
        gp_kind="G_p", gp=None, f=None, local=None,
        tso={"fcrn": TsoProduct(stability_threshold=0.4085, stability_margin_band=0.1,
                                stability_margin_wide=None, closed_loop_stable=None, performance_ratio=None,
                                k_red_dyn=None, k_red_dyn_min=0.9, passed=fcrn_pass)})
    return IdentifyReport(**{**base, **fields})


def fake_identify(signals, rated_mw, f0, plant=None, method="auto", **params):
    """An identification plug-in for the daemon tests: a fixed report of the window's good samples."""
    ok = signals["ok"] > 0
    t = signals["t"][ok]
    return report(method=method, samples=int(ok.sum()), duration_s=float(t[-1] - t[0]) if t.size else 0.0,
                  rated_mw=rated_mw, f0_hz=f0)
