"""Daemon figures: Modbus poll latency/rate, store write/read, MQTT publish throughput, and against the
SIMULATED GOVERNOR: sample-interval jitter at 10 and 50 Hz, CPU and memory (RSS) of ``fcrlive run`` at
10 Hz over a couple of minutes, and the delay from the end of a window to the result at an MQTT subscriber.

``python -m benchmarks daemon [--quick]``. Everything on loopback with real components (pymodbus server,
SQLite file, Mosquitto or the embedded amqtt broker, the daemon as a subprocess).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from fcrlive.daemon.broker import start_broker
from fcrlive.daemon.config import MqttConfig
from fcrlive.daemon.modbus_source import ModbusSource
from fcrlive.daemon.mqtt import MqttPublisher
from fcrlive.daemon.sample import Quality, Sample
from fcrlive.daemon.store import SampleWriter, connect, read_window
from fcrlive.modbus.client import ModbusParams
from fcrlive.modbus.mapfile import load_register_map
from testsupport.modbus_server import RegisterServer

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


async def bench_jitter(poll_hz: float, seconds: float = 10.0) -> None:
    """Intervals between sample arrivals polling the simulated governor (speed 1) with ModbusSource."""
    from sim_device import SimGovernor

    rmap = load_register_map(ROOT / "sim_device" / "registers.toml")
    gov = SimGovernor(port=0, speed=1.0, seed=0)
    await gov.start()
    try:
        async with ModbusSource(ModbusParams("127.0.0.1", gov.port, rmap, poll_hz=poll_hz)) as src:
            await src.wait_connected(5)
            got = []
            t0 = time.perf_counter()
            async for s in src.samples():
                got.append(s)
                if time.perf_counter() - t0 >= seconds:
                    break
    finally:
        await gov.stop()
    ok = [s for s in got if s.quality == Quality.OK]
    dev = 1e3 * (np.diff([s.t_wall for s in got]) - 1.0 / poll_hz)
    a = np.abs(dev)
    print(f"jitter vs the simulated governor at {poll_hz:g} Hz ({seconds:g} s, {len(got)} samples, "
          f"{len(ok)} ok, missed {src.stats.missed_ticks}): |interval − {1e3 / poll_hz:g} ms| "
          f"p50 {np.percentile(a, 50):.2f} ms p99 {np.percentile(a, 99):.2f} ms max {a.max():.2f} ms")


def _proc_cpu_rss(pid: int) -> tuple[float, float]:
    """(utime + stime [s], VmRSS [MiB]) of one process, from /proc."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    cpu = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    rss = 0.0
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                rss = int(line.split()[1]) / 1024
    return cpu, rss


def _children(pid: int) -> list[int]:
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            return [int(x) for x in f.read().split()]
    except OSError:
        return []


async def bench_daemon_process(seconds: float = 120.0, poll_hz: float = 10.0, speed: float = 10.0) -> None:
    """``fcrlive run`` (subprocess) against the simulated governor at ``poll_hz``: CPU and RSS of the
    daemon and its identification worker; delay from each window's end to the result at a subscriber."""
    import json
    import signal
    import subprocess
    import sys

    import aiomqtt

    from sim_device import SimGovernor

    every_min = 0.5
    with tempfile.TemporaryDirectory() as d:
        b = start_broker()
        async with b, SimGovernor(port=0, speed=speed, seed=1) as gov:
            cfg = Path(d) / "c.toml"
            cfg.write_text(f"""
[unit]
name = "B1"
rated_mw = 300.0
kd = 0.1
[source.modbus]
port = {gov.port}
register_map = "{ROOT / 'sim_device' / 'registers.toml'}"
poll_hz = {poll_hz}
[store]
path = "{Path(d) / 's.sqlite'}"
[identification]
every_min = {every_min}
window_min = {2 * every_min}
device_speed = {speed}
min_ok_fraction = 0.5
[mqtt]
host = "127.0.0.1"
port = {b.port}
[metrics]
enabled = false
""")
            env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
            proc = subprocess.Popen([sys.executable, "-m", "fcrlive.cli", "run", "--config", str(cfg)],
                                    stderr=subprocess.DEVNULL, env=env)
            delays: list[float] = []
            durations: list[float] = []
            try:
                await asyncio.sleep(5.0)  # start-up (imports) is not the steady state
                c0, _ = _proc_cpu_rss(proc.pid)
                t0 = time.monotonic()
                rss_max = 0.0
                worker_rss = 0.0

                async def sample_rss():
                    nonlocal rss_max, worker_rss
                    while True:
                        rss_max = max(rss_max, _proc_cpu_rss(proc.pid)[1])
                        for k in _children(proc.pid):
                            with contextlib.suppress(OSError, IndexError, ValueError):
                                worker_rss = max(worker_rss, _proc_cpu_rss(k)[1])
                        await asyncio.sleep(1.0)

                sampler = asyncio.create_task(sample_rss())
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(seconds), aiomqtt.Client("127.0.0.1", b.port) as cl:
                        await cl.subscribe("fcrlive/B1/result/latest", qos=1)
                        async for m in cl.messages:
                            now = time.time()
                            msg = json.loads(m.payload)
                            if m.retain:
                                continue
                            if msg["ok"]:  # skipped (window not full yet) and failed runs excluded
                                delays.append(now - msg["window"]["end"])
                                durations.append(msg["duration_s"])
                sampler.cancel()
                c1, _ = _proc_cpu_rss(proc.pid)
                wall = time.monotonic() - t0
                workers = _children(proc.pid)
                cw = 0.0
                for k in workers:
                    with contextlib.suppress(OSError, IndexError, ValueError):
                        cw += _proc_cpu_rss(k)[0]
            finally:
                proc.send_signal(signal.SIGTERM)
                proc.wait(30)
    print(f"daemon at {poll_hz:g} Hz vs the simulated governor, {wall:.0f} s: main process CPU "
          f"{100 * (c1 - c0) / wall:.1f} % of a core, RSS max {rss_max:.0f} MiB; identification worker "
          f"CPU {cw:.1f} s total (since start), RSS max {worker_rss:.0f} MiB; "
          f"{len(delays)} successful result(s), one every {every_min * 60:g} s")
    if delays:
        print(f"  window end → result at an MQTT subscriber: median {np.median(delays):.2f} s, "
              f"max {max(delays):.2f} s (identification itself: median {np.median(durations):.2f} s)")


def main(argv: list[str] | None = None) -> None:
    import argparse

    ap = argparse.ArgumentParser(prog="bench_daemon", description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="shorter runs (30 s daemon)")
    ap.add_argument("--daemon-seconds", type=float, default=120.0)
    args = ap.parse_args(argv)
    asyncio.run(bench_modbus(50.0, 10.0))
    asyncio.run(bench_modbus(25.0, 5.0))
    bench_store()
    asyncio.run(bench_mqtt())
    asyncio.run(bench_jitter(10.0, 5.0 if args.quick else 20.0))
    asyncio.run(bench_jitter(50.0, 5.0 if args.quick else 20.0))
    asyncio.run(bench_daemon_process(40.0 if args.quick else args.daemon_seconds))


if __name__ == "__main__":
    main()
