"""Closed-loop simulator of the paper's test system (Fig. 1 and 3): the studied hydro unit with its
digital PI governor in a two-machine grid with a stochastic load.

Signals (all at the controller rate Tc, per unit on unit 1's machine base unless noted):

- ``y[n]``: the governor's speed signal, i.e. the anti-aliased (Tf) rotor speed deviation sampled at
  t_n PLUS the process noise v[n] [pu]. The process noise is added to the speed signal fed to the
  governor (as in the author's Simulink), and the logged y is what the governor sees, so that
  ``epsilon = r − y`` is exactly the governor's input error (the paper's ε, Section 4.2.1) and carries
  v as in the paper's model ε = G_1 u + S r + v. ``omega`` is the true rotor speed deviation, ``v`` the
  process noise.
- ``r[n]`` excitation [pu] added to the reference; ``epsilon[n] = r[n] − y[n]``.
- ``c[n]`` gate demand and ``a[n]`` gate position, ABSOLUTE [pu of full opening]; deviations are
  ``c − g0``, ``a − g0``.
- ``u[n]``: electrical power deviation ΔPe1 [pu machine base] through the same anti-aliasing filter as
  the speed (paper Section 2: "obtained in a similar manner"), plus optional meter noise. With the
  filter on both, ε/u is the paper's G_1 = G_J S (:mod:`fcrlive.plant.transfer`).
- ``pe_mw = (Pm0 + u)·rated`` [MW]; ``pm`` unit 1's mechanical power [pu, absolute].
- ``grid_freq_hz``: the centre-of-inertia frequency f0 (1 + ω_coi) [Hz] plus optional meter noise.
- ``load_pu``: the load change at bus 5 [pu system base]: the random walk plus ``SimConfig.load_pu``.

Noise: the load is integrated white noise, sized by default so that 3σ of the grid frequency after
1800 s is 0.1 Hz (:func:`fcrlive.sim.linear.load_noise_std`); the process noise is white at Tc, sized
for the requested SNR (paper Section 7.1) from the linear model over a 1800 s window
(:func:`fcrlive.sim.linear.process_noise_std`). Every realisation draws from four independent streams
(load, process, power meter, frequency meter) of ``seed``; the excitation from its own
``excitation_seed`` ("generated once").

Models: ``"nonlinear"`` (nonlinear turbines and limiters; exponential integrator, exact for the linear
part: :mod:`fcrlive.sim.nonlinear`) and ``"linear"`` (the same discretisation without the
nonlinearity: :mod:`fcrlive.sim.linear`). Both start in steady state at Pm0.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from fcrlive.blas import single_threaded
from fcrlive.constants import PAPER_EXCITATION_STD_PU, TSO_STATIONARY_PERIODS
from fcrlive.errors import ConfigError
from fcrlive.plant.params import Plant
from fcrlive.sim import linear as _lin
from fcrlive.sim import nonlinear as _nl

__all__ = [
    "BatchSimResult",
    "SimConfig",
    "SimResult",
    "SineTestResult",
    "simulate",
    "simulate_batch",
    "sine_test",
]

SIGNALS = ("t", "y", "u", "c", "a", "r", "epsilon", "grid_freq_hz", "pe_mw", "pm", "omega", "v", "load_pu")
"""The per-sample fields of :class:`SimResult` (and of :class:`BatchSimResult`, per run)."""


@dataclass(frozen=True)
class SimConfig:
    """What to simulate. Units: s, pu (machine base of unit 1 unless noted), Hz."""

    duration_s: float = 1800.0
    snr_db: float | None = 12.0
    """Process noise sized for this SNR (paper 7.1: var u from load and r over var u from process noise);
    None: ``process_noise_std`` is used as given."""
    process_noise_std: float = 0.0
    """Std of the white process noise on the governor's speed signal [pu] (when ``snr_db`` is None)."""
    load_noise_std: float | None = None
    """Random-walk load intensity [pu system base / sqrt(s)]; None: sized for ±0.1 Hz (3σ at 1800 s)."""
    excitation: bool = False
    """Add the paper's white-noise excitation r[n] of std ``excitation_std``."""
    excitation_std: float = PAPER_EXCITATION_STD_PU
    excitation_seed: int = 12345
    r: np.ndarray | None = field(default=None, compare=False)
    """Explicit excitation r[n] [pu] (at least N samples); overrides ``excitation``."""
    meas_noise_power: float = 0.0
    """Std of the power meter noise as a fraction of rated power (0.01 = 1 %)."""
    meas_noise_freq_hz: float = 0.0
    """Std of the grid frequency meter noise [Hz]."""
    seed: int = 0
    model: Literal["nonlinear", "linear"] = "nonlinear"
    load_pu: np.ndarray | None = field(default=None, compare=False)
    """Deterministic load change at bus 5 [pu system base] at each sample (N or N + 1 values; linear in
    between), added to the stochastic load. For lock-in and step tests."""
    applied_freq_hz: np.ndarray | None = field(default=None, compare=False)
    """Open-loop (industry test) mode: this applied frequency [Hz] (N samples) replaces the governor's
    speed feedback; the unit stays connected to the grid."""
    integrator: Literal["exp", "rk4"] = "exp"
    """Nonlinear model's integrator (:mod:`fcrlive.sim.nonlinear`); "rk4" is a cross-check."""


