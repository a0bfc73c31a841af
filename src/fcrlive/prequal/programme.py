"""The prequalification test programme run on the simulated plant: which tests at which operating point,
each test simulated in the open-loop industry-test mode (the applied frequency replaces the governor's
speed feedback, the unit stays on the grid: :class:`fcrlive.sim.SimConfig` ``applied_freq_hz``), and
the unit description of the simulated plant (``[unit.prequal]``, docs/plant-toml.md).

Pure apart from the simulator: plans and logs in, :class:`fcrlive.tso.csvlog.TsoLog` out; the command
(``fcrlive simulate --tso-test``) writes the files.

Operating points. A description with ``[[unit.prequal.points]]`` is simulated at each point: set point
``power_mw`` (the turbine's Pm0 = power_mw / rated_mw) and droop ``droop`` (FCR-N tests) or
``droop_fcrd`` (FCR-D tests); every other parameter is the plant's. Without points, the plant runs at
its own operating point and droop as the only point, i.e. an entity that delivers FCR at a single set
point and a single droop (TR Section 5.1 exemptions: tests 2-4 omitted); every test ID of the programme
is then listed at that point.

Settling. The plant starts in steady state at 50 Hz; before each test it is held at the test's start
frequency for ``settle_tau`` times its slowest time constant (open-loop test set-up; 114 s for the
paper's plant 1), and that lead-in is not logged: the file starts where the TR's profile starts ("wait
until power is stable"). Sine tests get as many periods as it takes for the TR's stationary periods to
follow at least 5 time constants of sine (never fewer than the TR's recommended total). Every service
gets all ten periods of TR Table 6 (FCR-D needs 90-300 s only with mode shifting, but the TR lets the
provider test more, and Req. 8 and 9 are read over 10-300 s).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace
from datetime import datetime

import numpy as np

from fcrlive.plant.params import Plant
from fcrlive.prequal import profiles as pf
from fcrlive.tso.csvlog import TsoLog

__all__ = [
    "GROUPS",
    "PlannedTest",
    "SimPoint",
    "expand_names",
    "plan",
    "points_of",
    "run_test",
    "unit_toml",
]

GROUPS: dict[str, tuple[str, ...]] = {
    "fcrd-ramps": ("fcrd-up-ramps", "fcrd-down-ramps"),
    "fcrd-static": ("fcrd-static-up", "fcrd-static-down"),
    "linearity": ("linearity-fcrn", "linearity-fcrd-up", "linearity-fcrd-down"),
    "linearity-fcrd": ("linearity-fcrd-up", "linearity-fcrd-down"),
    "sines": ("sine-fcrn", "sine-fcrd-up", "sine-fcrd-down"),
    "sines-fcrn": ("sine-fcrn",),
    "sines-fcrd": ("sine-fcrd-up", "sine-fcrd-down"),
}
"""Names that stand for several profiles."""

ALL_DYNAMIC: tuple[str, ...] = (
    "fcrn-steps",
    "fcrd-up-ramps",
    "fcrd-down-ramps",
    "sine-fcrn",
    "sine-fcrd-up",
    "sine-fcrd-down",
    "linearity-fcrn",
    "linearity-fcrd-up",
    "linearity-fcrd-down",
    "operation",
)
"""``all`` for a unit with dynamic FCR-D (linearity tests included although a continuously controlled
unit needs them only for static FCR-D: they cost little and show the droop line)."""
ALL_STATIC: tuple[str, ...] = (
    *(n for n in ALL_DYNAMIC if n not in ("fcrd-up-ramps", "fcrd-down-ramps")),
    "fcrd-static-up",
    "fcrd-static-down",
)

TEST_NAMES: tuple[str, ...] = (*pf.PROFILE_NAMES, "operation")

# Table 21 corner index of the test IDs (1 high/high, 2 high/low, 3 low/high, 4 low/low) and the
# corners each test type is run at (TR Table 2b, Test Program Tables 2, 5, 8, 11, 13).
_CORNER_INDEX = {("high", "high"): 1, ("high", "low"): 2, ("low", "high"): 3, ("low", "low"): 4}
_LIN_INDEX = {("high", "low"): 1, ("low", "high"): 2}


@dataclass(frozen=True)
class SimPoint:
    """One operating point to simulate: the plant there and the test IDs run at it."""

    load: str
    droop_level: str
    power_mw: float
    droop: float
    droop_fcrd: float
    test_ids: tuple[str, ...]
    dp_ss_theo_mw: dict[str, float]

    @property
    def name(self) -> str:
        return f"{self.load} load, {self.droop_level} droop"

    def plant(self, base: Plant, service: str) -> Plant:
        """``base`` at this point's set point, with the droop of ``service``."""
        u = base.unit
        droop = self.droop if service == "Fcrn" else self.droop_fcrd
        return base.with_unit(
            turbine=replace(u.turbine, Pm0=self.power_mw / u.rated_mw),
            governor=replace(u.governor, droop=droop),
        )


