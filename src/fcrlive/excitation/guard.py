"""The safety guard: a pure state machine through which EVERY excitation value passes before it is written.

fcrlive may add a small excitation r[n] to the governor's frequency reference (paper Section 7.1). That
write is the one thing fcrlive does that can hurt a power station, so the value that reaches the writer
is never the generator's value but :attr:`GuardDecision.value_hz` from :meth:`SafetyGuard.step`.

Units: values in Hz of excitation added to the frequency reference (divide by f0 for pu of f0), rates in
Hz/s, times in s. ``now_s`` must come from a MONOTONIC clock (``time.monotonic()``): a clock that steps
backwards is treated as a fault.

Guarantees, whatever the inputs (NaN, ±inf, 1e300, time going backwards, None measurements, arbitrary
status words), for every decision:

- ``value_hz`` is finite and within ±``amplitude_hz``;
- either ``value_hz`` is exactly 0.0, or it moved from the previous value by at most
  ``rate_limit_hz_per_s · dt`` (dt the elapsed monotonic time since the previous valid step, 0 when the
  clock did not advance or was invalid);
- while a HARD interlock (see :data:`HARD_REASONS`) or the hold-off is present, ``value_hz`` is exactly 0.0:
  for a real governor, dropping a 0.1 Hz reference offset at once is the safe move when the grid is
  outside its band or the unit is not in FCR-N, so there is no ramp;
- on a normal :meth:`SafetyGuard.stop`, or when the daily budget runs out, the value ramps to zero at the
  rate limit and reaches exactly 0.0 within ``amplitude_hz / rate_limit_hz_per_s`` (at most 10 s) plus
  one step;
- every non-active decision carries reasons, and the guard keeps the time spent with each reason.

Re-enabling after any hard interlock needs ``holdoff_s`` of continuously healthy conditions (and the grid
frequency back inside the band by the hysteresis margin). The guard starts in that hold-off: nothing is
excited until all permissives have been fine for ``holdoff_s``.
"""

from __future__ import annotations

import math
import numbers
import operator
from collections import deque
from dataclasses import dataclass, fields
from typing import Any

from fcrlive.constants import F0_HZ
from fcrlive.errors import ConfigError

# ---- hard safe limits: GuardLimits rejects anything outside them -----------------------------------------

SAFE_MAX_AMPLITUDE_HZ = 0.1
"""Largest excitation amplitude [Hz]: the FCR-N band and the TSO's own sine-test amplitude (±100 mHz).
Beyond it the unit would answer the excitation with more than its full FCR-N capacity."""
SAFE_MIN_RATE_HZ_PER_S = 0.01
"""Smallest rate limit [Hz/s]: keeps the stop ramp from the full amplitude within 10 s."""
SAFE_MAX_RATE_HZ_PER_S = 5.0
"""Largest rate limit [Hz/s]: a full ±0.1 Hz swing takes at least 40 ms (two samples at 50 Hz)."""
SAFE_MAX_BUDGET_S = 4 * 3600.0
"""Largest excitation budget per rolling 24 h [s]: identification is meant to be non-intrusive."""
SAFE_MAX_BAND_HZ = 0.1
"""Widest frequency interlock band [Hz]: the FCR-N band; beyond ±0.1 Hz FCR-D may activate."""
SAFE_MAX_STALE_S = 5.0
"""Longest tolerated age of the grid-frequency measurement [s] (and longest gap between steps)."""
SAFE_MIN_HOLDOFF_S = 1.0
SAFE_MAX_HOLDOFF_S = 3600.0

BUDGET_WINDOW_S = 86400.0
"""The budget is counted over a ROLLING 24 h window of the guard's monotonic time (not a UTC calendar day:
a calendar day would allow two budgets back to back around midnight, and a monotonic clock has no date)."""
BUDGET_BUCKET_S = 60.0
"""Excitation time is booked in 1-minute buckets, each booked at the END of its interval; a bucket counts
until its whole minute has left the window, so the budget is enforced conservatively (never too late)."""
GROSS_REQUEST_FACTOR = 2.0
"""A finite request beyond ±amplitude is clamped, but one beyond GROSS_REQUEST_FACTOR·amplitude is a sign
of a broken caller (mHz passed as Hz gives 1000×) and is rejected as ``invalid_request`` (hard)."""

