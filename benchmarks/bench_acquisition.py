"""Buffered acquisition figures: the simulated governor at a 50 Hz and a 100 Hz controller rate, accelerated,
read by ``fcrlive run`` (a subprocess) from the ring buffer for one simulated hour each.

Printed per rate: samples lost (MISSING rows and counter continuity in the store), the daemon's CPU (user +
system, % of one core) and peak memory (VmHWM), Modbus requests per second (answered by the device), and
storage: bytes per controller-rate row and per operation-log row, as MB per simulated day.

``./dev bench acquisition [--sim-min 60] [--speed 10] [--rates 50,100] [--identify]``. Identification is
off by default (it runs in a worker process; ``--identify`` turns it on with 30-min windows).
"""

from __future__ import annotations

import argparse
import asyncio
import math
import os
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path


def _proc_cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _proc_hwm_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024.0
    return math.nan


def _db_bytes(db: Path) -> int:
    return sum(p.stat().st_size for p in db.parent.glob(db.name + "*"))


def oplog_bytes_per_row(tmp: Path) -> float:
    """One simulated day of the operation log written with its own schema: bytes per row on disk."""
    import numpy as np

    from fcrlive.daemon.oplog import OPLOG_SIGNALS, ensure_oplog

    db = tmp / "oplog.sqlite"
    con = sqlite3.connect(db)
    ensure_oplog(con)
    rng = np.random.default_rng(0)
    n = 86400
    t0 = 1.8e9
    vals = np.column_stack([200 + rng.normal(0, 5, n), 50 + rng.normal(0, 0.05, n), np.zeros(n),
                            80 + rng.normal(0, 2, n), 80 + rng.normal(0, 2, n)])
    cols = ", ".join(f'"{c}"' for c in OPLOG_SIGNALS)
    with con:
        con.executemany(f"INSERT INTO oplog(t, quality, {cols}) VALUES (?,?,?,?,?,?,?)",
                        [(t0 + k, 0, *map(float, vals[k])) for k in range(n)])
    con.execute("VACUUM")
    con.close()
    return _db_bytes(db) / n


async def run_rate(rate_hz: int, sim_min: float, speed: float, identify: bool, tmp: Path) -> dict:
    import sim_device
    from fcrlive.plant.description import load_plant
    from testsupport.daemon_config import daemon_toml

    plant_file = tmp / f"plant{rate_hz}.toml"
    plant_file.write_text(f'preset = "paper-plant1"\n[unit.governor]\nTc = {1.0 / rate_hz!r}\n')
    db = tmp / f"s{rate_hz}.sqlite"
    wall_s = sim_min * 60.0 / speed
    async with sim_device.SimGovernor(load_plant(plant_file), port=0, speed=speed, seed=1) as gov:
        regmap = tmp / f"m{rate_hz}.toml"
        regmap.write_text(replace(gov.register_map, acquisition="buffered").to_toml())
        cfg = tmp / f"c{rate_hz}.toml"
        cfg.write_text(daemon_toml(unit="B1", plant=plant_file, port=gov.port, regmap=regmap, store=db,
                                   identification={"enabled": identify, "every_min": 30.0 / speed,
                                                   "window_min": 30.0 / speed, "device_speed": speed}))
        log = tmp / f"d{rate_hz}.log"
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
        proc = subprocess.Popen([sys.executable, "-m", "fcrlive.cli", "run", "--config", str(cfg)],
                                stdout=subprocess.DEVNULL, stderr=log.open("w"), env=env)
        try:
            await asyncio.sleep(5.0)  # start-up (imports) out of the figures
            cpu0, req0, t0, n0 = _proc_cpu_s(proc.pid), gov.requests, time.monotonic(), gov.ring.pushed
            slips0 = gov.slips
            await asyncio.sleep(wall_s)
            cpu1, req1, t1, n1 = _proc_cpu_s(proc.pid), gov.requests, time.monotonic(), gov.ring.pushed
            hwm = _proc_hwm_mib(proc.pid)
            slips = gov.slips - slips0
        finally:
            proc.send_signal(signal.SIGTERM)
            proc.wait(60)
    con = sqlite3.connect(db)
    rows, missing, lo, hi = con.execute(
        "SELECT count(*), sum(quality = 2), min(seq), max(seq) FROM samples").fetchone()
    oplog_rows = con.execute("SELECT count(*) FROM oplog").fetchone()[0]
    con.close()
    size = _db_bytes(db)
    dt = t1 - t0
    return {"rate_hz": rate_hz, "wall_s": dt, "sim_s": (n1 - n0) / rate_hz, "rows": rows,
            "missing": int(missing or 0), "counter_holes": (hi - lo + 1) - rows,
            "cpu_pct": 100 * (cpu1 - cpu0) / dt,
            "rss_hwm_mib": hwm, "requests_per_s": (req1 - req0) / dt,
            "requests_per_sim_s": (req1 - req0) / ((n1 - n0) / rate_hz),
            "bytes_per_row": size / max(1, rows + oplog_rows), "slips": slips}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="bench_acquisition")
    ap.add_argument("--sim-min", type=float, default=60.0, help="simulated minutes per rate (default 60)")
    ap.add_argument("--speed", type=float, default=10.0, help="simulated s per wall s (default 10)")
    ap.add_argument("--rates", default="50,100", help="controller rates [Hz] (default 50,100)")
    ap.add_argument("--identify", action="store_true", help="identification on (30-min windows)")
    args = ap.parse_args(argv or [])
    import logging

    logging.getLogger("pymodbus").setLevel(logging.CRITICAL + 1)
    logging.getLogger("sim_device").setLevel(logging.ERROR)
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        per_row_oplog = oplog_bytes_per_row(tmp)
        oplog_day_mb = per_row_oplog * 86400 / 1e6
        print(f"operation log (1 Hz, 5 columns + quality): {per_row_oplog:.0f} bytes/row, "
              f"{oplog_day_mb:.1f} MB per day, {14 * oplog_day_mb:.0f} MB for the 14 days TR 6.2 asks")
        for rate in (int(x) for x in args.rates.split(",")):
            r = asyncio.run(run_rate(rate, args.sim_min, args.speed, args.identify, tmp))
            day_mb = r["bytes_per_row"] * rate * 86400 / 1e6
            print(f"{rate} Hz controller, speed {args.speed:g}: {r['sim_s'] / 60:.1f} simulated min in "
                  f"{r['wall_s']:.0f} s wall, {r['rows']} samples stored, lost {r['missing']} "
                  f"(MISSING rows), counter holes {r['counter_holes']}, device clock slips {r['slips']}")
            print(f"  daemon: CPU {r['cpu_pct']:.1f} % of a core at {rate * args.speed:.0f} samples/s "
                  f"(≈ {r['cpu_pct'] / args.speed:.2f} % at real time), peak RSS {r['rss_hwm_mib']:.0f} MiB; "
                  f"Modbus {r['requests_per_s']:.1f} requests/s wall = {r['requests_per_sim_s']:.1f} per "
                  f"simulated s (a real governor's rate)")
            print(f"  storage: {r['bytes_per_row']:.0f} bytes per controller-rate row = {day_mb:.0f} MB per "
                  f"simulated day if all were kept; kept only for the identification windows (2 × 30 min "
                  f"= {day_mb / 24:.0f} MB standing) + the operation log {oplog_day_mb:.1f} MB/day")


if __name__ == "__main__":
    main(sys.argv[1:])
