"""Monte Carlo study of the identification methods: the paper's Section 7 (Figs. 4-11, eqs. 35-36).

Cells: SNR × dataset length × method. Methods:

- ``zcu``, ``zur`` (paper 4.2.2, 4.2.1) on the SAME closed-loop datasets WITH the excitation r[n]
  (white, std 0.1/(50·3) pu, generated once from ``excitation_seed``);
- ``zu`` (4.2.1 eq. 16) on closed-loop datasets WITHOUT excitation (same seeds otherwise);
- ``sine``: the industry test (4.1), one open-loop sine test per period of :data:`PAPER_PERIODS_S`, each
  dataset as long as the cell's length (10 min → 110 min of tests, 30 min → 330 min, as in the paper).

Randomness (paper 7.1): r is generated once; the stochastic load and the process noise are regenerated
per run from the run's seed (:func:`run_seed`), the same seeds in every cell (common random numbers:
differences between cells are not blurred by different realisations). Every sine dataset has its own
seed (:func:`sine_seed`).

Process noise: its std is sized ONCE per SNR from the excited closed loop (``fcrlive.sim`` docstring:
SNR = var u from load and r over var u from the process noise) and the same std is used for the
unexcited Z_u datasets and for the sine tests (there added to the applied frequency the governor sees):
the noise is a property of the plant, not of the experiment.

Sine test datasets of length L at period T: the test signal starts at t = 0 from steady state; the first
k whole periods settle (k·T covers ``settle_time`` — 5 slowest open-loop time constants — but at most
L/3, at least one period), the remaining whole periods are evaluated (:func:`sine_layout`) by
:func:`fcrlive.analysis.sine_fit.evaluate_sine_test` (least-squares sine + offset + trend).

Figures of merit (per cell, over the successful runs):

- NRMSE (eq. 35) of G_1(1), max|G_1|, max|S|: ``sqrt(mean((a0 − a_i)²))``, absolute and divided by the
  truth a0; the bias ``mean(a_i) − a0``; the coverage of the reported 95 % intervals (fraction of runs
  whose interval contains a0). G_1(1) is the droop seen from the grid (ρ_eff = G_1(1) with K_d = 0), and
  the droop interval is the monotone image of the G_1(1) interval, so its coverage is the same.
- NRMSE(Ω) (eq. 36) of G_p at the Table 1 periods: ``sqrt(mean(|G_p − G_i|²/|G_p|²))`` on the COMPLEX
  responses; for the sine test G_i is the estimate of G_req compared with G_p as the paper does, and
  also with G_req (``nrmse_vs_greq``); the relative bias of |G_i| and the coverage of the 95 % interval
  of |G_i|.

Peaks are taken as :mod:`fcrlive.analysis.assess` does (grid from 1e-3 rad/s to the Nyquist frequency of
the identification rate, refined around the maximum); G_1(1) from the response at ω = 1e-7 rad/s.

Execution: tasks are (SNR, length, data kind, chunk of runs); a worker simulates its chunk in one
:func:`fcrlive.sim.simulate_batch` and identifies each run. Every finished task is written atomically to
``<out>/chunks/`` so an interrupted study resumes where it stopped; a failing identification is recorded
with its reason, never raised. BLAS is pinned to one thread per worker.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import time
import traceback
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from fcrlive.constants import PAPER_PERIODS_S
from fcrlive.errors import UserError

METHODS = ("zcu", "zur", "zu", "sine")
METHOD_LABELS = {"zcu": "Z_cu", "zur": "Z_ur", "zu": "Z_u", "sine": "sine test"}
KIND_OF = {"zcu": "excited", "zur": "excited", "zu": "plain", "sine": "sine"}
"""Which simulated datasets a method uses (zcu and zur share theirs)."""
SCALARS = ("g1_static", "max_g1", "max_s")
SCALAR_LABELS = {"g1_static": "G_1(1)", "max_g1": "max|G_1|", "max_s": "max|S|"}
OMEGA_MIN = 1e-3
"""Lower end of the peak grid [rad/s] (as fcrlive.analysis.assess)."""
GRID = np.geomspace(1e-3, 2.0, 80)
"""Frequencies [rad/s] of the stored responses for the mean-response figure (Figs. 4-6)."""
Z95 = 1.959963984540054


def _ptag(T: float) -> str:
    return f"T{T:g}"


# ---------------------------------------------------------------------------------------------------
# Configuration and truth


@dataclass(frozen=True)
class StudyConfig:
    """What to run (module docstring)."""

    runs: int = 100
    snr_db: tuple[float, ...] = (12.0, 6.0, 0.0)
    minutes: tuple[float, ...] = (10.0, 30.0)
    methods: tuple[str, ...] = METHODS
    seed: int = 0
    excitation_seed: int = 12345
    model: str = "nonlinear"
    chunk: int = 25
    """Runs per task, simulated in one batch (the batch's cost is nearly independent of its size up to
    about 50 runs); bounds a worker's memory: about 8 B · samples · 5 signals · chunk (25 runs of 30 min:
    90 MB of signals, about 250 MB peak)."""
    sine_amplitude_hz: float = 0.1
    periods_s: tuple[float, ...] = PAPER_PERIODS_S
    ts_id: float = 0.5

    def __post_init__(self):
        bad = [m for m in self.methods if m not in METHODS]
        if bad:
            raise UserError(f"unknown method(s) {', '.join(bad)}; use {', '.join(METHODS)}")
        if self.runs < 1:
            raise UserError(f"--runs must be at least 1, got {self.runs}")
        if self.chunk < 1:
            raise UserError(f"chunk must be at least 1, got {self.chunk}")
        if not self.snr_db or not self.minutes or not self.methods:
            raise UserError("need at least one SNR, one length and one method")
        if any(not m > 0 for m in self.minutes):
            raise UserError("dataset lengths must be positive")
        if self.model not in ("nonlinear", "linear"):
            raise UserError(f"model must be 'nonlinear' or 'linear', got {self.model!r}")

    def key(self, plant) -> str:
        """Identity of the study's tasks (everything but ``runs``, which may grow on resume)."""
        d = asdict(self)
        d.pop("runs")
        d["plant"] = repr(plant)
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]


