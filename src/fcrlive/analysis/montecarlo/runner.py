"""Monte Carlo study: tasks (simulate a chunk of runs, identify each), workers, storage and resume,
aggregation, and :func:`run_study` (package docstring)."""

from __future__ import annotations

import io
import json
import math
import os
import time
import traceback
import warnings
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from fcrlive.analysis.montecarlo.config import (
    GRID,
    KIND_OF,
    METHODS,
    StudyConfig,
    Truth,
    process_noise_levels,
    run_seed,
    sine_layout,
    sine_seed,
    truth,
)
from fcrlive.analysis.montecarlo.figures import make_figures
from fcrlive.analysis.montecarlo.metrics import closed_loop_estimates, sine_estimates, summarise_cell
from fcrlive.analysis.montecarlo.tables import markdown_gp_table, markdown_table, write_csv
from fcrlive.errors import UserError


@dataclass(frozen=True)
class Task:
    snr_db: float
    minutes: float
    kind: str
    """"excited" (zcu, zur), "plain" (zu) or "sine"."""
    chunk: int
    runs: tuple[int, ...]
    methods: tuple[str, ...]
    sigma_v: float

    @property
    def name(self) -> str:
        return f"snr{self.snr_db:g}_min{self.minutes:g}_{self.kind}_c{self.chunk:04d}"

    @property
    def cost(self) -> float:
        """Rough relative cost for scheduling (heavy first)."""
        per = {"excited": 1.0, "plain": 1.2, "sine": 11.0}[self.kind]
        return per * self.minutes * len(self.runs)



@dataclass
class TaskResult:
    task: Task
    rows: list[dict]
    grids: dict[str, np.ndarray] = field(default_factory=dict)
    """"<method>/<G>" → (runs, len(GRID)) complex responses."""
    sim_s: float = 0.0
    ident_s: float = 0.0



_WORKER: dict = {}



def _init_worker(plant, cfg: StudyConfig) -> None:
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"
    try:
        from threadpoolctl import threadpool_limits

        _WORKER["limits"] = threadpool_limits(1)
    except Exception:  # pragma: no cover - threadpoolctl is a dependency
        pass
    _WORKER["plant"] = plant
    _WORKER["cfg"] = cfg



def _worker_task(task: Task) -> TaskResult:
    return run_task(_WORKER["plant"], _WORKER["cfg"], task)



def _reason(exc: BaseException) -> str:
    msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    return f"{type(exc).__name__}: {msg}"[:300]



def _base_row(task: Task, method: str, run: int, seed: int) -> dict:
    return {
        "snr_db": task.snr_db,
        "minutes": task.minutes,
        "method": method,
        "run": run,
        "seed": seed,
        "status": "ok",
        "reason": "",
    }



def _finite_check(row: dict) -> None:
    vals = [row[k] for k in ("g1_static", "max_g1", "max_s") if k in row]
    vals += [row[k] for k in row if k.startswith("gp_re_") or k.startswith("gp_im_")]
    if any(not math.isfinite(v) for v in vals):
        raise FloatingPointError("non-finite estimate")



def run_task(plant, cfg: StudyConfig, task: Task, *, identify: Callable | None = None) -> TaskResult:
    """Simulate a chunk and identify every run; every failure becomes a row with its reason.

    ``identify(method, signals) -> ExperimentResult`` replaces the experiments (tests inject failures).
    """
    if task.kind == "sine":
        return _run_sine_task(plant, cfg, task)
    from fcrlive.sim import SimConfig, simulate_batch

    seeds = [run_seed(cfg.seed, i) for i in task.runs]
    res = TaskResult(task, [])
    excited = task.kind == "excited"
    sc = SimConfig(
        duration_s=task.minutes * 60.0,
        snr_db=None,
        process_noise_std=task.sigma_v,
        excitation=excited,
        excitation_seed=cfg.excitation_seed,
        model=cfg.model,
    )
    fields = ("y", "u", "c", "a", "epsilon")
    t0 = time.perf_counter()
    try:
        batch = simulate_batch(plant, sc, seeds, fields=fields)
    except Exception as exc:  # the whole chunk is lost, the study goes on
        for i, s in zip(task.runs, seeds):
            for m in task.methods:
                res.rows.append({**_base_row(task, m, i, s), "status": "failed",
                                 "reason": "simulation: " + _reason(exc)})
        return res
    res.sim_s = time.perf_counter() - t0
    identify = identify or _identify_closed_loop(plant, cfg)
    grids: dict[str, list] = {}
    N = batch.t.shape[1]
    from fcrlive.signals import PlantSignals

    for j, (i, s) in enumerate(zip(task.runs, seeds)):
        sig = PlantSignals(
            t=batch.t[j], Ts=batch.Tc, u=batch.u[j], y=batch.y[j], r=batch.r[j], epsilon=batch.epsilon[j],
            c=batch.c[j], a=batch.a[j], rated_mw=batch.rated_mw, f0=batch.f0, p0_mw=batch.p0_mw,
            has_excitation=excited, filled=np.zeros(N, bool), segments=((0, N),),
            sources=(f"sim seed {s}",),
        )
        for m in task.methods:
            row = _base_row(task, m, i, s)
            t1 = time.perf_counter()
            resp = {}
            try:
                exp = identify(m, sig)
                est, resp = closed_loop_estimates(exp, cfg.periods_s)
                _finite_check(est)
                row.update(est)
                row["warnings"] = len(getattr(exp, "warnings", ()))
            except Exception as exc:
                row.update(status="failed", reason=_reason(exc))
                resp = {}
            row["ident_s"] = time.perf_counter() - t1
            res.ident_s += row["ident_s"]
            res.rows.append(row)
            for k in ("G_1", "S", "G_p"):
                grids.setdefault(f"{m}/{k}", []).append(resp.get(k, np.full(GRID.size, np.nan + 0j)))
    res.grids = {k: np.asarray(v) for k, v in grids.items()}
    return res



