"""Simulator speed: 1800 s simulated at Tc = 0.02 s (90 000 samples), nonlinear and linear models.

- batch: ``simulate_batch`` over 1000 realisations (in chunks of 500, keeping u and epsilon), time per run;
- single: ``simulate`` of one realisation (best of 3);
- RealtimeSimulator: µs per step.

Each figure as wall-clock time and as CPU time of this process (``time.process_time``, which a machine
shared with other work disturbs less).

Run with ``python -m benchmarks sim`` (BLAS pinned to one thread); ``--runs N`` to change the batch size.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from fcrlive.plant.params import Plant
from fcrlive.sim import SimConfig, simulate, simulate_batch
from fcrlive.sim.realtime import RealtimeSimulator


def _batch(plant: Plant, cfg: SimConfig, runs: int, chunk: int) -> tuple[float, float]:
    """(wall, CPU) seconds per run."""
    t0, c0 = time.perf_counter(), time.process_time()
    for start in range(0, runs, chunk):
        seeds = range(start, min(runs, start + chunk))
        simulate_batch(plant, cfg, seeds, fields=("u", "epsilon"))
    return (time.perf_counter() - t0) / runs, (time.process_time() - c0) / runs


def _single(plant: Plant, cfg: SimConfig, repeat: int = 3) -> tuple[float, float]:
    """Best (wall, CPU) seconds of ``repeat`` runs (seeds 0, 1, ...)."""
    wall = cpu = np.inf
    for k in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        simulate(plant, SimConfig(**{**cfg.__dict__, "seed": k}))
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return wall, cpu


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="bench_sim", description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--chunk", type=int, default=500)
    ap.add_argument("--duration", type=float, default=1800.0)
    args = ap.parse_args(argv)
    plant = Plant()
    base = SimConfig(duration_s=args.duration, snr_db=12.0, excitation=True)
    simulate(plant, SimConfig(duration_s=10.0))  # warm the caches (model build, noise sizing)
    tc = plant.unit.governor.Tc
    print(f"{args.duration:g} s simulated at Tc = {tc} s, paper plant 1, SNR 12 dB, excitation")
    for model in ("nonlinear", "linear"):
        cfg = SimConfig(**{**base.__dict__, "model": model})
        wall, cpu = _single(plant, cfg)
        print(f"  {model:9s} single run: {1e3 * wall:8.1f} ms (CPU {1e3 * cpu:.1f} ms)", flush=True)
        wall, cpu = _batch(plant, cfg, args.runs, args.chunk)
        print(f"  {model:9s} batch of {args.runs} (chunks of {args.chunk}): {1e3 * wall:8.2f} ms/run "
              f"(CPU {1e3 * cpu:.2f} ms/run; {wall * args.runs:.1f} s total)", flush=True)
    rt = RealtimeSimulator(plant, seed=0)
    n = 20000
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(n):
        rt.step(0.0)
    us = 1e6 * (time.perf_counter() - t0) / n
    cpu_us = 1e6 * (time.process_time() - c0) / n
    print(f"  RealtimeSimulator: {us:.1f} µs/step (CPU {cpu_us:.1f} µs; "
          "real time at 50 Hz × 60 needs < 333 µs)")


if __name__ == "__main__":
    main()
