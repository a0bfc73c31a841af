"""Seeded excitation generators for r[n]: white noise, PRBS, multisine over the TSO periods, single sine.

Every generator produces r[n] in Hz (added to the governor's frequency reference; ``next_block_pu`` gives
pu of f0) and guarantees |r[n]| ≤ ``amplitude_hz`` ≤ 0.1 Hz for every sample. Each is

- deterministic under its seed and parameters;
- streamable: ``next_block(n)`` continues where the previous block ended, and the samples do not depend on
  how the stream is cut into blocks;
- replayable: ``state`` (a small JSON-able dict) can be stored and given back to ``restore``; ``seek(i)``
  jumps to sample i; ``description`` (kind, seed, all parameters) rebuilds the same generator through
  :func:`make_generator`, so the r[n] that was written can be reproduced for the identification.

What is written is the guard's output, not the generator's: the writer should log both (the guard may
clamp, rate-limit or zero samples), and the identification should use the logged, written r[n].
"""

from __future__ import annotations

import math
import numbers
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from scipy.optimize import minimize
from scipy.special import ndtr, ndtri

from fcrlive.constants import F0_HZ, PAPER_EXCITATION_STD_PU, TSO_PERIODS_S
from fcrlive.errors import ConfigError
from fcrlive.excitation.guard import SAFE_MAX_AMPLITUDE_HZ

DESCRIPTION_VERSION = 1

PRBS_TAPS: dict[int, tuple[int, ...]] = {
    # Exponents of primitive feedback polynomials x^n + ... + 1 (maximum-length Fibonacci LFSRs).
    3: (3, 2), 4: (4, 3), 5: (5, 3), 6: (6, 5), 7: (7, 6), 8: (8, 6, 5, 4), 9: (9, 5), 10: (10, 7),
    11: (11, 9), 12: (12, 11, 10, 4), 13: (13, 12, 11, 8), 14: (14, 13, 12, 2), 15: (15, 14),
    16: (16, 15, 13, 4), 17: (17, 14), 18: (18, 11), 19: (19, 18, 17, 14), 20: (20, 17),
}
"""Primitive polynomials by LFSR order (the tests check primitivity); PRBS period 2^n − 1 clock periods."""


def hz_to_pu(values_hz: Any, f0_hz: float = F0_HZ) -> Any:
    """Frequency deviation [Hz] → pu of f0."""
    return np.asarray(values_hz, dtype=float) / f0_hz


def pu_to_hz(values_pu: Any, f0_hz: float = F0_HZ) -> Any:
    """Frequency deviation [pu of f0] → Hz."""
    return np.asarray(values_pu, dtype=float) * f0_hz


def _err(name: str, message: str) -> ConfigError:
    err = ConfigError(f"excitation generator: {message}")
    err.field = name  # type: ignore[attr-defined]
    return err


def _check_real(name: str, value: Any, low: float, high: float, low_inclusive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)):
        raise _err(name, f"{name} = {value!r} is not a finite number")
    v = float(value)
    if v < low or (v == low and not low_inclusive) or v > high:
        lo = "[" if low_inclusive else "("
        raise _err(name, f"{name} = {v!r} is outside {lo}{low!r}, {high!r}]")
    return v