def run_seed(seed: int, run: int) -> int:
    """Seed of the load and process noise of run ``run`` (the same in every cell)."""
    return int(np.random.SeedSequence([int(seed), int(run)]).generate_state(1, np.uint32)[0])


def sine_seed(seed: int, run: int, period_index: int) -> int:
    """Seed of the sine-test dataset of run ``run`` at the ``period_index``-th period."""
    ss = np.random.SeedSequence([int(seed), int(run), 1 + int(period_index)])
    return int(ss.generate_state(1, np.uint32)[0])


@dataclass(frozen=True, eq=False)
class Truth:
    """The analytic values the estimates are compared with (continuous-time, fcrlive.plant.transfer)."""

    g1_static: float
    max_g1: float
    max_s: float
    periods_s: tuple[float, ...]
    gp: np.ndarray
    """G_p(jΩ) at the periods (complex)."""
    greq: np.ndarray
    """G_req(jΩ) at the periods (what the sine test measures, eq. 13)."""
    grid: np.ndarray
    responses: dict[str, np.ndarray]
    """G_1, S, G_p on ``grid``."""

    def scalar(self, name: str) -> float:
        return float(getattr(self, name))

    def to_json(self) -> dict:
        return {
            "g1_static": self.g1_static,
            "max_g1": self.max_g1,
            "max_s": self.max_s,
            "periods_s": list(self.periods_s),
            "abs_gp": [float(abs(g)) for g in self.gp],
            "abs_greq": [float(abs(g)) for g in self.greq],
        }