@dataclass(frozen=True)
class _Meta:
    plant: Plant
    Tc: float
    f0: float
    rated_mw: float
    p0_mw: float
    g0: float
    snr_db: float | None
    process_noise_std: float
    load_noise_std: float
    model: str


@dataclass(frozen=True, eq=False)
class SimResult:
    """One realisation; every signal a 1-D array of length N at Tc (module docstring for meanings)."""

    t: np.ndarray
    y: np.ndarray
    u: np.ndarray
    c: np.ndarray
    a: np.ndarray
    r: np.ndarray
    epsilon: np.ndarray
    grid_freq_hz: np.ndarray
    pe_mw: np.ndarray
    pm: np.ndarray
    omega: np.ndarray
    v: np.ndarray
    load_pu: np.ndarray
    plant: Plant
    Tc: float
    f0: float
    rated_mw: float
    p0_mw: float
    g0: float
    snr_db: float | None
    process_noise_std: float
    load_noise_std: float
    seed: int
    model: str

    @property
    def n(self) -> int:
        return len(self.t)


@dataclass(frozen=True, eq=False)
class BatchSimResult:
    """Realisations of ``seeds``: the fields of :class:`SimResult` as (n_runs, N) arrays (``t`` and the
    shared ``r`` are read-only broadcast views). Fields not requested with ``fields=`` are None."""

    t: np.ndarray
    y: np.ndarray | None
    u: np.ndarray | None
    c: np.ndarray | None
    a: np.ndarray | None
    r: np.ndarray
    epsilon: np.ndarray | None
    grid_freq_hz: np.ndarray | None
    pe_mw: np.ndarray | None
    pm: np.ndarray | None
    omega: np.ndarray | None
    v: np.ndarray | None
    load_pu: np.ndarray | None
    plant: Plant
    Tc: float
    f0: float
    rated_mw: float
    p0_mw: float
    g0: float
    snr_db: float | None
    process_noise_std: float
    load_noise_std: float
    seeds: tuple[int, ...]
    model: str

    @property
    def n_runs(self) -> int:
        return len(self.seeds)

    def run(self, i: int) -> SimResult:
        """Realisation i as a :class:`SimResult` (views; unrequested fields become NaN arrays)."""
        nan = np.full(self.t.shape[1], np.nan)
        sig = {}
        for name in SIGNALS:
            a = getattr(self, name)
            sig[name] = nan if a is None else a[i]
        return SimResult(**sig, **_meta_kwargs(self), seed=self.seeds[i])


def _meta_kwargs(obj) -> dict:
    return {k: getattr(obj, k) for k in _Meta.__dataclass_fields__}


# ---------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Prepared:
    N: int
    r: np.ndarray
    app: np.ndarray | None
    load_det: np.ndarray | None
    sigma_l: float
    sigma_v: float
    meta: _Meta


