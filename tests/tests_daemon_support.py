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


def fake_identify(signals, rated_mw, f0, plant=None, method="auto", **params):
    """An identification plug-in for the daemon tests: summary numbers, in the plug-in JSON shape."""
    import numpy as np

    ok = signals["ok"] > 0
    p = signals["power"][ok]
    return {"droop": {"value": 4.0, "std": 0.2, "unit": "%"}, "max_abs_s": 1.25,
            "tso": {"fcrn": {"passed": True, "margin": 0.1}},
            "n_ok": int(ok.sum()), "power_mean": float(np.mean(p)) if p.size else None,
            "rated_mw": rated_mw, "f0": f0, "method": method}
