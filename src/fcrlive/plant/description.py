"""Plant description files (TOML): a preset as the base, then tables overriding its fields.

Format (docs/plant-toml.md)::

    preset = "paper-plant1"        # optional base; without it the library defaults (= paper-plant1)
    [unit]                         # name, rated_mw, xd
    [unit.swing]                   # H, Kd
    [unit.governor]                # Kp, Ti, droop, Tf, Tc, droop_placement, droop_signal, digital
    [unit.servo]                   # Tg, g_min, g_max
    [unit.turbine]                 # Tw, q_nl, At, h_s, Pm0, Dturb
    [grid]                         # s_base_mw, x1, x2, D, damping_at, f0
    [grid.other]                   # the rest of the grid, same tables as [unit]
    [unit.prequal]                 # prequalification data of the unit (plant/prequal_unit.py)

Every key is optional; unknown keys, wrong types and out-of-range values raise
:class:`fcrlive.errors.ConfigError` naming the key (``unit.governor.Kp``) and the file.
"""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from fcrlive.errors import ConfigError
from fcrlive.plant.params import Plant, Unit, preset
from fcrlive.plant.prequal_unit import OperatingPoint as OperatingPoint
from fcrlive.plant.prequal_unit import PrequalModel, UnitDescription, prequal_unit_from_model
from fcrlive.plant.prequal_unit import PrequalUnit as PrequalUnit

# --------------------------------------------------------------------------------------------------
# Schema: every field optional (an override); strict types so "0.1" or true is not taken for a number.


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


class SwingModel(_Strict):
    H: float | None = Field(None, gt=0)
    Kd: float | None = Field(None, ge=0)


class GovernorModel(_Strict):
    Kp: float | None = Field(None, gt=0)
    Ti: float | None = Field(None, gt=0)
    droop: float | None = Field(None, gt=0)
    Tf: float | None = Field(None, ge=0)
    Tc: float | None = Field(None, gt=0)
    droop_placement: Literal["integral", "classic"] | None = None
    droop_signal: Literal["gate", "demand"] | None = None
    digital: bool | None = None
    integral_method: Literal["forward", "backward", "tustin"] | None = None
    Td: float | None = Field(None, ge=0)
    Tdf: float | None = Field(None, ge=0)


class ServoModel(_Strict):
    Tg: float | None = Field(None, gt=0)
    g_min: float | None = None
    g_max: float | None = None


class TurbineModel(_Strict):
    Tw: float | None = Field(None, gt=0)
    q_nl: float | None = Field(None, ge=0)
    At: float | None = Field(None, gt=0)
    h_s: float | None = Field(None, gt=0)
    Pm0: float | None = Field(None, ge=0)
    Dturb: float | None = Field(None, ge=0)


class UnitModel(_Strict):
    name: str | None = Field(None, min_length=1)
    rated_mw: float | None = Field(None, gt=0)
    xd: float | None = Field(None, gt=0)
    swing: SwingModel | None = None
    governor: GovernorModel | None = None
    servo: ServoModel | None = None
    turbine: TurbineModel | None = None


class StudiedUnitModel(UnitModel):
    """The studied unit: a unit plus its prequalification data (``[unit.prequal]``, prequal_unit.py)."""

    prequal: PrequalModel | None = None


class GridModel(_Strict):
    s_base_mw: float | None = Field(None, gt=0)
    x1: float | None = Field(None, ge=0)
    x2: float | None = Field(None, ge=0)
    D: float | None = Field(None, ge=0)
    damping_at: Literal["coi", "load_bus"] | None = None
    f0: float | None = Field(None, gt=0)
    other: UnitModel | None = None


class PlantModel(_Strict):
    preset: str | None = None
    unit: StudiedUnitModel | None = None
    grid: GridModel | None = None


# --------------------------------------------------------------------------------------------------


def _describe(err: dict[str, Any]) -> str:
    key = ".".join(str(p) for p in err["loc"]) or "(top level)"
    if err["type"] == "extra_forbidden":
        return f"unknown key {key!r}"
    got = err.get("input")
    shown = "" if isinstance(got, dict) else f" (got {got!r})"
    return f"{key}: {err['msg']}{shown}"


def _override(obj: Any, changes: dict[str, Any]) -> Any:
    updates = {}
    for name, value in changes.items():
        current = getattr(obj, name)
        updates[name] = _override(current, value) if dataclasses.is_dataclass(current) else value
    return dataclasses.replace(obj, **updates)


