"""Hardening of the daemon's configuration and start (issue 14, "Configuration and the daemon"): no
traceback on any file, every problem reported, check-config refuses what run would refuse at start, the
store private and never in a made-up directory, the rating cross-checked with the device, a retained
excitation state that survives a broker restart, the rejected-results metric, Home Assistant classes.

Real components: the CLI in subprocesses, the simulated governor (Modbus TCP), a real MQTT broker, SQLite."""

from __future__ import annotations

import asyncio
import json
import os
import stat
import subprocess
import sys
import time
from pathlib import Path

import aiomqtt
import pytest

from fcrlive.daemon.config import load_config
from fcrlive.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
MAP = ROOT / "sim_device" / "registers.toml"
TESTS = Path(__file__).resolve().parent
LIMITS = "[excitation.limits]\namplitude_hz = 0.1\n"


@pytest.fixture(autouse=True)
def _clean_env(monkeypatch):
    for k in list(os.environ):
        if k.upper().startswith("FCRLIVE_") or k == "STATE_DIRECTORY":
            monkeypatch.delenv(k)


def _toml(d: Path, *, unit: str = "rated_mw = 300", source: str = "", store: Path | None = None,
          ident: str = "", mqtt: str = "enabled = false", metrics: str = "enabled = false", exc: str = "",
          register_map: Path = MAP, port: int = 5020) -> Path:
    p = d / "fcrlive.toml"
    p.write_text(f'[unit]\nname = "G1"\n{unit}\n[source.modbus]\nport = {port}\n'
                 f'register_map = "{register_map}"\n{source}\n[store]\npath = "{store or d / "s.sqlite"}"\n'
                 f'[identification]\n{ident}\n'
                 f'[mqtt]\n{mqtt}\n[metrics]\n{metrics}\n{exc}')
    return p


def _cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS), str(ROOT)]), "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "fcrlive.cli", *args], capture_output=True, text=True,
                          timeout=timeout, env=env, cwd=str(ROOT))


def _errors(r: subprocess.CompletedProcess, command: str) -> list[str]:
    assert "Traceback" not in r.stderr, r.stderr
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert all(line.startswith(f"fcrlive {command}: error: ") for line in lines), lines
    return [line.removeprefix(f"fcrlive {command}: error: ") for line in lines]


# -- files that are not UTF-8 TOML --------------------------------------------------------------------


@pytest.mark.parametrize(("name", "encode", "hint"), [
    ("binary", lambda text: bytes(range(256)) * 4, "looks binary"),
    ("UTF-16 with BOM", lambda text: text.encode("utf-16"), "looks like UTF-16"),
    ("UTF-16-LE without BOM", lambda text: text.encode("utf-16-le"), "looks like UTF-16"),
    ("UTF-16-BE without BOM", lambda text: text.encode("utf-16-be"), "looks like UTF-16"),
])
def test_a_binary_or_utf16_config_is_one_line_in_check_config_and_run(tmp_path, name, encode, hint):
    p = _toml(tmp_path)
    p.write_bytes(encode(p.read_text()))
    for command, args in (("check-config", [str(p)]), ("run", ["--config", str(p)])):
        [line] = _errors(_cli(command, *args), command)
        assert line.startswith(f"{p}: not a UTF-8 text file (") and hint in line, line


def test_a_utf16_register_map_and_a_fifo_config_are_one_line(tmp_path):
    m = tmp_path / "map.toml"
    m.write_bytes(MAP.read_text().encode("utf-16"))
    with pytest.raises(ConfigError) as ei:
        load_config(_toml(tmp_path, register_map=m))
    assert str(ei.value).startswith(f"{m}: not a UTF-8 text file") and "UTF-16" in str(ei.value)
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)  # no writer: reading it would block forever
    with pytest.raises(ConfigError, match="not a regular file"):
        load_config(fifo)
    with pytest.raises(ConfigError, match="not a regular file"):
        load_config(tmp_path)


# -- every problem, one line each ---------------------------------------------------------------------


def test_every_problem_is_reported_one_line_each(tmp_path):
    p = _toml(tmp_path, unit="rated_mw = -1\nf0 = 80", source="poll_hz = 80\ntimeout_s = 9",
              mqtt="port = 0\nhots = 1", ident="every_min = 0")
    expected = [f"{p}: unit.rated_mw: must be > 0 and ≤ 5000 (got -1)",
                f"{p}: unit.f0: must be between 45 and 65 (got 80)",
                f"{p}: source.modbus.timeout_s: must be > 0 and ≤ 5 (got 9)",
                f"{p}: source.modbus.poll_hz: must be between 10 and 50 (got 80)",
                f"{p}: identification.every_min: must be > 0 and ≤ 1440 (got 0)",
                f"{p}: mqtt.port: must be between 1 and 65535 (got 0)",
                f"{p}: mqtt.hots: unknown key"]
    for command, args in (("check-config", [str(p)]), ("run", ["--config", str(p)])):
        assert sorted(_errors(_cli(command, *args), command)) == sorted(expected)