@dataclass(frozen=True)
class PlannedTest:
    """One test of the programme: a profile (None for normal operation) at a point."""

    name: str
    service: str
    test_type: str
    """The [TestType] of the file name (test ID, ``Sine40`` or ``Operation``)."""
    test_id: str
    point: SimPoint
    profile: pf.Profile | None

    @property
    def label(self) -> str:
        what = (
            self.name
            if self.profile is None or self.profile.sine is None
            else (f"{self.name} {self.profile.sine.period_s:g} s")
        )
        return f"{self.test_id} {what} ({self.point.name})"


def _band_dp(band_hz: float, f0: float, droop: float, rated_mw: float) -> float:
    # TR Appendix 1 example 1: ΔP_ss,theo = Δf/(f0·ep)·P_rated, ep in pu on the rated power
    return band_hz / (f0 * droop) * rated_mw


def points_of(plant: Plant, prequal=None) -> tuple[SimPoint, ...]:
    """The operating points to simulate: the description's ``[[unit.prequal.points]]`` (a resolved
    :class:`fcrlive.plant.description.PrequalUnit`), or the plant's own point as the only one."""
    u = plant.unit
    rated, f0 = u.rated_mw, plant.grid.f0
    if prequal is not None and prequal.points:
        out = []
        for p in prequal.points:
            droop = p.droop if p.droop is not None else u.governor.droop
            power = p.power_mw if p.power_mw is not None else u.turbine.Pm0 * rated
            out.append(
                SimPoint(
                    load=p.load,
                    droop_level=p.droop_level,
                    power_mw=float(power),
                    droop=float(droop),
                    droop_fcrd=float(p.droop_fcrd if p.droop_fcrd is not None else droop),
                    test_ids=tuple(p.test_ids),
                    dp_ss_theo_mw=dict(p.dp_ss_theo_mw),
                )
            )
        return tuple(out)
    rho = u.governor.droop
    ids = (
        "1.1",
        "2.1",
        "3.1",
        "4.1",
        "4.2",
        "4.3",
        "5.1",
        "6.1",
        "7.1",
        "Operation",
    )
    dp = {
        "Fcrn": _band_dp(0.1, f0, rho, rated),
        "FcrdUp": _band_dp(0.4, f0, rho, rated),
        "FcrdDo": _band_dp(0.4, f0, rho, rated),
    }
    return (SimPoint("high", "high", u.turbine.Pm0 * rated, rho, rho, ids, dp),)


def expand_names(names: list[str] | tuple[str, ...], fcrd: str = "dynamic") -> tuple[str, ...]:
    """Test names with groups and ``all`` expanded, in programme order, without repeats.
    ValueError naming the known names for an unknown one."""
    out: list[str] = []
    for n in names:
        if n == "all":
            got = ALL_STATIC if fcrd == "static" else ALL_DYNAMIC
        elif n in GROUPS:
            got = GROUPS[n]
        elif n in TEST_NAMES:
            got = (n,)
        else:
            known = ", ".join([*TEST_NAMES, *GROUPS, "all"])
            raise ValueError(f"unknown test {n!r}; known: {known}")
        out.extend(g for g in got if g not in out)
    return tuple(out)


def _wanted_index(profile_kind: str, point: SimPoint) -> int | None:
    corner = (point.load, point.droop_level)
    if profile_kind == "linearity":
        return _LIN_INDEX.get(corner)
    return _CORNER_INDEX.get(corner)


def _runs_here(test_id: str, point: SimPoint, default_ok: bool) -> bool:
    # An explicit list of test IDs decides; the default mapping of Table 21 otherwise.
    return test_id in point.test_ids if point.test_ids else default_ok


