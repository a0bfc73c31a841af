"""No way to turn writing on by accident (issue 14): only the TOML boolean ``true`` in the configuration file
enables the excitation, the environment may only disable it, explicit limits are required, and the
command-line driver needs the same explicit enabling (checked against the simulated governor: nothing is
written without it)."""

from __future__ import annotations

import asyncio
import os
import sys
from pathlib import Path

import pytest
from test_excitation_writer_support import MAP_PATH, governor

from fcrlive.daemon.config import load_config
from fcrlive.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
LIMITS = "[excitation.limits]\namplitude_hz = 0.1\n"


def _config(tmp_path: Path, excitation: str, limits: bool = True) -> Path:
    p = tmp_path / "fcrlive.toml"
    p.write_text(f'[unit]\nname = "G1"\nrated_mw = 300\n[source.modbus]\nregister_map = "{MAP_PATH}"\n'
                 f'[store]\npath = "{tmp_path / "s.sqlite"}"\n[excitation]\n{excitation}\n'
                 + (LIMITS if limits else ""))
    return p


def _refused(path: Path) -> str:
    with pytest.raises(ConfigError) as ei:
        load_config(path)
    return str(ei.value)


@pytest.fixture(autouse=True)
def _no_fcrlive_env(monkeypatch):
    for k in list(os.environ):
        if k.upper().startswith("FCRLIVE_"):
            monkeypatch.delenv(k)


@pytest.mark.parametrize("value", ['"yes"', '"on"', '"y"', '"1"', '"true"', '"True"', '"t"', "1", "1.0"])
def test_only_the_toml_boolean_enables_writing(tmp_path, value):
    p = _config(tmp_path, f"enabled = {value}")
    msg = _refused(p)
    assert msg.startswith(f"{p}: excitation.enabled: must be the TOML boolean true or false"), msg
    assert "\n" not in msg


def test_toml_true_with_limits_enables_and_false_disables(tmp_path):
    assert load_config(_config(tmp_path, "enabled = true")).excitation.enabled is True
    assert load_config(_config(tmp_path, "enabled = false")).excitation.enabled is False
    assert load_config(_config(tmp_path, "", limits=False)).excitation.enabled is False


@pytest.mark.parametrize("value", ["1", "yes", "true", "on", "y", "TRUE"])
def test_the_environment_cannot_enable_writing(tmp_path, monkeypatch, value):
    monkeypatch.setenv("FCRLIVE_EXCITATION__ENABLED", value)
    msg = _refused(_config(tmp_path, "enabled = false"))
    assert msg.startswith("FCRLIVE_EXCITATION__ENABLED (environment): excitation.enabled: the environment "
                          "may only disable writing"), msg


def test_the_environment_cannot_enable_writing_in_json_or_lower_case(tmp_path, monkeypatch):
    p = _config(tmp_path, "")
    monkeypatch.setenv("FCRLIVE_EXCITATION", '{"enabled": true}')
    assert "the environment may only disable writing" in _refused(p)
    monkeypatch.delenv("FCRLIVE_EXCITATION")
    monkeypatch.setenv("fcrlive_excitation__enabled", "1")
    msg = _refused(p)
    assert msg.startswith("fcrlive_excitation__enabled (environment)") and "only disable" in msg, msg


@pytest.mark.parametrize("value", ["false", "0", "no", "off"])
def test_the_environment_may_disable_writing(tmp_path, monkeypatch, value):
    monkeypatch.setenv("FCRLIVE_EXCITATION__ENABLED", value)
    assert load_config(_config(tmp_path, "enabled = true")).excitation.enabled is False


def test_enabled_needs_explicit_limits(tmp_path):
    p = _config(tmp_path, "enabled = true", limits=False)
    msg = _refused(p)
    assert msg.startswith(f"{p}: excitation: enabled = true needs an explicit [excitation.limits] table "
                          "with at least amplitude_hz"), msg
    p.write_text(p.read_text() + "[excitation.limits]\nholdoff_s = 10\n")
    assert "at least amplitude_hz" in _refused(p)
    p.write_text(p.read_text() + "amplitude_hz = 0.05\n")
    assert load_config(p).excitation.guard_limits().amplitude_hz == 0.05


