"""MQTT publisher against a real broker (private Mosquitto when on PATH, else embedded amqtt)."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import textwrap

import aiomqtt
import pytest

from fcrlive.daemon.broker import EmbeddedBroker, start_broker
from fcrlive.daemon.config import MqttConfig
from fcrlive.daemon.mqtt import MqttPublisher
from fcrlive.daemon.payloads import (
    DataQuality,
    ResultPayload,
    Window,
    render_docs,
    result_topics,
)


def _result(t=1000.0, droop=4.0):
    from tests_daemon_support import report

    d = droop / 100.0  # the report's droop is a fraction, published in %
    return ResultPayload(
        unit="G1", t=t, t_iso="x", window=Window.of(t - 1800, t), method="auto", ok=True, duration_s=0.1,
        quality=DataQuality(ok_fraction=0.99, samples=100, expected=101, counts={"ok": 99}, gaps=0, gap_s=0),
        result=report(droop=d, droop_ci95=(d - 0.002, d + 0.002), max_abs_s=1.3))


async def _collect(port, topic, n=1, timeout=10.0):
    """Messages on ``topic`` seen by a fresh subscriber (retained ones first)."""
    out = []
    async with aiomqtt.Client("127.0.0.1", port, identifier=None) as c:
        await c.subscribe(topic, qos=1)
        async with asyncio.timeout(timeout):
            async for m in c.messages:
                out.append((str(m.topic), m.payload.decode(), m.retain))
                if len(out) >= n:
                    break
    return out


@pytest.fixture
async def broker():
    async with start_broker() as b:
        yield b


async def test_retained_result_reaches_a_fresh_subscriber(broker):
    cfg = MqttConfig(host="127.0.0.1", port=broker.port, base_topic="fcrlive")
    async with MqttPublisher(cfg, "G1") as pub:
        for topic, payload in result_topics(_result()).items():
            pub.publish(topic, payload)
        await pub.drain(10)
        got = dict((t, p) for t, p, _ in await _collect(broker.port, "fcrlive/G1/#", n=6))
    assert got["fcrlive/G1/status"] == "online"
    assert json.loads(got["fcrlive/G1/droop"])["value"] == 4.0
    assert json.loads(got["fcrlive/G1/tso/fcrn"])["verdict"] == "pass"
    assert json.loads(got["fcrlive/G1/result/latest"])["result"]["max_abs_s"]["value"] == 1.3
    # clean exit: the publisher says offline itself
    [(_, status, retained)] = await _collect(broker.port, "fcrlive/G1/status")
    assert status == "offline" and retained


CHILD = textwrap.dedent("""
    import asyncio, sys
    from fcrlive.daemon.config import MqttConfig
    from fcrlive.daemon.mqtt import MqttPublisher
    async def main():
        async with MqttPublisher(MqttConfig(host="127.0.0.1", port=int(sys.argv[1])), "G7") as pub:
            await pub.connected.wait()
            await pub.drain()
            print("up", flush=True)
            await asyncio.sleep(60)
    asyncio.run(main())
""")


async def test_will_offline_when_the_process_dies(broker):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    proc = await asyncio.create_subprocess_exec(sys.executable, "-c", CHILD, str(broker.port),
                                                stdout=subprocess.PIPE, env=env)
    try:
        async with asyncio.timeout(20):
            assert (await proc.stdout.readline()).strip() == b"up"
        [(_, status, _)] = await _collect(broker.port, "fcrlive/G7/status")
        assert status == "online"
        async with aiomqtt.Client("127.0.0.1", broker.port) as c:
            await c.subscribe("fcrlive/G7/status", qos=1)
            proc.send_signal(signal.SIGKILL)
            async with asyncio.timeout(15):
                async for m in c.messages:
                    if m.payload == b"offline":
                        break
    finally:
        if proc.returncode is None:
            proc.kill()
        await proc.wait()
    [(_, status, retained)] = await _collect(broker.port, "fcrlive/G7/status")
    assert status == "offline" and retained


async def test_results_queued_while_broker_is_down_arrive_after_restart(broker):
    cfg = MqttConfig(host="127.0.0.1", port=broker.port, backoff_max_s=1.0)
    async with MqttPublisher(cfg, "G1") as pub:
        await asyncio.wait_for(pub.connected.wait(), 10)
        await broker.stop()
        async with asyncio.timeout(10):
            while pub.connected.is_set():
                await asyncio.sleep(0.05)
        for i in range(5):  # only the newest droop survives (retained), every live message queued
            pub.publish("droop", result_topics(_result(droop=float(i)))["droop"])
            pub.publish("live", f"tick {i}")
        await asyncio.sleep(2.0)
        assert pub.pending == 6
        await broker.start()
        await pub.drain(20)
        got = await _collect(broker.port, "fcrlive/G1/droop")
    assert json.loads(got[0][1])["value"] == 4.0
    assert pub.stats.connects >= 2 and pub.stats.published >= 6


async def test_embedded_amqtt_broker_retains():
    async with EmbeddedBroker() as b:
        async with aiomqtt.Client("127.0.0.1", b.port) as c:
            await c.publish("a/b", b"x", qos=1, retain=True)
        assert await _collect(b.port, "a/b") == [("a/b", "x", True)]


async def test_homeassistant_discovery_reannounced(broker):
    cfg = MqttConfig(host="127.0.0.1", port=broker.port, homeassistant_discovery=True)
    async with MqttPublisher(cfg, "G1") as pub:
        await pub.connected.wait()
        await _collect(broker.port, "homeassistant/sensor/+/config", n=3)  # announced by now
        cfgs = await _collect(broker.port, "homeassistant/sensor/+/config", n=3)
        assert all(r for _, _, r in cfgs)
        d = json.loads(cfgs[0][1])
        assert d["availability_topic"] == "fcrlive/G1/status"
        async with aiomqtt.Client("127.0.0.1", broker.port) as c:
            await c.subscribe("homeassistant/sensor/fcrlive_G1_droop/config")
            async with asyncio.timeout(10):
                async for m in c.messages:  # the retained copy first, then the re-announcement
                    if not m.retain:
                        break
                    await c.publish("homeassistant/status", b"online")


def test_docs_are_generated_from_the_models():
    path = os.path.join(os.path.dirname(__file__), "..", "docs", "mqtt.md")
    with open(path, encoding="utf-8") as fh:
        assert fh.read() == render_docs(), "run: python -m fcrlive.daemon.payloads docs/mqtt.md"