def test_start_up_problems_are_all_reported_too(tmp_path):
    (tmp_path / "adir").mkdir()
    p = _toml(tmp_path, store=tmp_path / "adir", ident='function = "os:system"',
              mqtt=f'password_file = "{tmp_path / "nope"}"')
    with pytest.raises(ConfigError) as ei:
        load_config(p)
    keys = [line.split(": ")[1] for line in str(ei.value).splitlines()]
    assert keys == ["store.path", "identification.function", "mqtt.password_file"]


# -- check-config refuses what run refuses -------------------------------------------------------------


def _read_only_offset_map(d: Path) -> Path:
    text = MAP.read_text()
    block = text[text.index('name = "excitation_offset"'):]
    block = block[:block.index("[[points]]")]
    m = d / "ro_map.toml"
    m.write_text(text.replace(block, block.replace("writable = true", "writable = false")))
    return m


ENABLED = "[excitation]\nenabled = true\n" + LIMITS
CASES = {
    "excitation offset register read-only in the map": (
        lambda d: _toml(d, register_map=_read_only_offset_map(d), exc=ENABLED),
        "excitation.points: point 'excitation_offset' (offset) must be writable"),
    "excitation points.offset names a read-only register": (
        lambda d: _toml(d, exc=ENABLED + '[excitation.points]\noffset = "excitation_limit"\n'),
        "excitation.points: point 'excitation_limit' (offset) must be writable"),
    "excitation points.heartbeat names an input register": (
        lambda d: _toml(d, exc=ENABLED + '[excitation.points]\nheartbeat = "status"\n'),
        "excitation.points: point 'status' (heartbeat) must be an holding register"),
    "excitation enabled without limits": (
        lambda d: _toml(d, exc="[excitation]\nenabled = true\n"),
        "excitation: enabled = true needs an explicit [excitation.limits] table"),
    "store path is a directory": (
        lambda d: (d / "adir").mkdir() or _toml(d, store=d / "adir"), "store.path: "),
    "store in a missing directory": (
        lambda d: _toml(d, store=d / "no" / "such" / "s.sqlite"), "store.path: directory "),
    "plug-in os:system": (
        lambda d: _toml(d, ident='function = "os:system"'),
        "identification.function: 'os:system' is not allowed"),
    "plug-in outside fcrlive_plugins": (
        lambda d: _toml(d, ident='function = "tests_daemon_support:fake_identify"'),
        "identification.function: 'tests_daemon_support:fake_identify' is not allowed"),
    "plug-in module missing": (
        lambda d: _toml(d, ident='function = "fcrlive_plugins.nothing_here:f"'),
        "identification.function: cannot import 'fcrlive_plugins.nothing_here'"),
    "plug-in function missing": (
        lambda d: _toml(d, ident='function = "fcrlive_plugins.testing:nope"'),
        "identification.function: module 'fcrlive_plugins.testing' has no function 'nope'"),
    "window too short to ever identify": (
        lambda d: _toml(d, ident="window_min = 0.1"),
        "identification.window_min: 0.1 min = 6 s of data is shorter than the 300 s"),
    "window too short also for an accelerated device": (
        lambda d: _toml(d, ident="window_min = 1\ndevice_speed = 4"),
        "identification.window_min: 1 min × device_speed 4 = 240 s of data"),
    "missing MQTT password_file": (
        lambda d: _toml(d, mqtt=f'host = "127.0.0.1"\nusername = "u"\npassword_file = "{d / "nope"}"'),
        "mqtt.password_file: password file "),
    "missing MQTT CA bundle": (
        lambda d: _toml(d, mqtt=f'host = "127.0.0.1"\n[mqtt.tls]\nca = "{d / "ca.pem"}"'),
        "mqtt.tls.ca: CA bundle "),
    "plant description that does not load": (
        lambda d: (d / "plant.toml").write_text("preset = 'nope'\n") and _toml(
            d, unit=f'rated_mw = 300\nplant = "{d / "plant.toml"}"'), "unit.plant: "),
}


@pytest.mark.parametrize("case", list(CASES))
def test_check_config_refuses_what_run_refuses_at_start(tmp_path, case):
    make, expect = CASES[case]
    p = make(tmp_path)
    checked = _errors(_cli("check-config", str(p)), "check-config")
    ran = _errors(_cli("run", "--config", str(p)), "run")
    assert checked == ran and len(checked) == 1, (checked, ran)
    assert checked[0].startswith(f"{p}: {expect}"), checked[0]
    assert not (tmp_path / "no").exists()  # nothing created on the way