def _identify_closed_loop(plant, cfg: StudyConfig) -> Callable:
    from fcrlive.analysis import experiments as ex

    ctl = ex.controller_from_plant(plant)

    def identify(method: str, sig):
        if method == "zcu":
            return ex.zcu(sig, controller=ctl, ts_id=cfg.ts_id)
        if method == "zur":
            return ex.zur(sig, ts_id=cfg.ts_id)
        if method == "zu":
            return ex.zu(sig, ts_id=cfg.ts_id)
        raise ValueError(f"not a closed-loop method: {method}")

    return identify



def _run_sine_task(plant, cfg: StudyConfig, task: Task) -> TaskResult:
    from fcrlive.analysis.sine_fit import evaluate_sine_test
    from fcrlive.sim import SimConfig, simulate_batch

    res = TaskResult(task, [])
    rows = {i: _base_row(task, "sine", i, run_seed(cfg.seed, i)) for i in task.runs}
    length = task.minutes * 60.0
    f0 = plant.grid.f0
    droop = plant.unit.governor.droop
    for k, T in enumerate(cfg.periods_s):
        try:
            N, _settle, n_eval = sine_layout(plant, T, length)
            Tc = plant.unit.governor.Tc
            t = np.arange(N) * Tc
            applied = f0 + cfg.sine_amplitude_hz * np.sin(2 * np.pi * t / T)
            sc = SimConfig(duration_s=N * Tc, snr_db=None, process_noise_std=task.sigma_v,
                           applied_freq_hz=applied, model=cfg.model)
            seeds = [sine_seed(cfg.seed, i, k) for i in task.runs]
            t0 = time.perf_counter()
            b = simulate_batch(plant, sc, seeds, fields=("epsilon", "u"))
            res.sim_s += time.perf_counter() - t0
        except Exception as exc:
            for i in task.runs:
                if rows[i]["status"] == "ok":
                    rows[i].update(status="failed", reason=f"simulation T={T:g} s: " + _reason(exc))
            continue
        for j, i in enumerate(task.runs):
            if rows[i]["status"] != "ok":
                continue
            t1 = time.perf_counter()
            try:
                r = evaluate_sine_test(
                    b.t[j], b.epsilon[j] * f0, b.u[j] * b.rated_mw + b.p0_mw, T, n_periods=n_eval,
                    rated_mw=b.rated_mw, droop=droop, f0_hz=f0, is_control_error=True,
                )
                est = sine_estimates([r])
                _finite_check(est)
                rows[i].update(est)
            except Exception as exc:
                rows[i].update(status="failed", reason=f"T={T:g} s: " + _reason(exc))
            dt = time.perf_counter() - t1
            rows[i]["ident_s"] = rows[i].get("ident_s", 0.0) + dt
            res.ident_s += dt
    res.rows = [rows[i] for i in task.runs]
    return res



def plan(cfg: StudyConfig, sigma_v: dict[float, float]) -> list[Task]:
    tasks = []
    for snr in cfg.snr_db:
        for mins in cfg.minutes:
            for kind in ("excited", "plain", "sine"):
                ms = tuple(m for m in cfg.methods if KIND_OF[m] == kind)
                if not ms:
                    continue
                for c, a in enumerate(range(0, cfg.runs, cfg.chunk)):
                    runs = tuple(range(a, min(a + cfg.chunk, cfg.runs)))
                    tasks.append(Task(float(snr), float(mins), kind, c, runs, ms, sigma_v[float(snr)]))
    return tasks



