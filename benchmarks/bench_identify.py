"""identify: time of a full re-identification of a 30-min window at 10 Hz (every applicable method +
assessment, one core) and accuracy vs the analytic truth per method on a few seeds (50 Hz logs).

``python -m benchmarks identify [--seeds N] [--repeat R]``
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np


def _signals(seed: int, excitation: bool, duration_s: float, sample_s: float | None):
    from fcrlive.plant.params import preset
    from fcrlive.sim import SimConfig, simulate
    from fcrlive.tso.signals import log_from_sim, plant_signals

    res = simulate(
        preset("paper-plant1"),
        SimConfig(duration_s=duration_s, snr_db=12.0, excitation=excitation, seed=seed),
    )
    return plant_signals(log_from_sim(res, sample_s=sample_s), rated_mw=300.0)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="bench_identify")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv or [])
    from threadpoolctl import threadpool_limits

    from fcrlive.analysis.identify import identify_signals
    from fcrlive.plant import transfer as tr
    from fcrlive.plant.params import preset

    T = tr.analytic(preset("paper-plant1"))
    kd = 0.1
    true = {
        "droop": 1 / (1 / tr.static_gain(T.G_1) - kd),
        "max_g1": tr.peak(T.G_1).value,
        "max_s": tr.peak(T.S).value,
    }
    with threadpool_limits(1):
        sig10 = _signals(100, True, 1800.0, 0.1)
        cases = {
            "zcu": sig10,
            "zur": replace(sig10, c=None, a=None),
            "zu": replace(sig10, has_excitation=False, r=np.zeros_like(sig10.r)),
        }
        total = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            for m, s in cases.items():
                identify_signals(s, rated_mw=300.0, kd=kd, method=m)
            total.append(time.perf_counter() - t0)
        print(
            f"30-min window at 10 Hz, zcu + zur + zu + assessment: median {np.median(total):.2f} s "
            f"(min {min(total):.2f} s) over {args.repeat} runs, 1 thread"
        )
        for m, s in cases.items():
            ts = []
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                identify_signals(s, rated_mw=300.0, kd=kd, method=m)
                ts.append(time.perf_counter() - t0)
            print(f"  {m}: median {1e3 * np.median(ts):.0f} ms")
        print(
            f"\naccuracy vs truth (droop {true['droop']:.4f}, max|G_1| {true['max_g1']:.4f}, "
            f"max|S| {true['max_s']:.4f}); 30 min, 12 dB, 50 Hz logs; * = truth inside the 95 % interval"
        )
        for seed in range(args.seeds):
            exc = _signals(seed, True, 1800.0, None)
            quiet = _signals(seed, False, 900.0, None)
            for m, s in (("zcu", exc), ("zur", replace(exc, c=None, a=None)), ("zu", quiet)):
                try:
                    r = identify_signals(s, rated_mw=300.0, kd=kd, method=m)
                except Exception as exc_:
                    print(f"  seed {seed} {m}: failed: {exc_}")
                    continue
                parts = []
                for key, name in (("droop", "droop"), ("max_abs_g1", "max_g1"), ("max_abs_s", "max_s")):
                    v = getattr(r, key)
                    if v is None or v.value is None:
                        continue
                    lo, hi = v.ci95
                    inside = "*" if lo is not None and hi is not None and lo <= true[name] <= hi else " "
                    err = 100 * (v.value / true[name] - 1)
                    parts.append(f"{name} {v.value:.4f} ({err:+.1f} %){inside}")
                print(f"  seed {seed} {m}{' (15 min, no r)' if m == 'zu' else ''}: " + ", ".join(parts))


if __name__ == "__main__":
    main()