def _check_int(name: str, value: Any, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise _err(name, f"{name} = {value!r} is not an integer")
    v = int(value)
    if not low <= v <= high:
        raise _err(name, f"{name} = {v!r} is outside [{low}, {high}]")
    return v


@dataclass(frozen=True)
class ExcitationDescription:
    """Everything needed to regenerate an excitation: store it with the samples.

    ``amplitude_hz`` is the guaranteed bound on |r| [Hz]; ``sample_time_s`` the sample period of r[n] [s];
    ``params`` the kind-specific parameters (JSON-able; for the multisine it includes the phases actually
    used, so a replay does not depend on the phase optimiser's floating-point path).
    """

    kind: str
    seed: int
    amplitude_hz: float
    sample_time_s: float
    params: dict[str, Any] = field(default_factory=dict)
    f0_hz: float = F0_HZ
    unit: str = "Hz"
    version: int = DESCRIPTION_VERSION

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "seed": self.seed, "amplitude_hz": self.amplitude_hz,
                "sample_time_s": self.sample_time_s, "params": dict(self.params), "f0_hz": self.f0_hz,
                "unit": self.unit, "version": self.version}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ExcitationDescription:
        try:
            return cls(kind=str(data["kind"]), seed=int(data["seed"]),
                       amplitude_hz=float(data["amplitude_hz"]),
                       sample_time_s=float(data["sample_time_s"]), params=dict(data.get("params", {})),
                       f0_hz=float(data.get("f0_hz", F0_HZ)), unit=str(data.get("unit", "Hz")),
                       version=int(data.get("version", DESCRIPTION_VERSION)))
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"excitation description is incomplete or malformed: {exc!r}") from exc


class ExcitationGenerator(ABC):
    """Base class: a seeded, streamable, replayable r[n] source bounded by ``amplitude_hz`` [Hz]."""

    kind: ClassVar[str]

    def __init__(self, amplitude_hz: float, sample_time_s: float, seed: int = 0, f0_hz: float = F0_HZ):
        self.amplitude_hz = _check_real("amplitude_hz", amplitude_hz, 0.0, SAFE_MAX_AMPLITUDE_HZ)
        self.sample_time_s = _check_real("sample_time_s", sample_time_s, 0.0, 10.0)
        self.seed = _check_int("seed", seed, 0, 2**63 - 1)
        self.f0_hz = _check_real("f0_hz", f0_hz, 40.0, 70.0, low_inclusive=True)
        self.index = 0
        """Index of the next sample (samples produced so far)."""

    @abstractmethod
    def _samples(self, start: int, n: int) -> np.ndarray:
        """Samples start … start+n−1 [Hz], unclipped; may update internal stream state."""

    @abstractmethod
    def params(self) -> dict[str, Any]:
        """Kind-specific parameters (JSON-able)."""

    def next_block(self, n: int) -> np.ndarray:
        """The next ``n`` samples of r [Hz], each within ±amplitude_hz."""
        n = _check_int("n", n, 0, 2**40)
        x = self._samples(self.index, n)
        self.index += n
        # Every generator is bounded by construction; the clip removes floating-point overshoot (ulps).
        return np.clip(np.asarray(x, dtype=float), -self.amplitude_hz, self.amplitude_hz)

    def next_block_pu(self, n: int) -> np.ndarray:
        """The next ``n`` samples in pu of f0."""
        return hz_to_pu(self.next_block(n), self.f0_hz)

    def seek(self, index: int) -> None:
        """Position the stream so that the next sample is sample ``index``."""
        self.index = _check_int("index", index, 0, 2**62)

    @property
    def state(self) -> dict[str, Any]:
        """Stream position (JSON-able): ``restore(state)`` continues exactly from here."""
        return {"kind": self.kind, "index": self.index}

    def restore(self, state: dict[str, Any]) -> None:
        if state.get("kind") != self.kind:
            raise ConfigError(f"cannot restore a {state.get('kind')!r} state into a {self.kind!r} generator")
        self.seek(state["index"])

    @property
    def description(self) -> ExcitationDescription:
        return ExcitationDescription(kind=self.kind, seed=self.seed, amplitude_hz=self.amplitude_hz,
                                     sample_time_s=self.sample_time_s, params=self.params(), f0_hz=self.f0_hz)