def truth(plant, periods_s: Sequence[float] = PAPER_PERIODS_S, grid: np.ndarray = GRID) -> Truth:
    from fcrlive.plant.transfer import analytic, freqresp, peak, static_gain

    tfs = analytic(plant)
    w = 2 * np.pi / np.asarray(periods_s, float)
    return Truth(
        g1_static=float(static_gain(tfs.G_1)),
        max_g1=float(peak(tfs.G_1).value),
        max_s=float(peak(tfs.S).value),
        periods_s=tuple(float(p) for p in periods_s),
        gp=np.asarray(freqresp(tfs.G_p, w), complex),
        greq=np.asarray(freqresp(tfs.G_req, w), complex),
        grid=np.asarray(grid, float),
        responses={k: np.asarray(freqresp(getattr(tfs, k), grid), complex) for k in ("G_1", "S", "G_p")},
    )


# ---------------------------------------------------------------------------------------------------
# Figures of merit (pure)


def nrmse(estimates, true_value: float) -> float:
    """Eq. 35: sqrt(mean((a0 − a_i)²)) over the finite estimates (NaN if none)."""
    a = np.asarray(estimates, float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return float("nan")
    return float(np.sqrt(np.mean((true_value - a) ** 2)))


def nrmse_omega(estimates, true_values) -> np.ndarray:
    """Eq. 36 per frequency: sqrt(mean_i |G − G_i|²/|G|²); ``estimates`` (L, P) complex, truth (P,).

    Rows with a non-finite value at a frequency are left out at that frequency."""
    G = np.asarray(true_values, complex)
    E = np.asarray(estimates, complex).reshape(-1, G.size)
    err = np.abs(E - G[None, :]) ** 2 / np.abs(G[None, :]) ** 2
    out = np.full(G.size, np.nan)
    for j in range(G.size):
        e = err[:, j][np.isfinite(err[:, j])]
        if e.size:
            out[j] = math.sqrt(float(np.mean(e)))
    return out


def coverage(lo, hi, true_value) -> float:
    """Fraction of the intervals [lo, hi] (finite ones) that contain the truth (broadcast)."""
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    ok = np.isfinite(lo) & np.isfinite(hi)
    if not np.any(ok):
        return float("nan")
    tv = np.broadcast_to(np.asarray(true_value, float), lo.shape)
    return float(np.mean((lo[ok] <= tv[ok]) & (tv[ok] <= hi[ok])))


# ---------------------------------------------------------------------------------------------------
# Estimates of one run


def closed_loop_estimates(exp, periods_s: Sequence[float], grid: np.ndarray = GRID) -> tuple[dict, dict]:
    """(row fields, responses on ``grid``) from an fcrlive.analysis.experiments.ExperimentResult."""
    fr = exp.responses
    wmax = exp.omega_max * 0.999
    row: dict = {}
    g0 = fr(np.array([1e-7]))["G_1"]
    v, sd = float(g0.value.real[0]), float(g0.sd_real[0])
    row.update(g1_static=v, g1_static_lo=v - Z95 * sd, g1_static_hi=v + Z95 * sd)
    # The same band as `fcrlive identify` reports: peaks beyond the data's passband are model artefacts.
    from fcrlive.analysis.assess import peak_band
    from fcrlive.gridsearch import uncertain_peak

    band = peak_band(exp.Ts)
    for name, key in (("max_g1", "G_1"), ("max_s", "S")):
        if key in exp.identifiable:
            pk = uncertain_peak(lambda w, k=key: fr(w)[k], *band, 1500)
            lo, hi = pk.ci95()
            row.update({name: pk.value, f"{name}_lo": lo, f"{name}_hi": hi, f"{name}_omega": pk.omega})
    keys = [k for k in ("G_1", "S", "G_p") if k in exp.identifiable]
    g = grid[grid < wmax]
    R = fr(g)
    resp = {}
    for k in keys:
        full = np.full(grid.size, np.nan + 0j)
        full[: g.size] = R[k].value
        resp[k] = full
    if "G_p" in exp.identifiable:
        Gp = fr(2 * np.pi / np.asarray(periods_s, float))["G_p"]
        lo, hi = Gp.ci95_abs()
        for T, val, a, b in zip(periods_s, Gp.value, lo, hi):
            t = _ptag(T)
            row.update({f"gp_re_{t}": val.real, f"gp_im_{t}": val.imag, f"gp_lo_{t}": a, f"gp_hi_{t}": b})
    return row, resp


def sine_estimates(results: Sequence) -> dict:
    """Row fields from sine_fit.SineTestResult per period: G_req and the 95 % interval of |G_req|."""
    row = {}
    for r in results:
        t = _ptag(r.period_s)
        g = complex(r.G_req)
        sd = r.gain_se * abs(g) / r.gain if r.gain > 0 else float("nan")
        row.update({
            f"gp_re_{t}": g.real,
            f"gp_im_{t}": g.imag,
            f"gp_lo_{t}": max(abs(g) - Z95 * sd, 0.0),
            f"gp_hi_{t}": abs(g) + Z95 * sd,
            f"lin_{t}": r.linearity,
        })
    return row


def sine_layout(plant, period_s: float, length_s: float) -> tuple[int, int, int]:
    """(samples, settling periods k, evaluated periods n) of a sine dataset (module docstring)."""
    from fcrlive.sim import settle_time

    Tc = plant.unit.governor.Tc
    total = math.floor(length_s / period_s + 1e-9)
    if total < 2:
        raise UserError(f"a {length_s:g} s sine dataset holds fewer than two {period_s:g} s periods")
    need = min(settle_time(plant, period_s), length_s / 3.0)
    k = min(max(1, math.ceil(need / period_s - 1e-9)), total - 1)
    return round(length_s / Tc), k, total - k


# ---------------------------------------------------------------------------------------------------
# Tasks (run in the workers)


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
    from fcrlive.tso.signals import PlantSignals

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


# ---------------------------------------------------------------------------------------------------
# Planning, storage, resume


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


def process_noise_levels(plant, cfg: StudyConfig) -> dict[float, float]:
    """Process noise std per SNR, sized from the excited closed loop (module docstring)."""
    from fcrlive.constants import PAPER_EXCITATION_STD_PU
    from fcrlive.sim.linear import load_noise_std, process_noise_std

    sl = load_noise_std(plant)
    r_std = PAPER_EXCITATION_STD_PU
    return {float(s): process_noise_std(plant, float(s), sl, r_std=r_std) for s in cfg.snr_db}


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


# ---------------------------------------------------------------------------------------------------
# Aggregation


def row_columns(periods_s: Sequence[float]) -> list[str]:
    cols = ["snr_db", "minutes", "method", "run", "seed", "status", "reason", "ident_s", "warnings"]
    for q in SCALARS:
        cols += [q, f"{q}_lo", f"{q}_hi"]
        if q != "g1_static":
            cols.append(f"{q}_omega")
    for T in periods_s:
        t = _ptag(T)
        cols += [f"gp_re_{t}", f"gp_im_{t}", f"gp_lo_{t}", f"gp_hi_{t}", f"lin_{t}"]
    return cols


def _col(rows: list[dict], key: str) -> np.ndarray:
    return np.array([float(r.get(key, np.nan)) if r.get(key) is not None else np.nan for r in rows])


def summarise_cell(rows: list[dict], tr: Truth) -> dict:
    """The figures of merit of one (SNR, length, method) cell (module docstring)."""
    ok = [r for r in rows if r["status"] == "ok"]
    failed = [r for r in rows if r["status"] != "ok"]
    reasons: dict[str, int] = {}
    for r in failed:
        reasons[r["reason"]] = reasons.get(r["reason"], 0) + 1
    out: dict = {"runs": len(rows), "ok": len(ok), "failed": len(failed),
                 "failure_reasons": dict(sorted(reasons.items(), key=lambda kv: -kv[1]))}
    for q in SCALARS:
        a = _col(ok, q)
        if not np.any(np.isfinite(a)):
            continue
        a0 = tr.scalar(q)
        e = nrmse(a, a0)
        out[q] = {
            "truth": a0,
            "n": int(np.isfinite(a).sum()),
            "mean": float(np.nanmean(a)),
            "bias": float(np.nanmean(a) - a0),
            "rel_bias": float(np.nanmean(a) / a0 - 1.0),
            "nrmse": e,
            "rel_nrmse": e / abs(a0),
            "coverage": coverage(_col(ok, f"{q}_lo"), _col(ok, f"{q}_hi"), a0),
            "median_abs_err": float(np.nanmedian(np.abs(a - a0))),
        }
    tags = [_ptag(T) for T in tr.periods_s]
    if ok and any(f"gp_re_{tags[0]}" in r for r in ok):
        G = np.column_stack([_col(ok, f"gp_re_{t}") + 1j * _col(ok, f"gp_im_{t}") for t in tags])
        lo = np.column_stack([_col(ok, f"gp_lo_{t}") for t in tags])
        hi = np.column_stack([_col(ok, f"gp_hi_{t}") for t in tags])
        absG = np.abs(G)
        out["gp"] = {
            "periods_s": list(tr.periods_s),
            "nrmse": nrmse_omega(G, tr.gp).tolist(),
            "nrmse_vs_greq": nrmse_omega(G, tr.greq).tolist(),
            "median_rel_err": np.nanmedian(np.abs(G / tr.gp[None, :] - 1.0), axis=0).tolist(),
            "rel_bias_abs": (np.nanmean(absG, axis=0) / np.abs(tr.gp) - 1.0).tolist(),
            "rel_bias_abs_vs_greq": (np.nanmean(absG, axis=0) / np.abs(tr.greq) - 1.0).tolist(),
            "coverage": [coverage(lo[:, j], hi[:, j], abs(tr.gp[j])) for j in range(len(tags))],
            "coverage_vs_greq": [coverage(lo[:, j], hi[:, j], abs(tr.greq[j])) for j in range(len(tags))],
        }
    return out


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


# ---------------------------------------------------------------------------------------------------
# Output: CSV, JSON, Markdown, figures


def write_csv(rows: list[dict], path: Path, periods_s: Sequence[float]) -> None:
    import csv

    cols = row_columns(periods_s)
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.9g}" if isinstance(v, float) else v) for k, v in r.items()})


