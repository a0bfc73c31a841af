"""Rounding sensitivity of the Box-Jenkins searches of Z_u and Z_ur: a relative change of 1e-13 in the data
(what another BLAS kernel or thread count makes of the same simulation or log) must not change the result
beyond rounding.

Measured before (one BLAS thread): Z_u, 10 min at 12 dB, seed 7: droop 7.98 % as simulated, 7.81 % and
1.34 % with ε × (1 + 1e-13·N(0, 1)) (two draws); Z_ur, 30 min at 12 dB, seed 9: 8.02 % or 10.04 % by the
simulation's BLAS threads (logs differing by 1.5e-15). Two causes, both fixed: the decimation filter as one
transfer function amplified the rounding of the log 1e9-fold at q = 50 (experiments._decimator, now
second-order sections), and the search's Jacobian left out Kaufman's term of the initial-state projection,
so searches stalled short of the minimum where the rounding put them (pem._IcProjection.kaufman). Both are
now the same to 1e-14 (Z_u moved by 2 % of its half-width while it ran 8 perturbed restarts per order).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fcrlive.analysis.identify import identify_full
from fcrlive.plant.params import preset
from fcrlive.sim import SimConfig, simulate
from fcrlive.tso.signals import log_from_sim, plant_signals

PLANT = preset("paper-plant1")
KD = 0.1


def _droops(sig, draws: int = 2) -> list[tuple[float, float, float]]:
    """(droop, lower, upper) of the assessment behind the report (before the quality rules withhold it), as
    logged and with ε × (1 + 1e-13·N(0, 1)) for ``draws`` seeded draws."""
    rng = np.random.default_rng(0)
    out = []
    for k in range(draws + 1):
        s = sig
        if k:
            eps = np.asarray(sig.epsilon)
            s = replace(sig, epsilon=eps * (1.0 + 1e-13 * rng.standard_normal(eps.size)))
        d = identify_full(s, rated_mw=300.0, kd=KD).assessment.droop
        out.append((d.value, d.lo, d.hi))
    return out


def _same_to_rounding(droops) -> None:
    v0, lo, hi = droops[0]
    half = 0.5 * (hi - lo)
    for v, _, _ in droops[1:]:
        # a 1e-13 change of the data may move the result by far less than its own uncertainty
        assert abs(v - v0) <= 1e-3 * half, [round(100 * x[0], 3) for x in droops]


def test_zu_droop_does_not_depend_on_rounding():
    res = simulate(PLANT, SimConfig(duration_s=600.0, snr_db=12.0, excitation=False, seed=7))
    sig = plant_signals(log_from_sim(res), rated_mw=300.0)
    _same_to_rounding(_droops(sig))


def test_zur_droop_does_not_depend_on_rounding():
    res = simulate(PLANT, SimConfig(duration_s=1800.0, snr_db=12.0, excitation=True, seed=9))
    sig = replace(plant_signals(log_from_sim(res), rated_mw=300.0), c=None, a=None)
    _same_to_rounding(_droops(sig))
