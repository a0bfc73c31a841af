"""excitation: a 1-hour accelerated closed-loop run with the excitation written through the real chain
(white noise → SafetyGuard → Modbus writer with read-back → simulated governor at --speed 60), and the
same hour without excitation (same plant noise seed).

Prints: the largest excitation ever written and applied versus the limit; the time the guard spent
inhibited, per reason, and how often each reason tripped; link and tick figures; then the identification
of both runs over the same durations (30 and 60 min): droop and its 95 % interval width, max|S| and
max|G_1| against the analytic truth of paper plant 1.

    python -m benchmarks excitation [--minutes 60] [--speed 60] [--seed 0]

The guard runs on simulated time (hold-off 30 s, budget 3600 s per 24 h, stale_after 5 s: 83 ms of wall
time at speed 60, so a CPU stall of the loop shows up as ``step_gap`` and a new hold-off).
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import time


def _fmt(c: dict) -> str:
    parts = [f"method {c['method']}"]
    if "droop" in c:
        w = c.get("droop_ci_width_pp")
        parts.append(f"droop {100 * c['droop']:.3f} % ({c['droop_err_pp']:+.3f} pp, 95 % width "
                     + (f"{w:.3f} pp)" if w is not None else "n/a)"))
    for name, label in (("max_s", "max|S|"), ("max_g1", "max|G_1|")):
        if name in c:
            parts.append(f"{label} {c[name]:.4f} ({c[f'{name}_err_pct']:+.1f} %)")
    return ", ".join(parts)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="bench_excitation", description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=60.0, help="simulated minutes per run")
    ap.add_argument("--speed", type=float, default=60.0)
    ap.add_argument("--seed", type=int, default=0, help="plant noise seed (both runs)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    from threadpoolctl import threadpool_limits

    from testsupport import excitation_study as study

    dur = 60.0 * args.minutes
    exc = asyncio.run(study.accelerated_run(dur, speed=args.speed, excitation=True, seed=args.seed))
    quiet = asyncio.run(study.accelerated_run(dur, speed=args.speed, excitation=False, seed=args.seed))
    st, ts = exc.status, exc.task_stats
    amp = st["amplitude_hz"]
    print(f"{args.minutes:g} simulated min at speed {args.speed:g}: {exc.wall_s:.1f} s wall with excitation, "
          f"{quiet.wall_s:.1f} s without; writer tick {0.02 * 1e3:.0f} ms wall = r held "
          f"{0.02 * args.speed:.2f} s simulated")
    print(f"largest |r| requested {ts['max_abs_requested_hz'] * 1e3:.2f} mHz, written "
          f"{st['max_abs_written_hz'] * 1e3:.2f} mHz, applied by the device "
          f"{st['max_abs_applied_hz'] * 1e3:.2f} mHz; limit {amp * 1e3:.0f} mHz "
          f"(guard amplitude; device clamp {exc.device['excitation_limit_hz']} Hz)")
    print(f"device: clamped writes {exc.device['clamped_writes']}, non-finite writes "
          f"{exc.device['nonfinite_writes']}, heartbeat-watchdog resets {exc.device['heartbeat_timeouts']}, "
          f"clock slips {exc.device['slips']}; r used by the identification = r written: {exc.r_consistent}")
    w = st["writer"]
    print(f"writer: {w['writes']} writes, {w['readback_checks']} read-backs, {w['write_failures']} failed, "
          f"{w['forced_zero_writes']} forced zero, {w['connects']} connect(s); ticks {ts['ticks']}, missed "
          f"{ts['missed_ticks']}, link down {ts['link_down_s']:.2f} s wall")
    elapsed = st["active_s"] + st["inhibited_s"]
    print(f"guard (simulated s): active {st['active_s']:.0f} s, inhibited {st['inhibited_s']:.0f} s "
          f"({100 * st['inhibited_s'] / max(elapsed, 1e-9):.1f} %), "
          f"budget left {st['budget_remaining_s']:.0f} s")
    for reason, secs in sorted(st["time_by_reason_s"].items(), key=lambda kv: -kv[1]):
        print(f"  {reason:<28} {secs:8.1f} s   trips {st['trips_by_reason'].get(reason, 0)}")
    truth = study.truth_figures(exc.truth)
    print(f"\nidentification vs truth (droop {100 * truth['droop']:.3f} %, max|S| {truth['max_s']:.4f}, "
          f"max|G_1| {truth['max_g1']:.4f}); tolerances: droop ±0.2 pp, peaks ±5 %")
    with threadpool_limits(1):
        for minutes in sorted({min(30.0, args.minutes), args.minutes}):
            for run, label in ((exc, "with excitation   "), (quiet, "without excitation")):
                part = run.window(0.0, 60.0 * minutes)
                t0 = time.perf_counter()
                try:
                    rep = study.identify(part)
                except Exception as e:  # report, do not hide
                    print(f"  {minutes:4.0f} min {label}: failed: {e}")
                    continue
                c = study.compare(rep, truth)
                ok = ""
                if run is exc and {"droop_err_pp", "max_s_err_pct", "max_g1_err_pct"} <= set(c):
                    inside = (abs(c["droop_err_pp"]) <= 0.2 and abs(c["max_s_err_pct"]) <= 5
                              and abs(c["max_g1_err_pct"]) <= 5)
                    ok = "  [within tolerances]" if inside else "  [OUTSIDE tolerances]"
                print(f"  {minutes:4.0f} min {label}: {_fmt(c)}{ok}  ({time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    main()
