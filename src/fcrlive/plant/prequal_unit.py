"""The ``[unit.prequal]`` section of a plant description: what a Nordic FCR prequalification needs to
know about the unit (TR v1.1 Sections 2.3, 5.1, Appendix 1-2) beyond its dynamic model.

Format (docs/plant-toml.md, "Prequalification data")::

    [unit.prequal]
    resource = "FCPG1"          # resource id of the TSO file names
    area = "NO5"                # bidding zone
    p_min_mw = 60.0             # operating range [MW]
    p_max_mw = 300.0
    dp_ss_method = "droop"      # "droop": ΔP_ss,theo = Δf/(f0·ep)·rated_mw (TR App. 1 ex. 1); "table";
                                # "curve": eqs. 37-39 from [unit.prequal.power_curve] (App. 1 ex. 2)
    t_fme_s = 1.0               # only when the sine test signal is generated inside the controller
    fcrd = "dynamic"            # or "static" (TR 3.1.3)
    continuous = true           # false: non-continuous control, the linearity steps (Req. 11) apply
    mode_shifting = false       # FCR-D mode shifting (Req. 13)
    fcrn_exemption = false      # Req. 8 FCR-N exemption to 75 % granted by the TSO
    single_setpoint = false     # FCR at one power set point only: TR 5.1 exempts the low-load tests
    single_droop = false        # FCR at one droop setting only: TR 5.1 exempts the low-droop tests
    power_accuracy_pct = 0.5    # stated accuracy of the measurement chain (TR 4.1)
    frequency_accuracy_mhz = 10
    [unit.prequal.governor]
    type = "digital PI, droop on gate"
    settings = { Kp = 1.0, Ti = 9.1 }
    [[unit.prequal.points]]     # the tested operating points (TR 5.1: load x droop corners)
    load = "high"               # high | low
    droop_level = "high"        # high | low
    power_mw = 280.0            # set point [MW]
    droop = 0.08                # ep, FCR-N [pu on rated_mw]; droop_fcrd for FCR-D when different
    dp_ss_theo_mw = { Fcrn = 7.5, FcrdUp = 30.0, FcrdDo = 30.0 }   # required with "table"

H and Kd are the ``[unit.swing]`` keys and the rated power ``[unit] rated_mw``: one description, no
second copy. This module is pure (schema and resolution); the file is read by plant/description.py.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from fcrlive.errors import ConfigError

if TYPE_CHECKING:
    from fcrlive.plant.params import Plant

PREQUAL_SERVICES: tuple[str, ...] = ("Fcrn", "FcrdUp", "FcrdDo")
BAND_HZ: Mapping[str, float] = MappingProxyType({"Fcrn": 0.1, "FcrdUp": 0.4, "FcrdDo": 0.4})
"""One-sided frequency change of full activation per service [Hz] (TR App. 1: 0.1 FCR-N, 0.4 FCR-D)."""

DEFAULT_TEST_POINTS: Mapping[str, tuple[str, str]] = MappingProxyType(
    {
        **{f"{s}.1": ("high", "high") for s in "123"},
        **{f"{s}.2": ("high", "low") for s in "123"},
        **{f"{s}.3": ("low", "high") for s in "123"},
        **{f"{s}.4": ("low", "low") for s in "123"},
        "4.1": ("high", "high"),
        "4.2": ("high", "low"),
        "4.3": ("high", "low"),
        **{f"{s}.1": ("high", "low") for s in "567"},
        **{f"{s}.2": ("low", "high") for s in "567"},
        "Operation": ("high", "low"),
    }
)
"""Test ID -> (load, droop level) of TR Appendix 2 Table 21 (an example the TSOs' test IDs follow);
normal operation is logged at high load, low droop (TR Table 2b)."""


# --------------------------------------------------------------------------------------------------
# Schema (pydantic, strict: the boundary)


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


class GovernorInfoModel(_Strict):
    type: str = Field(min_length=1)
    settings: dict[str, float | str | bool] = Field(default_factory=dict)


class DpSsModel(_Strict):
    Fcrn: float | None = Field(None, gt=0)
    FcrdUp: float | None = Field(None, gt=0)
    FcrdDo: float | None = Field(None, gt=0)


class PointModel(_Strict):
    load: Literal["high", "low"]
    droop_level: Literal["high", "low"]
    power_mw: float | None = Field(None, ge=0)
    droop: float | None = Field(None, gt=0)
    droop_fcrd: float | None = Field(None, gt=0)
    dp_ss_theo_mw: DpSsModel | None = None
    test_ids: list[str] | None = None
    y_setpoint: float | None = None
    gain_y_per_hz: float | None = Field(None, gt=0)
    gain_y_per_hz_fcrd: float | None = Field(None, gt=0)


class PowerCurveModel(_Strict):
    y: list[float] = Field(min_length=2)
    p_mw: list[float] = Field(min_length=2)


class PrequalModel(_Strict):
    resource: str = Field(min_length=1, pattern=r"^[A-Za-z0-9.\-_]+$")
    area: str = Field(min_length=1, pattern=r"^[A-Za-z0-9.\-]+$")
    p_min_mw: float | None = Field(None, ge=0)
    p_max_mw: float | None = Field(None, gt=0)
    dp_ss_method: Literal["droop", "table", "curve"] = "droop"
    t_fme_s: float | None = Field(None, gt=0)
    fcrd: Literal["dynamic", "static"] = "dynamic"
    services: list[Literal["Fcrn", "FcrdUp", "FcrdDo"]] | None = None
    mode_shifting: bool = False
    fcrn_exemption: bool = False
    single_setpoint: bool = False
    single_droop: bool = False
    continuous: bool = True
    power_accuracy_pct: float | None = Field(None, gt=0)
    frequency_accuracy_mhz: float | None = Field(None, gt=0)
    governor: GovernorInfoModel | None = None
    power_curve: PowerCurveModel | None = None
    points: list[PointModel] = Field(default_factory=list)


# --------------------------------------------------------------------------------------------------
# Resolved (frozen dataclasses: what the evaluation uses)


@dataclass(frozen=True)
class OperatingPoint:
    """One tested operating point (TR 5.1): a load × droop corner with its ΔP_ss,theo per service."""

    load: str
    """``high`` or ``low``."""
    droop_level: str
    """``high`` or ``low``."""
    power_mw: float | None
    """Set point [MW]."""
    droop: float | None
    """FCR-N droop ep [pu on rated power]."""
    droop_fcrd: float | None
    """FCR-D droop [pu]; the FCR-N droop when not given."""
    dp_ss_theo_mw: Mapping[str, float]
    """|ΔP_ss,theo| per service [MW] for full activation (0.1 Hz FCR-N, 0.4 Hz FCR-D)."""
    test_ids: tuple[str, ...]
    """Test IDs (TR App. 2 Table 21) run at this point."""

    @property
    def name(self) -> str:
        return f"{self.load} load, {self.droop_level} droop"


@dataclass(frozen=True)
class PrequalUnit:
    """The unit's prequalification data, resolved (ΔP_ss,theo computed where the method says so)."""

    resource: str
    area: str
    rated_mw: float
    f0_hz: float
    H: float
    """Inertia constant [s] on rated_mw ([unit.swing] H)."""
    Kd: float
    """Speed damping [pu/pu] ([unit.swing] Kd)."""
    p_min_mw: float | None
    p_max_mw: float | None
    dp_ss_method: str
    t_fme_s: float | None
    fcrd: str
    services: tuple[str, ...]
    mode_shifting: bool
    """FCR-D uses mode shifting (Req. 13 is then evaluated on the ramp tests)."""
    fcrn_exemption: bool
    """The TSO granted the FCR-N stability exemption (Req. 8 accepted down to 0.75·0.43)."""
    continuous: bool
    """Continuously controlled; False: the linearity step tests (Req. 11) are required."""
    single_setpoint: bool
    """FCR is provided at a single power set point: TR 5.1 lets the tests at low load (3, 4) be omitted."""
    single_droop: bool
    """FCR is provided at a single droop setting: TR 5.1 lets the tests at low droop (2, 4) be omitted."""
    power_accuracy_pct: float | None
    frequency_accuracy_mhz: float | None
    governor_type: str
    governor_settings: tuple[tuple[str, float | str | bool], ...]
    points: tuple[OperatingPoint, ...]

    def point_for_test(self, test_id: str) -> OperatingPoint | None:
        """The operating point a test ID was run at: one listing it, else Table 21's (load, droop)."""
        for p in self.points:
            if test_id in p.test_ids:
                return p
        return None

    def dp_ss_theo(self, service: str, test_id: str | None = None) -> float | None:
        """|ΔP_ss,theo| [MW] of ``service`` at the point of ``test_id``; without a test ID (or a point
        for it) the largest over the points (the capacity applied for). None when not known."""
        if test_id is not None:
            p = self.point_for_test(test_id)
            if p is not None:
                return p.dp_ss_theo_mw.get(service)
        values = [p.dp_ss_theo_mw[service] for p in self.points if service in p.dp_ss_theo_mw]
        return max(values) if values else None


def exempt_tests(test_ids: tuple[str, ...], single_setpoint: bool, single_droop: bool) -> tuple[str, ...]:
    """The test IDs of one family (e.g. 1.1-1.4, or linearity 5.1-5.2) that TR 5.1's exemptions let a
    unit omit: with a single set point the tests at low load (conditions 3-4), with a single droop those
    at low droop (2 and 4), corners of Table 21. When every test of the family sits at an omitted corner
    (linearity with both exemptions, the FCR-D sine test with a single droop) the first is still run,
    at the one point: the exemption spares repetitions, not the test."""

    def omitted(tid: str) -> bool:
        load, droop = DEFAULT_TEST_POINTS[tid]
        return (single_setpoint and load == "low") or (single_droop and droop == "low")

    out = [t for t in test_ids if omitted(t)]
    if out and len(out) == len(test_ids):
        out = out[1:]
    return tuple(out)


@dataclass(frozen=True)
class UnitDescription:
    """A plant description file read whole: the dynamic model and the prequalification data."""

    plant: Plant
    prequal: PrequalUnit | None = field(default=None)


def _dp_droop(band_hz: float, f0_hz: float, droop: float, rated_mw: float) -> float:
    # TR App. 1 example 1, eq. 35, with ep in pu of f0 per pu of the rated power.
    return band_hz / (f0_hz * droop) * rated_mw


def _dp_curve(curve: PowerCurveModel, p: PointModel, service: str, key: str) -> float:
    """TR App. 1 example 2, eqs. 37-39: ΔP_ss from the steady-state power curve P(Y) of the controlled
    variable at the set point Y_sp with the static gain 1/e_p [Y per Hz]."""
    g = p.gain_y_per_hz if service == "Fcrn" else (p.gain_y_per_hz_fcrd or p.gain_y_per_hz)
    if p.y_setpoint is None or g is None:
        raise ConfigError(f"{key}.y_setpoint and {key}.gain_y_per_hz: needed with dp_ss_method = 'curve'")
    y0 = p.y_setpoint
    at = {
        "Fcrn": ((y0 + 0.1 * g, y0 - 0.1 * g), 0.5),
        "FcrdUp": ((y0 + 0.5 * g, y0 + 0.1 * g), 1.0),
        "FcrdDo": ((y0 - 0.1 * g, y0 - 0.5 * g), 1.0),
    }[service]
    (ya, yb), k = at
    lo, hi = curve.y[0], curve.y[-1]
    for y in (ya, yb):
        if not lo <= y <= hi:
            raise ConfigError(
                f"{key}: {service} needs P(Y) at Y = {y:g}, outside unit.prequal.power_curve.y "
                f"[{lo:g}, {hi:g}]"
            )
    return abs(k * (float(np.interp(ya, curve.y, curve.p_mw)) - float(np.interp(yb, curve.y, curve.p_mw))))


def prequal_unit_from_model(m: PrequalModel, plant: Plant) -> PrequalUnit:
    """Resolve a validated ``[unit.prequal]`` against its plant; ConfigError naming the key."""
    u = plant.unit
    if m.dp_ss_method == "curve":
        c = m.power_curve
        if c is None:
            raise ConfigError("unit.prequal.power_curve: needed with dp_ss_method = 'curve'")
        if len(c.y) != len(c.p_mw):
            raise ConfigError(f"unit.prequal.power_curve: {len(c.y)} y values but {len(c.p_mw)} p_mw values")
        if any(b <= a for a, b in zip(c.y, c.y[1:])):
            raise ConfigError("unit.prequal.power_curve.y: must increase strictly")
    f0 = plant.grid.f0
    if m.p_min_mw is not None and m.p_max_mw is not None and not m.p_min_mw < m.p_max_mw:
        raise ConfigError(f"unit.prequal: p_min_mw ({m.p_min_mw}) must be below p_max_mw ({m.p_max_mw})")
    services = tuple(m.services) if m.services else PREQUAL_SERVICES
    points: list[OperatingPoint] = []
    seen: dict[tuple[str, str], int] = {}
    claimed: dict[str, int] = {}
    explicit = {t for p in m.points for t in (p.test_ids or ())}
    for i, p in enumerate(m.points):
        key = f"unit.prequal.points.{i}"
        corner = (p.load, p.droop_level)
        if m.single_setpoint and p.load == "low":
            raise ConfigError(
                f"{key}.load: 'low' with unit.prequal.single_setpoint = true (one set point: describe it "
                "as load = 'high', TR 5.1)"
            )
        if m.single_droop and p.droop_level == "low":
            raise ConfigError(
                f"{key}.droop_level: 'low' with unit.prequal.single_droop = true (one droop: describe it "
                "as droop_level = 'high', TR 5.1)"
            )
        if corner in seen:
            raise ConfigError(f"{key}: {p.load} load, {p.droop_level} droop is also points.{seen[corner]}")
        seen[corner] = i
        given = p.dp_ss_theo_mw.model_dump(exclude_none=True) if p.dp_ss_theo_mw is not None else {}
        dp: dict[str, float] = {}
        for s in services:
            if s in given:
                dp[s] = float(given[s])
            elif m.dp_ss_method == "curve":
                dp[s] = _dp_curve(m.power_curve, p, s, key)
            elif m.dp_ss_method == "droop":
                droop = p.droop if s == "Fcrn" else (p.droop_fcrd or p.droop)
                if droop is None:
                    raise ConfigError(
                        f"{key}.droop: needed to compute dp_ss_theo_mw.{s} (dp_ss_method = 'droop')"
                    )
                dp[s] = _dp_droop(BAND_HZ[s], f0, droop, u.rated_mw)
            else:
                raise ConfigError(f"{key}.dp_ss_theo_mw.{s}: required with dp_ss_method = 'table'")
        if p.test_ids is not None:
            ids = tuple(p.test_ids)
        else:
            ids = tuple(t for t, c in DEFAULT_TEST_POINTS.items() if c == corner and t not in explicit)
        for t in ids:
            if t in claimed:
                raise ConfigError(f"{key}.test_ids: test {t!r} is also listed at points.{claimed[t]}")
            claimed[t] = i
        if p.power_mw is not None and m.p_max_mw is not None and p.power_mw > m.p_max_mw:
            raise ConfigError(f"{key}.power_mw: {p.power_mw} MW is above p_max_mw = {m.p_max_mw}")
        points.append(
            OperatingPoint(
                load=p.load,
                droop_level=p.droop_level,
                power_mw=p.power_mw,
                droop=p.droop,
                droop_fcrd=p.droop_fcrd if p.droop_fcrd is not None else p.droop,
                dp_ss_theo_mw=MappingProxyType(dp),
                test_ids=ids,
            )
        )
    gov = m.governor
    return PrequalUnit(
        resource=m.resource,
        area=m.area,
        rated_mw=u.rated_mw,
        f0_hz=f0,
        H=u.swing.H,
        Kd=u.swing.Kd,
        p_min_mw=m.p_min_mw,
        p_max_mw=m.p_max_mw,
        dp_ss_method=m.dp_ss_method,
        t_fme_s=m.t_fme_s,
        fcrd=m.fcrd,
        services=services,
        mode_shifting=m.mode_shifting,
        fcrn_exemption=m.fcrn_exemption,
        continuous=m.continuous,
        single_setpoint=m.single_setpoint,
        single_droop=m.single_droop,
        power_accuracy_pct=m.power_accuracy_pct,
        frequency_accuracy_mhz=m.frequency_accuracy_mhz,
        governor_type=gov.type if gov is not None else "",
        governor_settings=tuple(sorted(gov.settings.items())) if gov is not None else (),
        points=tuple(points),
    )
