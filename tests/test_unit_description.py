"""The [unit.prequal] section of the plant description: resolution of ΔP_ss,theo (TR App. 1), test IDs of
the points (TR App. 2 Table 21), one-line errors naming the key."""

from __future__ import annotations

import re

import pytest

from fcrlive.errors import ConfigError
from fcrlive.plant.description import (
    load_plant,
    load_unit_description,
    plant_from_dict,
    unit_description_from_dict,
)


def _d(**prequal):
    base = {"resource": "U1", "area": "NO5"}
    base.update(prequal)
    return {"unit": {"rated_mw": 300.0, "prequal": base}}


def test_droop_method_is_appendix1_example1():
    u = unit_description_from_dict(
        _d(points=[{"load": "high", "droop_level": "high", "droop": 0.08, "droop_fcrd": 0.05}])
    ).prequal
    (p,) = u.points
    # ΔP = Δf/(f0·ep)·P_rated: 0.1/(50·0.08)·300 = 7.5 MW; FCR-D 0.4/(50·0.05)·300 = 48 MW
    assert p.dp_ss_theo_mw["Fcrn"] == pytest.approx(7.5)
    assert p.dp_ss_theo_mw["FcrdUp"] == pytest.approx(48.0) == p.dp_ss_theo_mw["FcrdDo"]
    assert p.name == "high load, high droop"
    assert set(p.test_ids) == {"1.1", "2.1", "3.1", "4.1"}
    assert u.dp_ss_theo("Fcrn", "1.1") == pytest.approx(7.5)
    assert u.H == 3.5 and u.Kd == 0.1 and u.rated_mw == 300.0  # from [unit.swing] / [unit] of the plant


def test_table_method_and_explicit_test_ids():
    u = unit_description_from_dict(
        _d(
            dp_ss_method="table",
            points=[
                {
                    "load": "low",
                    "droop_level": "low",
                    "dp_ss_theo_mw": {"Fcrn": 5, "FcrdUp": 10, "FcrdDo": 12},
                    "test_ids": ["1.4", "2.4", "Operation"],
                },
                {
                    "load": "high",
                    "droop_level": "low",
                    "dp_ss_theo_mw": {"Fcrn": 6, "FcrdUp": 11, "FcrdDo": 13},
                },
            ],
        )
    ).prequal
    assert u.point_for_test("Operation").load == "low"  # explicit beats Table 21's default
    assert "Operation" not in u.points[1].test_ids
    assert u.dp_ss_theo("FcrdDo", "2.2") == 13.0
    assert u.dp_ss_theo("FcrdDo") == 13.0  # the largest without a test


@pytest.mark.parametrize(
    "prequal, message",
    [
        ({"points": [{"load": "mid", "droop_level": "high"}]}, "unit.prequal.points.0.load"),
        ({"points": [{"load": "high", "droop_level": "high"}]}, "unit.prequal.points.0.droop: needed"),
        (
            {"dp_ss_method": "table", "points": [{"load": "high", "droop_level": "high", "droop": 0.1}]},
            "unit.prequal.points.0.dp_ss_theo_mw.Fcrn: required",
        ),
        ({"p_min_mw": 300.0, "p_max_mw": 100.0}, "p_min_mw (300.0) must be below p_max_mw"),
        (
            {
                "points": [
                    {"load": "high", "droop_level": "high", "droop": 0.1},
                    {"load": "high", "droop_level": "high", "droop": 0.2},
                ]
            },
            "also points.0",
        ),
        ({"colour": "red"}, "unknown key 'unit.prequal.colour'"),
        ({"t_fme_s": -1.0}, "unit.prequal.t_fme_s"),
        (
            {"single_setpoint": True, "points": [{"load": "low", "droop_level": "high", "droop": 0.1}]},
            "unit.prequal.points.0.load: 'low' with unit.prequal.single_setpoint = true",
        ),
        (
            {"single_droop": True, "points": [{"load": "high", "droop_level": "low", "droop": 0.1}]},
            "unit.prequal.points.0.droop_level: 'low' with unit.prequal.single_droop = true",
        ),
        ({"single_droop": "yes"}, "unit.prequal.single_droop"),
    ],
)
def test_errors_name_the_key(prequal, message):
    with pytest.raises(ConfigError, match=re.escape(message)) as e:
        unit_description_from_dict(_d(**prequal), where="u.toml")
    assert str(e.value).startswith("u.toml: ")