def _fmt(x, nd=3, pct=False) -> str:
    if x is None or not isinstance(x, (int, float)) or not math.isfinite(x):
        return "–"
    return f"{100 * x:.0f} %" if pct else f"{x:.{nd}g}"


def markdown_table(cells: list[dict], tr: Truth) -> str:
    """The per-cell summary (relative NRMSE and bias, coverage) as a Markdown table."""
    head = (
        "| SNR | length | method | ok/runs | G_1(1) NRMSE (rel.) | bias | cov. "
        "| max\\|G_1\\| NRMSE (rel.) | bias | cov. | max\\|S\\| NRMSE (rel.) | bias | cov. "
        "| G_p NRMSE(Ω) mean (max; med.) | \\|G_p\\| cov. |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for c in cells:
        parts = [f"{c['snr_db']:g} dB", f"{c['minutes']:g} min", METHOD_LABELS[c["method"]],
                 f"{c['ok']}/{c['runs']}"]
        for q in SCALARS:
            s = c.get(q)
            if s is None:
                parts += ["–", "–", "–"]
            else:
                med = _fmt(s["median_abs_err"] / abs(s["truth"]), pct=True)
                parts += [f"{s['nrmse']:.3g} ({_fmt(s['rel_nrmse'], pct=True)}; med. {med})",
                          f"{s['bias']:+.3g}", _fmt(s["coverage"], pct=True)]
        g = c.get("gp")
        if g is None:
            parts += ["–", "–"]
        else:
            e = np.array(g["nrmse"], float)
            cov = np.array(g["coverage"], float)
            med = float(np.nanmean(g["median_rel_err"]))
            parts += [f"{np.nanmean(e):.3g} ({np.nanmax(e):.3g}; med. {_fmt(med, pct=True)})"
                      if np.any(np.isfinite(e)) else "–",
                      _fmt(float(np.nanmean(cov)) if np.any(np.isfinite(cov)) else float("nan"), pct=True)]
        lines.append("| " + " | ".join(parts) + " |")
    truth_line = (
        f"Truth: G_1(1) = {tr.g1_static:.4g}, max|G_1| = {tr.max_g1:.4g}, max|S| = {tr.max_s:.4g}. "
        "NRMSE absolute (eq. 35) with, in brackets, the NRMSE relative to the truth and the median "
        "relative error (robust to the few wild runs that dominate an RMS); bias = mean estimate − truth; "
        "cov. = coverage of the reported 95 % intervals (successful runs); NRMSE(Ω) (eq. 36, relative, "
        "complex) of G_p averaged over the Table 1 periods (max over them; median relative error "
        "averaged over them); for the sine test G_i = Ĝ_req compared with G_p as in the paper."
    )
    return head + "\n".join(lines) + "\n\n" + truth_line + "\n"


def markdown_gp_table(cells: list[dict]) -> str:
    """NRMSE(Ω) of G_p per period (eq. 36), one row per cell holding G_p estimates."""
    cs = [c for c in cells if "gp" in c]
    if not cs:
        return ""
    periods = cs[0]["gp"]["periods_s"]
    head = "| SNR | length | method | " + " | ".join(f"{p:g} s" for p in periods) + " |\n"
    head += "|---|---|---|" + "---|" * len(periods) + "\n"
    lines = []
    for c in cs:
        e = c["gp"]["nrmse"]
        lines.append(f"| {c['snr_db']:g} dB | {c['minutes']:g} min | {METHOD_LABELS[c['method']]} | "
                     + " | ".join(_fmt(x, 2) for x in e) + " |")
        if c["method"] == "sine":
            e = c["gp"]["nrmse_vs_greq"]
            lines.append(f"| {c['snr_db']:g} dB | {c['minutes']:g} min | sine vs G_req | "
                         + " | ".join(_fmt(x, 2) for x in e) + " |")
    return head + "\n".join(lines) + "\n"


_STYLES = {12.0: "-", 6.0: "--", 0.0: ":"}
_COLORS = {"zcu": "C0", "zur": "C1", "zu": "C2", "sine": "C3"}


def _cell(cells, snr, mins, m):
    for c in cells:
        if c["snr_db"] == snr and c["minutes"] == mins and c["method"] == m:
            return c
    return None


def make_figures(res: StudyResult, out_dir: Path) -> list[Path]:
    """PNG figures like the paper's Figs. 4-10 (module docstring); returns the paths written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cfg, cells, tr = res.config, res.cells, res.truth
    snrs = sorted(cfg.snr_db, reverse=True)
    paths = []

    def save(fig, name):
        p = out_dir / name
        fig.tight_layout()
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(p)

    # Figs. 7a, 7b, 8: NRMSE of scalars vs SNR per method
    for q, name, title in (
        ("g1_static", "fig7a_nrmse_g1_static.png", "NRMSE of G_1(1) (eq. 35)"),
        ("max_g1", "fig7b_nrmse_max_g1.png", "NRMSE of max|G_1| (eq. 35)"),
        ("max_s", "fig8_nrmse_max_s.png", "NRMSE of max|S| (eq. 35)"),
    ):
        fig, ax = plt.subplots(figsize=(5.5, 3.8))
        drawn = False
        for m in cfg.methods:
            for mins in sorted(cfg.minutes, reverse=True):
                ys = [(_cell(cells, s, mins, m) or {}).get(q, {}).get("nrmse", np.nan) for s in snrs]
                if np.all(~np.isfinite(ys)):
                    continue
                ax.plot(snrs, ys, marker="o", color=_COLORS[m], ls="-" if mins == max(cfg.minutes) else "--",
                        label=f"{METHOD_LABELS[m]}, {mins:g} min")
                drawn = True
        ax.set_xlabel("SNR [dB]")
        ax.set_ylabel("NRMSE [pu]")
        ax.set_title(f"{title}; truth {tr.scalar(q):.4g}")
        ax.set_yscale("log")
        ax.invert_xaxis()
        ax.grid(True, which="both", alpha=0.3)
        if drawn:
            ax.legend(fontsize=8)
        save(fig, name)

    # Figs. 9, 10: NRMSE(Ω) of G_p vs period, Z_cu vs sine test, per length
    for mins in sorted(cfg.minutes, reverse=True):
        fig, ax = plt.subplots(figsize=(6, 4))
        drawn = False
        for m in ("zcu", "zur", "sine"):
            if m not in cfg.methods or (m == "zur" and "zcu" in cfg.methods):
                continue
            for s in snrs:
                c = _cell(cells, s, mins, m)
                if c is None or "gp" not in c:
                    continue
                ax.plot(c["gp"]["periods_s"], c["gp"]["nrmse"], marker="o", color=_COLORS[m],
                        ls=_STYLES.get(s, "-."), label=f"{METHOD_LABELS[m]}, {s:g} dB")
                drawn = True
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("period [s]")
        ax.set_ylabel("NRMSE(Ω) of G_p (eq. 36)")
        ax.set_title(f"G_p at the Table 1 periods, {mins:g} min datasets")
        ax.grid(True, which="both", alpha=0.3)
        if drawn:
            ax.legend(fontsize=8)
        tag = "fig9" if mins == max(cfg.minutes) else "fig10"
        save(fig, f"{tag}_nrmse_gp_{mins:g}min.png")

    # Figs. 4-6: mean |G| over the runs vs the truth (longest datasets)
    mins = max(cfg.minutes)
    ms = [m for m in cfg.methods if m != "sine"]
    for stat, fname in (("", "fig4-6_mean_responses.png"), ("_median", "fig4-6_median_responses.png")):
        if not ms:
            break
        fig, axes = plt.subplots(1, 3, figsize=(13, 4))
        for ax, g in zip(axes, ("G_1", "S", "G_p")):
            ax.loglog(tr.grid, np.abs(tr.responses[g]), "k-", lw=2, label="analytic")
            for m in ms:
                for s in snrs:
                    mr = res.mean_responses.get((s, mins, m), {}).get(g + stat)
                    if mr is None or not np.any(np.isfinite(mr)):
                        continue
                    ax.loglog(tr.grid, mr, color=_COLORS[m], ls=_STYLES.get(s, "-."),
                              label=f"{METHOD_LABELS[m]}, {s:g} dB")
            if g == "G_p" and "sine" in cfg.methods and not stat:
                for s in snrs:
                    c = _cell(cells, s, mins, "sine")
                    if c and "gp" in c:
                        w = 2 * np.pi / np.array(c["gp"]["periods_s"])
                        mag = np.abs(tr.gp) * (1 + np.array(c["gp"]["rel_bias_abs"]))
                        ax.loglog(w, mag, ls="none", marker="x", color=_COLORS["sine"],
                                  label=f"sine test, {s:g} dB")
            ax.set_title(f"{'median' if stat else 'mean'} |{g}| over the runs, {mins:g} min")
            ax.set_xlabel("ω [rad/s]")
            ax.grid(True, which="both", alpha=0.3)
        axes[0].legend(fontsize=7)
        save(fig, fname)
    return paths


# ---------------------------------------------------------------------------------------------------
# The study


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
