"""TSO file names: build, parse, refuse."""

from __future__ import annotations

from datetime import datetime

import pytest

from fcrlive.errors import DataError
from fcrlive.tso.names import format_sampling_rate, parse_tso_filename, sine_test_type, tso_filename

START = datetime(2026, 11, 1, 0, 0)
END = datetime(2026, 11, 1, 1, 0)


def test_build_matches_the_test_program_example():
    name = tso_filename("FCPG1", "Fcrn", "Operation", "NO5", "UTC", START, END, 0.1)
    assert name == "FCPG1_Fcrn_Operation_NO5_UTC_20261101T0000-20261101T0100_100ms.csv"


@pytest.mark.parametrize(("sample_s", "text"), [(0.05, "50ms"), (0.02, "20ms"), (1.0, "1s"), (2.5, "2.5s")])
def test_sampling_rate(sample_s, text):
    assert format_sampling_rate(sample_s) == text
    name = tso_filename("R", "FcrdUp", "Operation", "SE1", "CET", START, END, sample_s)
    assert parse_tso_filename(name).sample_s == pytest.approx(sample_s)


def test_parse_round_trip_with_underscored_resource_and_sine_period():
    name = tso_filename("Plant_G1", "FcrdDo", sine_test_type(40.0), "NO5", "UTC", START, END, 0.02)
    assert "_Sine40_" in name
    parsed = parse_tso_filename(f"/some/dir/{name}")
    assert parsed.resource == "Plant_G1"
    assert parsed.service == "FcrdDo"
    assert parsed.test_type == "Sine40"
    assert parsed.period_s == 40.0
    assert (parsed.start, parsed.end) == (START, END)
    assert parsed.name == name
    assert parse_tso_filename(name.replace("_Sine40_", "_Operation_")).period_s is None


@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("log.csv", "not a TSO file name"),
        ("FCPG1_Fcr_Operation_NO5_UTC_20261101T0000-20261101T0100_100ms.csv", "no service"),
        ("FCPG1_Fcrn_Operation_NO5_UTC_20261101-20261101T0100_100ms.csv", "interval"),
        ("FCPG1_Fcrn_Operation_NO5_UTC_20261301T0000-20261301T0100_100ms.csv", "not a valid date"),
        ("FCPG1_Fcrn_Operation_NO5_UTC_20261101T0000-20261101T0100_10Hz.csv", "sampling rate"),
    ],
)
def test_parse_refuses_with_data_error(name, text):
    with pytest.raises(DataError) as e:
        parse_tso_filename(name)
    assert text in e.value.message
    assert e.value.where == name


@pytest.mark.parametrize(
    "kwargs",
    [
        {"service": "FCRN"},
        {"area": "NO_5"},
        {"tz": "UTC+1"},
        {"resource": "A,B"},
        {"resource": "X_Fcrn"},
        {"end": datetime(2026, 10, 1)},
        {"sample_s": 0.0005},
    ],
)
def test_build_is_strict(kwargs):
    args = dict(
        resource="FCPG1",
        service="Fcrn",
        test_type="Operation",
        area="NO5",
        tz="UTC",
        start=START,
        end=END,
        sample_s=0.1,
    )
    args.update(kwargs)
    with pytest.raises(ValueError):
        tso_filename(**args)