def _prepare(plant: Plant, config: SimConfig) -> _Prepared:
    Tc = plant.unit.governor.Tc
    if not config.duration_s > 0 or not math.isfinite(config.duration_s):
        raise ConfigError(f"duration_s must be positive, got {config.duration_s}")
    N = max(2, round(config.duration_s / Tc))
    if config.model not in ("nonlinear", "linear"):
        raise ConfigError(f"model must be 'nonlinear' or 'linear', got {config.model!r}")
    for name in ("meas_noise_power", "meas_noise_freq_hz", "process_noise_std", "excitation_std"):
        if not getattr(config, name) >= 0:
            raise ConfigError(f"{name} must be >= 0, got {getattr(config, name)}")

    def _arr(a, name: str, need: int) -> np.ndarray:
        a = np.asarray(a, dtype=float)
        if a.ndim != 1 or len(a) < need or not np.all(np.isfinite(a[:need])):
            raise ConfigError(f"{name} must be a finite 1-D array of at least {need} samples")
        return a

    if config.r is not None:
        r = _arr(config.r, "r", N)[:N].copy()
        r_std, r_arr = 0.0, r
    elif config.excitation:
        r = config.excitation_std * np.random.default_rng(config.excitation_seed).standard_normal(N)
        r_std, r_arr = config.excitation_std, None
    else:
        r = np.zeros(N)
        r_std, r_arr = 0.0, None
    app = None
    if config.applied_freq_hz is not None:
        app = _arr(config.applied_freq_hz, "applied_freq_hz", N)[:N] / plant.grid.f0 - 1.0
    load_det = None
    if config.load_pu is not None:
        ld = _arr(config.load_pu, "load_pu", N)
        load_det = ld[:N + 1] if len(ld) > N else np.append(ld[:N], ld[N - 1])
    sigma_l = _lin.load_noise_std(plant) if config.load_noise_std is None else float(config.load_noise_std)
    if not sigma_l >= 0:
        raise ConfigError(f"load_noise_std must be >= 0, got {sigma_l}")
    if config.snr_db is None:
        sigma_v = float(config.process_noise_std)
    else:
        try:
            sigma_v = _lin.process_noise_std(plant, float(config.snr_db), sigma_l, r_std=r_std, r=r_arr)
        except ValueError as exc:
            raise ConfigError(f"snr_db: {exc}") from None
    unit = plant.unit
    from fcrlive.sim import model as _mdl

    m = _mdl.build(plant)
    meta = _Meta(
        plant=plant,
        Tc=Tc,
        f0=plant.grid.f0,
        rated_mw=unit.rated_mw,
        p0_mw=m.tp1.Pm0 * unit.rated_mw,
        g0=m.tp1.g0,
        snr_db=config.snr_db,
        process_noise_std=sigma_v,
        load_noise_std=sigma_l,
        model=config.model,
    )
    return _Prepared(N=N, r=r, app=app, load_det=load_det, sigma_l=sigma_l, sigma_v=sigma_v, meta=meta)


def _single_inputs(prep: _Prepared, seed: int) -> tuple[_nl.Inputs, list[np.random.Generator]]:
    N, Tc = prep.N, prep.meta.Tc
    gens = _nl.streams(seed)
    pl = np.zeros(N + 1)
    if prep.sigma_l > 0:
        np.cumsum(gens[_nl.LOAD].standard_normal(N) * (prep.sigma_l * math.sqrt(Tc)), out=pl[1:])
    if prep.load_det is not None:
        pl = pl + prep.load_det
    v = gens[_nl.PROCESS].standard_normal(N) * prep.sigma_v if prep.sigma_v > 0 else np.zeros(N)
    return _nl.Inputs(r=prep.r, v=v, pl=pl, app=prep.app), gens


