"""Daemon infrastructure figures: Modbus poll latency/rate, store write/read, MQTT publish throughput.

``python -m benchmarks daemon``. Everything on loopback with real components (pymodbus server,
SQLite file, Mosquitto or the embedded amqtt broker).
"""

from __future__ import annotations

import asyncio
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from fcrlive.daemon.broker import start_broker
from fcrlive.daemon.config import MqttConfig, load_register_map
from fcrlive.daemon.modbus_source import ModbusParams, ModbusSource
from fcrlive.daemon.modbus_testserver import RegisterServer
from fcrlive.daemon.mqtt import MqttPublisher
from fcrlive.daemon.sample import Quality, Sample
from fcrlive.daemon.store import SampleWriter, connect, read_window

ROOT = Path(__file__).resolve().parents[1]


async def bench_modbus(poll_hz: float = 50.0, seconds: float = 10.0) -> None:
    rmap = load_register_map(ROOT / "sim_device" / "registers.toml")
    async with RegisterServer(rmap) as srv:
        await srv.set({"sample_counter": 1, "power": 80.0, "grid_freq": 50.0})
        async with ModbusSource(ModbusParams("127.0.0.1", srv.port, rmap, poll_hz=poll_hz)) as src:
            await src.wait_connected(5)
            got = []
            t0 = time.perf_counter()
            async for s in src.samples():
                got.append(s)
                await srv.set({"sample_counter": len(got) + 1})
                if time.perf_counter() - t0 >= seconds:
                    break
    lat = sorted(s.latency_s for s in got if not math.isnan(s.latency_s))
    dts = np.diff([s.t_wall for s in got])
    print(f"modbus {poll_hz:g} Hz, {len(src.read_blocks)} read block(s), {len(src.names)} points: "
          f"{len(got)} samples in {seconds:g} s ({len(got) / seconds:.2f}/s), "
          f"missed {src.stats.missed_ticks}, "
          f"latency p50 {1e3 * lat[len(lat) // 2]:.2f} ms p99 {1e3 * lat[int(0.99 * len(lat))]:.2f} ms, "
          f"interval mean {1e3 * dts.mean():.2f} ms sd {1e3 * dts.std():.2f} ms")


def bench_store(n: int = 45_000) -> None:
    signals = ("power", "grid_freq", "speed", "controller_output", "guide_vane", "excitation_applied")
    with tempfile.TemporaryDirectory() as d:
        db = Path(d) / "s.sqlite"
        t0 = time.perf_counter()
        with SampleWriter(db, signals) as w:
            for i in range(n):
                w.add(Sample(1e9 + i * 0.04, math.nan, i, dict.fromkeys(signals, 1.0 * i), Quality.OK))
            w.flush(60)
        dt_write = time.perf_counter() - t0
        con = connect(db, readonly=True)
        t0 = time.perf_counter()
        win = read_window(con, 1e9, 1e9 + n * 0.04)
        dt_read = time.perf_counter() - t0
        size = db.stat().st_size + sum(p.stat().st_size for p in Path(d).glob("s.sqlite-*"))
    print(f"store: {n} samples × {len(signals)} signals written+committed in {dt_write:.2f} s "
          f"({n / dt_write:,.0f}/s); 30 min window at 25 Hz read back in {1e3 * dt_read:.0f} ms "
          f"({len(win)} rows); {size / n:.0f} bytes/sample on disk")


async def bench_mqtt(n: int = 2000) -> None:
    b = start_broker()
    async with b, MqttPublisher(MqttConfig(host="127.0.0.1", port=b.port, queue_max=n + 10), "G1") as pub:
        await pub.connected.wait()
        t0 = time.perf_counter()
        for i in range(n):
            pub.publish("live", f'{{"i": {i}}}', retain=False, qos=1)
        await pub.drain(120)
        dt = time.perf_counter() - t0
    print(f"mqtt ({b.kind}): {n} QoS 1 messages in {dt:.2f} s ({n / dt:,.0f}/s)")


def main(argv: list[str] | None = None) -> None:
    asyncio.run(bench_modbus(50.0, 10.0))
    asyncio.run(bench_modbus(25.0, 5.0))
    bench_store()
    asyncio.run(bench_mqtt())


if __name__ == "__main__":
    main()