def _save_task(res: TaskResult, chunk_dir: Path) -> None:
    path = chunk_dir / f"{res.task.name}.npz"
    tmp = chunk_dir / f".{res.task.name}.{os.getpid()}.tmp.npz"
    meta = {"task": asdict(res.task), "rows": res.rows, "sim_s": res.sim_s, "ident_s": res.ident_s}
    np.savez(tmp, meta=np.array(json.dumps(meta, default=float)), **{k.replace("/", "__"): v
                                                                       for k, v in res.grids.items()})
    os.replace(tmp, path)



def _load_task(path: Path) -> TaskResult:
    with np.load(path) as z:
        meta = json.loads(str(z["meta"]))
        grids = {k.replace("__", "/"): z[k] for k in z.files if k != "meta"}
    t = meta["task"]
    task = Task(t["snr_db"], t["minutes"], t["kind"], t["chunk"], tuple(t["runs"]), tuple(t["methods"]),
                t["sigma_v"])
    return TaskResult(task, meta["rows"], grids, meta["sim_s"], meta["ident_s"])



@dataclass(frozen=True, eq=False)
class StudyResult:
    config: StudyConfig
    truth: Truth
    rows: list[dict]
    cells: list[dict]
    """One dict per (snr_db, minutes, method): keys snr_db, minutes, method and :func:`summarise_cell`."""
    mean_responses: dict
    """(snr_db, minutes, method) → {"G_1": mean |G| on GRID, "G_1_median": median |G|, ...}."""
    timing: dict
    out_dir: Path | None = None