def test_the_shipped_and_valid_configurations_pass(tmp_path):
    r = _cli("check-config", str(ROOT / "deploy" / "fcrlive.toml"))
    assert r.returncode == 0 and r.stderr == "", r.stderr
    ok = _toml(tmp_path, ident='function = "fcrlive_plugins.testing:fake_identify"\nwindow_min = 1.0')
    assert load_config(ok).identification.function == "fcrlive_plugins.testing:fake_identify"
    fast = _toml(tmp_path, ident="window_min = 2.5\ndevice_speed = 4")  # 10 minutes of device time
    assert load_config(fast).identification.device_speed == 4


def test_metrics_beyond_localhost_warns(tmp_path):
    p = _toml(tmp_path, metrics='host = "0.0.0.0"')
    r = _cli("check-config", str(p))
    assert r.returncode == 0
    assert r.stderr.strip() == (f"fcrlive check-config: warning: {p}: metrics.host: '0.0.0.0' serves "
                                "/metrics beyond this machine (unauthenticated, unencrypted); keep it on "
                                "127.0.0.1 or put a proxy in front")
    for host in ("127.0.0.1", "::1", "localhost"):
        assert load_config(_toml(tmp_path, metrics=f'host = "{host}"')).warnings == ()


# -- the store on disk ---------------------------------------------------------------------------------


def _samples(n: int = 30):
    from fcrlive.daemon.sample import Quality, Sample

    t0 = time.time()
    return [Sample(t0 + 0.1 * i, float(i), i, {"power": 1.0}, Quality.OK) for i in range(n)]


def test_the_store_and_its_wal_and_shm_are_0600_whatever_the_umask(tmp_path):
    from fcrlive.daemon.store import SampleWriter

    old = os.umask(0o022)
    try:
        db = tmp_path / "s.sqlite"
        w = SampleWriter(db, ("power",)).open()
        for s in _samples():
            w.add(s)
        assert w.flush()
        files = {f: stat.S_IMODE(os.stat(f).st_mode) for f in (db, Path(f"{db}-wal"), Path(f"{db}-shm"))}
        w.close()
        assert files == {f: 0o600 for f in files}, {str(f): oct(m) for f, m in files.items()}
        os.chmod(db, 0o644)  # a store created by an older version: tightened on the next start
        with SampleWriter(db, ("power",)):
            assert stat.S_IMODE(os.stat(db).st_mode) == 0o600
    finally:
        os.umask(old)


def test_a_missing_store_directory_is_created_only_under_the_state_directory(tmp_path, monkeypatch):
    from fcrlive.daemon.store import SampleWriter

    with pytest.raises(ConfigError, match="does not exist"):
        SampleWriter(tmp_path / "nonexistent-dir" / "x" / "s.sqlite", ("power",)).open()
    assert not (tmp_path / "nonexistent-dir").exists()
    state = tmp_path / "state"
    monkeypatch.setenv("STATE_DIRECTORY", str(state))
    db = state / "sub" / "s.sqlite"
    assert load_config(_toml(tmp_path, store=db)).store.path == db  # check-config agrees
    with SampleWriter(db, ("power",)):
        pass
    assert {d: stat.S_IMODE(os.stat(d).st_mode) for d in (state, state / "sub")} == {state: 0o700,
                                                                                   state / "sub": 0o700}
    assert stat.S_IMODE(os.stat(db).st_mode) == 0o600


# -- rated power against the device ---------------------------------------------------------------------


async def test_rated_mw_is_checked_against_the_device(tmp_path):
    import sim_device
    from fcrlive.daemon.service import Service

    async with sim_device.SimGovernor(port=0, speed=1.0, seed=1) as gov:  # paper plant 1: 300 MW
        assert gov.rated_mw == 300.0
        wrong = _toml(tmp_path, unit="rated_mw = 100", port=gov.port, ident="enabled = false")
        r = await asyncio.to_thread(_cli, "check-config", str(wrong), "--connect")
        assert _errors(r, "check-config") == [
            "unit.rated_mw: 100 MW, but the device's rated_power register says 300 MW; every droop would be "
            "off by a factor 3: fix [unit] rated_mw (or the register map)"]
        right = tmp_path / "right.toml"
        right.write_text(wrong.read_text().replace("rated_mw = 100", "rated_mw = 300"))
        r = await asyncio.to_thread(_cli, "check-config", str(right), "--connect", "-q")
        assert r.returncode == 0, r.stderr
        # the daemon: stops with the same line once it has read the register (exit 2 from `fcrlive run`)
        svc = Service(load_config(wrong))
        with pytest.raises(ConfigError, match="rated_power register says 300 MW") as ei:
            await asyncio.wait_for(svc.run(asyncio.Event()), 60)
        assert ei.value.where == "unit.rated_mw"
        stop = asyncio.Event()
        ok = asyncio.create_task(Service(load_config(right)).run(stop))
        await asyncio.sleep(3.0)
        assert not ok.done()  # keeps running with the right rating
        stop.set()
        await asyncio.wait_for(ok, 30)


