"""The daemon against the paper's own plant (50 Hz digital governor), in REAL TIME.

The end-to-end test runs a 10 Hz governor at speed 4 so that it fits in CI; the paper's plant steps every
20 ms, so seeing every controller sample (what Z_cu needs: docs/daemon.md) means polling at 50 Hz of the
device's own time, i.e. speed 1 with the daemon's highest rate. This benchmark does that once: the
simulated governor (real Modbus server) + a real broker + ``fcrlive run`` with the white-noise
excitation and the plant description, one window (10 min by default), and prints what an MQTT subscriber
received against the plant's truth, with the sample interval and data quality the daemon saw.

``python -m benchmarks daemon_paper_plant [--window-min 10]`` (about window + 2 min of wall time).
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

async def run(window_min: float) -> None:
    import sim_device
    from fcrlive.daemon.broker import start_broker
    from fcrlive.plant.description import load_plant
    from testsupport.daemon_config import daemon_toml
    from testsupport.mqtt import first_identification

    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        plant_file = tmp / "plant.toml"
        plant_file.write_text('preset = "paper-plant1"\n')
        plant = load_plant(plant_file)
        broker = start_broker()
        async with broker, sim_device.SimGovernor(plant, port=0, speed=1.0, seed=3) as gov:
            truth = await asyncio.to_thread(gov.truth, True)
            cfg = tmp / "c.toml"
            regmap = ROOT / "sim_device" / "registers.toml"
            cfg.write_text(daemon_toml(unit="P1", plant=plant_file, port=gov.port, regmap=regmap,
                                       poll_hz=50.0, store=tmp / "s.sqlite",
                                       identification={"every_min": window_min, "window_min": window_min,
                                                       "min_ok_fraction": 0.5},
                                       mqtt={"port": broker.port}, excitation_period_s=0.1))
            log = tmp / "daemon.log"
            env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
            proc = subprocess.Popen([sys.executable, "-m", "fcrlive.cli", "run", "--config", str(cfg)],
                                    stdout=subprocess.DEVNULL, stderr=log.open("w"), env=env)
            try:
                res = await first_identification("127.0.0.1", broker.port, "P1", window_min * 60.0 + 300.0)
            finally:
                proc.send_signal(signal.SIGTERM)
                proc.wait(30)
    if not res["ok"]:
        print(f"no result: {res['error']}")
        return
    r = res["result"]
    droop_true = 100.0 / (1.0 / truth["g1_static"] - 0.1)
    print(f"paper-plant1 (Tc = 20 ms) in real time, polled at 50 Hz, excitation on, "
          f"{window_min:g}-min window:")
    print(f"  method {r['method']}, sample interval {r['sample_interval_s'] * 1e3:.1f} ms, "
          f"good samples {100 * res['quality']['ok_fraction']:.1f} %")
    lo, hi = (100.0 * x for x in r["droop"]["ci95"])
    print(f"  droop {100 * r['droop']['value']:.3f} % [{lo:.3f}, {hi:.3f}] (truth {droop_true:.3f} %)")
    for key, tk in (("max_abs_s", "max_S"), ("max_abs_g1", "max_G1")):
        v = r[key]
        if v is not None:
            print(f"  {key} {v['value']:.4f} [{v['ci95'][0]:.4f}, {v['ci95'][1]:.4f}] "
                  f"(truth {truth[tk]:.4f}, {100 * (v['value'] / truth[tk] - 1):+.1f} %)")
    for w in r.get("warnings", []):
        print(f"  warning: {w}")


def main(argv: list[str] | None = None) -> None:
    # pymodbus dumps its last frames with every error, e.g. a send cancelled at shutdown
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL + 1)
    ap = argparse.ArgumentParser(prog="bench_daemon_paper_plant", description=__doc__.split("\n\n")[0])
    ap.add_argument("--window-min", type=float, default=10.0)
    args = ap.parse_args(argv)
    asyncio.run(run(args.window_min))


if __name__ == "__main__":
    main(sys.argv[1:])
