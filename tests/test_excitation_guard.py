"""The safety guard: limits validation, interlocks, hold-off, budget, stop ramp, and the invariants that
must hold whatever goes in (property-based)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fcrlive.errors import ConfigError
from fcrlive.excitation.guard import (
    ALL_REASONS,
    BUDGET_EXHAUSTED,
    CLOCK_BACKWARDS,
    FCRD_ACTIVE,
    FREQUENCY_OUT_OF_BAND,
    GROSS_REQUEST_FACTOR,
    HARD_REASONS,
    HOLDOFF,
    INVALID_MEASUREMENT,
    INVALID_REQUEST,
    INVALID_TIME,
    STALE_MEASUREMENT,
    STEP_GAP,
    STOPPED,
    STOPPING,
    GuardLimits,
    SafetyGuard,
)

OK = 0b11  # FCR-N active + normal operation
NAN = math.nan
INF = math.inf


def run_healthy(guard: SafetyGuard, t0: float, t1: float, dt: float, req: float = 0.05, f: float = 50.0):
    """Step the guard with healthy inputs on [t0, t1) and return the decisions."""
    out = []
    for t in np.arange(t0, t1, dt):
        out.append(guard.step(float(t), req, f, OK))
    return out


# ---- limits -----------------------------------------------------------------------------------------------

def test_default_limits_are_the_papers_and_safe():
    lim = GuardLimits()
    assert lim.amplitude_hz == 0.1 and lim.band_hz == 0.1
    assert lim.stop_time_bound_s == pytest.approx(0.1)


@pytest.mark.parametrize(("field", "value"), [
    ("amplitude_hz", 0.2), ("amplitude_hz", 0.0), ("amplitude_hz", -0.05), ("amplitude_hz", NAN),
    ("amplitude_hz", INF), ("amplitude_hz", "0.1"), ("amplitude_hz", True), ("amplitude_hz", None),
    ("rate_limit_hz_per_s", 6.0), ("rate_limit_hz_per_s", 0.001), ("rate_limit_hz_per_s", -1.0),
    ("budget_s_per_day", 5 * 3600.0), ("budget_s_per_day", 0.0), ("band_hz", 0.2), ("band_hz", 1e300),
    ("stale_after_s", 10.0), ("stale_after_s", 0.0), ("holdoff_s", 0.5), ("holdoff_s", 7200.0),
    ("budget_resume_s", -1.0), ("band_hysteresis_hz", -0.001),
])
def test_unsafe_limits_are_rejected_naming_the_field(field, value):
    with pytest.raises(ConfigError) as exc:
        GuardLimits(**{field: value})
    assert field in str(exc.value)
    assert exc.value.field == field


def test_coupled_limits_are_checked():
    with pytest.raises(ConfigError, match="band_hysteresis_hz"):
        GuardLimits(band_hz=0.05, band_hysteresis_hz=0.05)
    with pytest.raises(ConfigError, match="budget_s_per_day"):  # shorter than the 10 s stop ramp
        GuardLimits(budget_s_per_day=5.0, budget_resume_s=1.0, amplitude_hz=0.1, rate_limit_hz_per_s=0.01)
    with pytest.raises(ConfigError, match="budget_resume_s"):
        GuardLimits(budget_s_per_day=100.0, budget_resume_s=200.0)


def test_from_mapping_rejects_unknown_keys():
    assert GuardLimits.from_mapping({"amplitude_hz": 0.05}).amplitude_hz == 0.05
    with pytest.raises(ConfigError, match="amplitud_hz"):
        GuardLimits.from_mapping({"amplitud_hz": 0.05})


def test_integer_limits_are_stored_as_floats():
    lim = GuardLimits(holdoff_s=5, rate_limit_hz_per_s=np.float32(2.0))
    assert type(lim.holdoff_s) is float and type(lim.rate_limit_hz_per_s) is float


@pytest.mark.parametrize("f0", [0.0, NAN, 500.0, "50", None])
def test_bad_f0_rejected(f0):
    with pytest.raises(ConfigError, match="f0"):
        SafetyGuard(GuardLimits(), f0=f0)


# ---- behaviour --------------------------------------------------------------------------------------------

def test_starts_in_holdoff_then_follows_request_at_the_rate_limit():
    g = SafetyGuard(GuardLimits(holdoff_s=2.0, rate_limit_hz_per_s=0.1))
    ds = run_healthy(g, 0.0, 2.0, 0.1, req=0.05)
    assert all(d.value_hz == 0.0 and HOLDOFF in d.reasons and d.inhibited for d in ds)
    d = g.step(2.0, 0.05, 50.0, OK)  # hold-off over, but the clock only advanced 0.1 s at this step
    assert d.active and not d.inhibited and d.reasons == ()
    assert d.value_hz == pytest.approx(0.01) and d.rate_limited
    ds = run_healthy(g, 2.1, 3.0, 0.1, req=0.05)
    assert ds[-1].value_hz == pytest.approx(0.05) and not ds[-1].rate_limited


def test_band_interlock_zeroes_at_once_and_reenables_after_hysteresis_and_holdoff():
    lim = GuardLimits(holdoff_s=5.0, band_hz=0.1, band_hysteresis_hz=0.01, rate_limit_hz_per_s=5.0)
    g = SafetyGuard(lim)
    run_healthy(g, 0.0, 6.0, 0.1, req=0.08)
    assert g.value_hz == 0.08
    d = g.step(6.0, 0.08, 50.101, OK)
    assert d.value_hz == 0.0 and FREQUENCY_OUT_OF_BAND in d.reasons and d.hard and d.inhibited
    # back inside the band but not by the hysteresis margin: still inhibited
    for t in np.arange(6.1, 20.0, 0.1):
        d = g.step(float(t), 0.08, 49.905, OK)
        assert d.value_hz == 0.0 and FREQUENCY_OUT_OF_BAND in d.reasons
    # well inside: hold-off of 5 s, then excitation again
    ts = np.arange(20.0, 30.0, 0.1)
    ds = [g.step(float(t), 0.08, 49.95, OK) for t in ts]
    first_active = next(t for t, d in zip(ts, ds) if d.active)
    assert 25.0 - 1e-9 <= first_active <= 25.2
    assert all(d.value_hz == 0.0 and d.reasons == (HOLDOFF,) for t, d in zip(ts, ds) if t < 24.95)
    assert ds[-1].value_hz == 0.08
    # low side, any excursion restarts the hold-off
    d = g.step(30.0, 0.08, 49.89, OK)
    assert d.value_hz == 0.0 and FREQUENCY_OUT_OF_BAND in d.reasons


def test_stale_measurement_inhibits():
    g = SafetyGuard(GuardLimits(holdoff_s=1.0, stale_after_s=0.55, rate_limit_hz_per_s=5.0))
    run_healthy(g, 0.0, 2.0, 0.1)
    assert g.value_hz == 0.05
    ds = [g.step(2.0 + 0.1 * k, 0.05, None, OK) for k in range(1, 8)]
    # last measurement at 1.9 s: ages 0.2 … 0.8 s; the 5th step (age 0.6 s > 0.55 s) is stale
    assert [d.value_hz != 0.0 for d in ds] == [True] * 4 + [False] * 3
    assert STALE_MEASUREMENT in ds[-1].reasons
    # a measurement stamped too long ago is stale too; one from the future is invalid
    g2 = SafetyGuard(GuardLimits(holdoff_s=1.0, stale_after_s=0.5))
    run_healthy(g2, 0.0, 2.0, 0.1)
    assert STALE_MEASUREMENT in g2.step(2.0, 0.05, 50.0, OK, measured_at_s=1.0).reasons
    assert INVALID_MEASUREMENT in g2.step(2.1, 0.05, 50.0, OK, measured_at_s=3.0).reasons
    assert INVALID_MEASUREMENT in g2.step(2.2, 0.05, NAN, OK).reasons


@pytest.mark.parametrize(("status", "reason"), [
    (None, "not_permitted:status_unknown"), (0b01, "not_permitted:abnormal_operation"),
    (0b10, "not_permitted:fcrn_inactive"), (0, "not_permitted:fcrn_inactive"),
    (-1, "not_permitted:status_invalid"), (2**40, "not_permitted:status_invalid"),
    (True, "not_permitted:status_invalid"), (3.0, "not_permitted:status_invalid"),
])
def test_status_word_permissive(status, reason):
    g = SafetyGuard(GuardLimits(holdoff_s=1.0, rate_limit_hz_per_s=5.0))
    run_healthy(g, 0.0, 2.0, 0.1)
    assert g.value_hz == 0.05
    d = g.step(2.0, 0.05, 50.0, status)
    assert d.value_hz == 0.0 and reason in d.reasons and d.inhibited


def test_other_status_bits_are_ignored_and_numpy_ints_accepted():
    g = SafetyGuard(GuardLimits(holdoff_s=1.0, rate_limit_hz_per_s=5.0))
    for k in range(20):
        d = g.step(k * 0.1, 0.05, 50.0, np.uint16(0xFF03))
    assert d.active and d.value_hz == 0.05


def test_fcrd_interlock():
    g = SafetyGuard(GuardLimits(holdoff_s=1.0, rate_limit_hz_per_s=5.0))
    run_healthy(g, 0.0, 2.0, 0.1)
    d = g.step(2.0, 0.05, 50.0, OK, fcrd_active=True)
    assert d.value_hz == 0.0 and FCRD_ACTIVE in d.reasons
    d = g.step(2.1, 0.05, 50.0, OK, fcrd_active=None)
    assert d.value_hz == 0.0 and "fcrd_unknown" in d.reasons
    d = g.step(2.2, 0.05, 50.0, OK)
    assert d.value_hz == 0.0 and d.reasons == (HOLDOFF,)


def test_clock_faults_and_step_gaps_zero_and_restart_holdoff():
    lim = GuardLimits(holdoff_s=1.0, rate_limit_hz_per_s=5.0, stale_after_s=1.0)
    g = SafetyGuard(lim)
    run_healthy(g, 100.0, 102.0, 0.1)
    assert g.value_hz == 0.05
    d = g.step(101.0, 0.05, 50.0, OK)  # backwards
    assert d.value_hz == 0.0 and CLOCK_BACKWARDS in d.reasons
    ds = run_healthy(g, 101.1, 103.0, 0.1)  # rebased: resumes after the hold-off, not after 1 s extra
    assert ds[-1].value_hz == 0.05
    for bad in (NAN, INF, -INF, "x", None):
        d = g.step(bad, 0.05, 50.0, OK)
        assert d.value_hz == 0.0 and INVALID_TIME in d.reasons
    ds = run_healthy(g, 103.0, 105.0, 0.1)
    assert ds[-1].value_hz == 0.05
    d = g.step(110.0, 0.05, 50.0, OK)  # 5 s without a step: the writer stalled
    assert d.value_hz == 0.0 and STEP_GAP in d.reasons


def test_requests_clamped_or_rejected():
    g = SafetyGuard(GuardLimits(holdoff_s=1.0, rate_limit_hz_per_s=5.0, amplitude_hz=0.05))
    run_healthy(g, 0.0, 2.0, 0.1)
    d = g.step(2.0, 0.07, 50.0, OK)
    assert d.clamped and d.value_hz == 0.05 and d.active
    d = g.step(2.1, -0.07, 50.0, OK)
    assert d.clamped and d.value_hz == -0.05
    for k, bad in enumerate((NAN, INF, -INF, 1e300, 0.05 * GROSS_REQUEST_FACTOR * 1.01, "0.05", None)):
        g2 = SafetyGuard(GuardLimits(holdoff_s=1.0, rate_limit_hz_per_s=5.0, amplitude_hz=0.05))
        run_healthy(g2, 0.0, 2.0, 0.1)
        d = g2.step(2.0, bad, 50.0, OK)
        assert d.value_hz == 0.0 and INVALID_REQUEST in d.reasons, k


def test_stop_ramps_to_exactly_zero_within_the_bound():
    lim = GuardLimits(holdoff_s=1.0, rate_limit_hz_per_s=0.03, amplitude_hz=0.1)
    g = SafetyGuard(lim)
    run_healthy(g, 0.0, 6.0, 0.1, req=-0.1)
    assert g.value_hz == -0.1
    g.stop()
    assert not g.stopped
    prev = g.value_hz
    t = 6.0
    while not g.stopped:
        d = g.step(t, -0.1, 50.0, OK)
        assert abs(d.value_hz - prev) <= 0.03 * 0.1 + 1e-15
        assert (STOPPED if g.stopped else STOPPING) in d.reasons
        assert not d.active
        prev = d.value_hz
        t = round(t + 0.1, 10)
        assert t <= 6.0 + lim.stop_time_bound_s + 0.1 + 1e-9
    assert d.value_hz == 0.0 and math.copysign(1.0, d.value_hz) == 1.0 and STOPPED in d.reasons
    for _ in range(5):  # stays at zero until start()
        t += 0.1
        assert g.step(t, 0.1, 50.0, OK).value_hz == 0.0
    g.start()
    t += 0.1
    assert g.step(t, 0.1, 50.0, OK).value_hz > 0.0


def test_stop_when_idle_is_immediate():
    g = SafetyGuard()
    g.stop()
    assert g.stopped


def test_budget_honoured_over_simulated_days():
    lim = GuardLimits(budget_s_per_day=3600.0, budget_resume_s=300.0, holdoff_s=1.0, stale_after_s=5.0)
    g = SafetyGuard(lim)
    dt = 2.0
    ts = np.arange(0.0, 2 * 86400.0, dt)
    on = np.zeros(ts.size, dtype=bool)
    for i, t in enumerate(ts):
        d = g.step(float(t), 0.05, 50.0, OK)
        on[i] = d.active or d.value_hz != 0.0
    # Exact rolling-24 h excitation time: interval i → i+1 is exciting when decision i was.
    excit = np.concatenate([[0.0], np.cumsum(on[:-1] * dt)])  # excitation up to ts[i]
    j = np.searchsorted(ts, ts - 86400.0)
    rolling = excit - excit[j]
    assert rolling.max() <= lim.budget_s_per_day + dt
    assert rolling[ts < 86400.0].max() >= lim.budget_s_per_day - 2 * dt  # the budget is actually usable
    assert on[(ts > 86400.0 + 600)].any()  # day 2 gets excitation again as day 1's minutes leave
    c = g.counters
    assert c.time_by_reason_s[BUDGET_EXHAUSTED] > 86400.0
    assert c.excitation_s == pytest.approx(on[:-1].sum() * dt)
    assert g.budget_used_s() <= lim.budget_s_per_day + dt


def test_counters_book_time_per_reason():
    g = SafetyGuard(GuardLimits(holdoff_s=2.0, rate_limit_hz_per_s=5.0))
    run_healthy(g, 0.0, 10.0, 0.5)  # hold-off 0 … 2 s, active 2 … 9.5 s
    for t in np.arange(10.0, 13.0, 0.5):
        g.step(float(t), 0.05, 50.5, OK)  # out of band 10 … 12.5 (booked until the next step)
    g.step(13.0, 0.05, 50.5, OK)
    c = g.counters
    assert c.time_by_reason_s[HOLDOFF] == pytest.approx(2.0)
    assert c.time_by_reason_s[FREQUENCY_OUT_OF_BAND] == pytest.approx(3.0)
    assert c.active_s == pytest.approx(8.0)
    assert c.inhibited_s == pytest.approx(5.0)
    assert c.trips_by_reason == {HOLDOFF: 1, FREQUENCY_OUT_OF_BAND: 1}
    assert c.steps == 27
    g.reset_counters()
    assert g.counters.steps == 0 and g.counters.time_by_reason_s == {}


# ---- invariants whatever goes in --------------------------------------------------------------------------

limits_st = st.builds(
    GuardLimits,
    amplitude_hz=st.floats(0.001, 0.1),
    rate_limit_hz_per_s=st.floats(0.01, 5.0),
    budget_s_per_day=st.floats(10.5, 60.0),
    budget_resume_s=st.just(1.0),
    band_hz=st.floats(0.02, 0.1),
    band_hysteresis_hz=st.just(0.005),
    holdoff_s=st.floats(1.0, 2.0),
    stale_after_s=st.floats(0.3, 5.0),
)
special = st.sampled_from([NAN, INF, -INF, 1e300, -1e300, -0.0, 5e-324])
time_st = st.one_of(
    st.tuples(st.just("dt"), st.floats(0.0, 0.3)),
    st.tuples(st.just("dt"), st.floats(0.05, 0.15)),
    st.tuples(st.just("dt"), st.floats(-5.0, 10.0)),
    st.tuples(st.just("abs"), special | st.floats(allow_nan=True, allow_infinity=True)),
)
any_float = st.floats(allow_nan=True, allow_infinity=True)
request_st = st.one_of(st.floats(-0.2, 0.2), st.floats(-0.2, 0.2), any_float, special)
freq_st = st.one_of(st.just(50.0), st.floats(49.8, 50.2), st.floats(49.95, 50.05), st.none(), any_float)
status_st = st.one_of(st.just(OK), st.just(OK), st.none(), st.integers(-(2**40), 2**40), st.booleans())
fcrd_st = st.one_of(st.just(False), st.just(False), st.just(False), st.booleans(), st.none())
action_st = st.sampled_from(["", "", "", "", "", "", "", "", "stop", "start"])
steps_st = st.lists(st.tuples(time_st, request_st, freq_st, status_st, fcrd_st, action_st),
                    min_size=1, max_size=150)


def check_invariants(lim: GuardLimits, steps) -> None:
    g = SafetyGuard(lim)
    t = 0.0
    last_now = None  # the last time the guard accepted (mirrors its rebase rule)
    prev_v, prev_tau = 0.0, 0.0
    was_stopped = False
    max_dt = 0.0
    for (kind, x), req, f, sw, fcrd, action in steps:
        if action == "stop":
            g.stop()
        elif action == "start":
            g.start()
            was_stopped = False
        if kind == "dt":
            t += x
            now = t
        else:
            now = x
        d = g.step(now, req, f, sw, fcrd)
        v = d.value_hz
        assert type(v) is float and math.isfinite(v)
        assert abs(v) <= lim.amplitude_hz
        assert set(d.reasons) <= ALL_REASONS and list(d.reasons) == sorted(set(d.reasons))
        assert d.dt_s >= 0.0 and d.t_s - prev_tau >= 0.0
        if last_now is None or not math.isfinite(now):
            assert d.dt_s == 0.0
        else:
            assert d.dt_s <= max(0.0, now - last_now)
        if INVALID_TIME not in d.reasons and math.isfinite(now):
            last_now = now
        max_dt = max(max_dt, d.dt_s)
        if d.hard or HOLDOFF in d.reasons:
            assert v == 0.0 and d.inhibited and not d.active
        else:  # every other change is rate-limited
            assert abs(v - prev_v) <= lim.rate_limit_hz_per_s * d.dt_s * (1 + 1e-9) + 1e-15
        if d.active:
            assert not (set(d.reasons) & (HARD_REASONS | {HOLDOFF, BUDGET_EXHAUSTED, STOPPING, STOPPED}))
            assert d.reasons == ()
        else:
            assert d.reasons
        if g.stopped:
            assert v == 0.0 and STOPPED in d.reasons
        if was_stopped:
            assert g.stopped  # once stopped, stays stopped until start()
        was_stopped = g.stopped
        # Overshoot: the step on which the budget ran out (booked whole), then the ramp down.
        assert g.budget_used_s() <= lim.budget_s_per_day + 2 * max_dt + lim.stop_time_bound_s + 1e-9
        prev_v, prev_tau = v, d.t_s
    c = g.counters
    assert c.steps == len(steps)
    assert all(s >= 0.0 and math.isfinite(s) for s in c.time_by_reason_s.values())


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(limits_st, steps_st)
def test_invariants_hold_whatever_goes_in(lim, steps):
    check_invariants(lim, steps)


healthy_step = st.tuples(st.tuples(st.just("dt"), st.floats(0.05, 0.2)), st.floats(-0.12, 0.12),
                         st.floats(49.97, 50.03), st.just(OK), st.just(False), st.just(""))


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(limits_st, st.lists(healthy_step, min_size=30, max_size=60), steps_st,
       st.lists(healthy_step, min_size=30, max_size=60))
def test_invariants_around_activity(lim, healthy1, chaos, healthy2):
    """Mostly healthy runs (so the guard is really active) with a burst of chaos in the middle."""
    check_invariants(lim, healthy1 + chaos + healthy2)


@settings(max_examples=100, deadline=None)
@given(limits_st, st.lists(st.floats(-0.1, 0.1), min_size=1, max_size=40), st.floats(0.01, 0.2))
def test_stop_always_reaches_exact_zero_in_bounded_time(lim, reqs, dt):
    g = SafetyGuard(lim)
    t = 0.0
    n_hold = math.ceil(lim.holdoff_s / dt) + 1
    for k in range(n_hold + len(reqs)):
        g.step(t, reqs[max(0, k - n_hold)], 50.0, OK)
        t += dt
    g.stop()
    n_max = math.ceil(lim.stop_time_bound_s / dt) + 1
    for _ in range(n_max):
        d = g.step(t, 0.1, 50.0, OK)
        t += dt
    assert g.stopped and d.value_hz == 0.0