# ---- reasons -----------------------------------------------------------------------------------------------

INVALID_TIME = "invalid_time"
CLOCK_BACKWARDS = "clock_backwards"
STEP_GAP = "step_gap"
INVALID_REQUEST = "invalid_request"
INVALID_MEASUREMENT = "invalid_measurement"
STALE_MEASUREMENT = "stale_measurement"
FREQUENCY_OUT_OF_BAND = "frequency_out_of_band"
FCRD_ACTIVE = "fcrd_active"
FCRD_UNKNOWN = "fcrd_unknown"
STATUS_UNKNOWN = "not_permitted:status_unknown"
STATUS_INVALID = "not_permitted:status_invalid"
FCRN_INACTIVE = "not_permitted:fcrn_inactive"
ABNORMAL_OPERATION = "not_permitted:abnormal_operation"
HOLDOFF = "holdoff"
BUDGET_EXHAUSTED = "budget_exhausted"
STOPPING = "stopping"
STOPPED = "stopped"

HARD_REASONS: frozenset[str] = frozenset({
    INVALID_TIME, CLOCK_BACKWARDS, STEP_GAP, INVALID_REQUEST, INVALID_MEASUREMENT, STALE_MEASUREMENT,
    FREQUENCY_OUT_OF_BAND, FCRD_ACTIVE, FCRD_UNKNOWN, STATUS_UNKNOWN, STATUS_INVALID, FCRN_INACTIVE,
    ABNORMAL_OPERATION,
})
"""Reasons that force the output to exactly 0.0 at once and restart the hold-off."""
SOFT_REASONS: frozenset[str] = frozenset({BUDGET_EXHAUSTED, STOPPING})
"""Reasons that ramp the output to zero at the rate limit."""
ALL_REASONS: frozenset[str] = HARD_REASONS | SOFT_REASONS | {HOLDOFF, STOPPED}

STATUS_BIT_FCRN_ACTIVE = 0x1
"""Device status word bit 0: FCR-N active."""
STATUS_BIT_NORMAL_OPERATION = 0x2
"""Device status word bit 1: unit in normal operation."""
STATUS_WORD_MAX = 0xFFFF_FFFF
"""A status word is one or two registers; anything else (negative, wider) is invalid."""


def _real(value: Any) -> float | None:
    """``value`` as a float if it is a real number (bools are not), else None. May be non-finite."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    try:
        return float(value)
    except (OverflowError, ValueError, TypeError):
        return None


def _fcrd_reasons(fcrd_active: bool | None) -> set[str]:
    """FCR-D activated, or unknown (None, or an object that cannot say whether it is true)."""
    if fcrd_active is None:
        return {FCRD_UNKNOWN}
    try:
        return {FCRD_ACTIVE} if bool(fcrd_active) else set()
    except Exception:  # an object that cannot say whether it is true: unknown
        return {FCRD_UNKNOWN}


def _status_reasons(status_word: int | None) -> set[str]:
    """The device status word's permissives: known, a valid word, FCR-N active, normal operation."""
    if status_word is None:
        return {STATUS_UNKNOWN}
    try:
        sw = operator.index(status_word)
    except TypeError:
        sw = -1
    if isinstance(status_word, bool) or not (0 <= sw <= STATUS_WORD_MAX):
        return {STATUS_INVALID}
    reasons = set()
    if not sw & STATUS_BIT_FCRN_ACTIVE:
        reasons.add(FCRN_INACTIVE)
    if not sw & STATUS_BIT_NORMAL_OPERATION:
        reasons.add(ABNORMAL_OPERATION)
    return reasons


