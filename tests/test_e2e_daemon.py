"""End to end on loopback: the simulated governor (real Modbus TCP server) + a real MQTT broker (Mosquitto
when on PATH, else the embedded amqtt) + ``fcrlive run`` in a subprocess, accelerated.

No mocks; no wall-clock asserts (waits have generous timeouts, assertions are on data).
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import aiomqtt
import pytest

from fcrlive.daemon.broker import free_port, start_broker
from fcrlive.daemon.store import connect, read_results, read_runs
from testsupport.daemon_config import daemon_toml

ROOT = Path(__file__).resolve().parents[1]
TESTS = Path(__file__).resolve().parent
sim_device = pytest.importorskip("sim_device")


def _toml(path: Path, *, port: int, store: Path, mqtt_port: int | None, poll_hz: float, window_min: float,
          every_min: float, function: str | None = None, unit: str = "G1", extra: str = "",
          unit_extra: str = "", device_speed: float = 1.0, min_ok_fraction: float = 0.5) -> Path:
    mqtt = {"port": mqtt_port, "stats_interval_s": 2.0, "backoff_max_s": 1.0} if mqtt_port else None
    path.write_text(daemon_toml(unit=unit, port=port, regmap=ROOT / "sim_device" / "registers.toml",
                                poll_hz=poll_hz, store=store,
                                identification={"every_min": every_min, "window_min": window_min,
                                                "device_speed": device_speed,
                                                "min_ok_fraction": min_ok_fraction, "function": function},
                                mqtt=mqtt, unit_extra=unit_extra, extra=extra))
    return path


def _daemon(cfg: Path, log: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]),
           "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "-m", "fcrlive.cli", "run", "--config", str(cfg)],
                            stdout=subprocess.DEVNULL, stderr=log.open("w"), env=env)


def _stop(proc: subprocess.Popen) -> int:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            return proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
            return proc.wait(10)
    return proc.returncode


def _query(db: Path, sql: str, *args):
    if not db.exists():
        return None
    try:
        con = connect(db, readonly=True)
        try:
            return con.execute(sql, args).fetchone()
        finally:
            con.close()
    except sqlite3.Error:  # not created yet
        return None


async def _until(cond, timeout: float, what: str, proc: subprocess.Popen | None = None,
                 log: Path | None = None):
    deadline = time.monotonic() + timeout
    while True:
        v = cond()
        if v:
            return v
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"daemon exited ({proc.returncode}) while waiting for {what}: "
                                 f"{log.read_text()[-2000:] if log else ''}")
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}: {log.read_text()[-2000:] if log else ''}")
        await asyncio.sleep(0.25)


async def test_results_over_mqtt_survive_a_broker_outage(tmp_path):
    """Daemon + real identification (Z_u, no excitation) at speed 15; the broker is down for > 10 s
    around the first identification: that result is delivered after the broker returns (Mosquitto
    keeps nothing across its restart, so it comes from the daemon's queue)."""
    speed, every_min = 15.0, 1.0
    broker = start_broker()
    async with broker, sim_device.SimGovernor(port=0, speed=speed, seed=1) as gov:
        db = tmp_path / "s.sqlite"
        cfg = _toml(tmp_path / "c.toml", port=gov.port, store=db, mqtt_port=broker.port, poll_hz=50.0,
                    window_min=every_min, every_min=every_min, device_speed=speed)
        log = tmp_path / "daemon.log"
        proc = _daemon(cfg, log)
        try:
            started = (await _until(lambda: _query(db, "SELECT started FROM runs ORDER BY id DESC"), 60,
                                    "the daemon's start", proc, log))[0]
            first_ident = started + every_min * 60.0
            await asyncio.sleep(max(0.0, first_ident - 8.0 - time.time()))
            await broker.stop()
            t_down = time.time()
            await asyncio.sleep(max(10.0, first_ident + 8.0 - time.time()))
            # the identification ran (stored) while the broker was away
            await _until(lambda: _query(db, "SELECT count(*) FROM results")[0] >= 1, 60,
                         "the first identification", proc, log)
            t_up = time.time()
            await broker.start()
            got: dict[str, dict] = {}
            async with asyncio.timeout(60), aiomqtt.Client("127.0.0.1", broker.port) as c:
                await c.subscribe("fcrlive/G1/#", qos=1)
                async for m in c.messages:
                    if str(m.topic) != "fcrlive/G1/status":
                        got[str(m.topic)] = json.loads(m.payload)
                    res = got.get("fcrlive/G1/result/latest")
                    # a result the quality rule rejects publishes no headline topics (docs/daemon.md)
                    if res and "fcrlive/G1/quality" in got and "fcrlive/G1/result_quality" in got and (
                            "fcrlive/G1/tso/fcrn" in got or res["result_quality"]["level"] == "rejected"):
                        break
        finally:
            rc = _stop(proc)
    assert rc == 0, log.read_text()[-2000:]
    res = got["fcrlive/G1/result/latest"]
    assert t_down < res["t"] < t_up, "the result delivered was made while the broker was down"
    assert res["ok"], res["error"]
    r = res["result"]
    assert r["method"] == "zu" and r["schema_version"] == 1
    verdict = got["fcrlive/G1/result_quality"]
    assert verdict["level"] == res["result_quality"]["level"]
    assert verdict["window_end"] == res["window"]["end"]
    if verdict["level"] == "rejected":
        assert verdict["reasons"] and "fcrlive/G1/droop" not in got and "fcrlive/G1/tso/fcrn" not in got
    else:
        assert got["fcrlive/G1/tso/fcrn"]["verdict"] == "unknown"  # no excitation: G_p not identifiable
    assert got["fcrlive/G1/quality"]["ok_fraction"] > 0.8
    assert abs(r["sample_interval_s"] - speed / 50.0) < 0.1
    con = connect(db, readonly=True)
    assert read_results(con)[-1].result["method"] == "zu"
    [stored] = [x for x in read_results(con) if x.t == res["t"]]
    assert stored.result_quality == res["result_quality"]
    assert read_runs(con)[-1]["clean"] == 1
    con.close()
    droop = got.get("fcrlive/G1/droop", {}).get("value")
    if droop is not None:
        assert 2.0 < droop < 20.0, f"droop {droop} % is not even plausible (truth 8 %)"
    # The ±0.5 pp accuracy requirement is asserted by the excited test below, on controller-rate data;
    # this outage test runs at speed 15 (0.3 simulated s between polls, no excitation), where only a
    # plausible droop can be expected (docs/daemon.md).


# The accuracy end-to-end test (the paper's 50 Hz plant, buffered acquisition, excitation on, with the
# export of the identified stretch and its off-line identification) is tests/test_e2e_buffered.py.


async def test_sigkill_mid_window_keeps_committed_samples_and_next_window_spans_both_runs(tmp_path):
    async with sim_device.SimGovernor(port=0, speed=60.0, seed=2) as gov:
        db = tmp_path / "s.sqlite"
        # the 60-s window holds ~12 s of run 1 and ~24 s of run 2 (≤ 60 % ok with perfect polling), and on
        # a loaded machine the in-process simulated governor misses polls (41 % seen): this test is about
        # the window spanning both runs, not the data's quality
        cfg = _toml(tmp_path / "c.toml", port=gov.port, store=db, mqtt_port=None, poll_hz=25.0,
                    window_min=1.0, every_min=0.4, function="fcrlive_plugins.testing:fake_identify",
                    min_ok_fraction=0.1)
        log1, log2 = tmp_path / "d1.log", tmp_path / "d2.log"
        p1 = _daemon(cfg, log1)
        try:
            await _until(lambda: (_query(db, "SELECT count(*) FROM samples WHERE quality = 0") or [0])[0]
                         > 250, 60, "samples of run 1", p1, log1)
            p1.send_signal(signal.SIGKILL)
            p1.wait(10)
            t_kill = time.time()
            n1, last1 = _query(db, "SELECT count(*), max(t) FROM samples WHERE run = 1")
            p2 = _daemon(cfg, log2)
            try:
                await _until(lambda: _query(db, "SELECT count(*) FROM results WHERE t > ?", t_kill)[0] >= 1,
                             90, "an identification after the restart", p2, log2)
            finally:
                rc2 = _stop(p2)
        finally:
            if p1.poll() is None:
                p1.kill()
    assert rc2 == 0, log2.read_text()[-2000:]
    con = connect(db, readonly=True)
    runs = read_runs(con)
    assert [r["clean"] for r in runs] == [0, 1], runs  # the killed run is visible as unclean
    assert con.execute("SELECT count(*), max(t) FROM samples WHERE run = 1").fetchone() == (n1, last1)
    res = [r for r in read_results(con) if r.t > t_kill][-1]
    assert res.error is None and res.t1 < last1 < res.t2
    in_window = con.execute("SELECT run, count(*) FROM samples WHERE t >= ? AND t <= ? AND quality = 0 "
                            "GROUP BY run ORDER BY run", (res.t1, res.t2)).fetchall()
    assert [r for r, _ in in_window] == [1, 2], in_window  # the window covers both runs
    # every stored sample of the window was read, except the last ≤ 1 s not yet committed when it was read
    assert 0 <= sum(n for _, n in in_window) - res.result["samples"] <= 30
    assert res.quality["gaps"] >= 1  # the restart gap is reported
    con.close()


def _cli(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fcrlive.cli", *args], capture_output=True, text=True,
                          timeout=timeout)


def test_unreachable_device_one_clear_line_and_exit_2(tmp_path):
    port = free_port()
    cfg = _toml(tmp_path / "c.toml", port=port, store=tmp_path / "s.sqlite", mqtt_port=None, poll_hz=25.0,
                window_min=5.0, every_min=1.0)
    p = _cli("check-config", str(cfg), "--connect", "--timeout", "2")
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert lines == [f"fcrlive check-config: error: cannot reach the Modbus device 127.0.0.1:{port} "
                     "(connection refused)"]


@pytest.mark.parametrize("edit, expect", [
    (("[metrics]", "[metrics]\nbogus = 1"), "metrics.bogus: unknown key"),
    (("poll_hz = 25.0", 'poll_hz = "fast"'), "source.modbus.poll_hz: must be a valid number"),
    (("[source.modbus]", "[source.modbus]\npoints = [{name = 'a', table = 'input', address = 0, "
      "type = 'float32'}, {name = 'b', table = 'input', address = 1, type = 'uint16'}]"),
     "give exactly one of register_map"),
])
def test_run_with_bad_config_one_line_exit_2(tmp_path, edit, expect):
    cfg = _toml(tmp_path / "c.toml", port=5020, store=tmp_path / "s.sqlite", mqtt_port=None, poll_hz=25.0,
                window_min=5.0, every_min=1.0)
    cfg.write_text(cfg.read_text().replace(*edit, 1))
    p = _cli("run", "--config", str(cfg))
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fcrlive run: error: ") and expect in lines[0], p.stderr
    assert "Traceback" not in p.stderr


def test_register_map_overlap_is_one_line(tmp_path):
    cfg = _toml(tmp_path / "c.toml", port=5020, store=tmp_path / "s.sqlite", mqtt_port=None, poll_hz=25.0,
                window_min=5.0, every_min=1.0)
    text = cfg.read_text()
    start = text.index("register_map")
    text = text[:start] + ("points = [{name = 'a', table = 'input', address = 0, type = 'float32'}, "
                           "{name = 'b', table = 'input', address = 1, type = 'uint16'}]") + \
        text[text.index("\n", start):]
    cfg.write_text(text)
    p = _cli("run", "--config", str(cfg))
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert p.stderr.strip().splitlines() == [
        f"fcrlive run: error: {cfg}: source.modbus: points 'a' (input 0-1) and 'b' (input 1-1) overlap"]