def test_shipped_configurations_that_enable_writing_give_limits():
    """deploy/fcrlive.toml, the demo's configuration and the daemon tests' excitation section."""
    import tomllib

    from test_e2e_buffered import config

    e2e = tomllib.loads(config(plant="p", port=1, regmap="m", store="s", window=1.0, mqtt_port=2, period=0.1,
                               speed=1.0))
    assert "amplitude_hz" in e2e["excitation"]["limits"]
    deploy = tomllib.loads((ROOT / "deploy" / "fcrlive.toml").read_text())
    assert deploy["excitation"]["enabled"] is False
    from fcrlive.commands.demo import excitation_settings

    assert "amplitude_hz" in excitation_settings(speed=4.0)["limits"]


# -- python -m fcrlive.excitation -------------------------------------------------------------------


async def _driver(*args: str, timeout: float = 60.0) -> tuple[int, str, str]:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "fcrlive.excitation", *args, "--log-level", "ERROR",
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE, cwd=str(ROOT), env=env)
    try:
        out, err = await asyncio.wait_for(proc.communicate(), timeout)
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()
    return proc.returncode, out.decode(), err.decode()


async def test_the_driver_refuses_to_write_without_explicit_enabling(tmp_path):
    disabled = _config(tmp_path, "enabled = false")
    async with governor() as dev:
        port = str(dev.port)
        runs = [
            ("--port", port, "--register-map", str(MAP_PATH)),  # the case: no configuration at all
            ("--port", port, "--register-map", str(MAP_PATH), "--i-understand-this-writes"),  # no amplitude
            ("--config", str(disabled), "--port", port),
        ]
        results = [await _driver(*a) for a in runs]
        await asyncio.sleep(0.3)
        assert dev.commands == []  # nothing reached the device
    for (rc, out, err), args in zip(results, runs):
        assert rc == 2 and out == "", (args, err)
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
        assert err.startswith("python -m fcrlive.excitation: error: ")
    assert "refusing to write to a governor without explicit enabling" in results[0][2]
    assert "needs --amplitude-hz" in results[1][2]
    assert "[excitation] enabled = true is not set" in results[2][2]


@pytest.mark.parametrize(("amplitude", "why"), [
    ("0.5", "above its safe maximum 0.1"), ("-0.1", "must be > 0"), ("nan", "not a finite number"),
    ("1e300", "above its safe")])
async def test_an_out_of_range_amplitude_is_one_line(amplitude, why):
    rc, out, err = await _driver("--port", "1", "--register-map", str(MAP_PATH), "--i-understand-this-writes",
                                 "--amplitude-hz", amplitude)
    assert rc == 2 and out == "" and "Traceback" not in err
    assert err.strip().splitlines() == [err.strip()]
    assert err.startswith("python -m fcrlive.excitation: error: --amplitude-hz: excitation guard: ")
    assert why in err


async def test_the_driver_says_what_it_writes_where_and_writes_with_a_config_file(tmp_path):
    cfg = _config(tmp_path, "enabled = true\nperiod_s = 0.05\n[excitation.generator]\nseed = 3\n",
                  limits=False)
    cfg.write_text(cfg.read_text() + "[excitation.limits]\namplitude_hz = 0.08\nholdoff_s = 1\n")
    async with governor() as dev:
        rc, _, err = await _driver("--config", str(cfg), "--port", str(dev.port), "--seconds", "3")
        written = [c[1] for c in dev.commands if c[1] is not None]
    assert rc == 0, err
    first = err.strip().splitlines()[0]
    assert first.startswith(f"python -m fcrlive.excitation: WRITING to the governor at 127.0.0.1:{dev.port} "
                            "unit 1: excitation_offset (holding 100, float32)"), first
    assert "|r| ≤ 0.08 Hz (seed 3)" in first and "hold-off 1 s" in first
    assert written and max(abs(w) for w in written) <= 0.08 and written[-1] == 0.0
    assert any(w != 0.0 for w in written)  # it did write once enabled explicitly
