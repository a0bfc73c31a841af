"""The simulated governor under load: polls per second it serves at --speed 60, and its CPU use.

Starts ``python -m sim_device --port 0 --speed 60`` as a subprocess, then one pymodbus client reads the
whole input block (one FC4 request per poll) back to back for ``--seconds`` (default 5). Prints the poll
rate, latency percentiles, how well the device kept its speed factor (device_time against wall time, the
device's own counter), and the device process's CPU use from /proc/PID/stat (utime + stime), split into
an idle phase (simulating, nobody polling) and the polling phase.

    python -m benchmarks sim_device
    python -m benchmarks.bench_sim_device --speed 60 --seconds 5
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import sys
import time

import numpy as np


def _cpu_seconds(pid: int) -> float:
    """utime + stime of a process [s], from /proc (no psutil)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    ticks = os.sysconf("SC_CLK_TCK")
    return (int(fields[11]) + int(fields[12])) / ticks  # fields 14, 15 of stat(5), after "pid (comm)"


async def _bench(speed: float, seconds: float, idle_s: float) -> dict:
    from pymodbus.client import AsyncModbusTcpClient

    from sim_device.registers import load_map

    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    rmap = load_map()
    start, count = rmap.span("input")
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sim_device", "--port", "0", "--speed", str(speed), "--log-level", "WARNING",
        stdout=asyncio.subprocess.PIPE, env=env,
    )  # fmt: skip
    try:
        line = (await asyncio.wait_for(proc.stdout.readline(), 60)).decode()
        if not line.startswith("listening on"):
            raise RuntimeError(f"device did not start: {line!r}")
        port = int(line.rsplit(":", 1)[1])
        client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=1.0, retries=0, reconnect_delay=0)
        if not await client.connect():
            raise RuntimeError("cannot connect")

        async def snap():
            rr = await client.read_input_registers(start, count=count, device_id=rmap.unit_id)
            return rmap.decode_block("input", start, rr.registers)

        await asyncio.sleep(0.5)
        # idle phase: the device simulates, nobody polls
        c0, w0, v0 = _cpu_seconds(proc.pid), time.perf_counter(), await snap()
        await asyncio.sleep(idle_s)
        c1, w1, v1 = _cpu_seconds(proc.pid), time.perf_counter(), await snap()
        # polling phase: back-to-back full-block reads
        lat = []
        t_end = time.perf_counter() + seconds
        c2, w2 = _cpu_seconds(proc.pid), time.perf_counter()
        first = await snap()
        while time.perf_counter() < t_end:
            t = time.perf_counter()
            rr = await client.read_input_registers(start, count=count, device_id=rmap.unit_id)
            lat.append(time.perf_counter() - t)
            if rr.isError():
                raise RuntimeError(rr)
        last = await snap()
        c3, w3 = _cpu_seconds(proc.pid), time.perf_counter()
        client.close()
    finally:
        if proc.returncode is None:
            proc.terminate()
        await proc.wait()
    lat_ms = np.array(lat) * 1e3
    return {
        "speed": speed,
        "polls": len(lat),
        "polls_per_s": len(lat) / (w3 - w2),
        "p50_ms": float(np.percentile(lat_ms, 50)),
        "p99_ms": float(np.percentile(lat_ms, 99)),
        "max_ms": float(lat_ms.max()),
        "speed_idle": (v1["device_time"] - v0["device_time"]) / (w1 - w0),
        "speed_polled": (last["device_time"] - first["device_time"]) / (w3 - w2),
        "cpu_idle": (c1 - c0) / (w1 - w0),
        "cpu_polled": (c3 - c2) / (w3 - w2),
        "samples_per_s": speed / 0.02,
    }


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="bench_sim_device", description=__doc__.split("\n\n")[0])
    p.add_argument("--speed", type=float, default=60.0)
    p.add_argument("--seconds", type=float, default=5.0, help="polling phase [wall s]")
    p.add_argument("--idle", type=float, default=3.0, help="idle phase [wall s]")
    a = p.parse_args(argv)
    r = asyncio.run(_bench(a.speed, a.seconds, a.idle))
    print(
        f"sim_device at --speed {r['speed']:g} ({r['samples_per_s']:.0f} controller samples per wall second)"
    )
    print(f"  idle:    device clock {r['speed_idle']:.2f}x, CPU {100 * r['cpu_idle']:.1f} % of one core")
    print(
        f"  polling: {r['polls']} full-block FC4 reads in {a.seconds:g} s = {r['polls_per_s']:.0f} polls/s, "
        f"latency p50 {r['p50_ms']:.2f} ms, p99 {r['p99_ms']:.2f} ms, max {r['max_ms']:.1f} ms"
    )
    print(f"           device clock {r['speed_polled']:.2f}x, CPU {100 * r['cpu_polled']:.1f} % of one core")


if __name__ == "__main__":
    main(sys.argv[1:])