@dataclass(frozen=True)
class GuardLimits:
    """Limits of the safety guard; validated against the hard safe limits of this module.

    Raises :class:`fcrlive.errors.ConfigError` naming the field when a value is not a finite number or is
    outside its safe range (the error also carries ``.field``).
    """

    amplitude_hz: float = 0.1
    """Largest |r| written [Hz] (default 0.1 Hz = 0.002 pu of 50 Hz, the paper's 3σ); (0, 0.1]."""
    rate_limit_hz_per_s: float = 1.0
    """Largest |dr/dt| [Hz/s]; [0.01, 5]. Also the rate of the stop ramp."""
    budget_s_per_day: float = 3600.0
    """Excitation time allowed per rolling 24 h [s]; (0, 14400]. Time counts while active or non-zero."""
    budget_resume_s: float = 300.0
    """After the budget ran out, remaining budget needed before excitation resumes [s]; [0, budget].
    Avoids chattering on and off as old minutes leave the window."""
    band_hz: float = 0.1
    """Excitation only while |f − f0| ≤ band_hz [Hz]; (0, 0.1]."""
    band_hysteresis_hz: float = 0.01
    """After leaving the band, f must return to |f − f0| ≤ band_hz − hysteresis [Hz]; [0, band_hz)."""
    holdoff_s: float = 30.0
    """Continuously healthy time needed before (re-)enabling after a hard interlock or at start [s];
    [1, 3600]."""
    stale_after_s: float = 1.0
    """A grid-frequency measurement older than this inhibits [s]; so does a gap this long between steps;
    (0, 5]."""

    def __post_init__(self) -> None:
        ranges: dict[str, tuple[float, float, bool, str]] = {
            # name: (low, high, low_inclusive, why the high limit)
            "amplitude_hz": (0.0, SAFE_MAX_AMPLITUDE_HZ, False, "the FCR-N band / TSO sine-test amplitude"),
            "rate_limit_hz_per_s": (SAFE_MIN_RATE_HZ_PER_S, SAFE_MAX_RATE_HZ_PER_S, True,
                                    "a full swing must take at least 40 ms"),
            "budget_s_per_day": (0.0, SAFE_MAX_BUDGET_S, False, "identification must stay non-intrusive"),
            "budget_resume_s": (0.0, math.inf, True, ""),
            "band_hz": (0.0, SAFE_MAX_BAND_HZ, False, "the FCR-N band; FCR-D may act beyond it"),
            "band_hysteresis_hz": (0.0, math.inf, True, ""),
            "holdoff_s": (SAFE_MIN_HOLDOFF_S, SAFE_MAX_HOLDOFF_S, True, ""),
            "stale_after_s": (0.0, SAFE_MAX_STALE_S, False, "older frequency data cannot protect the grid"),
        }
        for f in fields(self):
            raw = getattr(self, f.name)
            value = _real(raw)
            if value is None or not math.isfinite(value):
                raise _limit_error(f.name, f"{f.name} = {raw!r} is not a finite number")
            low, high, low_inclusive, why = ranges[f.name]
            if value < low or (value == low and not low_inclusive):
                op = "≥" if low_inclusive else ">"
                raise _limit_error(f.name, f"{f.name} = {value!r} must be {op} {low!r}")
            if value > high:
                raise _limit_error(f.name, f"{f.name} = {value!r} is above its safe maximum {high!r}"
                                   + (f" ({why})" if why else ""))
            object.__setattr__(self, f.name, value)
        if self.budget_resume_s > self.budget_s_per_day:
            raise _limit_error("budget_resume_s", f"budget_resume_s = {self.budget_resume_s!r} must not "
                               f"exceed budget_s_per_day = {self.budget_s_per_day!r}")
        if self.budget_s_per_day <= self.stop_time_bound_s:
            raise _limit_error("budget_s_per_day", f"budget_s_per_day = {self.budget_s_per_day!r} s must "
                               "exceed the stop ramp amplitude_hz/rate_limit_hz_per_s = "
                               f"{self.stop_time_bound_s!r} s")
        if self.band_hysteresis_hz >= self.band_hz:
            raise _limit_error("band_hysteresis_hz", f"band_hysteresis_hz = {self.band_hysteresis_hz!r} "
                               f"must be below band_hz = {self.band_hz!r}")

    @classmethod
    def from_mapping(cls, data: dict[str, Any]) -> GuardLimits:
        """Build from a config mapping; unknown keys are an error (a typo must not silently fall back)."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(f"unknown excitation guard limit(s) {', '.join(unknown)}; "
                              f"known: {', '.join(sorted(known))}")
        return cls(**data)

    @property
    def stop_time_bound_s(self) -> float:
        """Longest stop ramp from full amplitude to exactly 0.0 [s] (plus one step)."""
        return self.amplitude_hz / self.rate_limit_hz_per_s


def _limit_error(name: str, message: str) -> ConfigError:
    err = ConfigError(f"excitation guard: {message}")
    err.field = name  # type: ignore[attr-defined]
    return err


@dataclass(frozen=True)
class GuardDecision:
    """What the guard allows to be written at one step.

    ``value_hz`` is the ONLY value that may be written [Hz]. ``active`` means the request is being
    followed (possibly clamped or rate-limited); ``inhibited`` means an interlock, the hold-off or the
    budget keeps the request from being followed. ``reasons`` lists every condition present (sorted).
    """

    t_s: float
    """The guard's monotonic time τ [s] (0 at the first step; does not advance on invalid/backward time)."""
    dt_s: float
    """Time credited at this step [s]: now − previous accepted now, 0 on invalid or backward time, at most
    one day after a gap. The rate limit is applied over this."""
    value_hz: float
    requested_hz: float
    """The request as received (may be NaN/inf: it is only recorded)."""
    active: bool
    inhibited: bool
    reasons: tuple[str, ...]
    clamped: bool
    """The request was beyond ±amplitude and was clamped."""
    rate_limited: bool
    """The rate limit kept the value from reaching its target at this step."""

    @property
    def hard(self) -> bool:
        """A hard interlock is present (value is then exactly 0.0)."""
        return any(r in HARD_REASONS for r in self.reasons)


