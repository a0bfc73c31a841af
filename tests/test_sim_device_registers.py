"""The shipped register map: the contract (names, one contiguous input block at 0), the loader, the codec."""

from __future__ import annotations

import itertools
import math
import re
import tomllib
from pathlib import Path

import pytest

from fcrlive.errors import ConfigError
from fcrlive.modbus.mapfile import parse_register_map as parse_map
from fcrlive.modbus.registers import RegisterMap
from sim_device.registers import DEFAULT_MAP_PATH, load_map

CONTRACT_INPUTS = {
    "sample_counter": "uint32",
    "device_time": "float64",
    "status": "uint16",
    "speed": "float32",
    "grid_freq": "float32",
    "power": "float32",
    "controller_output": "float32",
    "guide_vane": "float32",
    "excitation_applied": "float32",
}
CONTRACT_HOLDING = {"excitation_offset": "float32", "excitation_enable": "uint16", "heartbeat": "uint16"}
# the test-profile mode (applied frequency, sim_device/profiles.py)
TEST_HOLDING = {"test_profile": "uint16", "test_command": "uint16", "test_period": "float32",
                "test_options": "uint16"}


def test_shipped_map_keeps_the_contract():
    m = load_map()
    assert isinstance(m, RegisterMap) and m.unit_id == 1 and m.word_order == "big" and m.byte_order == "big"
    for name, typ in {**CONTRACT_INPUTS, **CONTRACT_HOLDING}.items():
        assert m.point(name).type == typ, name
    # measurements: one contiguous input block from address 0, no holes
    pts = m.table("input")
    assert pts[0].address == 0
    for a, b in itertools.pairwise(pts):
        assert b.address == a.end, (a.name, b.name)
    assert m.span("input") == (0, pts[-1].end) and pts[-1].end <= 125  # one FC4 request
    # only holding points are writable, and exactly the three commands and the test-profile registers
    assert {p.name for p in m.points if p.writable} == set(CONTRACT_HOLDING) | set(TEST_HOLDING)
    assert all(p.table == "holding" for p in m.points if p.writable)
    # the raw TOML has exactly the documented keys
    raw = tomllib.loads(DEFAULT_MAP_PATH.read_text())
    assert set(raw) == {"unit_id", "word_order", "byte_order", "acquisition", "buffer", "points"}
    assert raw["acquisition"] == "polled" and m.buffer is not None  # buffered: docs/buffered-acquisition.md
    keys = {"name", "table", "address", "type", "scale", "offset", "unit", "writable", "description"}
    assert all(set(p) == keys for p in raw["points"])


def test_registers_md_documents_every_point():
    md = (Path(DEFAULT_MAP_PATH).parent / "REGISTERS.md").read_text()
    for p in load_map().points:
        row = re.search(rf"^\|\s*`{p.name}`\s*\|.*$", md, re.M)
        assert row, f"{p.name} missing from REGISTERS.md"
        cells = [c.strip().strip("`") for c in row.group(0).strip("|").split("|")]
        assert cells[1] == p.table and cells[2] == str(p.address) and cells[3] == str(p.address + 1)
        assert cells[4] == p.type, p.name


@pytest.mark.parametrize("order", ["big", "little"])
def test_codec_round_trips(order):
    m = load_map().with_word_order(order)
    values = {"sample_counter": 4_000_000_123, "device_time": 1234.56, "status": 0b1011, "speed": 1.0004}
    start, regs = m.encode_block("input", values)
    back = m.decode_block("input", start, regs)
    assert back["sample_counter"] == 4_000_000_123 and back["device_time"] == 1234.56 and back["status"] == 11
    assert back["speed"] == pytest.approx(1.0004, rel=1e-7)
    assert math.isnan(m.decode("speed", m.encode("speed", math.nan)))
    hi, lo = m.encode("sample_counter", 0x00010002)
    assert (hi, lo) == ((1, 2) if order == "big" else (2, 1))
    with pytest.raises(ValueError):
        m.encode("status", 70000)