def test_missing_resource_and_other_unit_has_no_prequal():
    with pytest.raises(ConfigError, match=re.escape("unit.prequal.resource")):
        unit_description_from_dict({"unit": {"prequal": {"area": "NO5"}}})
    with pytest.raises(ConfigError, match=re.escape("unknown key 'grid.other.prequal'")):
        plant_from_dict({"grid": {"other": {"prequal": {"resource": "X", "area": "NO5"}}}})


def test_one_format_plant_readers_ignore_the_section(tmp_path):
    path = tmp_path / "u.toml"
    path.write_text(
        'preset = "paper-plant1"\n[unit]\nrated_mw = 250.0\n[unit.prequal]\nresource = "U1"\narea = "SE3"\n'
    )
    plant = load_plant(path)  # the plant readers (fcrlive model, identify) read the same file
    assert plant.unit.rated_mw == 250.0
    desc = load_unit_description(path)
    assert desc.plant == plant and desc.prequal.area == "SE3" and desc.prequal.points == ()
    assert load_unit_description(tmp_path / "u.toml").prequal.rated_mw == 250.0


def test_curve_method_is_appendix1_example2():
    # P(Y): 0.6 MW/% up to 50 %, 0.4 MW/% above; Y_sp = 60 %, 1/e_p = 50 %/Hz (eqs. 37-39):
    # FCR-N (P(65) − P(55))/2 = 2.0 MW; FCR-D up P(85) − P(65) = 8.0 MW; down P(55) − P(35) = 32 − 21 = 11 MW
    d = _d(
        dp_ss_method="curve",
        power_curve={"y": [0.0, 50.0, 100.0], "p_mw": [0.0, 30.0, 50.0]},
        points=[{"load": "high", "droop_level": "high", "y_setpoint": 60.0, "gain_y_per_hz": 50.0}],
    )
    (p,) = unit_description_from_dict(d).prequal.points
    assert p.dp_ss_theo_mw["Fcrn"] == pytest.approx(2.0)
    assert p.dp_ss_theo_mw["FcrdUp"] == pytest.approx(8.0)
    assert p.dp_ss_theo_mw["FcrdDo"] == pytest.approx(11.0)
    d["unit"]["prequal"]["points"][0]["y_setpoint"] = 90.0  # 90 + 0.5·50 = 115 % is off the curve
    with pytest.raises(
        ConfigError, match=re.escape("needs P(Y) at Y = 115, outside unit.prequal.power_curve.y")
    ):
        unit_description_from_dict(d)
    d["unit"]["prequal"]["power_curve"] = {"y": [0.0, 50.0, 40.0], "p_mw": [0.0, 1.0, 2.0]}
    with pytest.raises(ConfigError, match=re.escape("power_curve.y: must increase strictly")):
        unit_description_from_dict(d)


@pytest.mark.parametrize(
    "setpoint, droop, exempt",
    [
        (False, False, ((), ())),
        (True, False, (("1.3", "1.4"), ("5.2",))),  # TR 5.1: tests 3) and 4) omitted
        (False, True, (("1.2", "1.4"), ("5.1",))),  # tests 2) and 4)
        (True, True, (("1.2", "1.3", "1.4"), ("5.2",))),  # one linearity test is still run
    ],
)
def test_tr51_exemptions_collapse_the_corners(setpoint, droop, exempt):
    from fcrlive.plant.prequal_unit import exempt_tests

    assert exempt_tests(("1.1", "1.2", "1.3", "1.4"), setpoint, droop) == exempt[0]
    assert exempt_tests(("5.1", "5.2"), setpoint, droop) == exempt[1]
    assert exempt_tests(("4.2",), setpoint, droop) == ()  # the FCR-D sine test is not spared
    u = unit_description_from_dict(
        _d(single_setpoint=setpoint, single_droop=droop,
           points=[{"load": "high", "droop_level": "high", "droop": 0.08}])
    ).prequal
    assert (u.single_setpoint, u.single_droop) == (setpoint, droop)
