"""identify: time of a full re-identification of a 30-min window at 10 Hz (every applicable method +
assessment, one core) and accuracy vs the analytic truth per method on a few seeds (50 Hz logs).

``python -m benchmarks identify [--seeds N] [--repeat R] [--windows W] [--zu60 R] [--coverage M]``
(``--seeds 0 --windows 0 --coverage 0`` for the timing alone).

``--windows W``: the same timing on W other windows (seeds 101..): a window's time depends on how many
restarts its fits take, so one window is not the whole story.

``--zu60 R``: Z_u on a 60-min record at 50 Hz without excitation (the longest record docs/identify.md
quotes), R times, median and min.

``--coverage M``: over M seeds, how often each 95 % interval holds the truth (nominal 0.95), per method,
with the mean error and its seed-to-seed sd.
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


def _cases10(sig10):
    """The 30-min 10 Hz window as each method sees it: all signals, no c and a, no excitation."""
    return {
        "zcu": sig10,
        "zur": replace(sig10, c=None, a=None),
        "zu": replace(sig10, has_excitation=False, r=np.zeros_like(sig10.r)),
    }


def _plant_kw(method: str) -> dict:
    """Z_cu gets the plant description (its controller), as the daemon's [unit] plant gives it: identified
    from a 10 Hz log of the 50 Hz governor the controller does not fit (analysis.controller) and Z_cu would
    stop there."""
    from fcrlive.plant.params import preset

    return {"plant": preset("paper-plant1")} if method == "zcu" else {}


def _fresh() -> None:
    """Forget the start models ident.pem keeps for the last data sets: each timed run repeats the same
    window, the daemon re-identifies a new one (the starts are shared only within one identification)."""
    from fcrlive.ident import pem

    pem._START_CACHE.clear()


def _times(sig, method: str, kd: float, repeat: int) -> tuple[list[float], list[float]]:
    """Wall-clock and CPU times [s] of ``repeat`` identifications (the CPU time of this one-thread
    process is what other work on a shared machine disturbs least)."""
    from fcrlive.analysis.identify import identify_signals

    wall, cpu = [], []
    for _ in range(repeat):
        _fresh()
        t0, c0 = time.perf_counter(), time.process_time()
        identify_signals(sig, rated_mw=300.0, kd=kd, method=method, **_plant_kw(method))
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return wall, cpu


def _auto_times(sig, kd: float, repeat: int) -> tuple[list[float], list[float], str]:
    """:func:`_times` of what the daemon runs per window: ``--method auto`` with the plant description of
    [unit] plant; also the method auto picked."""
    from fcrlive.analysis.identify import identify_signals
    from fcrlive.plant.params import preset

    plant = preset("paper-plant1")
    wall, cpu, picked = [], [], ""
    for _ in range(repeat):
        _fresh()
        t0, c0 = time.perf_counter(), time.process_time()
        picked = identify_signals(sig, rated_mw=300.0, kd=kd, method="auto", plant=plant).method
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return wall, cpu, picked


def _stats(wall: list[float], cpu: list[float], unit: str = "s") -> str:
    k = 1e3 if unit == "ms" else 1.0
    nd = 0 if unit == "ms" else 2
    return (f"median {k * np.median(wall):.{nd}f} {unit} (min {k * min(wall):.{nd}f} {unit}); "
            f"CPU median {k * np.median(cpu):.{nd}f} {unit} (min {k * min(cpu):.{nd}f} {unit})")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="bench_identify", description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3, help="accuracy on seeds 0..N-1 (3; 0 skips)")
    ap.add_argument("--repeat", type=int, default=5,
                    help="timed runs of the 30-min window, all methods and per method (5)")
    ap.add_argument("--windows", type=int, default=10, help="timing on this many other windows (10; 0 skips)")
    ap.add_argument("--zu60", type=int, default=3, metavar="R",
                    help="time Z_u on a 60-min 50 Hz record R times (3; 0 skips)")
    ap.add_argument("--coverage", type=int, default=20,
                    help="interval coverage over this many seeds (20; 0 skips)")
    args = ap.parse_args(argv)
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
        cases = _cases10(sig10)
        for m, s in cases.items():  # imports and first-call set-up out of the timing
            identify_signals(s, rated_mw=300.0, kd=kd, method=m, **_plant_kw(m))
        total, total_cpu = [], []
        for _ in range(args.repeat):
            t0, c0 = time.perf_counter(), time.process_time()
            for m, s in cases.items():
                _fresh()
                identify_signals(s, rated_mw=300.0, kd=kd, method=m, **_plant_kw(m))
            total.append(time.perf_counter() - t0)
            total_cpu.append(time.process_time() - c0)
        print(
            f"30-min window at 10 Hz, zcu + zur + zu + assessment: {_stats(total, total_cpu)} "
            f"over {args.repeat} runs, 1 thread"
        )
        for m, s in cases.items():
            print(f"  {m}: {_stats(*_times(s, m, kd, args.repeat), unit='ms')}")
        # what the daemon runs per window: one method, the one --method auto picks ([identify] method's
        # default), with the plant description of [unit] plant
        wall, cpu, picked = _auto_times(sig10, kd, args.repeat)
        print(f"  the daemon's re-identification (--method auto, plant description; it picked {picked}): "
              f"{_stats(wall, cpu, unit='ms')}")
        # the daemon samples every controller sample: the same record at 50 Hz, where auto picks Z_cu
        # with the data sheet's G_J (experiments.zcu_swing) and all its checks
        sig50 = _signals(100, True, 1800.0, None)
        _auto_times(sig50, kd, 1)  # the first call's set-up out of the timing
        wall, cpu, picked = _auto_times(sig50, kd, args.repeat)
        print(f"  the same at the controller rate (50 Hz, as the daemon samples; it picked {picked}): "
              f"{_stats(wall, cpu, unit='ms')}")
        if args.windows:
            per = {m: [] for m in cases}
            per_cpu = {m: [] for m in cases}
            for seed in range(101, 101 + args.windows):
                for m, s in _cases10(_signals(seed, True, 1800.0, 0.1)).items():
                    wall, cpu = _times(s, m, kd, 2)
                    per[m].append(min(wall))
                    per_cpu[m].append(min(cpu))
            tot = np.sum(list(per.values()), axis=0)
            print(
                f"  {args.windows} other windows (seeds 101-{100 + args.windows}), all three: mean "
                f"{tot.mean():.2f} s, max {tot.max():.2f} s ("
                + ", ".join(f"{m} mean {1e3 * np.mean(v):.0f} ms" for m, v in per.items()) + ")"
            )
            # CPU time: what a shared machine's other load disturbs least (the wall times above move with it)
            tot_cpu = np.sum(list(per_cpu.values()), axis=0)
            print(
                f"  CPU per window, all three: median {np.median(tot_cpu):.2f} s, max {tot_cpu.max():.2f} s ("
                + ", ".join(f"{m} median {1e3 * np.median(v):.0f} ms" for m, v in per_cpu.items()) + ")"
            )
        if args.zu60:
            quiet60 = _signals(100, False, 3600.0, None)
            print(f"  zu on a 60-min record at 50 Hz: {_stats(*_times(quiet60, 'zu', kd, args.zu60))} "
                  f"over {args.zu60} runs")
        if args.seeds:
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


        if args.coverage:
            coverage(args.coverage, true, kd)


def coverage(n_seeds: int, true: dict, kd: float, methods=("zcu", "zur", "zu")) -> dict:
    """Empirical coverage of the 95 % intervals over seeds 1000.. (30 min excited / 15 min quiet, 12 dB):
    per method and quantity, how many were shown (the rest withheld as not identifiable, or failed) and
    how many of those shown hold the truth (nominal 0.95)."""
    from fcrlive.analysis.identify import identify_signals

    keys = (("droop", "droop"), ("max_abs_g1", "max_g1"), ("max_abs_s", "max_s"))
    hits = {m: {k: [] for _, k in keys} for m in methods}
    errs = {m: {k: [] for _, k in keys} for m in methods}
    failed = dict.fromkeys(methods, 0)
    for seed in range(1000, 1000 + n_seeds):
        exc = _signals(seed, True, 1800.0, None)
        quiet = _signals(seed, False, 900.0, None) if "zu" in methods else None
        cases = {"zcu": exc, "zur": replace(exc, c=None, a=None), "zu": quiet}
        for m in methods:
            try:
                r = identify_signals(cases[m], rated_mw=300.0, kd=kd, method=m)
            except Exception:
                failed[m] += 1
                continue
            for attr, k in keys:
                v = getattr(r, attr)
                if v is None or v.value is None:
                    continue  # withheld: counted as not shown
                lo, hi = v.ci95
                hits[m][k].append(bool(lo is not None and hi is not None and lo <= true[k] <= hi))
                errs[m][k].append(100 * (v.value / true[k] - 1))
    print(f"\ncoverage of the 95 % intervals over {n_seeds} seeds (nominal 0.95): covered / shown "
          "(the others withheld as not identifiable); error of those shown, mean ± sd [%]")
    for m in methods:
        parts = []
        for _, k in keys:
            h = hits[m][k]
            if not h:
                parts.append(f"{k} 0 shown")
                continue
            e = np.asarray(errs[m][k])
            parts.append(f"{k} {sum(h)}/{len(h)} ({e.mean():+.2f} ± {e.std():.2f})")
        fail = f"; {failed[m]} failed" if failed[m] else ""
        print(f"  {m}: " + ", ".join(parts) + fail)
    return hits


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
