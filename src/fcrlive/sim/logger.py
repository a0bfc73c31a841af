"""A measurement chain between the governor and a TSO log: what a real logger does to the signals.

:func:`log` is pure: it takes a simulated controller-rate record (:class:`fcrlive.sim.SimResult`) and a
:class:`Logger` and returns the TSO log (:class:`fcrlive.tso.csvlog.TsoLog`) such a logger writes;
:func:`signals` returns the :class:`fcrlive.tso.signals.PlantSignals` an identification reads from it.
Everything random comes from ``seed`` (independent of the simulation's own streams).

What a logger does, in this order:

0. **Power transducer dynamics** (``power_lag_s``, ``power_delay_s``): the power the meter reports is the
   generator's electrical power through a first-order lag (a transducer's response; IEC 60688 transducers
   answer within 0.1-0.4 s) and a dead time (a meter's averaging window, or a power column stamped by
   another device than the frequency columns), applied at the controller rate. Only InsAcPow: the
   frequency columns and the governor's own columns come from the governor.
1. **Power meter noise** (``meter_noise_pct``, % of rated power, white). ``noise_at="log"`` (default):
   on each logged InsAcPow value, so the whole variance lands below the log's Nyquist frequency (the
   harsh case for a slow log, and what a column of a real log shows); ``"meter"``: white at the
   controller rate before the logger (a transducer read by the governor), which a block average then
   averages down by √n.
2. **Frequency meter** noise (``freq_noise_mhz``, white, std in mHz) and resolution
   (``freq_resolution_mhz``: GridFreq quantised to this step, e.g. 1 mHz or 10 mHz).
3. **Sampling**: instantaneous samples every ``every``-th controller sample (1, 2, 5, 10: the
   controller rate and 1/2, 1/5, 1/10 of it), the values taken at the instants t_n + δ_n with
   ``jitter_ms`` timestamp jitter (δ uniform in ±jitter, values linear between controller samples,
   timestamps written as the nominal t_n); or **block averages** over ``block_s`` (a historian's 1 s
   means of the controller-rate samples, stamped at the block start).
4. **Column rounding** as real TSO logs have it (:data:`COLUMN_DECIMALS`: GridFreq 3 decimals [Hz],
   ApplFreqSig 6, InsAcPow 3 [MW], ContOutSig/GuideVane 3 [%]); ``round_columns=False`` keeps full
   precision.

Columns (``columns``): ``"tso"`` is what a TSO normal-operation log carries: GridFreq, ApplFreqSig,
InsAcPow. ``"governor"`` adds ContOutSig and GuideVane (a log taken from the governor's own controller,
as Z_cu needs). ApplFreqSig is always written: in normal operation it equals the governor's frequency
(f0 (1 + y)) at the governor's 6-decimal precision while GridFreq carries the meter's resolution, as on a
real log; with an excitation it is f0 (1 + y − r). GridFreq is the governor's speed signal f0 (1 + y)
(as :func:`fcrlive.tso.signals.log_from_sim`), through the frequency meter of step 2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from datetime import datetime
from typing import Literal

import numpy as np

from fcrlive.errors import ConfigError
from fcrlive.signals import PlantSignals, transducer
from fcrlive.tso.csvlog import TsoLog
from fcrlive.tso.signals import DEFAULT_START, plant_signals

COLUMN_DECIMALS: dict[str, int] = {
    "GridFreq": 3,
    "ApplFreqSig": 6,
    "InsAcPow": 3,
    "ContOutSig": 3,
    "GuideVane": 3,
}
"""Decimals of each column in a real TSO log (and in the files ``fcrlive simulate --logger`` writes)."""

Columns = Literal["tso", "governor"]
NoiseAt = Literal["log", "meter"]


@dataclass(frozen=True)
class Logger:
    """One measurement chain (module docstring). Units: %, mHz, ms, s."""

    name: str = "ideal"
    every: int = 1
    """Instantaneous samples: keep every ``every``-th controller sample (1 = the controller rate)."""
    block_s: float | None = None
    """Block averages over this many seconds (a historian); None for instantaneous samples."""
    meter_noise_pct: float = 0.0
    """Std of the white power meter noise [% of rated power]."""
    noise_at: NoiseAt = "log"
    """Where the power meter noise enters: on each logged value, or at the controller rate (docstring)."""
    freq_resolution_mhz: float = 0.0
    """GridFreq quantisation step [mHz]; 0: none beyond the column rounding."""
    freq_noise_mhz: float = 0.0
    """Std of white frequency meter noise on GridFreq [mHz]."""
    jitter_ms: float = 0.0
    """Sampling-instant jitter, uniform in ±jitter_ms [ms] (instantaneous samples only)."""
    power_lag_s: float = 0.0
    """Time constant of the power transducer's first-order lag [s]; 0: none."""
    power_delay_s: float = 0.0
    """Dead time of the power measurement [s], rounded to whole controller samples; 0: none."""
    columns: Columns = "tso"
    round_columns: bool = True
    description: str = ""

    def check(self) -> None:
        """Raise ConfigError naming the bad field."""
        if self.block_s is not None and not (self.block_s > 0 and math.isfinite(self.block_s)):
            raise ConfigError(f"logger {self.name}: block_s must be positive, got {self.block_s}")
        if not (isinstance(self.every, int) and self.every >= 1):
            raise ConfigError(f"logger {self.name}: every must be a whole number >= 1, got {self.every}")
        if self.block_s is not None and self.every != 1:
            raise ConfigError(f"logger {self.name}: block averages and every > 1 exclude each other")
        if self.block_s is not None and self.jitter_ms:
            raise ConfigError(f"logger {self.name}: jitter applies to instantaneous samples only")
        for f in ("meter_noise_pct", "freq_resolution_mhz", "freq_noise_mhz", "jitter_ms", "power_lag_s",
                  "power_delay_s"):
            v = getattr(self, f)
            if not (v >= 0 and math.isfinite(v)):
                raise ConfigError(f"logger {self.name}: {f} must be >= 0, got {v}")
        if self.noise_at not in ("log", "meter"):
            raise ConfigError(f"logger {self.name}: noise_at must be 'log' or 'meter', "
                              f"got {self.noise_at!r}")
        if self.columns not in ("tso", "governor"):
            raise ConfigError(f"logger {self.name}: columns must be 'tso' or 'governor', "
                              f"got {self.columns!r}")

    def sample_s(self, Tc: float) -> float:
        """The log's sample interval [s] for a controller at Tc [s]."""
        return float(self.block_s) if self.block_s is not None else self.every * Tc

    def summary(self, Tc: float | None = None) -> str:
        """One line: rate, sampling, noise, resolution, jitter, columns."""
        if self.block_s is not None:
            how = f"{self.block_s:g} s block averages"
        elif Tc is not None:
            how = f"instantaneous at {1.0 / (self.every * Tc):g} Hz (1/{self.every} of the controller rate)"
        else:
            how = ("instantaneous at the controller rate" if self.every == 1
                   else f"instantaneous, 1/{self.every} of the controller rate")
        parts = [how, f"power noise {self.meter_noise_pct:g} % of rated ({self.noise_at})"]
        if self.power_lag_s or self.power_delay_s:
            parts.append(f"power transducer lag {self.power_lag_s:g} s, dead time {self.power_delay_s:g} s")
        if self.freq_resolution_mhz:
            parts.append(f"frequency resolution {self.freq_resolution_mhz:g} mHz")
        if self.freq_noise_mhz:
            parts.append(f"frequency noise {self.freq_noise_mhz:g} mHz")
        if self.jitter_ms:
            parts.append(f"jitter ±{self.jitter_ms:g} ms")
        parts.append("columns " + ("GridFreq/ApplFreqSig/InsAcPow" if self.columns == "tso"
                                   else "GridFreq/ApplFreqSig/InsAcPow/ContOutSig/GuideVane"))
        return ", ".join(parts)