# -- MQTT: the excitation state after a broker restart; HA discovery -----------------------------------


async def _retained(port: int, topic: str, timeout: float = 10.0) -> dict | None:
    async with aiomqtt.Client("127.0.0.1", port) as c:
        await c.subscribe(topic, qos=1)
        try:
            async with asyncio.timeout(timeout):
                async for m in c.messages:
                    return json.loads(m.payload)
        except TimeoutError:
            return None


async def test_the_retained_excitation_state_is_republished_after_a_broker_restart():
    from fcrlive.daemon.broker import start_broker
    from fcrlive.daemon.config import MqttConfig
    from fcrlive.daemon.mqtt import MqttPublisher
    from fcrlive.daemon.payloads import ExcitationEventPayload

    async with start_broker() as broker:
        cfg = MqttConfig(host="127.0.0.1", port=broker.port, backoff_max_s=1.0)
        async with MqttPublisher(cfg, "G1") as pub:
            await asyncio.wait_for(pub.connected.wait(), 10)
            pub.publish("excitation", ExcitationEventPayload(t_wall=1.0, state="active", reasons=[]))
            await pub.drain(10)
            assert (await _retained(broker.port, "fcrlive/G1/excitation"))["state"] == "active"
            await broker.stop()  # no persistence: its retained messages are gone
            async with asyncio.timeout(10):
                while pub.connected.is_set():
                    await asyncio.sleep(0.05)
            await broker.start()
            await asyncio.wait_for(pub.connected.wait(), 20)
            await pub.drain(10)
            got = await _retained(broker.port, "fcrlive/G1/excitation")
            assert got is not None and got["state"] == "active"
            # only the sticky topic: results are not sent twice
            assert await _retained(broker.port, "fcrlive/G1/droop", timeout=1.0) is None


def test_homeassistant_live_sensors_have_units_and_classes_and_fcrd_sensors_exist():
    from fcrlive.daemon.mqtt import discovery_configs

    cfgs = {c["unique_id"].removeprefix("fcrlive_G1_"): c
            for c in discovery_configs("fcrlive/G1", "G1").values()}
    classes = {k: (cfgs[k]["unit_of_measurement"], cfgs[k]["device_class"], cfgs[k]["state_class"])
               for k in ("live_power", "live_grid_freq")}
    assert classes == {"live_power": ("MW", "power", "measurement"),
                       "live_grid_freq": ("Hz", "frequency", "measurement")}
    assert {"tso_fcrd", "tso_fcrd_up", "tso_fcrd_down"} <= set(cfgs)
    assert cfgs["tso_fcrd_up"]["state_topic"] == "fcrlive/G1/tso/fcrd_up"


# -- metrics: rejected runs ------------------------------------------------------------------------------


async def test_rejected_runs_are_counted_in_results_total(tmp_path):
    from fcrlive.daemon.service import Service
    from fcrlive.daemon.store import SampleWriter
    from fcrlive.daemon.worker import IdentificationWorker

    cfg = load_config(_toml(tmp_path, ident='function = "fcrlive_plugins.testing:failing_identify"\n'
                                            "window_min = 1\nmin_ok_fraction = 0.0"))
    svc = Service(cfg)
    svc.writer = SampleWriter(cfg.store.path, svc.signals).open()

    def rejected() -> float:
        return svc.metrics.registry.get_sample_value("fcrlive_identification_results_total",
                                                     {"level": "rejected"})

    try:
        cfg.identification.min_ok_fraction = 0.5  # nothing stored yet: skipped for too little data
        p = await svc.identify_once(None)
        assert not p.ok and p.result_quality.level == "rejected" and rejected() == 1.0
        cfg.identification.min_ok_fraction = 0.0  # the plug-in fails
        async with IdentificationWorker(cfg.identification.function, 60.0) as worker:
            p = await svc.identify_once(worker)
        assert not p.ok and "deliberately" in p.error and rejected() == 2.0
        assert svc.metrics.registry.get_sample_value("fcrlive_identification_runs_total",
                                                     {"outcome": "skipped"}) == 1.0
    finally:
        svc.writer.close()
