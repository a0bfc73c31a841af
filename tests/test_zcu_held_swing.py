"""Z_cu with the data sheet's swing equation holds G_jp's swing pole where Kd = 0 (experiments.SwingPole):
on the zoo's units without damping (B, G) the fit of G_t = servo × turbine is a converged minimum, and the
same log gives the same published numbers under two BLAS kernels.

Before, G_jp's swing pole was fitted and pressed against the stability guard on most excited logs of B and G
(31 of 40 main fits); where such a search stopped depended on the rounding of the arithmetic:
Haswell vs Sandybridge kernels, B and G, ideal and 0.1 % meter noise, excited, 15/30 min, 5 seeds: 227 of
1341 published numbers differed by more than 1e-4 relative, 43 by more than 1 % (docs/zoo.md)."""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys

import numpy as np
import pytest

from fcrlive.analysis import experiments as ex
from fcrlive.constants import Z95
from fcrlive.sim import zoo

A = "A-classic-tustin-20Hz"
B = "B-int-beuler-10Hz"
G = "G-classic-fwd-40Hz-poor"


@pytest.mark.parametrize("plant,seed", [(B, 4), (B, 6), (G, 4), (G, 6)])
def test_the_turbine_path_of_a_unit_without_damping_converges(plant, seed):
    """Records whose fitted swing pole stalled at the guard (the G_jp fit with the pole free did not
    converge on any of them); the held pole with the drift column converges on each."""
    tr = zoo.truth(plant)
    sig = zoo.signals(plant, "ctl-ideal", minutes=15, excitation=True, seed=seed)
    res = ex.zcu_swing(sig, H=tr.H, kd=tr.kd, jackknife=False, rate_check=False, delay_check=False,
                       meter_check=False)
    m = res.models["y+G_J u<-G_J c"]
    assert m.report.converged, m.report.stop_reason
    assert m.nf == (2,)  # servo × turbine: the swing pole is not a parameter
    assert any("pole held (Kd = 0)" in n for n in res.notes)


_CHILD = r"""
import json, pickle, sys
from threadpoolctl import threadpool_info
from fcrlive.analysis.identify import identify_signals

archs = sorted({i.get("architecture") or "" for i in threadpool_info()
                if i.get("internal_api") == "openblas"})
rows = []
for sig, kw in pickle.load(open(sys.argv[1], "rb")):
    rep = identify_signals(sig, **kw)
    nums = []
    for key in ("droop", "max_abs_s", "max_abs_g1"):
        q = getattr(rep, key)
        nums.append(None if q is None else [q.value, *(q.ci95 or [None, None])])
    nums.append([[p.abs, *(p.abs_ci95 or [None, None])] for p in (rep.gp or [])])
    rows.append(nums)
print(json.dumps({"archs": archs, "rows": rows}))
"""