def test_scale_offset_and_byte_order():
    m = parse_map(
        {
            "byte_order": "little",
            "points": [
                {"name": "p", "table": "input", "address": 3, "type": "int16", "scale": 0.1, "offset": -5.0}
            ],
        }
    )
    regs = m.encode("p", 7.5)  # raw = (7.5 + 5)/0.1 = 125 = 0x007D, bytes swapped in the register
    assert regs == [0x7D00]
    assert m.decode("p", regs) == pytest.approx(7.5)


def test_to_toml_round_trips(tmp_path):
    m = load_map().with_word_order("little")
    f = tmp_path / "map.toml"
    f.write_text(m.to_toml())
    assert load_map(f) == m


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ({"points": []}, "no [[points]]"),
        ({"word_order": "middle", "points": [{}]}, "word_order"),
        ({"points": [{"name": "a", "table": "coil", "address": 0, "type": "uint16"}]}, "table"),
        ({"points": [{"name": "a", "table": "input", "address": 0, "type": "float16"}]}, "type"),
        ({"points": [{"name": "a", "table": "input", "address": -1, "type": "uint16"}]}, "address"),
        (
            {"points": [{"name": "a", "table": "input", "address": 0, "type": "uint16", "writable": True}]},
            "writable",
        ),
        (
            {"points": [{"name": "a", "table": "input", "address": 0, "type": "uint16", "colour": "red"}]},
            "colour",
        ),
        (
            {
                "points": [
                    {"name": "a", "table": "input", "address": 0, "type": "float32"},
                    {"name": "b", "table": "input", "address": 1, "type": "uint16"},
                ]
            },
            "overlap",
        ),
        (
            {
                "points": [
                    {"name": "a", "table": "input", "address": 0, "type": "uint16"},
                    {"name": "a", "table": "holding", "address": 0, "type": "uint16"},
                ]
            },
            "duplicate",
        ),
    ],
)
def test_bad_maps_are_config_errors(doc, message):
    with pytest.raises(ConfigError, match=re.escape(message)):
        parse_map(doc)


_PT = {"name": "a", "table": "input", "address": 0, "type": "uint16"}
_BUF = {"header_address": 1000, "slots_address": 1016, "slots": 1024}


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ({"acquisition": "buffered", "points": [_PT]}, 'acquisition = "buffered" needs a [buffer] table'),
        ({"acquisition": "streamed", "points": [_PT]}, "acquisition:"),
        ({"points": [_PT], "buffer": {**_BUF, "slots": 1000}}, "buffer.slots: must be a power of two"),
        ({"points": [_PT], "buffer": {**_BUF, "depth": 3}}, "buffer.depth: unknown key"),
        ({"points": [_PT], "buffer": {**_BUF, "fields": ["power", "power"]}}, "distinct"),
        ({"points": [_PT], "buffer": {**_BUF, "slots_address": 1004}}, "header and slots overlap"),
        ({"points": [_PT], "buffer": {**_BUF, "slots": 8192}}, "past register 65535"),
        ({"points": [{**_PT, "address": 1020}], "buffer": _BUF}, "inside the ring buffer"),
    ],
)
def test_bad_buffers_are_config_errors_of_the_one_map_loader(doc, message):
    """``acquisition`` and ``[buffer]`` (docs/buffered-acquisition.md) are checked by the map loader the
    daemon and the simulator share: one line naming the key."""
    with pytest.raises(ConfigError, match=re.escape(message)):
        parse_map(doc)


def test_buffered_map_round_trips_through_toml():
    m = parse_map({"acquisition": "buffered", "points": [_PT], "buffer": {**_BUF, "fields": ["power"]}})
    assert m.acquisition == "buffered" and m.buffer.fields == ("power",) and m.buffer.slot_words == 5
    assert parse_map(tomllib.loads(m.to_toml())) == m


def test_load_map_file_errors(tmp_path):
    with pytest.raises(ConfigError, match="cannot read"):
        load_map(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("unit_id = \n")
    with pytest.raises(ConfigError, match="invalid TOML"):
        load_map(bad)