def aggregate(cfg: StudyConfig, tr: Truth, results: Iterable[TaskResult]) -> tuple[list, list, dict, dict]:
    rows: list[dict] = []
    grids: dict[tuple, dict[str, list]] = {}
    sim_s = {}
    ident_s = {}
    nruns = {}
    for res in results:
        t = res.task
        rows += res.rows
        sim_s[t.kind, t.minutes] = sim_s.get((t.kind, t.minutes), 0.0) + res.sim_s
        nruns[t.kind, t.minutes] = nruns.get((t.kind, t.minutes), 0) + len(t.runs)
        for r in res.rows:
            k = (r["method"], t.minutes)
            ident_s[k] = ident_s.get(k, 0.0) + float(r.get("ident_s", 0.0))
        for key, arr in res.grids.items():
            m, g = key.split("/")
            ok = np.array([r["status"] == "ok" for r in res.rows if r["method"] == m])
            grids.setdefault((t.snr_db, t.minutes, m), {}).setdefault(g, []).append(np.asarray(arr)[ok])
    rows.sort(key=lambda r: (-r["snr_db"], r["minutes"], METHODS.index(r["method"]), r["run"]))
    cells = []
    for snr in cfg.snr_db:
        for mins in cfg.minutes:
            for m in cfg.methods:
                sel = [r for r in rows if r["snr_db"] == snr and r["minutes"] == mins and r["method"] == m]
                if sel:
                    cells.append({"snr_db": float(snr), "minutes": float(mins), "method": m,
                                  **summarise_cell(sel, tr)})
    means = {}
    for key, d in grids.items():
        means[key] = {}
        for g, parts in d.items():
            A = np.concatenate(parts, axis=0) if parts else np.empty((0, GRID.size))
            with np.errstate(invalid="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                nan = np.full(GRID.size, np.nan)
                means[key][g] = np.nanmean(np.abs(A), axis=0) if len(A) else nan
                means[key][g + "_median"] = np.nanmedian(np.abs(A), axis=0) if len(A) else nan
    timing = {"sim_s_per_run": {f"{k}/{m:g}min": sim_s[k, m] / max(nruns[k, m], 1) for k, m in sim_s},
              "ident_s_per_run": {f"{m}/{mins:g}min": ident_s[m, mins] / max(
                  sum(1 for r in rows if r["method"] == m and r["minutes"] == mins), 1)
                  for m, mins in ident_s}}
    return rows, cells, means, timing



def _progress(total: int, enabled: bool):
    if not enabled:
        return None
    try:
        from tqdm import tqdm

        return tqdm(total=total, unit="fit", desc="montecarlo", dynamic_ncols=True)
    except Exception:  # pragma: no cover
        return None



def run_study(
    plant,
    cfg: StudyConfig,
    out_dir: str | Path,
    *,
    workers: int | None = None,
    progress: bool = True,
    fresh: bool = False,
    figures: bool = True,
    log: Callable[[str], None] | None = None,
) -> StudyResult:
    """Run (or resume) the study into ``out_dir`` and write runs.csv, summary.json, summary.md, figures."""
    out = Path(out_dir)
    chunk_dir = out / "chunks"
    chunk_dir.mkdir(parents=True, exist_ok=True)
    key = cfg.key(plant)
    manifest = out / "study.json"
    if manifest.exists() and not fresh:
        old = json.loads(manifest.read_text())
        if old.get("key") != key and any(chunk_dir.glob("*.npz")):
            raise UserError(
                f"{out} holds results of a different study (other options or plant); use another --out "
                "or --fresh to discard them"
            )
    if fresh:
        for p in chunk_dir.glob("*.npz"):
            p.unlink()
    manifest.write_text(json.dumps({"key": key, "config": asdict(cfg), "plant": repr(plant)}, indent=1))
    tr = truth(plant, cfg.periods_s)
    sigma_v = process_noise_levels(plant, cfg)
    tasks = plan(cfg, sigma_v)
    done: dict[str, TaskResult] = {}
    for t in tasks:
        p = chunk_dir / f"{t.name}.npz"
        if p.exists():
            try:
                r = _load_task(p)
                if r.task.runs == t.runs and r.task.methods == t.methods:
                    done[t.name] = r
            except Exception:
                pass
    todo = sorted((t for t in tasks if t.name not in done), key=lambda t: -t.cost)
    if log and done:
        log(f"resuming: {len(done)} of {len(tasks)} tasks already done in {chunk_dir}")
    n_fits = sum(len(t.runs) * len(t.methods) for t in todo)
    bar = _progress(n_fits, progress)
    t_start = time.perf_counter()
    workers = max(1, int(workers or os.cpu_count() or 1))

    def finished(r: TaskResult, save: bool = True) -> None:
        if save:  # a task lost with its worker is not saved: a resumed study runs it again
            _save_task(r, chunk_dir)
        done[r.task.name] = r
        if bar is not None:
            bar.update(len(r.task.runs) * len(r.task.methods))

    def lost(t: Task, exc: BaseException) -> TaskResult:
        rows = [{**_base_row(t, m, i, run_seed(cfg.seed, i)), "status": "failed",
                 "reason": "worker: " + _reason(exc)} for i in t.runs for m in t.methods]
        return TaskResult(t, rows)

    try:
        if workers == 1 or len(todo) <= 1:
            _init_worker(plant, cfg)
            for t in todo:
                try:
                    r = run_task(plant, cfg, t)
                except Exception as exc:  # a bug outside the guarded identification: record, go on
                    if log:
                        log(traceback.format_exc())
                    finished(lost(t, exc), save=False)
                    continue
                finished(r)
        else:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor, as_completed

            ctx = mp.get_context("spawn")
            with ProcessPoolExecutor(min(workers, len(todo)), mp_context=ctx, initializer=_init_worker,
                                     initargs=(plant, cfg)) as pool:
                futs = {pool.submit(_worker_task, t): t for t in todo}
                for f in as_completed(futs):
                    t = futs[f]
                    try:
                        r = f.result()
                    except Exception as exc:  # a crashed worker: record, go on with the rest
                        finished(lost(t, exc), save=False)
                        continue
                    finished(r)
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - t_start
    results = [done[t.name] for t in tasks if t.name in done]
    rows, cells, means, timing = aggregate(cfg, tr, results)
    timing["wall_s"] = wall
    timing["workers"] = workers
    timing["tasks_run"] = len(todo)
    res = StudyResult(cfg, tr, rows, cells, means, timing, out)
    write_outputs(res, out, figures=figures)
    return res



def write_outputs(res: StudyResult, out: Path, *, figures: bool = True) -> None:
    cfg, tr = res.config, res.truth
    write_csv(res.rows, out / "runs.csv", cfg.periods_s)
    summary = {"config": asdict(cfg), "truth": tr.to_json(), "cells": res.cells, "timing": res.timing}
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=float, allow_nan=True))
    md = io.StringIO()
    md.write(markdown_table(res.cells, tr))
    gp = markdown_gp_table(res.cells)
    if gp:
        md.write("\nNRMSE(Ω) of G_p per period (eq. 36):\n\n" + gp)
    (out / "summary.md").write_text(md.getvalue())
    np.savez(out / "mean_responses.npz", grid=GRID,
             **{f"snr{k[0]:g}_min{k[1]:g}_{k[2]}_{g}": v for k, d in res.mean_responses.items()
                for g, v in d.items()})
    if figures:
        make_figures(res, out)