class WhiteNoiseGenerator(ExcitationGenerator):
    """Truncated Gaussian white noise, the paper's excitation (Section 7.1).

    The underlying normal has σ = amplitude/``sigma_factor`` (default 3: 0.1 Hz → σ = 0.1/3 Hz, i.e. the
    paper's 0.1/(50·3) pu) and is TRUNCATED at ±amplitude by inverse-CDF sampling (no clipping, so the
    samples stay i.i.d. and the spectrum flat). The truncation makes the actual standard deviation a little
    smaller than σ: 0.9866·σ at 3σ (``std_hz``). Each value is held for ``hold_samples`` samples.

    Random access: draw j is the j-th double of ``numpy.random.PCG64(seed)``, so any sample can be
    regenerated from (seed, index) without replaying the stream.
    """

    kind = "white"

    def __init__(self, amplitude_hz: float = SAFE_MAX_AMPLITUDE_HZ, sample_time_s: float = 0.1, seed: int = 0,
                 sigma_factor: float = 3.0, hold_samples: int = 1, f0_hz: float = F0_HZ):
        super().__init__(amplitude_hz, sample_time_s, seed, f0_hz)
        self.sigma_factor = _check_real("sigma_factor", sigma_factor, 1.0, 6.0, low_inclusive=True)
        self.hold_samples = _check_int("hold_samples", hold_samples, 1, 10**6)
        self.sigma_hz = self.amplitude_hz / self.sigma_factor
        k = self.sigma_factor
        self._p_lo = float(ndtr(-k))
        self._p_span = float(ndtr(k) - ndtr(-k))
        phi = math.exp(-k * k / 2) / math.sqrt(2 * math.pi)
        self.std_hz = self.sigma_hz * math.sqrt(1.0 - 2.0 * k * phi / self._p_span)
        """Standard deviation of the truncated distribution [Hz]."""

    @classmethod
    def paper(cls, seed: int = 0, sample_time_s: float = 0.02) -> WhiteNoiseGenerator:
        """The paper's excitation: σ = 0.1/(50·3) pu of 50 Hz, truncated at 3σ = 0.1 Hz."""
        # 3·PAPER_EXCITATION_STD_PU·F0_HZ is 0.1 Hz up to rounding, which would fail the ≤ 0.1 Hz check
        assert math.isclose(3.0 * PAPER_EXCITATION_STD_PU * F0_HZ, 0.1)
        return cls(amplitude_hz=0.1, sample_time_s=sample_time_s, seed=seed, sigma_factor=3.0)

    def _samples(self, start: int, n: int) -> np.ndarray:
        if n == 0:
            return np.zeros(0)
        j0 = start // self.hold_samples
        j1 = (start + n - 1) // self.hold_samples
        bitgen = np.random.PCG64(self.seed)
        bitgen.advance(j0)  # one 64-bit output per double
        u = np.random.Generator(bitgen).random(j1 - j0 + 1)
        z = ndtri(self._p_lo + u * self._p_span)
        draws = self.sigma_hz * z
        return draws[np.arange(start, start + n) // self.hold_samples - j0]

    def params(self) -> dict[str, Any]:
        return {"sigma_factor": self.sigma_factor, "hold_samples": self.hold_samples,
                "sigma_hz": self.sigma_hz, "std_hz": self.std_hz,
                "rng": "numpy PCG64, inverse-CDF truncation"}


class PrbsGenerator(ExcitationGenerator):
    """Maximum-length PRBS ±amplitude from a Fibonacci LFSR of ``order`` n.

    One bit per clock period of ``clock_samples`` samples; the sequence repeats every (2^n − 1) clock
    periods and holds 2^(n−1) high and 2^(n−1) − 1 low bits per period. The seed picks the starting
    register (seed mod (2^n − 1) + 1): different seeds are shifts of the same m-sequence. Its spectrum is
    flat to about 0.44/(clock_samples·Ts) Hz; choose (2^n − 1)·clock_samples·Ts ≥ the longest period to
    identify (300 s for the TSO periods).
    """

    kind = "prbs"

    def __init__(self, amplitude_hz: float = SAFE_MAX_AMPLITUDE_HZ, sample_time_s: float = 0.1, seed: int = 0,
                 order: int = 10, clock_samples: int = 1, f0_hz: float = F0_HZ):
        super().__init__(amplitude_hz, sample_time_s, seed, f0_hz)
        self.order = _check_int("order", order, min(PRBS_TAPS), max(PRBS_TAPS))
        self.clock_samples = _check_int("clock_samples", clock_samples, 1, 10**6)
        self.taps = PRBS_TAPS[self.order]
        self.period_bits = 2**self.order - 1
        self._init_register = self.seed % self.period_bits + 1
        self._register = self._init_register  # register at clock count index // clock_samples

    def _shift(self, reg: int) -> int:
        n = self.order
        fb = 0
        for t in self.taps:
            fb ^= (reg >> (n - t)) & 1
        return (reg >> 1) | (fb << (n - 1))

    def _samples(self, start: int, n: int) -> np.ndarray:
        if n == 0:
            return np.zeros(0)
        c0 = start // self.clock_samples
        c_next = (start + n) // self.clock_samples
        reg = self._register
        bits = [reg & 1]
        for _ in range(c_next - c0):
            reg = self._shift(reg)
            bits.append(reg & 1)
        self._register = reg  # the register at the clock count of the next sample
        b = np.asarray(bits, dtype=float)[np.arange(start, start + n) // self.clock_samples - c0]
        return self.amplitude_hz * (2.0 * b - 1.0)

    def seek(self, index: int) -> None:
        super().seek(index)
        reg = self._init_register
        for _ in range((self.index // self.clock_samples) % self.period_bits):  # O(period): fine to n = 20
            reg = self._shift(reg)
        self._register = reg

    @property
    def state(self) -> dict[str, Any]:
        return {**super().state, "register": self._register}

    def restore(self, state: dict[str, Any]) -> None:
        super().restore(state)
        if "register" in state:  # cheaper than seek's replay, and checked against the index by the tests
            self._register = int(state["register"])

    def params(self) -> dict[str, Any]:
        return {"order": self.order, "clock_samples": self.clock_samples, "taps": list(self.taps),
                "period_samples": self.period_bits * self.clock_samples,
                "initial_register": self._init_register}


def _schroeder_phases(K: int) -> np.ndarray:
    """Schroeder (1970) phases for K equal-amplitude components: low crest factor without iteration."""
    k = np.arange(1, K + 1)
    return -np.pi * k * (k - 1) / K


def crest_factor(x: np.ndarray) -> float:
    """max|x| / rms(x) (√2 for a sine)."""
    x = np.asarray(x, dtype=float)
    return float(np.max(np.abs(x)) / np.sqrt(np.mean(x**2)))


class MultisineGenerator(ExcitationGenerator):
    """Periodic multisine with equal-amplitude components at the TSO sine-test periods.

    One record of ``record_samples`` samples (Ts = ``sample_time_s``) repeats. Each requested period T is
    rounded to the record's DFT bin k = round(N·Ts/T), so every component is exactly periodic in the record
    (no leakage when the identification uses whole records); the realised periods N·Ts/k are reported.
    The default record of 900 s gives ≤ 4 % period rounding over 10-300 s.

    Phases: ``"schroeder"``, ``"min_crest"`` (default: Schroeder start, then an L_p-norm minimisation with
    p → 128, ``iterations`` BFGS steps per stage), or ``"random"`` (from the seed). For the ten TSO periods
    in a 900 s record the crest factor is about 2.04 (Schroeder 2.83, equal phases √20 = 4.47). The record
    is scaled so its largest sample is exactly ``amplitude_hz``; ``crest_factor`` = peak/rms of the sampled
    record.
    """

    kind = "multisine"

    def __init__(self, amplitude_hz: float = SAFE_MAX_AMPLITUDE_HZ, sample_time_s: float = 0.1, seed: int = 0,
                 periods_s: tuple[float, ...] = TSO_PERIODS_S, record_samples: int | None = None,
                 phases: str = "min_crest", iterations: int = 200,
                 phases_rad: tuple[float, ...] | None = None, f0_hz: float = F0_HZ):
        super().__init__(amplitude_hz, sample_time_s, seed, f0_hz)
        if record_samples is None:
            record_samples = round(900.0 / self.sample_time_s)
        N = self.record_samples = _check_int("record_samples", record_samples, 4, 10**7)
        if not periods_s:
            raise _err("periods_s", "periods_s is empty")
        self.periods_requested_s = tuple(_check_real("periods_s", p, 0.0, 1e6) for p in periods_s)
        if phases not in ("schroeder", "min_crest", "random"):
            raise _err("phases", f"phases = {phases!r} is not one of schroeder, min_crest, random")
        self.phase_method = phases
        self.iterations = _check_int("iterations", iterations, 0, 100_000)
        record_s = N * self.sample_time_s
        bins = [round(record_s / p) for p in self.periods_requested_s]
        for p, k in zip(self.periods_requested_s, bins):
            if k < 1 or k >= N / 2:
                raise _err("periods_s", f"periods_s: period {p!r} s does not fit a record of "
                           f"record_samples = {N} × sample_time_s = {self.sample_time_s!r} s "
                           f"(bin {k}; need 1 ≤ bin < N/2)")
        if len(set(bins)) != len(bins):
            raise _err("record_samples", f"record_samples: a record of {record_s!r} s is too short: periods "
                       f"{self.periods_requested_s} round to colliding bins {bins}")
        self.bins = tuple(int(k) for k in bins)
        self.periods_s = tuple(record_s / k for k in self.bins)
        """Realised periods [s] (requested periods rounded to the record's bins)."""
        K = len(self.bins)
        if phases_rad is not None:  # replay from a description: use the stored phases as they are
            if len(phases_rad) != K:
                raise _err("phases_rad", f"{len(phases_rad)} phases for {K} components")
            ph = np.array([_check_real("phases_rad", p, -1e9, 1e9) for p in phases_rad])
        elif phases == "random":
            ph = np.random.default_rng(self.seed).uniform(-np.pi, np.pi, K)
        else:
            ph = _schroeder_phases(K)
            if phases == "min_crest":
                ph = self._min_crest(ph)
        self.phases_rad = tuple(float(p) for p in ph)
        unit = self._synth(ph)
        peak = float(np.max(np.abs(unit)))
        self.crest_factor = crest_factor(unit)
        self.component_amplitude_hz = self.amplitude_hz / peak
        """Amplitude of each sine component [Hz]."""
        self._record = unit * self.component_amplitude_hz
        self.rms_hz = float(np.sqrt(np.mean(self._record**2)))

    def _synth(self, phases: np.ndarray) -> np.ndarray:
        """Σ cos(2π k n/N + φ_k) over one record, unit amplitude per component."""
        X = np.zeros(self.record_samples // 2 + 1, dtype=complex)
        X[list(self.bins)] = np.exp(1j * np.asarray(phases)) * (self.record_samples / 2)
        return np.fft.irfft(X, self.record_samples)

    def _min_crest(self, phases: np.ndarray) -> np.ndarray:
        # Minimise the L_p norm of the signal over the phases for p = 4 … 128 (a smooth stand-in for the
        # peak, Guillaume et al. 1991), each stage started from the previous one. The multisine is
        # band-limited to the highest bin, so the optimiser works on a grid of 8× that bin; the result is
        # kept only if it beats the start on the full record.
        if self.iterations == 0:
            return phases
        bins = np.asarray(self.bins, dtype=float)
        M = int(min(self.record_samples, max(256, 8 * int(bins.max()))))
        ang = 2 * np.pi * np.outer(bins, np.arange(M)) / M

        def objective(ph: np.ndarray, p: int) -> tuple[float, np.ndarray]:
            a = ang + ph[:, None]
            x = np.cos(a).sum(axis=0)
            xp1 = x ** (p - 1)
            s = float(np.dot(xp1, x))
            return math.log(s), -p * (np.sin(a) @ xp1) / s  # log: keeps p = 128 inside float range

        ph = np.asarray(phases, dtype=float)
        for p in (4, 8, 16, 32, 64, 128):
            ph = minimize(objective, ph, args=(p,), jac=True, method="BFGS",
                          options={"maxiter": self.iterations}).x
        ph = np.mod(ph + np.pi, 2 * np.pi) - np.pi
        return ph if crest_factor(self._synth(ph)) < crest_factor(self._synth(phases)) else phases

    def _samples(self, start: int, n: int) -> np.ndarray:
        return self._record[np.arange(start, start + n) % self.record_samples]

    def params(self) -> dict[str, Any]:
        return {"periods_requested_s": list(self.periods_requested_s), "periods_s": list(self.periods_s),
                "bins": list(self.bins), "record_samples": self.record_samples,
                "phases": self.phase_method, "iterations": self.iterations,
                "phases_rad": list(self.phases_rad),
                "crest_factor": self.crest_factor, "component_amplitude_hz": self.component_amplitude_hz,
                "rms_hz": self.rms_hz}


class SineGenerator(ExcitationGenerator):
    """A single sine amplitude·sin(2π·i·Ts/period + phase): the TSO sine test's test signal."""

    kind = "sine"

    def __init__(self, amplitude_hz: float = SAFE_MAX_AMPLITUDE_HZ, sample_time_s: float = 0.1, seed: int = 0,
                 period_s: float = 60.0, phase_rad: float = 0.0, f0_hz: float = F0_HZ):
        super().__init__(amplitude_hz, sample_time_s, seed, f0_hz)
        self.period_s = _check_real("period_s", period_s, 2.0 * self.sample_time_s, 1e6)
        self.phase_rad = _check_real("phase_rad", phase_rad, -1e6, 1e6, low_inclusive=True)

    def _samples(self, start: int, n: int) -> np.ndarray:
        i = np.arange(start, start + n, dtype=float)
        return self.amplitude_hz * np.sin(2 * np.pi * i * self.sample_time_s / self.period_s + self.phase_rad)

    def params(self) -> dict[str, Any]:
        return {"period_s": self.period_s, "phase_rad": self.phase_rad}


_KINDS: dict[str, type[ExcitationGenerator]] = {
    c.kind: c for c in (WhiteNoiseGenerator, PrbsGenerator, MultisineGenerator, SineGenerator)}

_CONSTRUCTOR_PARAMS: dict[str, tuple[str, ...]] = {
    "white": ("sigma_factor", "hold_samples"),
    "prbs": ("order", "clock_samples"),
    "multisine": ("periods_requested_s", "record_samples", "phases", "iterations", "phases_rad"),
    "sine": ("period_s", "phase_rad"),
}


def make_generator(description: ExcitationDescription | dict[str, Any]) -> ExcitationGenerator:
    """Rebuild the generator a description came from (positioned at sample 0)."""
    d = description if isinstance(description, ExcitationDescription) else \
        ExcitationDescription.from_dict(description)
    if d.version != DESCRIPTION_VERSION:
        raise ConfigError(f"excitation description version {d.version} is not supported "
                          f"(this fcrlive writes {DESCRIPTION_VERSION})")
    cls = _KINDS.get(d.kind)
    if cls is None:
        raise ConfigError(f"unknown excitation kind {d.kind!r}; known: {', '.join(sorted(_KINDS))}")
    kwargs = {k: d.params[k] for k in _CONSTRUCTOR_PARAMS[d.kind] if k in d.params}
    if "periods_requested_s" in kwargs:
        kwargs["periods_s"] = tuple(kwargs.pop("periods_requested_s"))
    if "phases_rad" in kwargs:
        kwargs["phases_rad"] = tuple(kwargs["phases_rad"])
    return cls(amplitude_hz=d.amplitude_hz, sample_time_s=d.sample_time_s, seed=d.seed, f0_hz=d.f0_hz,
               **kwargs)


def replay(description: ExcitationDescription | dict[str, Any], start: int, n: int) -> np.ndarray:
    """Samples start … start+n−1 [Hz] of the excitation a description came from."""
    g = make_generator(description)
    g.seek(start)
    return g.next_block(n)