def _finish(raw: dict, prep: _Prepared, config: SimConfig, gens_list, N: int) -> dict:
    """Measured signals from the raw ones (meter noise, units). Arrays (..., N)."""
    meta = prep.meta
    out = {}
    u = raw.get("u")
    if u is not None:
        if config.meas_noise_power > 0:
            noise = np.stack([g[_nl.MEAS_P].standard_normal(N) for g in gens_list])
            u = u + config.meas_noise_power * noise.reshape(u.shape)
        out["u"] = u
        out["pe_mw"] = (meta.p0_mw / meta.rated_mw + u) * meta.rated_mw
    w = raw.get("w_coi")
    if w is not None:
        f = meta.f0 * (1.0 + w)
        if config.meas_noise_freq_hz > 0:
            noise = np.stack([g[_nl.MEAS_F].standard_normal(N) for g in gens_list])
            f = f + config.meas_noise_freq_hz * noise.reshape(f.shape)
        out["grid_freq_hz"] = f
    for k in ("y", "epsilon", "c", "a", "pm", "omega", "v", "load_pu"):
        if k in raw:
            out[k] = raw[k]
    return out


@single_threaded
def simulate(plant: Plant, config: SimConfig | None = None) -> SimResult:
    """One realisation of the closed loop (module docstring), from steady state at Pm0.

    A single run is solved as a waveform fixed point over the whole record (equal to stepping it, to
    about 1e-10 relative): about 0.1 s for 1800 s at Tc = 0.02 s.
    """
    config = config or SimConfig()
    prep = _prepare(plant, config)
    inp, gens = _single_inputs(prep, config.seed)
    raw = _nl.run_single(plant, inp, open_loop=prep.app is not None, nonlinear=config.model == "nonlinear",
                         integrator=config.integrator)
    raw["v"] = inp.v
    raw["load_pu"] = inp.pl[:prep.N]
    sig = _finish(raw, prep, config, [gens], prep.N)
    return SimResult(t=np.arange(prep.N) * prep.meta.Tc, r=prep.r, **sig, **_meta_kwargs(prep.meta),
                     seed=int(config.seed))


@single_threaded
def simulate_batch(plant: Plant, config: SimConfig | None = None, seeds: Sequence[int] = (0,), *,
                   fields: Sequence[str] | None = None) -> BatchSimResult:
    """Realisations for ``seeds`` stepped together (realisation i equals ``simulate`` with
    ``seed=seeds[i]`` to round-off). One shared r. ``config.seed`` is ignored.

    Memory: 8·N bytes per run per field (1000 runs of 1800 s at 0.02 s: 720 MB per field); ``fields``
    restricts which of :data:`SIGNALS` are kept (``t`` and ``r`` always are).
    """
    config = config or SimConfig()
    seeds = tuple(int(s) for s in seeds)
    if not seeds:
        raise ConfigError("simulate_batch needs at least one seed")
    wanted = set(SIGNALS) if fields is None else set(fields)
    unknown = wanted - set(SIGNALS)
    if unknown:
        raise ConfigError(f"unknown fields {sorted(unknown)}; known: {', '.join(SIGNALS)}")
    prep = _prepare(plant, config)
    raw_fields = set()
    for k in wanted:
        raw_fields |= {"pe_mw": {"u"}, "grid_freq_hz": {"w_coi"}, "t": set(), "r": set(),
                       "load_pu": {"load"}}.get(k, {k})
    kw = dict(r=prep.r, app=prep.app, sigma_l=prep.sigma_l, sigma_v=prep.sigma_v, load_det=prep.load_det,
              fields=sorted(raw_fields), open_loop=prep.app is not None)
    if config.model == "linear":
        raw = _nl.run_batch_linear(plant, prep.N, seeds, **kw)
    else:
        raw = _nl.run_batch(plant, prep.N, seeds, integrator=config.integrator, **kw)
    raw = {k: v.T for k, v in raw.items()}  # (R, N) views of the time-major arrays
    if "load" in raw:
        raw["load_pu"] = raw.pop("load")
    gens = [_nl.streams(s) for s in seeds] if (config.meas_noise_power or config.meas_noise_freq_hz) else []
    sig = _finish(raw, prep, config, gens, prep.N)
    R = len(seeds)
    out = {k: (sig.get(k) if k in wanted else None) for k in SIGNALS if k not in ("t", "r")}
    t = np.broadcast_to(np.arange(prep.N) * prep.meta.Tc, (R, prep.N))
    r = np.broadcast_to(prep.r, (R, prep.N))
    return BatchSimResult(t=t, r=r, **out, **_meta_kwargs(prep.meta), seeds=seeds)