def _rng(seed: int) -> list[np.random.Generator]:
    # Own streams, keyed apart from the simulator's (which spawns from SeedSequence(seed)).
    return [np.random.default_rng(s) for s in np.random.SeedSequence([int(seed), 0x10663E]).spawn(4)]


def _block_mean(x: np.ndarray, n: int) -> np.ndarray:
    m = len(x) // n
    return x[: m * n].reshape(m, n).mean(axis=1)


def log(result, logger: Logger, *, seed: int = 0, start: datetime = DEFAULT_START) -> TsoLog:
    """The TSO log ``logger`` writes of the controller-rate record ``result`` (a SimResult or anything
    with ``t, y, r, pe_mw, c, a, f0, rated_mw, Tc``). Pure; deterministic in ``seed``."""
    logger.check()
    Tc = float(result.Tc)
    f0 = float(result.f0)
    rated = float(result.rated_mw)
    t = np.asarray(result.t, dtype=float)
    N = len(t)
    g_pow, g_freq, g_jit, _ = _rng(seed)
    p = transducer(np.asarray(result.pe_mw, dtype=float), Tc, logger.power_lag_s, logger.power_delay_s)
    noise_std_mw = logger.meter_noise_pct / 100.0 * rated
    if noise_std_mw > 0 and logger.noise_at == "meter":
        p += noise_std_mw * g_pow.standard_normal(N)
    y = np.asarray(result.y, dtype=float)
    r = np.asarray(result.r, dtype=float)
    sig = {
        "GridFreq": f0 * (1.0 + y),
        "ApplFreqSig": f0 * (1.0 + y - r),
        "InsAcPow": p,
    }
    if logger.columns == "governor":
        sig["ContOutSig"] = 100.0 * np.asarray(result.c, dtype=float)
        sig["GuideVane"] = 100.0 * np.asarray(result.a, dtype=float)
    if logger.block_s is not None:
        n = round(logger.block_s / Tc)
        if n < 1 or abs(n * Tc - logger.block_s) > 1e-6 * logger.block_s:
            raise ConfigError(f"logger {logger.name}: block {logger.block_s:g} s is not a whole number of "
                              f"controller samples ({Tc:g} s)")
        if 2 * n > N:
            raise ConfigError(f"logger {logger.name}: the record is shorter than two blocks")
        cols = {k: _block_mean(v, n) for k, v in sig.items()}
        t_log = t[: len(cols["InsAcPow"]) * n : n]
    else:
        k = logger.every
        idx = np.arange(0, N, k)
        if len(idx) < 2:
            raise ConfigError(f"logger {logger.name}: fewer than two samples")
        t_log = t[idx]
        if logger.jitter_ms > 0:
            tj = t_log + g_jit.uniform(-1.0, 1.0, len(idx)) * logger.jitter_ms * 1e-3
            tj = np.clip(tj, t[0], t[-1])
            # Every column linear between the controller's samples: a sample taken δ late mixes δ/Tc
            # of the next one in (a held signal would instead jump a whole sample for any δ < 0).
            cols = {name: np.interp(tj, t, v) for name, v in sig.items()}
        else:
            cols = {name: v[idx] for name, v in sig.items()}
    n_log = len(t_log)
    if noise_std_mw > 0 and logger.noise_at == "log":
        cols["InsAcPow"] = cols["InsAcPow"] + noise_std_mw * g_pow.standard_normal(n_log)
    if logger.freq_noise_mhz > 0:
        cols["GridFreq"] = cols["GridFreq"] + logger.freq_noise_mhz * 1e-3 * g_freq.standard_normal(n_log)
    if logger.freq_resolution_mhz > 0:
        q = logger.freq_resolution_mhz * 1e-3
        cols["GridFreq"] = np.round(cols["GridFreq"] / q) * q
    if logger.round_columns:
        cols = {k: np.round(v, COLUMN_DECIMALS[k]) for k, v in cols.items()}
    return TsoLog.from_arrays(t_log, cols, start)


def signals(result, logger: Logger, *, seed: int = 0, start: datetime = DEFAULT_START,
            p0_mw: float | None = None) -> PlantSignals:
    """:func:`log` read back as the identification's :class:`PlantSignals` (rated power from ``result``)."""
    lg = log(result, logger, seed=seed, start=start)
    ps = plant_signals(lg, float(result.rated_mw), f0=float(result.f0), p0_mw=p0_mw)
    return replace(ps, sources=(f"zoo logger {logger.name}",))