@dataclass(frozen=True)
class GuardCounters:
    """Accumulated times [s] and counts since construction (or :meth:`SafetyGuard.reset_counters`).

    A step's time is booked to the decision that was in force during it (the written value is held).
    """

    steps: int
    elapsed_s: float
    active_s: float
    excitation_s: float
    """Time active or with a non-zero value written (what the budget counts)."""
    inhibited_s: float
    time_by_reason_s: dict[str, float]
    """Time with each reason present [s]; reasons overlap, so these do not sum to inhibited_s."""
    trips_by_reason: dict[str, int]
    """How often each reason appeared (was absent at the previous step)."""
    clamped_steps: int
    rate_limited_steps: int


class SafetyGuard:
    """The safety state machine; see the module docstring for its guarantees.

    >>> g = SafetyGuard(GuardLimits(holdoff_s=1.0))
    >>> [g.step(t / 10, 0.05, 50.0, 0b11).value_hz for t in range(3)]
    [0.0, 0.0, 0.0]
    """

    def __init__(self, limits: GuardLimits | None = None, f0: float = F0_HZ):
        f0v = _real(f0)
        if f0v is None or not (40.0 <= f0v <= 70.0):
            raise ConfigError(f"excitation guard: f0 = {f0!r} Hz is not a nominal grid frequency (40-70 Hz)")
        self.limits = limits if limits is not None else GuardLimits()
        self.f0 = f0v
        self._last_now: float | None = None
        self._tau = 0.0
        self._value = 0.0
        self._prev: GuardDecision | None = None
        self._stop_requested = False
        self._stopped = False
        self._healthy_since: float | None = None
        self._last_freq: float | None = None
        self._last_fresh: float | None = None
        self._in_band = False
        self._budget_exhausted = False
        self._ledger: deque[list[float]] = deque()  # [bucket index, seconds]
        self.reset_counters()

    # ---- control ------------------------------------------------------------------------------------------

    def stop(self) -> None:
        """Ramp to zero at the rate limit from the next step on; :attr:`stopped` once exactly 0.0."""
        self._stop_requested = True
        if self._value == 0.0:
            self._stopped = True

    def start(self) -> None:
        """Re-arm after :meth:`stop`. Interlocks, hold-off and budget still apply."""
        self._stop_requested = False
        self._stopped = False

    @property
    def stopped(self) -> bool:
        """True once a stop was requested and the written value is exactly 0.0."""
        return self._stopped

    @property
    def stopping(self) -> bool:
        return self._stop_requested

    @property
    def value_hz(self) -> float:
        """The last value the guard allowed [Hz] (0.0 before the first step)."""
        return self._value

    # ---- budget -------------------------------------------------------------------------------------------

    def budget_used_s(self) -> float:
        """Excitation time booked in the rolling 24 h window ending now [s] (conservative, see module)."""
        self._expire_ledger()
        return sum(sec for _, sec in self._ledger)

    def budget_remaining_s(self) -> float:
        return max(0.0, self.limits.budget_s_per_day - self.budget_used_s())

    def _expire_ledger(self) -> None:
        # A bucket k covers [60k, 60k + 60); keep it while any of it is inside (τ − 24 h, τ].
        oldest = math.floor((self._tau - BUDGET_WINDOW_S) / BUDGET_BUCKET_S)
        while self._ledger and self._ledger[0][0] <= oldest:
            self._ledger.popleft()

    def _book(self, seconds: float) -> None:
        seconds = min(seconds, BUDGET_WINDOW_S)
        bucket = math.floor(self._tau / BUDGET_BUCKET_S)
        if self._ledger and self._ledger[-1][0] == bucket:
            self._ledger[-1][1] += seconds
        else:
            self._ledger.append([bucket, seconds])

    # ---- counters -----------------------------------------------------------------------------------------

    def reset_counters(self) -> None:
        """Zero the counters (e.g. at the start of each report period); the budget ledger is kept."""
        self._c_steps = 0
        self._c_elapsed = 0.0
        self._c_active = 0.0
        self._c_excitation = 0.0
        self._c_inhibited = 0.0
        self._c_by_reason: dict[str, float] = {}
        self._c_trips: dict[str, int] = {}
        self._c_clamped = 0
        self._c_rate_limited = 0

    @property
    def counters(self) -> GuardCounters:
        return GuardCounters(
            steps=self._c_steps, elapsed_s=self._c_elapsed, active_s=self._c_active,
            excitation_s=self._c_excitation, inhibited_s=self._c_inhibited,
            time_by_reason_s=dict(self._c_by_reason), trips_by_reason=dict(self._c_trips),
            clamped_steps=self._c_clamped, rate_limited_steps=self._c_rate_limited)

    # ---- the step -----------------------------------------------------------------------------------------

    def step(self, now_s: float, requested_hz: float, grid_freq_hz: float | None, status_word: int | None,
             fcrd_active: bool | None = False, measured_at_s: float | None = None) -> GuardDecision:
        """Decide the value that may be written now.

        ``now_s``: monotonic time [s]. ``requested_hz``: the generator's r [Hz]. ``grid_freq_hz``: a NEW
        grid-frequency measurement [Hz], or None when none arrived since the last step (the previous one
        keeps being used until it is older than ``stale_after_s``). ``measured_at_s``: when it was measured,
        on the same clock as ``now_s`` (default: now). ``status_word``: the device status word (bit 0 FCR-N
        active, bit 1 normal operation; None = unknown). ``fcrd_active``: FCR-D activated (None = unknown).

        The phases, in order (each adds the reasons it finds): time, measurement, permissives, request,
        hold-off, budget, stop; then the value, and the decision is recorded.
        """
        reasons: set[str] = set()
        now, dt = self._advance_time(now_s, reasons)
        self._take_measurement(grid_freq_hz, measured_at_s, now, reasons)
        self._check_frequency(reasons)
        reasons |= _fcrd_reasons(fcrd_active) | _status_reasons(status_word)
        requested, target, clamped = self._clamp_request(requested_hz, reasons)
        hard = self._check_holdoff(reasons)
        self._check_budget(reasons)
        if self._stop_requested:
            reasons.add(STOPPING)
        value, rate_limited = self._next_value(target, dt, hard, reasons)
        self._update_stopped(value, reasons)

        inhibited = hard or bool(reasons & {HOLDOFF, BUDGET_EXHAUSTED})
        active = not inhibited and not self._stop_requested
        decision = GuardDecision(
            t_s=self._tau, dt_s=dt, value_hz=value, requested_hz=requested, active=active,
            inhibited=inhibited, reasons=tuple(sorted(reasons)), clamped=clamped and active,
            rate_limited=rate_limited)
        self._record(decision)
        return decision

    # ---- the phases of a step (each one idea; ``reasons`` collects what they find) -------------------------

    def _advance_time(self, now_s: float, reasons: set[str]) -> tuple[float | None, float]:
        """(now as a real number or None, dt credited) after advancing τ and booking the interval just ended.

        The guard runs on its own monotonic time τ, advanced only by valid forward steps, so a bad clock can
        never open a hold-off or age the budget early.
        """
        now = _real(now_s)
        dt = 0.0
        if now is None or not math.isfinite(now):
            reasons.add(INVALID_TIME)
        elif self._last_now is not None and now < self._last_now:
            reasons.add(CLOCK_BACKWARDS)
            self._last_now = now  # rebase: otherwise a clock stepped back 1 h would block for 1 h
        else:
            if self._last_now is not None:
                dt = now - self._last_now
                if not math.isfinite(dt) or not math.isfinite(self._tau + dt):
                    reasons.add(INVALID_TIME)
                    dt = 0.0
                elif dt > self.limits.stale_after_s:
                    reasons.add(STEP_GAP)  # nobody called us: the writer loop stalled
                    # Credit at most one budget window: enough to expire the whole ledger, and it keeps τ
                    # small enough that later steps of milliseconds still advance it (1e300 + 0.1 == 1e300).
                    dt = min(dt, BUDGET_WINDOW_S)
            if INVALID_TIME not in reasons:
                self._last_now = now
        self._tau += dt
        self._account(dt)
        return now, dt

    def _take_measurement(self, grid_freq_hz: float | None, measured_at_s: float | None, now: float | None,
                          reasons: set[str]) -> None:
        """Keep a new valid grid frequency and when it was fresh (on τ); flag invalid or stale ones."""
        if grid_freq_hz is not None:
            f = _real(grid_freq_hz)
            age = 0.0
            if measured_at_s is not None:
                at = _real(measured_at_s)
                if at is None or now is None or not math.isfinite(at) or not math.isfinite(now):
                    age = math.nan
                else:
                    age = now - at
            if f is None or not math.isfinite(f) or not (age >= 0.0):  # future timestamps are invalid too
                reasons.add(INVALID_MEASUREMENT)
            else:
                self._last_freq = f
                self._last_fresh = self._tau - age
        if self._last_fresh is None or self._tau - self._last_fresh > self.limits.stale_after_s:
            reasons.add(STALE_MEASUREMENT)

    def _check_frequency(self, reasons: set[str]) -> None:
        """The band interlock with hysteresis on the last grid frequency."""
        lim = self.limits
        if self._last_freq is not None:
            dev = abs(self._last_freq - self.f0)
            if self._in_band and dev > lim.band_hz:
                self._in_band = False
            elif not self._in_band and dev <= lim.band_hz - lim.band_hysteresis_hz:
                self._in_band = True
            if not self._in_band:
                reasons.add(FREQUENCY_OUT_OF_BAND)

    def _clamp_request(self, requested_hz: float, reasons: set[str]) -> tuple[float, float, bool]:
        """(the request as recorded, the target within ±amplitude, whether it was clamped)."""
        lim = self.limits
        req = _real(requested_hz)
        requested = req if req is not None else math.nan
        target = 0.0
        clamped = False
        if req is None or not math.isfinite(req) or abs(req) > GROSS_REQUEST_FACTOR * lim.amplitude_hz:
            reasons.add(INVALID_REQUEST)
        else:
            clamped = abs(req) > lim.amplitude_hz
            target = min(max(req, -lim.amplitude_hz), lim.amplitude_hz)
        return requested, target, clamped

    def _check_holdoff(self, reasons: set[str]) -> bool:
        """Whether a hard reason is present. Every hard reason restarts the hold-off; healthy time counts
        from the first healthy step."""
        hard = bool(reasons & HARD_REASONS)
        if hard:
            self._healthy_since = None
        elif self._healthy_since is None:
            self._healthy_since = self._tau
        if not hard and self._tau - self._healthy_since < self.limits.holdoff_s:
            reasons.add(HOLDOFF)
        return hard

    def _check_budget(self, reasons: set[str]) -> None:
        """Budget with hysteresis: stop early enough that the ramp down also fits in the budget."""
        lim = self.limits
        remaining = lim.budget_s_per_day - self.budget_used_s()
        if not self._budget_exhausted and remaining <= lim.stop_time_bound_s:
            self._budget_exhausted = True
        elif self._budget_exhausted and remaining >= min(lim.budget_s_per_day,
                                                         lim.budget_resume_s + lim.stop_time_bound_s):
            self._budget_exhausted = False
        if self._budget_exhausted:
            reasons.add(BUDGET_EXHAUSTED)

    def _next_value(self, target: float, dt: float, hard: bool, reasons: set[str]) -> tuple[float, bool]:
        """(the value to write, whether the rate limit held it back): exactly 0.0 under a hard reason or the
        hold-off, a ramp to 0.0 under a soft one, else towards ``target`` at the rate limit."""
        lim = self.limits
        prev = self._value
        rate_limited = False
        if hard or HOLDOFF in reasons:
            value = 0.0
        else:
            if reasons & SOFT_REASONS:
                target = 0.0
            max_step = lim.rate_limit_hz_per_s * dt
            delta = target - prev
            if abs(delta) <= max_step:
                value = target  # reaches 0.0 exactly on a ramp down
            else:
                value = prev + math.copysign(max_step, delta)
                rate_limited = True
        value = min(max(value, -lim.amplitude_hz), lim.amplitude_hz) + 0.0  # + 0.0 turns −0.0 into 0.0
        if not math.isfinite(value):  # cannot happen; the last line of defence costs nothing
            value = 0.0
        self._value = value
        return value, rate_limited

    def _update_stopped(self, value: float, reasons: set[str]) -> None:
        """A requested stop is complete once the value is exactly 0.0; then STOPPED replaces STOPPING."""
        if self._stop_requested and value == 0.0:
            self._stopped = True
        if self._stopped:
            reasons.discard(STOPPING)
            reasons.add(STOPPED)

    def _record(self, decision: GuardDecision) -> None:
        """Count the step, its newly present reasons (trips), clamping and rate limiting."""
        prev_reasons = set(self._prev.reasons) if self._prev is not None else set()
        for r in decision.reasons:  # sorted: new reasons enter the trip counts in a reproducible order
            if r not in prev_reasons:
                self._c_trips[r] = self._c_trips.get(r, 0) + 1
        self._c_steps += 1
        self._c_clamped += decision.clamped
        self._c_rate_limited += decision.rate_limited
        self._prev = decision

    def _account(self, dt: float) -> None:
        """Book the interval just ended (length dt [s]) to the decision that was in force during it."""
        p = self._prev
        if p is None or dt <= 0.0:
            return
        self._c_elapsed += dt
        if p.active:
            self._c_active += dt
        if p.inhibited:
            self._c_inhibited += dt
        for r in p.reasons:
            self._c_by_reason[r] = self._c_by_reason.get(r, 0.0) + dt
        if p.active or p.value_hz != 0.0:
            self._c_excitation += dt
            self._book(dt)