def _identify_under(kernel: str, path) -> dict:
    env = {**os.environ, "OPENBLAS_CORETYPE": kernel, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", _CHILD, str(path)], env=env, capture_output=True, text=True,
                         timeout=600, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _flat(x) -> list:
    if isinstance(x, list):
        return [v for e in x for v in _flat(e)]
    return [x]


def test_the_same_log_gives_the_same_numbers_under_two_blas_kernels(tmp_path):
    """B at 0.1 % meter noise, 15 min, seed 1: max|S| 1.519 [1.216, 1.822] under one kernel and
    [1.012, 2.025] under the other before (the delay check then withheld it under one only); G seed 3:
    jackknife refits 0.3 % apart (at 0.1 % meter noise; since the block means its G_p is withheld there,
    its ideal log is the one with G_p). Now every published number agrees to 1e-4 relative (the
    project's standard, ../shared/tools/blas-determinism; what is left is the searches' stopping
    tolerance), and what is withheld is withheld under both (B's G_p: its turbine path follows the meter
    noise, experiments.TURBINE_TAU_MAX_S). A at 0.1 % meter noise, 15 min, seed 1: the fits' turbine pole
    pinned at the stability guard, where the searches stopped by rounding (the two-rate fit 1e-2 apart in
    θ, max|S|'s interval ends 1.4 % apart) until they were continued with that root held
    (fcrlive.ident.pem._polish_on_guard)."""
    cases = []
    for plant, seed, logger in ((B, 1, "ctl-0.1pct"), (G, 3, "ctl-ideal"), (A, 1, "ctl-0.1pct")):
        tr = zoo.truth(plant)
        sig = zoo.signals(plant, logger, minutes=15, excitation=True, seed=seed)
        cases.append((sig, {"rated_mw": tr.rated_mw, "kd": tr.kd, "h": tr.H}))
    path = tmp_path / "logs.pkl"
    path.write_bytes(pickle.dumps(cases))
    a = _identify_under("Haswell", path)
    b = _identify_under("Sandybridge", path)
    if a["archs"] != ["Haswell"] or b["archs"] != ["Sandybridge"]:
        pytest.skip(f"this machine's OpenBLAS did not take both kernels: {a['archs']} / {b['archs']}")
    assert len(a["rows"]) == 3
    for ra in a["rows"]:
        assert sum(x is not None for x in _flat(ra)) >= 3  # the droop and its interval at least
    assert _same_numbers(a, b) >= 30  # G's peaks and G_p points as well


def _same_numbers(a: dict, b: dict) -> int:
    """Asserts that two children's rows agree (shown under both, to 1e-4); the count of shown numbers."""
    shown = 0
    for ra, rb in zip(a["rows"], b["rows"], strict=True):
        fa, fb = _flat(ra), _flat(rb)
        assert [x is None for x in fa] == [x is None for x in fb]  # shown under both or withheld under both
        shown += sum(x is not None for x in fa)
        for x, y in zip(fa, fb):
            if x is not None:
                assert y == pytest.approx(x, rel=1e-4)
    return shown


def test_held_out_logs_give_the_same_numbers_under_avx512_and_avx2_kernels(tmp_path):
    """Plants no estimator was developed on, at 0.1 % meter noise, 15 min, excited: held-out-2 seed 0 showed
    G_p under SkylakeX (AVX-512) only, held-out-4 (Kd = 0) seed 1 had max|S|'s interval [1.01, 1.71] under
    SkylakeX and [0.89, 1.82] under Haswell (a jackknife refit's root left 1e-7 or 1.2e-6 inside the
    guard: held and polished under one kernel only). The Gauss-Newton step by SVD (ident.pem._gn_step)
    and the wider pinned-root test (ident.pem.GUARD_PINNED) bring them together. held-out-30 (30 min, seed
    1): two drift poles against the guard, one held; 20 numbers more than 1 % apart until both were held
    (ident.pem._pin_constraints). Skipped where this machine's OpenBLAS cannot take the AVX-512 kernel."""
    cases = []
    for plant, seed, minutes in (("held-out-2", 0, 15), ("held-out-4", 1, 15), ("held-out-30", 1, 30)):
        tr = zoo.truth(plant)
        sig = zoo.signals(plant, "ctl-0.1pct", minutes=minutes, excitation=True, seed=seed)
        cases.append((sig, {"rated_mw": tr.rated_mw, "kd": tr.kd, "h": tr.H}))
    path = tmp_path / "logs.pkl"
    path.write_bytes(pickle.dumps(cases))
    a = _identify_under("SkylakeX", path)
    if a["archs"] != ["SkylakeX"]:
        pytest.skip(f"this machine's OpenBLAS did not take the SkylakeX kernel: {a['archs']}")
    b = _identify_under("Haswell", path)
    assert b["archs"] == ["Haswell"]
    assert _same_numbers(a, b) >= 40  # held-out-2's and -30's G_p points among them


def test_a_turbine_path_that_follows_the_meter_noise_withholds_g_p():
    """B at 0.1 % meter noise, 15 min, seed 7: the held fit's servo × turbine path takes a pole far slower
    than a turbine's, following the meter noise's random walk through the swing. G_p and the TSO checks
    are withheld with the reason (on the zoo's logs where this happens G_p covered 95 % with two points
    outside by more than their half-width); the peaks stay, with intervals that hold the truth (73/73 and
    77/77 there, experiments.TURBINE_TAU_MAX_S). A unit without damping is not refitted with a pole for
    the drift (experiments.DRIFT_REFIT: not the same numbers under two kernels there). The ideal log of
    the same record keeps G_p."""
    from fcrlive.analysis.identify import identify_signals

    tr = zoo.truth(B)
    noisy = zoo.signals(B, "ctl-0.1pct", minutes=15, excitation=True, seed=7)
    rep = identify_signals(noisy, rated_mw=tr.rated_mw, kd=tr.kd, h=tr.H, method="zcu")
    why = rep.not_identifiable["gp"]
    assert why.startswith("not identifiable") and "servo × turbine path has a pole" in why and "Kd = 0" in why
    assert rep.not_identifiable["tso"] == why and rep.gp is None and rep.tso is None
    for key, truth in (("max_abs_s", tr.max_s), ("max_abs_g1", tr.max_g1)):
        assert "servo × turbine" not in rep.not_identifiable.get(key, "")
        q = getattr(rep, key)
        if q.value is not None:  # shown: its interval holds the truth
            assert q.ci95[0] <= truth <= q.ci95[1], key
    ideal = zoo.signals(B, "ctl-ideal", minutes=15, excitation=True, seed=7)
    rep_i = identify_signals(ideal, rated_mw=tr.rated_mw, kd=tr.kd, h=tr.H, method="zcu")
    assert not any("servo × turbine path" in why for why in rep_i.not_identifiable.values())
    assert rep_i.max_abs_s.value is not None and rep_i.max_abs_g1.value is not None and rep_i.gp


C = "C-pid-tustin-50Hz"


def test_a_turbine_path_that_follows_a_slow_drift_is_refitted_with_a_pole_for_it(monkeypatch):
    """C (Kd = 1) at 0.1 % meter noise, 15 min, seed 7: G_t's fit (3, 2) puts a pole at the stability guard
    (the meter noise's drift through the swing, experiments.DAMPED_TURBINE_TAU_MAX_S), leaving one pole
    for servo and turbine. With one pole more for the drift (experiments.DRIFT_REFIT) servo and turbine
    have their two fast poles again and G_p is shown, its interval at least as wide as the distance to
    the first fit's G_p at every TSO period (the structure check, DRIFT_CHECK_FACTOR = 1). Without the
    refit G_p is withheld."""
    tr = zoo.truth(C)
    sig = zoo.signals(C, "ctl-0.1pct", minutes=15, excitation=True, seed=7)
    kw = dict(H=tr.H, kd=tr.kd, jackknife=False, rate_check=False, delay_check=False, meter_check=False)
    periods = np.array([p for p, _ in tr.gp])
    w = 2.0 * np.pi / periods

    res = ex.zcu_swing(sig, **kw)
    m = res.models["y+G_J u<-G_J c"]
    assert m.nf == (3,) and any("refitted with 1 pole(s) more" in n for n in res.notes)
    tau = np.sort(-m.Ts / np.log(np.abs(np.roots(m.f[0]))))
    assert tau[1] <= ex.DAMPED_TURBINE_TAU_MAX_S < tau[2]  # servo and turbine fast, the drift's pole slow
    assert "gp" not in res.not_identifiable and "tso" not in res.not_identifiable
    gp = res.responses(w)["G_p"]
    assert any("drift-pole structure check" in k for k, _ in gp.sources)

    monkeypatch.setattr(ex, "DRIFT_REFIT", 0)
    first = ex.zcu_swing(sig, **kw)
    assert first.models["y+G_J u<-G_J c"].nf == (2,)
    assert "servo × turbine path has a pole" in first.not_identifiable["gp"]
    diff = np.abs(np.abs(first.responses(w)["G_p"].value) - np.abs(gp.value))
    assert np.all(diff > 0)
    assert np.all(Z95 * gp.sd_abs >= diff * (1.0 - 1e-9))


def test_a_damped_units_drift_pole_at_10_to_30_s_is_not_taken_for_the_turbine(monkeypatch):
    """held-out-2 (a PID plant no estimator was developed on, Kd = 0.51, 2H/Kd = 19.7 s) at 0.1 % meter
    noise, 30 min, seed 2: G_t's fit puts a pole at about 22 s, the meter noise's drift through the swing,
    which the 30-s rule (TURBINE_TAU_MAX_S) took for the turbine's; G_p at 10 s was then 11 % low with an
    interval that missed (4 such misses on the held-out and zoo logs, all with a pole of 12-28 s).
    For a unit with damping the rule is 10 s (experiments.DAMPED_TURBINE_TAU_MAX_S): the refit with a
    pole more for the drift is tried and, where it does not give servo and turbine fast poles, G_p is
    withheld with the reason."""
    name = "held-out-2"
    tr = zoo.truth(name)
    sig = zoo.signals(name, "ctl-0.1pct", minutes=30, excitation=True, seed=2)
    kw = dict(H=tr.H, kd=tr.kd, jackknife=False, rate_check=False, delay_check=False, meter_check=False)

    monkeypatch.setattr(ex, "DRIFT_REFIT", 0)
    first = ex.zcu_swing(sig, **kw).models["y+G_J u<-G_J c"]
    tau = np.sort(-first.Ts / np.log(np.abs(np.roots(first.f[0]))))
    assert ex.DAMPED_TURBINE_TAU_MAX_S < tau[-1] < ex.TURBINE_TAU_MAX_S  # the old rule let it through

    monkeypatch.undo()
    res = ex.zcu_swing(sig, **kw)
    refitted = any("refitted with" in n for n in res.notes)
    why = res.not_identifiable.get("gp")
    assert refitted or (why is not None and "servo × turbine path has a pole with a time constant" in why)
    if why is not None:
        assert "2H/Kd = 20 s" in why and res.not_identifiable["tso"] == why


def test_a_search_pinned_at_the_stability_guard_ends_at_the_minimum_with_that_root_held(monkeypatch):
    """A at 0.1 % meter noise, 15 min, seed 1: G_t's search stops against the guard ("no descent even with
    maximal damping") with a real pole at |z| = 1 − 1e-7. Continued with that root held just inside the
    guard it reaches the minimum of the rest of θ: a lower loss (N·ΔV/V ≈ 9 on this record), the root where
    it was held, and no Gauss-Newton decrease left along the guard."""
    import numpy as np

    from fcrlive.ident import pem

    tr = zoo.truth(A)
    sig = zoo.signals(A, "ctl-0.1pct", minutes=15, excitation=True, seed=1)
    monkeypatch.setattr(ex, "DRIFT_REFIT", 0)  # the one fit of G_t whose search this is about

    def fit():
        res = ex.zcu_swing(sig, H=tr.H, kd=tr.kd, jackknife=False, rate_check=False, delay_check=False,
                           meter_check=False)
        return res.models["y+G_J u<-G_J c"]

    m = fit()
    assert "held on the stability guard: predicted relative loss decrease below tolerance" in \
        m.report.stop_reason, m.report.stop_reason
    r = np.roots(m.f[0])
    assert np.max(np.abs(r)) == pytest.approx(pem._GUARD_HOLD, abs=1e-12)
    assert not m.report.converged  # a point on the guard is not a converged fit (the verdict is kept)
    monkeypatch.setattr(pem, "_polish_on_guard", lambda st, r, *a: r)
    stalled = fit()
    assert "no descent" in stalled.report.stop_reason and "held" not in stalled.report.stop_reason
    assert m.report.loss < stalled.report.loss * (1.0 - 1e-4)


def test_a_turbine_path_with_every_pole_on_the_drift_withholds_the_peaks():
    """held-out-12 (Kd = 0, max|S| 1.90) at 0.1 % meter noise, 30 min, excited, seed 0: G_t's fit puts both
    of its poles at the stability guard, following the meter noise's random walk, with nothing left for
    servo and turbine; max|S| came out 1.41 [1.35, 1.46], 9 half-widths from the truth. Now max|S| and
    max|G_1| are withheld with the reason (experiments._no_turbine_pole), as G_p was. The ideal log of the
    same record keeps them (there 1.88 [1.76, 2.01] against 1.90)."""
    from fcrlive.analysis.identify import identify_signals

    name = "held-out-12"
    tr = zoo.truth(name)
    noisy = zoo.signals(name, "ctl-0.1pct", minutes=30, excitation=True, seed=0)
    rep = identify_signals(noisy, rated_mw=tr.rated_mw, kd=tr.kd, h=tr.H, method="zcu")
    for key in ("max_abs_s", "max_abs_g1"):
        why = rep.not_identifiable[key]
        assert why.startswith("not identifiable") and "even the fastest pole" in why
        assert getattr(rep, key).value is None
    assert rep.gp is None
    ideal = zoo.signals(name, "ctl-ideal", minutes=30, excitation=True, seed=0)
    rep_i = identify_signals(ideal, rated_mw=tr.rated_mw, kd=tr.kd, h=tr.H, method="zcu")
    for key in ("max_abs_s", "max_abs_g1"):
        assert getattr(rep_i, key).value is not None and key not in rep_i.not_identifiable


def test_two_roots_pinned_at_the_stability_guard_are_held_together(monkeypatch):
    """held-out-30 (Kd 0.65) at 0.1 % meter noise, 30 min, excited, seed 1: starts of G_t's drift refit with
    two poles more end with both drift poles against the guard. Holding one of them left the other
    pressing on it: the held search stopped "no descent" where the rounding had left it, and SkylakeX and
    Haswell showed max|S|, max|G_1| and G_p more than 1 % apart. Held as a double root
    (pem._pin_constraints), those searches end at the minimum along the guard."""
    import numpy as np

    from fcrlive.ident import pem

    name = "held-out-30"
    tr = zoo.truth(name)
    sig = zoo.signals(name, "ctl-0.1pct", minutes=30, excitation=True, seed=1)
    fits = []
    oe = ex.oe

    def recording_oe(*a, **kw):
        m = oe(*a, **kw)
        fits.append(m)
        return m

    monkeypatch.setattr(ex, "oe", recording_oe)

    def held_fits():
        fits.clear()
        ex.zcu_swing(sig, H=tr.H, kd=tr.kd, jackknife=False, rate_check=False, delay_check=False,
                     meter_check=False)
        return [m for m in fits if "held on the stability guard" in m.report.stop_reason]

    held = held_fits()
    doubles = [m for m in held if np.sum(np.abs(np.abs(np.roots(m.f[0])) - pem._MULTI_HOLD) < 1e-6) == 2]
    assert doubles, [m.report.stop_reason for m in held]
    for m in held:
        assert m.report.stop_reason.endswith("predicted relative loss decrease below tolerance"), \
            m.report.stop_reason
    single = pem._pinned
    monkeypatch.setattr(pem, "_pinned", lambda st, th: [(sl, z if k == 1 else pem._GUARD_HOLD, 1)
                                                        for sl, z, k in single(st, th)])
    assert any(m.report.stop_reason.endswith("no descent") for m in held_fits())
