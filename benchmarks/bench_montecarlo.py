"""Monte Carlo cost: ONE cell of the study (default Z_cu at 12 dB, 30 min datasets) on 2 workers.

The target is 1000 runs (the paper's study size) in at most 5 min on 2 cores. By default 200 runs are
timed and the 1000-run time extrapolated linearly (the cost is linear in the runs: tasks of ``--chunk``
runs, each simulated as one batch, then identified run by run); ``--runs 1000`` times the real thing.
Prints the per-run cost split between simulation (one process) and identification (one process).

Run with ``python -m benchmarks montecarlo`` (defaults) or
``python -m benchmarks montecarlo [--runs N] [--workers W] [--method zcu|zur|zu|sine]``.
"""

from __future__ import annotations

import argparse
import tempfile
import time

from fcrlive.analysis.montecarlo.config import StudyConfig
from fcrlive.analysis.montecarlo.runner import run_study
from fcrlive.plant.params import preset

TARGET_S = 300.0


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="bench_montecarlo", description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--method", default="zcu", choices=["zcu", "zur", "zu", "sine"])
    ap.add_argument("--snr-db", type=float, default=12.0)
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--chunk", type=int, default=25)
    ap.add_argument("--model", default="nonlinear", choices=["nonlinear", "linear"])
    a = ap.parse_args(argv)
    cfg = StudyConfig(runs=a.runs, snr_db=(a.snr_db,), minutes=(a.minutes,), methods=(a.method,),
                      chunk=a.chunk, model=a.model)
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        res = run_study(preset("paper-plant1"), cfg, out, workers=a.workers, progress=False, figures=False)
        wall = time.perf_counter() - t0
    tm = res.timing
    kind = {"zcu": "excited", "zur": "excited", "zu": "plain", "sine": "sine"}[a.method]
    sim = tm["sim_s_per_run"][f"{kind}/{a.minutes:g}min"]
    ident = tm["ident_s_per_run"][f"{a.method}/{a.minutes:g}min"]
    cell = res.cells[0]
    fails = cell["failed"]
    print(f"cell {a.method} at {a.snr_db:g} dB, {a.minutes:g} min datasets, {a.model} model, "
          f"{a.runs} runs on {a.workers} workers (chunks of {a.chunk}): {wall:.1f} s wall "
          f"({fails} failed identifications)")
    print(f"  per run, one process: simulation {sim:.3f} s + identification {ident:.3f} s "
          f"= {sim + ident:.3f} s ({100 * sim / (sim + ident):.0f} % simulation)")
    per_run = wall / a.runs
    est = per_run * 1000
    how = "measured" if a.runs == 1000 else f"extrapolated linearly from {a.runs} runs"
    verdict = "meets" if est <= TARGET_S else "MISSES"
    print(f"  1000 runs: {est:.0f} s ({how}; includes worker start-up); {verdict} the "
          f"{TARGET_S:.0f} s target")
    g = cell.get("g1_static")
    if g:
        print(f"  sanity: G_1(1) NRMSE {g['nrmse']:.3g} (rel. {100 * g['rel_nrmse']:.1f} %), "
              f"coverage {100 * g['coverage']:.0f} %")


if __name__ == "__main__":
    main()
