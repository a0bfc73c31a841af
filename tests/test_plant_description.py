"""Plant description files: presets as bases, overrides, round trips, errors naming the key."""

from __future__ import annotations

import dataclasses
import json
import tomllib
from pathlib import Path

import pytest

from fcrlive.errors import ConfigError
from fcrlive.plant import description as desc
from fcrlive.plant.description import load_plant, plant_from_dict, plant_to_dict, plant_to_toml
from fcrlive.plant.params import PRESETS, Governor, Grid, Plant, Servo, Swing, Turbine, Unit, preset

EXAMPLE = Path(__file__).resolve().parents[1] / "docs" / "examples" / "plant1.toml"


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_round_trip_dict_json_toml(name):
    plant = preset(name)
    d = plant_to_dict(plant)
    assert plant_from_dict(d) == plant
    assert plant_from_dict(json.loads(json.dumps(d))) == plant
    assert plant_from_dict(tomllib.loads(plant_to_toml(plant))) == plant


def test_round_trip_of_a_changed_plant_keeps_every_field():
    plant = Plant(
        unit=Unit(
            name="Ålvik G2",
            rated_mw=45.5,
            swing=Swing(H=2.75, Kd=0.0),
            governor=Governor(Kp=2.5, Ti=4.0, droop=0.04, Tf=0.0, Tc=0.1, droop_signal="demand"),
            servo=Servo(Tg=0.35, g_min=0.05, g_max=0.98),
            turbine=Turbine(Tw=1.8, q_nl=0.12, At=1.15, Pm0=0.5, Dturb=0.3),
        ),
        grid=dataclasses.replace(Grid(), D=20, damping_at="load_bus"),
    )
    back = plant_from_dict(tomllib.loads(plant_to_toml(plant)))
    assert back == plant
    assert isinstance(back.grid.D, float)  # an int in the TOML comes back as the float field it is


def test_example_file_is_plant1():
    assert load_plant(EXAMPLE) == preset("paper-plant1")


def test_preset_base_and_overrides(tmp_path):
    f = tmp_path / "p.toml"
    f.write_text('preset = "paper-plant1-classic"\n[unit.turbine]\nPm0 = 0.8\n[grid.other.swing]\nH = 7\n')
    plant = load_plant(f)
    assert plant.unit.governor.droop_placement == "classic"
    assert plant.unit.turbine.Pm0 == 0.8
    assert plant.unit.turbine.Tw == 1.0  # untouched fields come from the preset
    assert plant.grid.other.swing.H == 7.0
    assert plant.grid.other.governor.Kp == pytest.approx(1 / 0.3)


def test_base_argument_used_only_without_preset_key(tmp_path):
    classic = preset("paper-plant1-classic")
    f = tmp_path / "p.toml"
    f.write_text("[unit.swing]\nH = 4.0\n")
    assert load_plant(f, base=classic).unit.governor.droop_placement == "classic"
    assert load_plant(f).unit.governor.droop_placement == "integral"
    f.write_text('preset = "paper-plant1"\n')
    assert load_plant(f, base=classic) == preset("paper-plant1")


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("[unit.governor]\nkp = 1.0\n", "unknown key 'unit.governor.kp'"),
        ("[unit]\ncolour = 'red'\n", "unknown key 'unit.colour'"),
        ("[grid.other.turbine]\nTwater = 1.0\n", "unknown key 'grid.other.turbine.Twater'"),
        ("[plant]\nH = 1\n", "unknown key 'plant'"),
        ("[unit.governor]\nTi = 'nine'\n", "unit.governor.Ti"),
        ("[unit.governor]\nKp = true\n", "unit.governor.Kp"),
        ("[unit.governor]\ndigital = 1\n", "unit.governor.digital"),
        ("[unit.governor]\ndroop_placement = 'cascade'\n", "unit.governor.droop_placement"),
        ("[unit]\nswing = 3.5\n", "unit.swing"),
        ("[unit.swing]\nH = -3.5\n", "unit.swing.H"),
        ("[unit.servo]\ng_min = 1.0\ng_max = 0.5\n", "g_min"),
        ("[unit.turbine]\nPm0 = 1.5\n", "unit.turbine.Pm0"),
        ("preset = 'paper-plant9'\n", "unknown preset 'paper-plant9'"),
        ("preset = 3\n", "preset"),
        ("[unit.swing\nH = 1\n", "not valid TOML"),
    ],
)
def test_errors_name_the_key_and_the_file(tmp_path, text, needle):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_plant(f)
    assert needle in info.value.message
    assert info.value.where == str(f)
    assert str(f) in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="cannot read") as info:
        load_plant(tmp_path / "nope.toml")
    assert info.value.where.endswith("nope.toml")


def test_non_table_input():
    with pytest.raises(ConfigError, match="table"):
        plant_from_dict([1, 2], where="x")


def _schema_fields(model) -> set[str]:
    return set(model.model_fields)


def test_schema_covers_every_parameter_field():
    # Catches drift when params.py gains a field the description format does not know.
    pairs = [
        (desc.SwingModel, Swing),
        (desc.GovernorModel, Governor),
        (desc.ServoModel, Servo),
        (desc.TurbineModel, Turbine),
        (desc.UnitModel, Unit),
        (desc.GridModel, Grid),
    ]
    for model, cls in pairs:
        assert _schema_fields(model) == {f.name for f in dataclasses.fields(cls)}, cls.__name__
    assert _schema_fields(desc.PlantModel) == {"preset"} | {f.name for f in dataclasses.fields(Plant)}
