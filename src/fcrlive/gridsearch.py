"""Extrema of a function of frequency: a dense log grid, then a bounded 1-D refinement in log ω.

The one search behind every peak of fcrlive (max|G_1|, max|S| of the analytic plant, of identified
models and of uncertain responses) and every minimum over frequency (|1 + F G|, |1 + L|, the Req. 9
ratio). It imports nothing of fcrlive, so ``plant``, ``ident`` and ``analysis`` can all use it.

A grid alone misses a sharp resonance between two points; the refinement searches between the grid
neighbours of the best point, so the result is never worse than the grid's and is accurate to
``xatol`` in log ω. Frequencies in rad/s.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np


def log_grid(omega_min: float, omega_max: float, n: int) -> np.ndarray:
    """``n`` log-spaced frequencies from ``omega_min`` to ``omega_max`` [rad/s]."""
    return np.geomspace(omega_min, omega_max, n)


def _grid_best(fun: Callable[[np.ndarray], np.ndarray], w: np.ndarray, vals: np.ndarray | None
               ) -> tuple[float, float, float, float] | None:
    """(value, ω, lower neighbour, upper neighbour) of the finite grid minimum of ``fun`` on ``w``
    (``vals`` = ``fun(w)`` when the caller has it); None when no value is finite."""
    vals = np.asarray(fun(w) if vals is None else vals, dtype=float)
    ok = np.isfinite(vals)
    if not ok.any():
        return None
    i = int(np.argmin(np.where(ok, vals, np.inf)))
    return float(vals[i]), float(w[i]), float(w[max(i - 1, 0)]), float(w[min(i + 1, w.size - 1)])


def refined_min(fun: Callable[[np.ndarray], np.ndarray], w: np.ndarray, vals: np.ndarray | None = None,
                *, xatol: float = 1e-7) -> tuple[float, float]:
    """``(min value, ω [rad/s])`` of ``fun`` (vectorised over ω) on the grid ``w``, refined between the
    grid neighbours of the minimum. ``vals`` = ``fun(w)`` when the caller has it; non-finite values are
    ignored; ``(nan, nan)`` when none is finite."""
    from scipy.optimize import minimize_scalar  # lazily: importing the plant model stays light

    start = _grid_best(fun, w, vals)
    if start is None:
        return float("nan"), float("nan")
    best_v, best_w, lo, hi = start
    if hi > lo:
        res = minimize_scalar(
            lambda lx: float(np.asarray(fun(np.array([np.exp(lx)])), dtype=float).ravel()[0]),
            bounds=(np.log(lo), np.log(hi)),
            method="bounded",
            options={"xatol": xatol},
        )
        if np.isfinite(res.fun) and res.fun < best_v:
            best_v, best_w = float(res.fun), float(np.exp(res.x))
    return best_v, best_w


REFINE_ROUNDS = 3
"""Rounds of :func:`refined_min_grid`."""
REFINE_POINTS = 63
"""Points per round of :func:`refined_min_grid` (odd: the best point so far is the middle one)."""


def refined_min_grid(fun: Callable[[np.ndarray], np.ndarray], w: np.ndarray, vals: np.ndarray | None = None,
                     *, rounds: int = REFINE_ROUNDS, points: int = REFINE_POINTS) -> tuple[float, float]:
    """:func:`refined_min` with the refinement on nested grids instead of Brent's scalar search: for
    functions whose every call costs more than its points (an identified model's responses with their
    uncertainty, the TSO checks' margins), where Brent's 10-25 one-point calls were most of the time.

    Each round evaluates ``points`` log-spaced ω between the neighbours of the best point, in one call,
    and brackets the next round by the neighbours of its best: the bracket shrinks (points − 1)/2 times
    a round, 3 rounds of 63 points take a 2000-point grid's 2 steps down to ~1e-7 in log ω (Brent's
    ``xatol``). Never worse than the grid's best; a grid between the neighbours also finds the lower of
    two minima there, where Brent may not. ``(nan, nan)`` when no value is finite.
    """
    start = _grid_best(fun, w, vals)
    if start is None:
        return float("nan"), float("nan")
    best_v, best_w, lo, hi = start
    for _ in range(rounds):
        if not hi > lo:
            break
        x = np.exp(np.linspace(np.log(lo), np.log(hi), points))
        v = np.asarray(fun(x), dtype=float).ravel()
        ok = np.isfinite(v)
        if not ok.any():
            break
        j = int(np.argmin(np.where(ok, v, np.inf)))
        if v[j] < best_v:
            best_v, best_w = float(v[j]), float(x[j])
        lo, hi = float(x[max(j - 1, 0)]), float(x[min(j + 1, points - 1)])
    return best_v, best_w


def peak(mag: Callable[[np.ndarray], np.ndarray], omega_min: float, omega_max: float, n: int = 3000,
         *, xatol: float = 1e-7) -> tuple[float, float]:
    """``(max, ω [rad/s])`` of ``mag`` (e.g. ``|H(jω)|``, vectorised) over ``[omega_min, omega_max]``:
    an ``n``-point log grid, then the refinement of :func:`refined_min`."""
    v, w = refined_min(lambda x: -np.asarray(mag(x), dtype=float), log_grid(omega_min, omega_max, n),
                       xatol=xatol)
    return -v, w


def uncertain_peak(response: Callable[[np.ndarray], Any], omega_min: float, omega_max: float,
                   n: int = 1500) -> Any:
    """Peak of an uncertain response: ``response(ω)`` returns a :class:`fcrlive.ident.freqresp.FreqResp`
    (or anything with ``.abs`` and ``.max_abs()``); the peak's ω is found by :func:`peak` on |G| and
    the response is evaluated there, so value, ω and sd (``PeakGain``) belong to the same point. The
    refinement is :func:`refined_min_grid` (each evaluation of such a response costs more than its points)."""
    _, w = refined_min_grid(lambda x: -np.asarray(response(x).abs, dtype=float),
                            log_grid(omega_min, omega_max, n))
    return response(np.array([w])).max_abs()
