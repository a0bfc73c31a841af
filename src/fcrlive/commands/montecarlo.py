"""``fcrlive montecarlo``: the paper's Monte Carlo study (Section 7) of Z_cu, Z_ur, Z_u and the sine test.

See :mod:`fcrlive.analysis.montecarlo` for what is simulated and how the figures of merit are defined.
Writes into ``--out``: ``runs.csv`` (one row per run and method), ``summary.json`` (per cell),
``summary.md`` (the tables printed), ``mean_responses.npz``, PNG figures like the paper's Figs. 4-10 and
``chunks/`` (finished tasks: re-running the same command resumes).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

NAME = "montecarlo"
HELP = "Monte Carlo study of the identification methods vs the sine test (paper Section 7)."


def configure(p: argparse.ArgumentParser) -> None:
    p.add_argument("--runs", type=int, default=100, help="runs per cell (default 100; the paper used 1000)")
    p.add_argument("--snr-db", type=float, nargs="+", default=[12.0, 6.0, 0.0], metavar="DB",
                   help="SNR values [dB] (default 12 6 0)")
    p.add_argument("--minutes", type=float, nargs="+", default=[10.0, 30.0], metavar="MIN",
                   help="dataset lengths [min] (default 10 30); per sine period for the sine test")
    p.add_argument("--methods", nargs="+", default=["zcu", "zur", "zu", "sine"],
                   choices=["zcu", "zur", "zu", "sine"], help="methods (default all)")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: all cores)")
    p.add_argument("--seed", type=int, default=0, help="base seed of the load and process noise (default 0)")
    p.add_argument("--excitation-seed", type=int, default=12345,
                   help="seed of the excitation r, generated once (default 12345)")
    p.add_argument("--out", type=Path, default=Path("montecarlo-out"), metavar="DIR",
                   help="output directory (default montecarlo-out)")
    p.add_argument("--preset", default="paper-plant1", help="plant preset (default: %(default)s)")
    p.add_argument("--plant", type=Path, metavar="FILE.toml", help="plant description; overrides --preset")
    p.add_argument("--model", choices=["nonlinear", "linear"], default="nonlinear",
                   help="simulation model (default nonlinear, as the paper)")
    p.add_argument("--chunk", type=int, default=25, help="runs simulated together per task (default 25)")
    p.add_argument("--sine-amplitude-hz", type=float, default=0.1,
                   help="amplitude of the sine tests [Hz] (default 0.1)")
    p.add_argument("--fresh", action="store_true", help="discard finished tasks in --out instead of resuming")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")


def _plant(args):
    if args.plant is not None:
        from fcrlive.plant.description import load_plant

        return load_plant(args.plant)
    from fcrlive.plant.params import preset

    return preset(args.preset)


def run(args: argparse.Namespace) -> int:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    import time

    from fcrlive.analysis.montecarlo.config import StudyConfig
    from fcrlive.analysis.montecarlo.runner import run_study
    from fcrlive.analysis.montecarlo.tables import markdown_table
    from fcrlive.errors import UserError

    if args.workers is not None and args.workers < 1:
        raise UserError(f"--workers must be at least 1, got {args.workers}", where="--workers")
    cfg = StudyConfig(
        runs=args.runs,
        snr_db=tuple(float(x) for x in args.snr_db),
        minutes=tuple(float(x) for x in args.minutes),
        methods=tuple(dict.fromkeys(args.methods)),
        seed=args.seed,
        excitation_seed=args.excitation_seed,
        model=args.model,
        chunk=args.chunk,
        sine_amplitude_hz=args.sine_amplitude_hz,
    )
    plant = _plant(args)
    t0 = time.perf_counter()
    res = run_study(
        plant, cfg, args.out, workers=args.workers, progress=not args.no_progress, fresh=args.fresh,
        figures=not args.no_figures, log=lambda m: print(m, file=sys.stderr),
    )
    print(markdown_table(res.cells, res.truth))
    n_fail = sum(1 for r in res.rows if r["status"] != "ok")
    tm = res.timing
    print(f"{len(res.rows)} fits ({n_fail} failed) in {time.perf_counter() - t0:.1f} s on {tm['workers']} "
          f"worker(s); results in {args.out}/ (runs.csv, summary.json, summary.md, figures)")
    for k, v in sorted(tm["sim_s_per_run"].items()):
        print(f"  simulation {k}: {v:.3f} s per run (one process)")
    for k, v in sorted(tm["ident_s_per_run"].items()):
        print(f"  identification {k}: {v:.3f} s per run (one process)")
    return 0
