"""Identification data in the spirit of the toolbox's ``iddata``: one output, several inputs, experiments.

``IdData`` holds the samples of every experiment concatenated: ``y`` (N,), ``u`` (N, nu) and the
experiment boundaries ``starts`` (index of the first sample of each experiment). Estimators treat every
experiment on its own: filters restart (zero initial conditions) at each experiment start and losses
are summed over experiments, so gaps in a recording never create fake transients in the regressors.

NaN/inf samples are allowed in an ``IdData`` (that is how gaps arrive); :meth:`IdData.split` cuts them
out. Estimators call :meth:`IdData.require_finite` and refuse data with non-finite samples.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.signal as sps

from fcrlive.ident.errors import NonFiniteDataError, NotExcitingError, TooFewSamplesError


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class IdData:
    """Sampled input/output data of one or several experiments.

    Attributes:
        y: output samples (N,), all experiments concatenated.
        u: input samples (N, nu); a 1-D array is taken as one input.
        Ts: sample time [s].
        output_name, input_names: signal names used in error messages and reports.
        output_unit, input_units: physical units (free text, e.g. "pu", "Hz").
        starts: index of the first sample of each experiment (starts[0] == 0, increasing).
    """

    y: np.ndarray
    u: np.ndarray
    Ts: float
    output_name: str = "y"
    input_names: tuple[str, ...] = ()
    output_unit: str = ""
    input_units: tuple[str, ...] = ()
    starts: tuple[int, ...] = (0,)

    def __post_init__(self) -> None:
        y = np.asarray(self.y, dtype=float)
        if y.ndim != 1:
            y = y.reshape(-1) if y.ndim == 2 and 1 in y.shape else y
        if y.ndim != 1:
            raise ValueError(f"output {self.output_name!r} must be 1-D, got shape {np.shape(self.y)}")
        u = np.asarray(self.u, dtype=float)
        if u.ndim == 1:
            u = u[:, None]
        if u.ndim != 2 or u.shape[0] != y.shape[0]:
            raise ValueError(
                f"inputs must have shape (N, nu) with N = {y.shape[0]} samples of {self.output_name!r}, "
                f"got {np.shape(self.u)}"
            )
        nu = u.shape[1]
        names = tuple(self.input_names) or tuple(f"u{i + 1}" for i in range(nu))
        if len(names) != nu:
            raise ValueError(f"{len(names)} input names for {nu} inputs")
        units = tuple(self.input_units) or ("",) * nu
        if len(units) != nu:
            raise ValueError(f"{len(units)} input units for {nu} inputs")
        if not (np.isfinite(self.Ts) and self.Ts > 0):
            raise ValueError(f"sample time Ts must be a positive number of seconds, got {self.Ts}")
        starts = tuple(int(s) for s in self.starts)
        n = y.shape[0]
        increasing = all(b > a for a, b in itertools.pairwise(starts))
        if not starts or starts[0] != 0 or not increasing or (n > 0 and starts[-1] >= n):
            raise ValueError(f"experiment starts {starts} must begin at 0 and increase below N = {n}")
        object.__setattr__(self, "y", _readonly(y))
        object.__setattr__(self, "u", _readonly(u))
        object.__setattr__(self, "Ts", float(self.Ts))
        object.__setattr__(self, "input_names", names)
        object.__setattr__(self, "input_units", units)
        object.__setattr__(self, "starts", starts)

    # ----------------------------------------------------------------- shape and access
    @property
    def N(self) -> int:
        """Total number of samples over all experiments."""
        return int(self.y.shape[0])

    @property
    def nu(self) -> int:
        """Number of inputs."""
        return int(self.u.shape[1])

    @property
    def n_experiments(self) -> int:
        return len(self.starts)

    @property
    def bounds(self) -> tuple[tuple[int, int], ...]:
        """(start, stop) sample indices of each experiment."""
        stops = (*self.starts[1:], self.N)
        return tuple(zip(self.starts, stops))

    @property
    def lengths(self) -> tuple[int, ...]:
        return tuple(b - a for a, b in self.bounds)

    def segments(self) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Yield (y, u) views of each experiment."""
        for a, b in self.bounds:
            yield self.y[a:b], self.u[a:b]

    def experiment(self, i: int) -> IdData:
        """Experiment ``i`` as a single-experiment IdData (the toolbox's ``getexp``)."""
        a, b = self.bounds[i]
        return self._with(y=self.y[a:b], u=self.u[a:b], starts=(0,))

    def select_inputs(self, inputs: Sequence[int | str]) -> IdData:
        """Keep the listed inputs (by index or name), in that order."""
        idx = [self.input_index(i) for i in inputs]
        return self._with(
            u=self.u[:, idx],
            input_names=tuple(self.input_names[i] for i in idx),
            input_units=tuple(self.input_units[i] for i in idx),
        )

    def input_index(self, i: int | str) -> int:
        if isinstance(i, str):
            if i not in self.input_names:
                raise KeyError(f"no input named {i!r}; inputs are {self.input_names}")
            return self.input_names.index(i)
        if not -self.nu <= i < self.nu:
            raise IndexError(f"input {i} out of range for {self.nu} inputs")
        return int(i) % self.nu

    def _with(self, **kw) -> IdData:
        args = dict(
            y=self.y, u=self.u, Ts=self.Ts, output_name=self.output_name, input_names=self.input_names,
            output_unit=self.output_unit, input_units=self.input_units, starts=self.starts,
        )
        args.update(kw)
        return IdData(**args)

    # ----------------------------------------------------------------- checks used by estimators
    def require_finite(self) -> None:
        """Raise NonFiniteDataError naming the first signal with NaN/inf samples."""
        for name, x in ((self.output_name, self.y), *zip(self.input_names, self.u.T)):
            bad = ~np.isfinite(x)
            if bad.any():
                first = int(np.argmax(bad))
                raise NonFiniteDataError(
                    f"{int(bad.sum())} NaN/inf samples (first at index {first}); "
                    "cut them out with IdData.split() before estimating",
                    where=f"signal {name!r}",
                )

    def require_exciting(self, inputs: Sequence[int] | None = None) -> None:
        """Raise NotExcitingError if an input is constant within every experiment."""
        for i in range(self.nu) if inputs is None else inputs:
            x = self.u[:, i]
            spread = max((np.ptp(x[a:b]) if b > a else 0.0) for a, b in self.bounds)
            scale = max(float(np.max(np.abs(x))), 1e-300) if x.size else 1.0
            if not spread > 1e-12 * scale:
                raise NotExcitingError(
                    "input is constant, so it does not excite the system; remove it from the model or "
                    "add excitation",
                    where=f"input {self.input_names[i]!r}",
                )

    # ----------------------------------------------------------------- preprocessing
    def detrend(self, kind: str = "mean") -> IdData:
        """Remove the mean (``kind="mean"``) or a straight line (``"linear"``) per experiment and signal."""
        if kind not in ("mean", "linear"):
            raise ValueError(f"detrend kind must be 'mean' or 'linear', got {kind!r}")
        typ = "constant" if kind == "mean" else "linear"
        y = self.y.copy()
        u = self.u.copy()
        for a, b in self.bounds:
            y[a:b] = sps.detrend(y[a:b], type=typ)
            u[a:b] = sps.detrend(u[a:b], axis=0, type=typ)
        return self._with(y=y, u=u)

    def decimate(self, q: int, ftype: str = "iir", order: int | None = None) -> IdData:
        """Decimate by the integer factor ``q`` with a zero-phase anti-aliasing filter.

        Each experiment and signal is filtered forwards and backwards (no phase shift, so delays are
        preserved) and every q-th sample kept, like ``scipy.signal.decimate(zero_phase=True)``:
        ``ftype="iir"`` is an order-8 Chebyshev type I low-pass at 0.8·(Nyquist/q), ``"fir"`` a
        30·q-tap Hamming FIR. The sample time becomes q·Ts.
        """
        q = int(q)
        if q < 1:
            raise ValueError(f"decimation factor must be a positive integer, got {q}")
        if q == 1:
            return self
        ys, us, starts = [], [], []
        n = 0
        for k, (y, u) in enumerate(self.segments()):
            # filtfilt pads with 3·(filter length) samples: shorter segments cannot be filtered
            need = 3 * ((order or 8) + 1) + 1 if ftype == "iir" else 3 * (30 * q + 1) + 1
            if y.shape[0] <= need:
                raise TooFewSamplesError(
                    f"{y.shape[0]} samples, the anti-aliasing filter needs more than {need} for q = {q}",
                    where=f"experiment {k}",
                )
            ys.append(sps.decimate(y, q, n=order, ftype=ftype, zero_phase=True))
            us.append(sps.decimate(u, q, n=order, ftype=ftype, axis=0, zero_phase=True))
            starts.append(n)
            n += ys[-1].shape[0]
        return self._with(y=np.concatenate(ys), u=np.concatenate(us), Ts=self.Ts * q, starts=tuple(starts))

    def split(self, valid: np.ndarray | None = None, min_length: int = 2) -> IdData:
        """Cut out invalid samples: a multi-experiment IdData of the runs of good samples.

        A sample is good when ``valid`` is True (if given) and y and every input are finite there.
        Existing experiment boundaries are kept; runs shorter than ``min_length`` are dropped.
        """
        good = np.isfinite(self.y) & np.all(np.isfinite(self.u), axis=1)
        if valid is not None:
            valid = np.asarray(valid, dtype=bool)
            if valid.shape != (self.N,):
                raise ValueError(f"valid mask must have shape ({self.N},), got {valid.shape}")
            good &= valid
        runs: list[tuple[int, int]] = []
        for a, b in self.bounds:
            g = np.concatenate(([False], good[a:b], [False]))
            edges = np.flatnonzero(np.diff(g.astype(np.int8)))
            for s, e in zip(edges[::2], edges[1::2]):
                if e - s >= min_length:
                    runs.append((a + int(s), a + int(e)))
        if not runs:
            raise TooFewSamplesError(
                f"no run of at least {min_length} valid samples", where=f"output {self.output_name!r}"
            )
        idx = np.concatenate([np.arange(a, b) for a, b in runs])
        starts = tuple(int(s) for s in np.cumsum([0] + [b - a for a, b in runs[:-1]]))
        return self._with(y=self.y[idx], u=self.u[idx], starts=starts)

    @staticmethod
    def merge(*datas: IdData) -> IdData:
        """Merge data sets into one multi-experiment IdData (same Ts, inputs and names required)."""
        if len(datas) == 1 and not isinstance(datas[0], IdData):
            datas = tuple(datas[0])  # type: ignore[arg-type]
        if not datas:
            raise ValueError("nothing to merge")
        d0 = datas[0]
        for d in datas[1:]:
            if not np.isclose(d.Ts, d0.Ts, rtol=1e-9):
                raise ValueError(f"cannot merge data with Ts = {d0.Ts} s and Ts = {d.Ts} s")
            if d.nu != d0.nu or d.input_names != d0.input_names or d.output_name != d0.output_name:
                raise ValueError(
                    f"cannot merge data with signals {d0.output_name}/{d0.input_names} and "
                    f"{d.output_name}/{d.input_names}"
                )
        starts, n = [], 0
        for d in datas:
            starts.extend(n + s for s in d.starts)
            n += d.N
        return d0._with(
            y=np.concatenate([d.y for d in datas]),
            u=np.concatenate([d.u for d in datas]),
            starts=tuple(starts),
        )

    def split_signal(self, x: np.ndarray) -> list[np.ndarray]:
        """Cut a signal aligned with the concatenated samples into per-experiment pieces."""
        x = np.asarray(x, dtype=float)
        if x.shape[0] != self.N:
            raise ValueError(f"signal has {x.shape[0]} samples, the data has {self.N}")
        return [x[a:b] for a, b in self.bounds]


def as_iddata(data: IdData | tuple, Ts: float | None = None) -> IdData:
    """Accept an IdData or a (y, u) tuple (then ``Ts`` is required)."""
    if isinstance(data, IdData):
        return data
    if isinstance(data, tuple) and len(data) == 2:
        if Ts is None:
            raise ValueError("pass Ts with a (y, u) tuple, or build an IdData")
        return IdData(y=data[0], u=data[1], Ts=Ts)
    raise TypeError(f"expected IdData or (y, u), got {type(data).__name__}")
