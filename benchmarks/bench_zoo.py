"""The validation zoo benchmark (issue 12): how right are the estimates on plants and logs that are not
the reference plant, and do their intervals cover?

For every cell plant × logger × length × with/without excitation (fcrlive.sim.zoo) and several seeds per
cell, one record is simulated, logged, and identified with
``fcrlive.analysis.identify.identify_signals(signals, rated_mw=..., kd=<the plant's Kd>, h=<its H>,
method=...)``, H and Kd as a plant owner has them from the generator's data sheet (``--no-h`` leaves H out;
``--with-plant`` also passes the plant description). Per quantity (droop, max|S|, max|G_1|, |G_p| at
the TSO periods) the table gives, over the seeds of a cell: the median and 95th percentile of the
absolute error, the median signed error (bias), the coverage of the 95 % interval, and the share
reported "not identifiable". A result counts as not identifiable when its value is missing/None/NaN or
its interval is missing or has a missing/non-finite end (so a per-quantity ``null`` with a reason is
read as such); errors and coverage are over the identifiable results only. An identification that
raises counts as not identifiable for every quantity (its reason is listed).

Errors: droop in percentage points; peaks and |G_p| in % of the truth. The truth is the analytic
sampled-data model at the controller rate (fcrlive.sim.zoo.Truth).

Run: ``./dev bench zoo [options]`` or ``python -m benchmarks.bench_zoo --help``. ``--quick`` runs a few
cells (4 plants; normal operation through a half-rate 0.5 % logger and a 1 s historian for 15 and
60 min; excited 30 min at the controller rate with 0.1 % noise; 3 seeds) in a few minutes.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from datetime import UTC, datetime  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

QUANTITIES = ("droop", "max_s", "max_g1", "gp")
LABEL = {"droop": "droop [pp]", "max_s": "max|S| [%]", "max_g1": "max|G_1| [%]",
         "gp": "|G_p| at TSO periods [%]"}

QUICK_PLANTS = ("A-classic-tustin-20Hz", "B-int-beuler-10Hz", "E-stiff5pct-classic-demand-25Hz",
                "F-pid-classic-2pct-25Hz")
QUICK_NORMAL = (("half-0.5pct", 15.0), ("half-0.5pct", 60.0), ("hist-1s", 15.0), ("hist-1s", 60.0))
QUICK_EXCITED = (("ctl-0.1pct", 30.0),)


@dataclass(frozen=True)
class Task:
    """One simulated record (plant, minutes, excitation, seed) and the loggers to read it through."""

    plant: str
    minutes: float
    excitation: bool
    seed: int
    loggers: tuple[str, ...]


def _finite(x) -> bool:
    try:
        return x is not None and math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def _entry(value, ci, truth: float) -> dict:
    """One quantity of one fit: value, interval, truth, identifiable."""
    lo = hi = None
    if ci is not None:
        try:
            lo, hi = ci[0], ci[1]
        except (TypeError, IndexError):
            lo = hi = None
    ok = _finite(value) and _finite(lo) and _finite(hi)
    return {"value": float(value) if _finite(value) else None, "lo": float(lo) if _finite(lo) else None,
            "hi": float(hi) if _finite(hi) else None, "truth": float(truth), "identifiable": ok}


def _reason(q) -> str | None:
    for k in ("reason", "not_identifiable", "why"):
        r = getattr(q, k, None)
        if isinstance(r, str) and r:
            return r
    return None


def _fit(task: Task, logger: str, sig, tr, method: str, with_plant: bool, with_h: bool = True,
         known_chain: bool = False) -> dict:
    from fcrlive.analysis.identify import identify_signals
    from fcrlive.sim import zoo

    row = {"plant": task.plant, "logger": logger, "minutes": task.minutes, "excitation": task.excitation,
           "seed": task.seed}
    kw = {"rated_mw": tr.rated_mw, "kd": tr.kd, "method": method}
    if with_h:
        kw["h"] = tr.H
    if with_plant:
        kw["plant"] = zoo.zoo_plant(task.plant).plant
    lgr = zoo.zoo_logger(logger)
    if known_chain and (lgr.power_lag_s or lgr.power_delay_s):
        from fcrlive.signals import PowerChain

        kw["power_chain"] = PowerChain(lgr.power_lag_s, lgr.power_delay_s)
    t0 = time.perf_counter()
    try:
        rep = identify_signals(sig, **kw)
    except Exception as exc:  # an estimator that raises: recorded, the benchmark goes on
        row.update(status="error", reason=f"{type(exc).__name__}: {exc}".splitlines()[0][:200],
                   method=None, seconds=time.perf_counter() - t0)
        row["q"] = {"droop": [_entry(None, None, tr.droop)], "max_s": [_entry(None, None, tr.max_s)],
                    "max_g1": [_entry(None, None, tr.max_g1)],
                    "gp": [_entry(None, None, abs(v)) | {"period_s": p} for p, v in tr.gp]}
        return row
    row.update(status="ok", method=getattr(rep, "method", None), seconds=time.perf_counter() - t0,
               notes=list(getattr(rep, "notes", ()) or ()))
    q = {}
    d = getattr(rep, "droop", None)
    q["droop"] = [_entry(getattr(d, "value", None), getattr(d, "ci95", None), tr.droop)
                  | {"reason": _reason(d), "method": getattr(d, "method", None)}]
    for key, attr, truth in (("max_s", "max_abs_s", tr.max_s), ("max_g1", "max_abs_g1", tr.max_g1)):
        pk = getattr(rep, attr, None)
        q[key] = [_entry(getattr(pk, "value", None), getattr(pk, "ci95", None), truth)
                  | {"omega": getattr(pk, "omega", None), "reason": _reason(pk)}]
    gp = {round(float(pv.period_s), 6): pv for pv in (getattr(rep, "gp", None) or [])}
    # why G_p was withheld, for the rows' readers (the TSO periods share one reason)
    gp_why = (getattr(rep, "not_identifiable", None) or {}).get("gp")
    ents = []
    for p, v in tr.gp:
        pv = gp.get(round(p, 6))
        ents.append(_entry(getattr(pv, "abs", None), getattr(pv, "abs_ci95", None), abs(v))
                    | {"period_s": p, "reason": None if pv is not None else gp_why})
    q["gp"] = ents
    row["q"] = q
    return row


def run_task(task: Task, method: str = "auto", with_plant: bool = False, with_h: bool = True,
             known_chain: bool = False) -> list[dict]:
    """Simulate one record, read it through each logger, identify: one row per logger."""
    from fcrlive.sim import logger as lg
    from fcrlive.sim import zoo

    tr = zoo.truth(task.plant)
    # the simulation and the identification run on one BLAS thread whatever the process was started with
    # (fcrlive.blas): the same rows under OPENBLAS_NUM_THREADS=1 and 2
    res = zoo.simulate(task.plant, minutes=task.minutes, excitation=task.excitation, seed=task.seed)
    rows = []
    for name in task.loggers:
        sig = lg.signals(res, zoo.zoo_logger(name), seed=zoo.logger_seed(task.seed, name))
        rows.append(_fit(task, name, sig, tr, method, with_plant, with_h, known_chain))
    return rows


def _worker(args) -> list[dict]:
    task, method, with_plant, with_h, known_chain = args
    try:
        return run_task(task, method, with_plant, with_h, known_chain)
    except Exception:
        tb = traceback.format_exc().strip().splitlines()
        return [{"plant": task.plant, "logger": lgr, "minutes": task.minutes, "excitation": task.excitation,
                 "seed": task.seed, "status": "error", "reason": "simulation/logging: " + tb[-1][:200],
                 "method": None, "q": None} for lgr in task.loggers]


def plan(plants, loggers, minutes, excitation, seeds, quick: bool) -> list[Task]:
    tasks = []
    if quick:
        for p in plants:
            for s in seeds:
                for mins in sorted({m for _, m in QUICK_NORMAL}):
                    tasks.append(Task(p, mins, False, s, tuple(lg for lg, m in QUICK_NORMAL if m == mins)))
                for mins in sorted({m for _, m in QUICK_EXCITED}):
                    tasks.append(Task(p, mins, True, s, tuple(lg for lg, m in QUICK_EXCITED if m == mins)))
        return tasks
    for p in plants:
        for mins in minutes:
            for exc in excitation:
                for s in seeds:
                    tasks.append(Task(p, mins, exc, s, tuple(loggers)))
    return tasks


# ---------------------------------------------------------------------------------------------------
# The table


def _err(key: str, e: dict) -> float:
    if key == "droop":
        return 100.0 * (e["value"] - e["truth"])
    return 100.0 * (e["value"] / e["truth"] - 1.0)


def summarise(rows: list[dict], key: str) -> dict:
    """Median/95th-percentile absolute error, median signed error, coverage, not-identifiable share."""
    ents = []
    for r in rows:
        if r.get("q") is None:
            ents.append({"identifiable": False})
        else:
            ents += r["q"][key]
    n = len(ents)
    ok = [e for e in ents if e["identifiable"]]
    errs = np.array([_err(key, e) for e in ok])
    cov = [e["lo"] <= e["truth"] <= e["hi"] for e in ok]
    return {
        "n": n,
        "n_ok": len(ok),
        "median_abs": float(np.median(np.abs(errs))) if len(ok) else None,
        "p95_abs": float(np.percentile(np.abs(errs), 95)) if len(ok) else None,
        "median": float(np.median(errs)) if len(ok) else None,
        "coverage": float(np.mean(cov)) if len(ok) else None,
        "not_identifiable": (n - len(ok)) / n if n else None,
    }


def _f(x, fmt: str) -> str:
    return "–" if x is None else format(x, fmt)


def _cell_key(r: dict) -> tuple:
    return (r["plant"], r["logger"], r["minutes"], r["excitation"])


def table(rows: list[dict]) -> str:
    cells: dict[tuple, list[dict]] = {}
    for r in rows:
        cells.setdefault(_cell_key(r), []).append(r)
    out = []
    for key in QUANTITIES:
        out += [f"### {LABEL[key]}", "",
                "| plant | logger | min | exc. | runs | method | median abs err | p95 abs err | median err | "
                "coverage 95 % | not identifiable |",
                "|---|---|---|---|---|---|---|---|---|---|---|"]
        for ck in sorted(cells, key=lambda k: (k[0], k[1], k[2], k[3])):
            rs = cells[ck]
            s = summarise(rs, key)
            methods = sorted({str(r.get("method")) for r in rs})
            unit = " pp" if key == "droop" else " %"
            fmt = ".3f" if key == "droop" else ".1f"
            out.append(
                f"| {ck[0]} | {ck[1]} | {ck[2]:g} | {'yes' if ck[3] else 'no'} | {len(rs)} | "
                f"{'/'.join(methods)} | "
                f"{_f(s['median_abs'], fmt)}{unit if s['median_abs'] is not None else ''} | "
                f"{_f(s['p95_abs'], fmt)} | {_f(s['median'], '+' + fmt)} | "
                f"{_f(None if s['coverage'] is None else 100 * s['coverage'], '.0f')} % ({s['n_ok']}) | "
                f"{_f(100 * s['not_identifiable'], '.0f')} % |")
        s = summarise(rows, key)
        out.append(f"| **all cells** | | | | {len(rows)} | | "
                   f"{_f(s['median_abs'], '.3f' if key == 'droop' else '.1f')} | "
                   f"{_f(s['p95_abs'], '.3f' if key == 'droop' else '.1f')} | "
                   f"{_f(s['median'], '+.3f' if key == 'droop' else '+.1f')} | "
                   f"{_f(None if s['coverage'] is None else 100 * s['coverage'], '.0f')} % ({s['n_ok']}) | "
                   f"{_f(100 * s['not_identifiable'], '.0f')} % |")
        out.append("")
    errs = [r for r in rows if r.get("status") == "error"]
    if errs:
        out.append(f"{len(errs)} identification(s) raised; first reasons:")
        for r in errs[:5]:
            out.append(f"- {r['plant']} / {r['logger']} / {r['minutes']:g} min / seed {r['seed']}: "
                       f"{r['reason']}")
        out.append("")
    return "\n".join(out)


def _commit() -> str:
    """The commit of the fcrlive package that ran, flagged when src/ has uncommitted changes (a baseline
    must say which estimators it measured)."""
    import fcrlive

    where = Path(fcrlive.__file__).resolve().parent
    try:
        run = lambda *a: subprocess.run(["git", *a], capture_output=True, text=True, cwd=where,  # noqa: E731
                                        timeout=10).stdout.strip()
        head = run("rev-parse", "--short", "HEAD")
        if not head:
            return f"? ({where}, not a git checkout)"
        dirty = run("status", "--porcelain", "--", ".")
        return head + (" + uncommitted changes in src/fcrlive" if dirty else "")
    except Exception:
        return "?"


def main(argv: list[str] | None = None) -> None:
    from fcrlive.errors import ConfigError
    from fcrlive.sim import zoo

    ap = argparse.ArgumentParser(prog="bench_zoo", description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="a few cells with few seeds (a few minutes)")
    ap.add_argument("--plants", nargs="+", metavar="NAME", help="zoo plants (default: all but the reference; "
                    "--quick: 4)")
    ap.add_argument("--held-out", type=int, metavar="N", help="the held-out plants held-out-0 .. N-1 "
                    "(fcrlive.sim.zoo.held_out: drawn at random, which no estimator was developed on) "
                    "instead of the named ones")
    ap.add_argument("--loggers", nargs="+", metavar="NAME", help="zoo loggers (default: all)")
    ap.add_argument("--minutes", nargs="+", type=float, default=[15.0, 30.0, 60.0], help="log lengths [min]")
    ap.add_argument("--excitation", choices=["no", "yes", "both"], default="both")
    ap.add_argument("--seeds", type=int, default=None, help="seeds per cell (default 5; --quick 3)")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--method", default="auto", help="identification method (default auto)")
    ap.add_argument("--with-plant", action="store_true", help="give identify_signals the plant description")
    ap.add_argument("--no-h", action="store_true", help="do not give identify_signals H (the data sheet's "
                    "inertia constant)")
    ap.add_argument("--known-chain", action="store_true", help="give identify_signals the logger's power "
                    "transducer (lag and dead time) as the plant owner's data sheet would (PowerChain)")
    ap.add_argument("--out", type=Path, metavar="FILE.md", help="also write the table here")
    ap.add_argument("--rows", type=Path, metavar="FILE.json", help="write every fit's numbers here")
    ap.add_argument("--list", action="store_true", help="list the zoo's plants and loggers and exit")
    ap.add_argument("--no-progress", action="store_true")
    a = ap.parse_args([] if argv is None else argv)
    if a.list:
        print(zoo.table())
        return
    known_p, known_l = zoo.plants(), zoo.loggers()
    plants = a.plants or (list(QUICK_PLANTS) if a.quick else [p for p in known_p if not p.startswith("ref-")])
    if a.held_out is not None:
        plants = [*(a.plants or []), *(f"{zoo.HELD_OUT_PREFIX}{k}" for k in range(a.held_out))]
    loggers = a.loggers or list(known_l)
    for p in plants:
        try:
            zoo.zoo_plant(p)
        except ConfigError as e:
            sys.exit(f"bench_zoo: {e}")
    for lg in loggers:
        if lg not in known_l:
            sys.exit(f"bench_zoo: unknown logger {lg!r}; known: {', '.join(known_l)}")
    n_seeds = a.seeds or (3 if a.quick else 5)
    seeds = list(range(a.first_seed, a.first_seed + n_seeds))
    exc = {"no": [False], "yes": [True], "both": [False, True]}[a.excitation]
    tasks = plan(plants, loggers, a.minutes, exc, seeds, a.quick)
    n_fits = sum(len(t.loggers) for t in tasks)
    # longest records first: the pool ends with short tasks
    tasks.sort(key=lambda t: -t.minutes * len(t.loggers) / zoo.truth(t.plant).Tc)
    print(f"zoo benchmark: {len(tasks)} records, {n_fits} identifications on {a.workers} worker(s)",
          file=sys.stderr)
    bar = None
    if not a.no_progress:
        try:
            from tqdm import tqdm

            bar = tqdm(total=n_fits, unit="fit", desc="zoo", dynamic_ncols=True, file=sys.stderr)
        except Exception:
            bar = None
    rows: list[dict] = []
    t0 = time.perf_counter()
    args = [(t, a.method, a.with_plant, not a.no_h, a.known_chain) for t in tasks]
    try:
        if a.workers <= 1:
            for x in args:
                rs = _worker(x)
                rows += rs
                if bar is not None:
                    bar.update(len(rs))
        else:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor, as_completed

            with ProcessPoolExecutor(a.workers, mp_context=mp.get_context("spawn")) as pool:
                futs = [pool.submit(_worker, x) for x in args]
                for f in as_completed(futs):
                    rs = f.result()
                    rows += rs
                    if bar is not None:
                        bar.update(len(rs))
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - t0
    now = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    head = (f"Zoo benchmark at commit {_commit()}, {now}: {len(tasks)} records, {n_fits} identifications "
            f"({n_seeds} seeds per cell, method {a.method}"
            f"{', with the plant description' if a.with_plant else ''}"
            f"{'' if a.no_h else ', H and Kd from the data sheet'}) "
            f"in {wall:.0f} s on {a.workers} worker(s). Errors: droop in percentage points, the rest in % of "
            "the truth; coverage of the 95 % interval over the identifiable results (their count in "
            "brackets).\n")
    text = head + "\n" + table(rows)
    print(text)
    if a.out is not None:
        a.out.write_text(text + "\n")
    if a.rows is not None:
        a.rows.write_text(json.dumps(rows, indent=1, default=str))


if __name__ == "__main__":
    main(sys.argv[1:])