def plan(
    names: tuple[str, ...],
    points: tuple[SimPoint, ...],
    *,
    endurance: bool = False,
    sine_periods: tuple[float, ...] | None = None,
) -> tuple[PlannedTest, ...]:
    """The tests of ``names`` (expanded) at the points where the TR runs them (Table 2b; a point's
    explicit ``test_ids`` decide). ``endurance``: the endurance variants (FCR-N steps, FCR-D ramps,
    static FCR-D) at the high-load low-droop point, or the first point when there is none.
    FCR-D ramps include ramps 7-8 (FCR-N/FCR-D combination) at the high-droop points."""
    out: list[PlannedTest] = []
    endurance_point = next((p for p in points if (p.load, p.droop_level) == ("high", "low")), points[0])
    for name in names:
        for point in points:
            endure = endurance and point is endurance_point
            if name == "operation":
                # TR 5.4 / Table 2b: one hour of normal operation at high load, low droop (or the only point)
                if _runs_here("Operation", point, point is endurance_point):
                    out.append(PlannedTest(name, "Fcrn", "Operation", "Operation", point, None))
                continue
            if name.startswith("sine-"):
                service = {"sine-fcrn": "Fcrn", "sine-fcrd-up": "FcrdUp", "sine-fcrd-down": "FcrdDo"}[name]
                tid = pf.SINE_TEST_ID[service]
                default = (point.load, point.droop_level) == (
                    ("high", "high") if service == "Fcrn" else ("high", "low")
                )
                if not _runs_here(tid, point, default):
                    continue
                for p in pf.sine_profiles(service, periods=sine_periods or pf.SINE_PERIODS_S):
                    out.append(PlannedTest(name, service, pf.tso_test_type(p), tid, point, p))
                continue
            p = pf.profile(
                name,
                endurance=endure,
                combination=name.endswith("ramps") and point.droop_level == "high",
            )
            index = _wanted_index(p.kind, point)
            if index is None and not point.test_ids:
                continue
            tid = pf.tso_test_id(p, index or 1)
            if point.test_ids and tid not in point.test_ids:
                # an explicit list may name the test at another index of this point
                tid = next((t for t in point.test_ids if t.rsplit(".", 1)[0] == tid.rsplit(".", 1)[0]), "")
                if not tid:
                    continue
            out.append(PlannedTest(name, p.service, tid, tid, point, p))
    return tuple(out)


# --------------------------------------------------------------------------------------------------
# Running one test


def _sine_periods_needed(p: pf.Profile, tau_s: float) -> pf.Profile:
    s = p.sine
    assert s is not None
    n = max(s.n_periods, s.n_stationary + math.ceil(5.0 * tau_s / s.period_s - 1e-9))
    return pf.sine(p.service, s.period_s, n_periods=n, amplitude_hz=s.amplitude_hz)


def run_test(
    base: Plant,
    test: PlannedTest,
    *,
    start: datetime,
    sample_s: float,
    snr_db: float | None,
    seed: int,
    operation_s: float = 3600.0,
    settle_tau: float = 8.0,
    test_noise_pu: float = 0.001,
) -> tuple[pf.Profile | None, TsoLog]:
    """Simulate one planned test and return (the profile as run, its TSO log).

    Noise: normal operation has the grid's load noise and process noise for ``snr_db`` (as ``fcrlive
    simulate --out``). In a test the governor sees the artificial signal, not the process noise, and
    the grid is kept quiet: the random-walk load of the paper's two-machine grid rings its lightly
    damped 1.8 Hz inter-machine mode by ±5 MW on the unit's power, which would bury the test's
    response; a test has a power meter noise of ``test_noise_pu`` of the rated power (std, white at
    Tc) only.

    Columns: ``InsAcPow`` [MW], ``GridFreq`` (the simulated grid frequency) [Hz], ``ApplFreqSig`` (the
    profile) [Hz], ``ContOutSig`` and ``GuideVane`` [%], ``CalcBaseline`` (the set point) [MW] and
    ``ContMode_<service>`` (the point's parameter set). Normal operation: the closed loop for
    ``operation_s`` as :func:`fcrlive.tso.signals.log_from_sim` writes it.
    """
    from fcrlive.sim import SimConfig, simulate
    from fcrlive.sim.linear import slowest_time_constant
    from fcrlive.tso.signals import log_from_sim

    plant = test.point.plant(base, test.service)
    if test.profile is None:
        res = simulate(plant, SimConfig(duration_s=operation_s, snr_db=snr_db, seed=seed))
        return None, log_from_sim(res, start=start, sample_s=sample_s, excitation=False)
    tau = slowest_time_constant(plant, open_loop=True)
    prof = test.profile
    if prof.sine is not None:
        prof = _sine_periods_needed(prof, tau)
    Tc = plant.unit.governor.Tc
    lead = math.ceil(settle_tau * tau / Tc) * Tc if math.isfinite(tau) else 0.0
    run = pf.with_lead_in(prof, lead)
    t, applied = run.sampled(Tc)
    res = simulate(
        plant,
        SimConfig(
            duration_s=len(t) * Tc,
            applied_freq_hz=applied,
            snr_db=None,
            process_noise_std=0.0,
            load_noise_std=0.0,
            meas_noise_power=test_noise_pu,
            seed=seed,
        ),
    )
    k = round(sample_s / Tc)
    if k < 1 or abs(k * Tc - sample_s) > 1e-9:
        raise ValueError(f"sample interval {sample_s} s is not a whole multiple of Tc = {Tc} s")
    i0 = round(lead / Tc)
    sel = slice(i0, None, k)
    n = len(t[sel])
    mode = f"{test.service.upper()}{_CORNER_INDEX.get((test.point.load, test.point.droop_level), 1)}"
    cols: dict[str, np.ndarray] = {
        "InsAcPow": res.pe_mw[sel],
        "GridFreq": res.grid_freq_hz[sel],
        "ApplFreqSig": applied[sel],
        "ContOutSig": 100.0 * res.c[sel],
        "GuideVane": 100.0 * res.a[sel],
        "CalcBaseline": np.full(n, res.p0_mw),
        f"ContMode_{test.service}": np.full(n, mode),
    }
    log = TsoLog.from_arrays(t[sel] - t[i0], cols, start, period_s=prof.period_s)
    return prof, log


