"""Synthetic TSO test files with exactly known responses, for the prequalification tests.

The applied frequency is piecewise linear (the TR profiles); the power is the TR's ideal static
response put through an EXACT first-order lag: for a piecewise-linear input u(t) = Σ Δk_i (t − τ_i)_+
the lagged output is y(t) = Σ Δk_i r(t − τ_i) with r(s) = s − T(1 − e^{−s/T}) (s > 0), and its integral
Σ Δk_i R(·) with R(s) = s²/2 − T s + T²(1 − e^{−s/T}). Every figure of a test is computed from these
closed forms here, independently of the evaluation code.
"""

from __future__ import annotations

import math
from datetime import datetime, timedelta

import numpy as np

from fcrlive.tso.csvlog import TsoLog, write_log
from fcrlive.tso.names import tso_filename

START = datetime(2026, 11, 2, 8, 0)
DT = 0.1


def test_closed_forms_agree_with_quadrature():
    # The helpers below are themselves checked: lag and its integral against a fine numerical solution.
    tk, uk = [0.0, 5.0, 8.0, 20.0], [0.0, 0.0, 3.0, 3.0]
    lag = Lag(tk, uk, T=2.0)
    t = np.linspace(0, 20, 200001)
    y = np.zeros_like(t)
    u = np.interp(t, tk, uk)
    h = t[1] - t[0]
    for i in range(1, len(t)):  # trapezoidal ODE step T y' = u − y
        y[i] = (y[i - 1] * (1 - h / (2 * 2.0)) + h / (2 * 2.0) * (u[i] + u[i - 1])) / (1 + h / (2 * 2.0))
    assert np.max(np.abs(lag(t) - y)) < 1e-6
    assert (
        abs(lag.integral(6.0, 15.0) - np.trapezoid(y[(t >= 6) & (t <= 15)], t[(t >= 6) & (t <= 15)])) < 1e-5
    )


class Lag:
    """Exact first-order lag (time constant T) of a piecewise-linear input given by knots."""

    def __init__(self, t_knots, u_knots, T: float):
        tk = np.asarray(t_knots, float)
        uk = np.asarray(u_knots, float)
        slopes = np.diff(uk) / np.diff(tk)
        self.u0 = float(uk[0])
        self.tau = tk[:-1]
        self.dk = np.diff(np.concatenate(([0.0], slopes)))
        self.T = float(T)

    def _r(self, s):
        s = np.maximum(s, 0.0)
        return s - self.T * (1.0 - np.exp(-s / self.T)) if self.T > 0 else s

    def _R(self, s):
        s = np.maximum(s, 0.0)
        if self.T == 0:
            return 0.5 * s**2
        return 0.5 * s**2 - self.T * s + self.T**2 * (1.0 - np.exp(-s / self.T))

    def __call__(self, t):
        t = np.asarray(t, float)
        return self.u0 + sum(k * self._r(t - tau) for k, tau in zip(self.dk, self.tau))

    def integral(self, a: float, b: float) -> float:
        return float(
            self.u0 * (b - a)
            + sum(k * (self._R(b - tau) - self._R(a - tau)) for k, tau in zip(self.dk, self.tau))
        )


def activation_knots(t_knots, f_knots, f_zero: float, f_full: float, extend: bool = False):
    """Knots of the ideal activation a(t) = clip((f_zero − f)/(f_zero − f_full), 0, 1) of a piecewise-linear
    f (crossings of f_zero and f_full inserted, so a is piecewise linear on the new knots)."""
    tk, fk = list(map(float, t_knots)), list(map(float, f_knots))
    out_t, out_f = [tk[0]], [fk[0]]
    for i in range(len(tk) - 1):
        for lv in (f_zero, f_full):
            if (fk[i] - lv) * (fk[i + 1] - lv) < 0:
                tc = tk[i] + (lv - fk[i]) / (fk[i + 1] - fk[i]) * (tk[i + 1] - tk[i])
                out_t.append(tc)
                out_f.append(lv)
        out_t.append(tk[i + 1])
        out_f.append(fk[i + 1])
    order = np.argsort(out_t, kind="stable")
    t_arr, f_arr = np.asarray(out_t)[order], np.asarray(out_f)[order]
    a = (f_zero - f_arr) / (f_zero - f_full)
    if not extend:
        a = np.clip(a, 0.0, 1.0)
    else:
        a = np.maximum(a, 0.0)
    return t_arr, a


# --------------------------------------------------------------------------------------------------
# TR profiles as knots (time [s], frequency [Hz]); ramps start on the 0.1 s grid


