"""Daemon config: one clear ConfigError line per problem; check-config exits non-zero, no traceback."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from fcrlive.daemon.config import load_config
from fcrlive.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]

MAP = """
unit_id = 3
word_order = "little"
[[points]]
name = "sample_counter"
table = "input"
address = 0
type = "uint32"
[[points]]
name = "power"
table = "input"
address = {power_address}
type = "float32"
unit = "MW"
[[points]]
name = "excitation_offset"
table = "holding"
address = 0
type = "float32"
writable = true
"""

BASE = """
[unit]
name = "G1"
rated_mw = 100
[source]
kind = "modbus"
[source.modbus]
register_map = "map.toml"
poll_hz = {poll_hz}
{extra}
"""


def _write(tmp_path, poll_hz=20, extra="", power_address=2, base=BASE):
    (tmp_path / "map.toml").write_text(MAP.format(power_address=power_address))
    p = tmp_path / "fcrlive.toml"
    p.write_text(base.format(poll_hz=poll_hz, extra=extra))
    return p


def _err(path) -> str:
    with pytest.raises(ConfigError) as ei:
        load_config(path)
    msg = str(ei.value)
    assert "\n" not in msg
    return msg


def test_valid_config_resolves_map_relative_to_file(tmp_path, monkeypatch):
    monkeypatch.chdir("/")
    cfg = load_config(_write(tmp_path))
    m = cfg.source.modbus.load_map()
    assert m.unit_id == 3 and m.word_order == "little" and m.names[1] == "power"
    assert cfg.signals == ("sample_counter", "power")
    assert cfg.mqtt.base_topic == "fcrlive" and cfg.identification.every_min == 5


def test_out_of_range_rate(tmp_path):
    p = _write(tmp_path, poll_hz=80)
    assert _err(p) == f"{p}: source.modbus.poll_hz: must be between 10 and 50 (got 80)"


def test_unknown_key_is_named(tmp_path):
    p = _write(tmp_path, extra="pol_hz = 20")
    assert _err(p) == f"{p}: source.modbus.pol_hz: unknown key"
    p.write_text(p.read_text() + "\n[mqtt]\nhots = 'x'\n")
    with pytest.raises(ConfigError) as ei:  # both problems, one line each
        load_config(p)
    assert str(ei.value).splitlines() == [f"{p}: source.modbus.pol_hz: unknown key",
                                          f"{p}: mqtt.hots: unknown key"]


def test_wrong_type(tmp_path):
    p = _write(tmp_path, extra='timeout_s = "fast"')
    msg = _err(p)
    assert msg.startswith(f"{p}: source.modbus.timeout_s: must be a valid number") and "'fast'" in msg


def test_overlapping_registers_in_map_file(tmp_path):
    p = _write(tmp_path, power_address=1)  # uint32 at 0-1 and float32 at 1-2
    msg = _err(p)
    assert msg.startswith(str(tmp_path / "map.toml"))
    assert "'sample_counter' (input 0-1) and 'power' (input 1-2) overlap" in msg


def test_overlapping_inline_points(tmp_path):
    p = tmp_path / "f.toml"
    p.write_text("""
[unit]
name = "G1"
rated_mw = 100
[source.modbus]
points = [
  {name = "a", table = "holding", address = 10, type = "float64"},
  {name = "b", table = "holding", address = 13, type = "int16"},
  {name = "c", table = "input", address = 13, type = "int16"},
]
""")
    msg = _err(p)
    assert msg.startswith(f"{p}: source.modbus: ") and "'a' (holding 10-13) and 'b' (holding 13-13)" in msg


def test_missing_and_env_override(tmp_path, monkeypatch):
    p = _write(tmp_path)
    monkeypatch.setenv("FCRLIVE_MQTT__HOST", "broker.example")
    monkeypatch.setenv("FCRLIVE_SOURCE__MODBUS__PORT", "1502")
    cfg = load_config(p)
    assert cfg.mqtt.host == "broker.example" and cfg.source.modbus.port == 1502
    assert cfg.source.modbus.poll_hz == 20  # the file's other keys survive the deep merge
    monkeypatch.setenv("FCRLIVE_SOURCE__MODBUS__POLL_HZ", "5")
    assert _err(p) == "FCRLIVE_SOURCE__MODBUS__POLL_HZ (environment): source.modbus.poll_hz: " \
                      "must be between 10 and 50 (got 5)"
    q = tmp_path / "g.toml"
    q.write_text("[unit]\nname = 'G1'\n[source.modbus]\nregister_map = 'map.toml'\n")
    monkeypatch.delenv("FCRLIVE_SOURCE__MODBUS__POLL_HZ")
    assert _err(q) == f"{q}: unit.rated_mw: required key missing"


def test_bad_toml_and_missing_file(tmp_path):
    p = tmp_path / "x.toml"
    p.write_text("[unit\n")
    assert _err(p).startswith(f"{p}: invalid TOML")
    assert _err(tmp_path / "nope.toml") == f"{tmp_path / 'nope.toml'}: no such file"


def _cli(*args):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    return subprocess.run([sys.executable, "-m", "fcrlive.cli", *args], capture_output=True, text=True,
                          env=env, timeout=60)


def test_check_config_cli(tmp_path):
    bad = _write(tmp_path, poll_hz=80)
    r = _cli("check-config", str(bad))
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip() == (f"fcrlive check-config: error: {bad}: source.modbus.poll_hz: "
                                "must be between 10 and 50 (got 80)")
    assert "Traceback" not in r.stderr
    good = _cli("check-config", str(ROOT / "deploy" / "fcrlive.toml"))
    assert good.returncode == 0, good.stderr
    assert "source modbus" in good.stdout and "grid_freq" in good.stdout


def test_config_docs_are_generated_from_the_models():
    from fcrlive.daemon.config.docs import render_config_docs

    assert (ROOT / "docs" / "config.md").read_text(encoding="utf-8") == render_config_docs(), \
        "run: python -m fcrlive.daemon.config docs/config.md"
