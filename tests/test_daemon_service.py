"""The daemon end to end: SimGovernor (Modbus) → store → identification worker → MQTT (real broker)."""

from __future__ import annotations

import asyncio
import json
import os
import socket
import urllib.request
from pathlib import Path

import aiomqtt
import pytest

from fcrlive.daemon.broker import start_broker
from fcrlive.daemon.config import load_config
from fcrlive.daemon.health import Metrics, sd_notify
from fcrlive.daemon.sample import Quality, Sample
from fcrlive.daemon.service import Service
from fcrlive.daemon.store import connect, read_results, read_runs

ROOT = Path(__file__).resolve().parents[1]


async def test_service_end_to_end(tmp_path):
    sim_device = pytest.importorskip("sim_device")
    from tests_daemon_support import ToySimulator

    async with start_broker() as broker:
        gov = sim_device.SimGovernor(simulator=ToySimulator(), port=0, speed=1.0)
        async with gov:
            cfg = load_config(
                ROOT / "deploy" / "fcrlive.toml",
                source={"kind": "modbus", "modbus": {
                    "port": gov.port, "poll_hz": 25.0,
                    "register_map": str(ROOT / "sim_device/registers.toml")}},
                store={"path": str(tmp_path / "s.sqlite")},
                identification={"every_min": 0.04, "window_min": 1, "min_ok_fraction": 0.0,
                                "function": "fcrlive_plugins.testing:fake_identify"},
                mqtt={"host": "127.0.0.1", "port": broker.port, "stats_interval_s": 1.0},
                metrics={"enabled": False})
            svc = Service(cfg)
            stop = asyncio.Event()
            task = asyncio.create_task(svc.run(stop))
            async with aiomqtt.Client("127.0.0.1", broker.port) as c:
                await c.subscribe("fcrlive/G1/#", qos=1)
                seen = {}
                async with asyncio.timeout(40):
                    async for m in c.messages:
                        seen[str(m.topic)] = m.payload.decode()
                        if {"fcrlive/G1/droop", "fcrlive/G1/live", "fcrlive/G1/tso/fcrn"} <= set(seen):
                            break
            stop.set()
            await asyncio.wait_for(task, 20)
    res = json.loads(seen["fcrlive/G1/result/latest"])
    assert res["ok"] and res["result"]["samples"] > 10 and res["result"]["rated_mw"] == 300.0
    assert json.loads(seen["fcrlive/G1/droop"])["value"] == 4.0
    live = json.loads(seen["fcrlive/G1/live"])
    assert live["signals"]["grid_freq"]["mean"] == pytest.approx(50.0, abs=0.1) and live["rate_hz"] > 5
    con = connect(tmp_path / "s.sqlite", readonly=True)
    n_ok = con.execute("SELECT count(*) FROM samples WHERE quality = 0").fetchone()[0]
    assert n_ok > 25
    assert read_results(con)[0].result["droop"]["value"] == 0.04  # the report: a fraction
    assert read_runs(con)[-1]["clean"] == 1
    assert svc.metrics.samples.labels("ok")._value.get() > 25


def test_sd_notify_and_metrics(monkeypatch, tmp_path):
    path = str(tmp_path / "notify")
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as s:
        s.bind(path)
        monkeypatch.delenv("NOTIFY_SOCKET", raising=False)
        assert sd_notify("READY=1") is False
        monkeypatch.setenv("NOTIFY_SOCKET", path)
        assert sd_notify("READY=1") is True
        assert s.recv(100) == b"READY=1"
    m = Metrics("G1")
    m.observe_sample(Sample(0.0, 0.0, 0, {}, Quality.OK, latency_s=0.002))
    m.observe_sample(Sample(0.0, 0.0, 1, {}, Quality.MISSING))
    server, _thread = m.serve("127.0.0.1", 0)
    try:
        port = server.server_address[1]
        text = urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=5).read().decode()
    finally:
        server.shutdown()
    assert 'fcrlive_samples_total{quality="ok"} 1.0' in text
    assert "fcrlive_missed_ticks_total 1.0" in text
    assert "fcrlive_poll_latency_seconds_count 1.0" in text
    assert os.environ["NOTIFY_SOCKET"] == path