# ---------------------------------------------------------------------------------------------------
# The industry open-loop sine test


@dataclass(frozen=True, eq=False)
class SineTestResult:
    """One open-loop sine test (paper Section 4.1; TSO Test Program): the governor's speed feedback is
    replaced by ``applied_freq_hz`` = f0 + A sin(2π t/T) from t = 0; the unit stays on the grid.

    Signals as in :class:`SimResult` (``epsilon = r − (applied − f0)/f0 − v`` is the governor's input
    error). ``settle_s`` of settling precede ``n_periods`` stationary periods starting at sample
    ``stationary_start``.
    """

    period_s: float
    amplitude_hz: float
    t: np.ndarray
    applied_freq_hz: np.ndarray
    grid_freq_hz: np.ndarray
    pe_mw: np.ndarray
    u: np.ndarray
    c: np.ndarray
    a: np.ndarray
    epsilon: np.ndarray
    y: np.ndarray
    pm: np.ndarray
    settle_s: float
    n_periods: int
    stationary_start: int
    plant: Plant
    Tc: float
    f0: float
    rated_mw: float
    p0_mw: float
    g0: float

    @property
    def stationary(self) -> slice:
        """The stationary periods' samples."""
        return slice(self.stationary_start, None)


def settle_time(plant: Plant, period_s: float, n_tau: float = 5.0) -> float:
    """Settling time [s] before the stationary periods: whole periods covering ``n_tau`` times the
    slowest time constant of the open-loop test set-up (:func:`fcrlive.sim.linear.slowest_time_constant`;
    about 114 s for the paper's plant 1 with the droop in the integral channel), at least one period."""
    tau = _lin.slowest_time_constant(plant, open_loop=True)
    k = max(1, math.ceil(n_tau * tau / period_s - 1e-9))
    return k * period_s


def sine_test(plant: Plant, period_s: float, amplitude_hz: float = 0.1, n_periods: int | None = None,
              config: SimConfig | None = None, *, settle_s: float | None = None) -> SineTestResult:
    """Simulate one industry sine test (see :class:`SineTestResult`).

    ``n_periods`` defaults to the TSO count (5 up to 90 s, 3 at 150 s, 2 at 300 s); ``settle_s`` to
    :func:`settle_time` (whole periods ≥ 5 slowest time constants). ``config`` supplies the noise
    (default: the grid's load noise, no process noise) and seed; its duration, r and applied signal are
    ignored. Process noise, if any, is added to the applied signal the governor sees.
    """
    if not period_s > 0:
        raise ConfigError(f"period_s must be positive, got {period_s}")
    config = config or SimConfig(snr_db=None)
    if n_periods is None:
        n_periods = TSO_STATIONARY_PERIODS.get(float(period_s), 5 if period_s <= 90 else 3 if period_s <= 150
                                               else 2)
    if settle_s is None:
        settle_s = settle_time(plant, period_s)
    Tc = plant.unit.governor.Tc
    duration = settle_s + n_periods * period_s
    N = round(duration / Tc)
    t = np.arange(N) * Tc
    f0 = plant.grid.f0
    applied = f0 + amplitude_hz * np.sin(2.0 * math.pi * t / period_s)
    from dataclasses import replace

    cfg = replace(config, duration_s=N * Tc, applied_freq_hz=applied, r=None, excitation=False)
    res = simulate(plant, cfg)
    return SineTestResult(
        period_s=float(period_s),
        amplitude_hz=float(amplitude_hz),
        t=res.t,
        applied_freq_hz=applied,
        grid_freq_hz=res.grid_freq_hz,
        pe_mw=res.pe_mw,
        u=res.u,
        c=res.c,
        a=res.a,
        epsilon=res.epsilon,
        y=res.y,
        pm=res.pm,
        settle_s=float(settle_s),
        n_periods=int(n_periods),
        stationary_start=round(settle_s / Tc),
        plant=plant,
        Tc=Tc,
        f0=f0,
        rated_mw=res.rated_mw,
        p0_mw=res.p0_mw,
        g0=res.g0,
    )