def seeds(seed: int) -> Iterator[int]:
    """Independent noise per test: seed, seed + 1, ..."""
    k = seed
    while True:
        yield k
        k += 1


# --------------------------------------------------------------------------------------------------
# The unit description of the simulated plant


def _toml_str(s: str) -> str:
    import json

    return json.dumps(s)


def unit_toml(
    plant: Plant,
    points: tuple[SimPoint, ...],
    *,
    resource: str,
    area: str,
    fcrd: str = "dynamic",
    single_setpoint: bool = False,
    single_droop: bool = False,
) -> str:
    """The plant description of the simulated plant with its ``[unit.prequal]`` section (the format of
    :mod:`fcrlive.plant.prequal_unit`): resource, area, operating range, the simulated points with
    their droops and test IDs, ΔP_ss,theo by the droop method, the governor, and T_FME = the speed
    filter Tf (the simulated test signal replaces the measured frequency after the measurement).
    ``single_setpoint``/``single_droop``: the TR 5.1 exemptions the unit claims (written when true)."""
    from fcrlive.plant.description import plant_to_toml

    u = plant.unit
    g = u.governor
    lines = [
        plant_to_toml(plant).rstrip(),
        "",
        "# Prequalification data of the simulated unit (fcrlive simulate --tso-test)",
        "[unit.prequal]",
        f"resource = {_toml_str(resource)}",
        f"area = {_toml_str(area)}",
        # Maximum power: the turbine at full gate and static head, At·(g_max − q_nl)·rated
        f"p_max_mw = {float(u.turbine.At * (u.servo.g_max - u.turbine.q_nl) * u.rated_mw)!r}",
        'dp_ss_method = "droop"',
        # The simulated test signal enters after the speed measurement filter: an internal test
        # signal (TR 4.4) whose measurement dynamics are the filter's first-order lag.
        f"t_fme_s = {max(float(g.Tf), 1e-3)!r}",
        f"fcrd = {_toml_str(fcrd)}",
        *(["single_setpoint = true"] if single_setpoint else []),
        *(["single_droop = true"] if single_droop else []),
        "",
        "[unit.prequal.governor]",
        _toml_str(
            f"{'digital' if g.digital else 'analogue'} PI, droop in the "
            f"{g.droop_placement} channel from the {g.droop_signal}"
        ).join(("type = ", "")),
        f"settings = {{ Kp = {float(g.Kp)!r}, Ti = {float(g.Ti)!r}, droop = {float(g.droop)!r}, "
        f"Tf = {float(g.Tf)!r}, Tc = {float(g.Tc)!r} }}",
    ]
    for p in points:
        ids = ", ".join(_toml_str(t) for t in p.test_ids)
        lines += [
            "",
            "[[unit.prequal.points]]",
            f"load = {_toml_str(p.load)}",
            f"droop_level = {_toml_str(p.droop_level)}",
            f"power_mw = {float(p.power_mw)!r}",
            f"droop = {float(p.droop)!r}",
            f"droop_fcrd = {float(p.droop_fcrd)!r}",
            f"test_ids = [{ids}]",
        ]
    return "\n".join(lines) + "\n"