def _check_unit(unit: Unit, key: str) -> None:
    from fcrlive.plant.transfer import turbine_linear

    servo = unit.servo
    if not servo.g_min < servo.g_max:
        raise ConfigError(f"{key}.servo: g_min ({servo.g_min}) must be below g_max ({servo.g_max})")
    g0 = turbine_linear(unit.turbine).g0
    if not servo.g_min <= g0 <= servo.g_max:
        raise ConfigError(
            f"{key}.turbine.Pm0: operating point Pm0 = {unit.turbine.Pm0} needs gate opening "
            f"g0 = {g0:.4g}, outside [{servo.g_min}, {servo.g_max}]"
        )


def check_plant(plant: Plant) -> None:
    """Cross-field checks the schema cannot make (gate limits, operating point within them)."""
    _check_unit(plant.unit, "unit")
    _check_unit(plant.grid.other, "grid.other")


def plant_from_dict(d: dict[str, Any], where: str | None = None, base: Plant | None = None) -> Plant:
    """Build a :class:`Plant` from a description dict (parsed TOML/JSON); ``where`` names the source.

    The description's ``preset`` is the base it overrides; without one, ``base`` (default: the library
    defaults, which are the paper's plant 1).

    Raises ConfigError naming the offending key for unknown keys, wrong types, bad values and an
    unknown preset.
    """
    if not isinstance(d, dict):
        raise ConfigError(f"a plant description must be a table, got {type(d).__name__}", where=where)
    try:
        model = PlantModel.model_validate(d)
    except ValidationError as exc:
        raise ConfigError("; ".join(_describe(e) for e in exc.errors()), where=where) from None
    base = Plant() if base is None else base
    if model.preset is not None:
        try:
            base = preset(model.preset)
        except ConfigError as exc:
            raise ConfigError(f"preset: {exc.message}", where=where) from None
    changes = model.model_dump(exclude_none=True, exclude={"preset": True, "unit": {"prequal"}})
    plant = _override(base, changes)
    try:
        check_plant(plant)
    except ConfigError as exc:
        raise ConfigError(exc.message, where=where) from None
    return plant


def unit_description_from_dict(
    d: dict[str, Any], where: str | None = None, base: Plant | None = None
) -> UnitDescription:
    """The plant of ``d`` (as :func:`plant_from_dict`) and its ``[unit.prequal]`` section resolved into a
    :class:`PrequalUnit` (None when the section is absent). ConfigError naming the key on bad input."""
    plant = plant_from_dict(d, where=where, base=base)
    model = PlantModel.model_validate(d)  # valid: plant_from_dict checked it
    pq = model.unit.prequal if model.unit is not None else None
    if pq is None:
        return UnitDescription(plant, None)
    try:
        return UnitDescription(plant, prequal_unit_from_model(pq, plant))
    except ConfigError as exc:
        raise ConfigError(exc.message, where=where) from None


def load_unit_description(path: str | Path, base: Plant | None = None) -> UnitDescription:
    """Read a plant description TOML file with its ``[unit.prequal]`` section (docs/plant-toml.md)."""
    return unit_description_from_dict(_read_toml(path), where=str(Path(path)), base=base)


def load_plant(path: str | Path, base: Plant | None = None) -> Plant:
    """Read a plant description TOML file (format in docs/plant-toml.md); ``base`` as in
    :func:`plant_from_dict`."""
    return plant_from_dict(_read_toml(path), where=str(Path(path)), base=base)


def _read_toml(path: str | Path) -> dict[str, Any]:
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot read plant description: {exc.strerror or exc}", where=str(p)) from None
    except UnicodeDecodeError:
        raise ConfigError("plant description is not UTF-8 text", where=str(p)) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"not valid TOML: {exc}", where=str(p)) from None
    return data


def plant_to_dict(plant: Plant) -> dict[str, Any]:
    """Every field of ``plant`` as nested plain dicts (no preset key); round-trips through
    :func:`plant_from_dict`, JSON and :func:`plant_to_toml`."""
    return {"unit": dataclasses.asdict(plant.unit), "grid": dataclasses.asdict(plant.grid)}


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string is a valid TOML basic string
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _toml_table(d: dict[str, Any], prefix: str, out: list[str]) -> None:
    scalars = {k: v for k, v in d.items() if not isinstance(v, dict)}
    tables = {k: v for k, v in d.items() if isinstance(v, dict)}
    if prefix and (scalars or not tables):
        out.append(f"\n[{prefix}]")
    out.extend(f"{k} = {_toml_value(v)}" for k, v in scalars.items())
    for k, v in tables.items():
        _toml_table(v, f"{prefix}.{k}" if prefix else k, out)


def plant_to_toml(plant: Plant) -> str:
    """``plant`` as a complete TOML description (every field written out, no preset)."""
    out: list[str] = ["# fcrlive plant description (docs/plant-toml.md); per unit on each machine's base"]
    _toml_table(plant_to_dict(plant), "", out)
    return "\n".join(out).strip() + "\n"
