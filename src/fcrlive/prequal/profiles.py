"""The applied-frequency profiles of the Nordic FCR prequalification tests (TR v1.1 Section 3, Test Program).

Each profile is the frequency signal that replaces the governor's measured frequency during a test
(TR Section 5, Figure 30): a piecewise-linear signal (holds, steps, ramps at a given rate) and, for the
sine tests, a sine superposed on it. Pure: no I/O; time in s from the start of the test, frequency in Hz.

The profiles and where they come from:

=======================  =========  ==========  ====================================================
name                     service    test IDs    source
=======================  =========  ==========  ====================================================
``fcrn-steps``           Fcrn       1.x         TR Table 3 (Test Program Table 3): 50 → 49.95 → 50 →
                                                49.9 → 50.1 → 50 Hz; 5-min steps, 15 min (endurance)
``fcrd-up-ramps``        FcrdUp     2.x         TR Table 4 (Test Program Table 6): ramps 1-6 (7-8 for
                                                the FCR-N/FCR-D combination); 900 s after ramp 3 when
                                                the endurance is tested
``fcrd-down-ramps``      FcrdDo     3.x         TR Table 4 (Test Program Table 9), mirrored at 50 Hz
``fcrd-static-up``       FcrdUp     2.x         TR Section 3.1.3 Table 5 (Test Program Table 12):
                                                49.9 → 49.5 Hz at 0.24 Hz/s, held 60/900/1800 s
``fcrd-static-down``     FcrdDo     3.x         TR Table 5 (Test Program Table 14), 50.1 → 50.5 Hz
``linearity-fcrn``       Fcrn       5.x         TR Section 3.4.2, Figure 14: 20 mHz steps 50 → 49.9
                                                → 50.1 → 50 Hz, 120 s each
``linearity-fcrd-up``    FcrdUp     6.x         TR 3.4.2, Figure 17: 100 mHz steps 49.9 → 49.5 Hz and
                                                back to 49.91 Hz, 120 s each
``linearity-fcrd-down``  FcrdDo     7.x         TR 3.4.2, Figure 18: 50.1 → 50.5 → 50.09 Hz
``sine-fcrn``            Fcrn       4.1         TR Table 6 (Test Program Table 4): 50 Hz ± 100 mHz,
                                                one profile (and file) per period
``sine-fcrd-up``         FcrdUp     4.2         TR Table 6: 49.7 Hz ± 100 mHz
``sine-fcrd-down``       FcrdDo     4.3         TR Table 6: 50.3 Hz ± 100 mHz
=======================  =========  ==========  ====================================================

Test IDs are those of TR Appendix 2 Table 21 (the digit after the dot is the operating point). The TR
gives the static FCR-D ramp test no test ID of its own: it takes the FCR-D ramp test's (2.x / 3.x), and
the evaluation tells the two apart from the applied frequency.
Sine files carry the period in the test type (``Sine40``, TR Section 6.2.1) and the test ID follows
from the service (4.1 FCR-N, 4.2 FCR-D up, 4.3 FCR-D down).

Ramp ends. The FCR-D tables give a ramp speed, a target frequency and a ramp end time, and three of
them disagree: ramp 1 (49.9 → 49.45 Hz at 0.14 Hz/s takes 3.21 s, the table says it ends at 33.1 s),
ramp 7 (50.0 → 49.7 Hz at 0.24 Hz/s takes 1.25 s, table 1050.8 s) and ramp 8 (49.7 → 49.89 Hz takes
0.79 s, table 1350.4 s). The profiles follow the speed and the target frequency (what the
requirements are read against: the activation levels and the ramp's start), so ramp 1 ends at
33.214 s, ramp 7 at 1051.25 s and ramp 8 at 1350.79 s; start times are the tables'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

__all__ = [
    "PROFILE_NAMES",
    "SINE_PERIODS_S",
    "SINE_STATIONARY",
    "SINE_TOTAL",
    "Event",
    "Profile",
    "SineSpec",
    "fcrd_ramps",
    "fcrd_static",
    "fcrn_steps",
    "linearity",
    "profile",
    "sine",
    "sine_profiles",
    "tso_test_id",
    "tso_test_type",
    "with_lead_in",
]

F0_HZ = 50.0

SINE_PERIODS_S: tuple[float, ...] = (10.0, 15.0, 25.0, 40.0, 50.0, 60.0, 70.0, 90.0, 150.0, 300.0)
"""Sine-test periods of TR Table 6 [s] (FCR-D: 90, 150, 300 s only with mode shifting)."""
SINE_STATIONARY: dict[float, int] = {
    10.0: 5,
    15.0: 5,
    25.0: 5,
    40.0: 5,
    50.0: 5,
    60.0: 5,
    70.0: 5,
    90.0: 5,
    150.0: 3,
    300.0: 2,
}
"""Stationary periods needed per period (TR Table 6)."""
SINE_TOTAL: dict[float, int] = {
    10.0: 20,
    15.0: 15,
    25.0: 10,
    40.0: 7,
    50.0: 7,
    60.0: 7,
    70.0: 7,
    90.0: 7,
    150.0: 4,
    300.0: 3,
}
"""Recommended total number of periods (TR Table 6, in brackets)."""
FCRD_SINE_PERIODS_S: tuple[float, ...] = (10.0, 15.0, 25.0, 40.0, 50.0, 60.0, 70.0)
"""FCR-D sine periods without mode shifting (Test Program Tables 7 and 10)."""

SINE_CENTRE_HZ: dict[str, float] = {"Fcrn": 50.0, "FcrdUp": 49.7, "FcrdDo": 50.3}
"""Centre of the sine tests per service (TR Table 6) [Hz]."""
SINE_TEST_ID: dict[str, str] = {"Fcrn": "4.1", "FcrdUp": "4.2", "FcrdDo": "4.3"}


@dataclass(frozen=True)
class Event:
    """A named instant of a profile (a step or the start of a ramp), for plots and evaluation."""

    label: str
    t_s: float
    f_hz: float
    """The frequency the step or ramp goes to [Hz]."""


@dataclass(frozen=True)
class SineSpec:
    """A sine superposed on the piecewise-linear part from ``start_s`` for ``n_periods`` periods."""

    period_s: float
    amplitude_hz: float
    start_s: float
    n_periods: int
    n_stationary: int
    """Periods the TR needs stationary (the last ones are evaluated)."""

    @property
    def end_s(self) -> float:
        return self.start_s + self.n_periods * self.period_s


@dataclass(frozen=True)
class Profile:
    """One test's applied frequency: knots (t, f) joined linearly, plus an optional sine.

    A step is two knots at the same time (the later one wins from that instant on); a hold is two
    knots with the same frequency. ``duration_s`` is the end of the test (the last knot).
    """

    name: str
    """Profile name (``fcrn-steps``, ``sine-fcrn`` ...)."""
    service: str
    """``Fcrn``, ``FcrdUp`` or ``FcrdDo``."""
    kind: str
    """``fcrn-steps``, ``fcrd-ramps``, ``fcrd-static``, ``linearity``, ``sine`` (as the evaluation's)."""
    knots_t: tuple[float, ...]
    knots_f: tuple[float, ...]
    source: str
    """Where the profile comes from (TR table or section)."""
    events: tuple[Event, ...] = ()
    sine: SineSpec | None = None
    variant: str = ""
    """``endurance``, ``combination``, ``LER`` ... or "" for the general test."""
    notes: tuple[str, ...] = field(default=())

    @property
    def duration_s(self) -> float:
        return float(self.knots_t[-1])

    @property
    def start_hz(self) -> float:
        return float(self.knots_f[0])

    @property
    def period_s(self) -> float | None:
        return None if self.sine is None else self.sine.period_s

    def frequency(self, t_s: np.ndarray | float) -> np.ndarray:
        """Applied frequency [Hz] at the times ``t_s`` [s] (held at the ends outside the profile)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        kt = np.asarray(self.knots_t)
        kf = np.asarray(self.knots_f)
        # Index of the last knot at or before t (the later of two knots at a step).
        i = np.clip(np.searchsorted(kt, t, side="right") - 1, 0, len(kt) - 1)
        j = np.minimum(i + 1, len(kt) - 1)
        span = kt[j] - kt[i]
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.where(span > 0, (t - kt[i]) / np.where(span > 0, span, 1.0), 0.0)
        w = np.clip(w, 0.0, 1.0)
        f = kf[i] + w * (kf[j] - kf[i])
        if self.sine is not None:
            s = self.sine
            on = (t >= s.start_s) & (t < s.end_s)
            f = f + np.where(on, s.amplitude_hz * np.sin(2.0 * math.pi * (t - s.start_s) / s.period_s), 0.0)
        return f

    def sampled(self, dt_s: float, duration_s: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(t, f) on the grid n·dt for n = 0 … N−1, N = round(duration/dt) (default the profile's)."""
        d = self.duration_s if duration_s is None else float(duration_s)
        n = max(2, round(d / dt_s))
        t = np.arange(n) * dt_s
        return t, self.frequency(t)


class _Builder:
    """Knots of a piecewise-linear frequency signal, built in time order."""

    def __init__(self, f_hz: float):
        self.t: list[float] = [0.0]
        self.f: list[float] = [float(f_hz)]
        self.events: list[Event] = []

    @property
    def now(self) -> float:
        return self.t[-1]

    def hold_until(self, t_s: float) -> None:
        if t_s < self.now - 1e-9:
            raise ValueError(f"hold until {t_s} s is before the profile's {self.now} s")
        if t_s > self.now:
            self.t.append(float(t_s))
            self.f.append(self.f[-1])

    def step(self, f_hz: float, label: str) -> None:
        self.events.append(Event(label, self.now, float(f_hz)))
        self.t.append(self.now)
        self.f.append(float(f_hz))

    def ramp(self, f_hz: float, rate_hz_s: float, label: str) -> None:
        self.events.append(Event(label, self.now, float(f_hz)))
        self.t.append(self.now + abs(f_hz - self.f[-1]) / rate_hz_s)
        self.f.append(float(f_hz))

    def build(self, **kw) -> Profile:
        return Profile(knots_t=tuple(self.t), knots_f=tuple(self.f), events=tuple(self.events), **kw)


def _mirror(f_hz: float, service: str) -> float:
    """A frequency of an FCR-D up profile moved to the down profile (mirrored at 50 Hz)."""
    return f_hz if service == "FcrdUp" else round(2.0 * F0_HZ - f_hz, 6)


def _check_service(service: str, allowed: tuple[str, ...]) -> None:
    if service not in allowed:
        raise ValueError(f"service must be one of {', '.join(allowed)}, got {service!r}")


# --------------------------------------------------------------------------------------------------
# The profiles


def fcrn_steps(*, endurance: bool = False) -> Profile:
    """FCR-N step sequence (TR Table 3): steps 1 and 2 held 5 min, or 15 min for the endurance test."""
    hold = 15.0 if endurance else 5.0
    b = _Builder(50.0)
    b.hold_until(30.0)
    b.step(49.95, "pre-step")
    b.hold_until(60.0)
    b.step(50.0, "step 0")
    b.hold_until(360.0)
    b.step(49.9, "step 1")
    b.hold_until(360.0 + hold * 60.0)
    b.step(50.1, "step 2")
    b.hold_until(360.0 + 2 * hold * 60.0)
    b.step(50.0, "step 3")
    b.hold_until(360.0 + 2 * hold * 60.0 + 300.0)
    return b.build(
        name="fcrn-steps",
        service="Fcrn",
        kind="fcrn-steps",
        source="TR v1.1 Table 3 (Test Program Table 3)",
        variant="endurance" if endurance else "",
    )


# Table 4: (ramp, start [s], speed [Hz/s], FCR-D up frequency [Hz], label)
_FCRD_RAMPS: tuple[tuple[int, float, float, float, str], ...] = (
    (1, 30.0, 0.14, 49.45, "activation test 1"),
    (2, 34.9, 0.09, 49.9, "deactivation test 1"),
    (3, 90.0, 0.24, 49.5, "steady state at full activation"),
    (4, 390.0, 0.24, 49.9, "steady state at zero activation"),
    (5, 690.0, 0.24, 49.0, "activation test 2"),
    (6, 750.0, 0.24, 50.0, "deactivation test 2"),
    (7, 1050.0, 0.24, 49.7, "FCR-N/FCR-D combination"),
    (8, 1350.0, 0.24, 49.89, "FCR-N/FCR-D combination"),
)


def fcrd_ramps(service: str, *, endurance: bool = False, combination: bool = False) -> Profile:
    """FCR-D fast ramp test (TR Table 4): ramps 1-6, with 7-8 when ``combination`` (FCR-N active at
    the high droop); the level after ramp 3 is held 900 s instead of 300 s when ``endurance``."""
    _check_service(service, ("FcrdUp", "FcrdDo"))
    shift = 600.0 if endurance else 0.0  # ramp 3 held 900 s: every later ramp 600 s later
    b = _Builder(_mirror(49.9, service))
    for n, start, speed, f_up, label in _FCRD_RAMPS:
        if n >= 7 and not combination:
            break
        b.hold_until(start + (shift if n >= 4 else 0.0))
        b.ramp(_mirror(f_up, service), speed, f"ramp {n}: {label}")
    b.hold_until((1650.0 if combination else 1050.0) + shift)
    variant = "+".join(v for v, on in (("endurance", endurance), ("combination", combination)) if on)
    return b.build(
        name="fcrd-up-ramps" if service == "FcrdUp" else "fcrd-down-ramps",
        service=service,
        kind="fcrd-ramps",
        source="TR v1.1 Table 4 (Test Program Tables 6 and 9)",
        variant=variant,
        notes=("ramp ends follow the ramp speed and target frequency (see fcrlive.prequal.profiles)",),
    )


def fcrd_static(service: str, *, endurance: bool = False, ler: bool = False) -> Profile:
    """Static FCR-D ramp test (TR Section 3.1.3, Table 5): 180 s at 49.9 Hz, a 0.24 Hz/s ramp to
    49.5 Hz held 60 s (900 s endurance, 1800 s for LER units), back to 49.9 Hz for 1200 s."""
    _check_service(service, ("FcrdUp", "FcrdDo"))
    hold = 1800.0 if ler else 900.0 if endurance else 60.0
    b = _Builder(_mirror(49.9, service))
    b.hold_until(180.0)
    b.ramp(_mirror(49.5, service), 0.24, "ramp 1: activation test 1")
    b.hold_until(180.0 + hold)
    b.ramp(_mirror(49.9, service), 0.24, "ramp 2: deactivation test 1")
    b.hold_until(180.0 + hold + 1200.0)
    return b.build(
        name="fcrd-static-up" if service == "FcrdUp" else "fcrd-static-down",
        service=service,
        kind="fcrd-static",
        source="TR v1.1 Section 3.1.3 Table 5 (Test Program Tables 12 and 14)",
        variant="LER" if ler else "endurance" if endurance else "",
    )


def _linearity_levels(service: str) -> tuple[float, ...]:
    if service == "Fcrn":
        down = [round(50.0 - 0.02 * k, 2) for k in range(6)]  # 50.00 … 49.90
        up = [round(49.90 + 0.02 * k, 2) for k in range(1, 11)]  # 49.92 … 50.10
        back = [round(50.10 - 0.02 * k, 2) for k in range(1, 6)]  # 50.08 … 50.00
        return (*down, *up, *back)
    # FCR-D: 100 mHz steps to full activation and back, the last step into the normal band
    levels = (49.9, 49.8, 49.7, 49.6, 49.5, 49.6, 49.7, 49.8, 49.91)
    return tuple(_mirror(f, service) for f in levels)


def linearity(service: str, *, step_s: float = 120.0) -> Profile:
    """Linearity step sequence (TR Section 3.4.2): FCR-N 20 mHz steps 50 → 49.9 → 50.1 → 50 Hz
    (Figure 14), FCR-D 100 mHz steps 49.9 → 49.5 → 49.91 Hz (Figures 17-18, mirrored for down).
    Each level is held ``step_s`` (at least 120 s: 60 s to settle, 60 s evaluated; up to 4 min of
    settling is allowed, so at most 300 s)."""
    _check_service(service, ("Fcrn", "FcrdUp", "FcrdDo"))
    if not 120.0 <= step_s <= 300.0:
        raise ValueError(f"step_s must be 120-300 s (TR 3.4.2), got {step_s}")
    levels = _linearity_levels(service)
    b = _Builder(levels[0])
    for k, f in enumerate(levels[1:], start=1):
        b.hold_until(k * step_s)
        b.step(f, f"step {k}")
    b.hold_until(len(levels) * step_s)
    names = {"Fcrn": "linearity-fcrn", "FcrdUp": "linearity-fcrd-up", "FcrdDo": "linearity-fcrd-down"}
    figure = {"Fcrn": "Figure 14", "FcrdUp": "Figure 17", "FcrdDo": "Figure 18"}[service]
    return b.build(
        name=names[service],
        service=service,
        kind="linearity",
        source=f"TR v1.1 Section 3.4.2, {figure} (Test Program Sections 3.3, 4.3, 5.3)",
    )


def sine(
    service: str,
    period_s: float,
    *,
    lead_in_s: float = 0.0,
    n_periods: int | None = None,
    amplitude_hz: float = 0.1,
) -> Profile:
    """One sine test (TR Section 3.2, Table 6): ``lead_in_s`` at the centre frequency (50, 49.7 or
    50.3 Hz), then ``n_periods`` periods of ±``amplitude_hz`` (default the recommended total of
    Table 6; never fewer than the stationary periods the TR needs)."""
    _check_service(service, ("Fcrn", "FcrdUp", "FcrdDo"))
    if not period_s > 0:
        raise ValueError(f"period_s must be positive, got {period_s}")
    need = SINE_STATIONARY.get(float(period_s), 5 if period_s <= 90 else 3 if period_s <= 150 else 2)
    total = SINE_TOTAL.get(float(period_s), need) if n_periods is None else int(n_periods)
    if total < need:
        raise ValueError(f"a {period_s:g} s sine needs at least {need} periods (TR Table 6), got {total}")
    if lead_in_s < 0:
        raise ValueError(f"lead_in_s must be >= 0, got {lead_in_s}")
    centre = SINE_CENTRE_HZ[service]
    b = _Builder(centre)
    b.hold_until(lead_in_s)
    start = b.now
    b.events.append(Event(f"sine {period_s:g} s", start, centre))
    b.hold_until(start + total * period_s)
    names = {"Fcrn": "sine-fcrn", "FcrdUp": "sine-fcrd-up", "FcrdDo": "sine-fcrd-down"}
    return b.build(
        name=names[service],
        service=service,
        kind="sine",
        source="TR v1.1 Section 3.2 Table 6 (Test Program Tables 4, 7, 10)",
        sine=SineSpec(float(period_s), float(amplitude_hz), start, total, need),
    )


def sine_profiles(service: str, *, periods: tuple[float, ...] | None = None, **kw) -> tuple[Profile, ...]:
    """The sine tests of one service: every period of Table 6 for FCR-N, the seven up to 70 s for FCR-D
    (90-300 s only with mode shifting) unless ``periods`` says otherwise."""
    if periods is None:
        periods = SINE_PERIODS_S if service == "Fcrn" else FCRD_SINE_PERIODS_S
    return tuple(sine(service, p, **kw) for p in periods)


# --------------------------------------------------------------------------------------------------
# By name


PROFILE_NAMES: tuple[str, ...] = (
    "fcrn-steps",
    "fcrd-up-ramps",
    "fcrd-down-ramps",
    "fcrd-static-up",
    "fcrd-static-down",
    "linearity-fcrn",
    "linearity-fcrd-up",
    "linearity-fcrd-down",
    "sine-fcrn",
    "sine-fcrd-up",
    "sine-fcrd-down",
)
"""Single profiles (the sine ones stand for one per period)."""


def profile(
    name: str,
    *,
    endurance: bool = False,
    combination: bool = False,
    ler: bool = False,
    period_s: float = 40.0,
    **sine_kw,
) -> Profile:
    """The profile called ``name`` (:data:`PROFILE_NAMES`); a sine profile for ``period_s``.
    ValueError naming the known names otherwise."""
    if name == "fcrn-steps":
        return fcrn_steps(endurance=endurance)
    if name in ("fcrd-up-ramps", "fcrd-down-ramps"):
        return fcrd_ramps(
            "FcrdUp" if "up" in name else "FcrdDo", endurance=endurance, combination=combination
        )
    if name in ("fcrd-static-up", "fcrd-static-down"):
        return fcrd_static("FcrdUp" if "up" in name else "FcrdDo", endurance=endurance, ler=ler)
    lin = {"linearity-fcrn": "Fcrn", "linearity-fcrd-up": "FcrdUp", "linearity-fcrd-down": "FcrdDo"}
    if name in lin:
        return linearity(lin[name])
    sines = {"sine-fcrn": "Fcrn", "sine-fcrd-up": "FcrdUp", "sine-fcrd-down": "FcrdDo"}
    if name in sines:
        return sine(sines[name], period_s, **sine_kw)
    raise ValueError(f"unknown test profile {name!r}; known: {', '.join(PROFILE_NAMES)}")


_ID_BASE = {
    "fcrn-steps": "1",
    "fcrd-ramps-FcrdUp": "2",
    "fcrd-ramps-FcrdDo": "3",
    "fcrd-static-FcrdUp": "2",
    "fcrd-static-FcrdDo": "3",
    "linearity-Fcrn": "5",
    "linearity-FcrdUp": "6",
    "linearity-FcrdDo": "7",
}


def tso_test_id(p: Profile, point: int = 1) -> str:
    """The TR Appendix 2 Table 21 test ID of profile ``p`` run at operating point ``point`` (1-4);
    sine tests: 4.1 / 4.2 / 4.3 by service."""
    if p.kind == "sine":
        return SINE_TEST_ID[p.service]
    key = p.kind if p.kind == "fcrn-steps" else f"{p.kind}-{p.service}"
    return f"{_ID_BASE[key]}.{int(point)}"


def tso_test_type(p: Profile, point: int = 1) -> str:
    """The [TestType] field of the TSO file name: the test ID, ``Sine<period>`` for a sine test."""
    if p.kind == "sine":
        assert p.sine is not None
        return f"Sine{p.sine.period_s:g}"
    return tso_test_id(p, point)


def with_lead_in(p: Profile, lead_in_s: float) -> Profile:
    """``p`` with ``lead_in_s`` more seconds at its starting frequency before it (events shifted)."""
    if lead_in_s <= 0:
        return p
    t = (0.0, *(x + lead_in_s for x in p.knots_t))
    f = (p.knots_f[0], *p.knots_f)
    ev = tuple(replace(e, t_s=e.t_s + lead_in_s) for e in p.events)
    sine_spec = None if p.sine is None else replace(p.sine, start_s=p.sine.start_s + lead_in_s)
    return replace(p, knots_t=t, knots_f=f, events=ev, sine=sine_spec)