def fcrn_steps(endurance: bool = False, pre: float = 20.0):
    """TR Table 3 from ``pre`` s: steps within one sample (0.1 s ramps)."""
    hold = 900.0 if endurance else 300.0
    seq = [(0, 50.0), (30, 49.95), (60, 50.0), (360, 49.9), (360 + hold, 50.1), (360 + 2 * hold, 50.0)]
    end = 360 + 2 * hold + 300
    tk, fk = [0.0], [50.0]
    for ts, lv in seq[1:]:
        tk += [pre + ts, pre + ts + DT]
        fk += [fk[-1], lv]
    tk.append(pre + end)
    fk.append(50.0)
    return tk, fk


def fast_ramps(service: str = "FcrdUp", combi: bool = False, endurance: bool = False, pre: float = 10.0):
    """TR Table 4: (start [s], level [Hz], rate [Hz/s]) per ramp; FCR-D down mirrored around 50 Hz."""
    wait3 = 900.0 if endurance else 300.0
    ramps = [(30.0, 49.45, 0.14), (34.9, 49.9, 0.09), (90.0, 49.5, 0.24), (90.0 + wait3, 49.9, 0.24)]
    t5 = 90.0 + wait3 + 300.0
    ramps += [(t5, 49.0, 0.24), (t5 + 60.0, 50.0, 0.24)]
    end = t5 + 60.0 + 300.0
    if combi:
        ramps += [(end, 49.7, 0.24), (end + 300.0, 49.89, 0.24)]
        end += 600.0
    tk, fk = [0.0], [49.9]
    for ts, lv, rate in ramps:
        t0 = pre + ts
        tk.append(t0)
        fk.append(fk[-1])
        tk.append(t0 + abs(lv - fk[-1]) / rate)
        fk.append(lv)
    tk.append(pre + end)
    fk.append(fk[-1])
    if service == "FcrdDo":
        fk = [100.0 - x for x in fk]
    return tk, fk


def static_ramps(service: str = "FcrdUp", endurance: bool = False, pre: float = 10.0, after: float = 1200.0):
    hold = 900.0 if endurance else 60.0
    r = 0.4 / 0.24
    tk = [
        0.0,
        pre + 180.0,
        pre + 180.0 + r,
        pre + 180.0 + hold,
        pre + 180.0 + hold + r,
        pre + 180.0 + hold + after,
    ]
    fk = [49.9, 49.9, 49.5, 49.5, 49.9, 49.9]
    if service == "FcrdDo":
        fk = [100.0 - x for x in fk]
    return tk, fk


def linearity_levels(service: str):
    if service == "Fcrn":
        down = [round(50.0 - 0.02 * k, 2) for k in range(1, 6)]
        up = [round(49.9 + 0.02 * k, 2) for k in range(1, 11)]
        back = [round(50.1 - 0.02 * k, 2) for k in range(1, 6)]
        return [50.0, *down, *up, *back]
    lv = [49.9, 49.8, 49.7, 49.6, 49.5, 49.91]
    return lv if service == "FcrdUp" else [round(100.0 - x, 2) for x in lv]


def steps(levels, hold: float = 120.0, pre: float = 60.0):
    tk, fk = [0.0], [levels[0]]
    t = pre
    for lv in levels[1:]:
        tk += [t, t + DT]
        fk += [fk[-1], lv]
        t += hold
    tk.append(t)
    fk.append(fk[-1])
    return tk, fk


# --------------------------------------------------------------------------------------------------
# Files


def sample(tk, fk, dt: float = DT):
    n = round(tk[-1] / dt)
    t = np.arange(n + 1) * dt
    return t, np.interp(t, tk, fk)


def write(
    folder,
    service: str,
    test_type: str,
    t,
    columns: dict,
    *,
    period: float | None = None,
    resource: str = "TESTU1",
    dt: float = DT,
    start: datetime = START,
) -> str:
    """A TSO CSV file in ``folder`` with a TSO name; returns its path."""
    end = start + timedelta(seconds=float(t[-1]))
    name = tso_filename(resource, service, test_type, "NO5", "UTC", start, end, dt)
    cols = {k: np.asarray(v) for k, v in columns.items()}
    log = TsoLog.from_arrays(np.asarray(t, float), cols, start, period_s=period)
    return str(write_log(folder / name, log))


def r_value(t_rel: float, T: float) -> float:
    return t_rel - T * (1 - math.exp(-t_rel / T))
