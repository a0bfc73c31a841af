"""Polynomial input-output models in the toolbox's conventions.

    A(q) y(t) = Σ_i B_i(q)/F_i(q) u_i(t) + C(q)/D(q) e(t),      e white with variance λ

All polynomials are in the delay operator q⁻¹ (z⁻¹): ``a = [1, a_1, ..., a_na]`` and so on.
``b[i]`` holds nk_i leading zeros followed by the nb_i estimated coefficients (like MATLAB's ``B``):
``nb`` counts coefficients, ``nk`` the leading zeros (the input delay in samples). A, C, D, F_i are
monic. ARX is (A, B), OE is (B, F), BJ is (B, C, D, F).

The parameter vector θ is ordered [a, b_1, ..., b_nu, c, d, f_1, ..., f_nu] (the toolbox's order),
each block without the fixed leading 1 (or the nk zeros of b). ``covariance`` is Cov θ (P, P).
"""

from __future__ import annotations

import uuid
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.signal as sps

from fcrlive.gridsearch import uncertain_peak
from fcrlive.ident.data import IdData
from fcrlive.ident.freqresp import FreqResp


@dataclass(frozen=True)
class EstimationReport:
    """How an estimate was obtained.

    Attributes:
        method: "arx", "oe", "bj", "two-stage oe", ...
        n_samples: samples in the loss (after dropping initial rows for ARX).
        loss: V = mean squared prediction error (1/N)Σε².
        iterations: search iterations of the retained start (0 for ARX).
        converged: whether the search met its tolerance (always True for ARX).
        stop_reason: why the search stopped, in words.
        algorithm: "qr"/"cholqr2" for ARX, "gn" or "gn+lm" for the prediction-error search.
        start_losses: loss reached from each start of the multi-start search (first = default start).
        notes: caveats (e.g. on the covariance of two-stage estimates).
    """

    method: str
    n_samples: int
    loss: float
    iterations: int = 0
    converged: bool = True
    stop_reason: str = "closed form"
    algorithm: str = ""
    start_losses: tuple[float, ...] = ()
    notes: tuple[str, ...] = ()


def polyval_zinv(p: np.ndarray, zinv: np.ndarray) -> np.ndarray:
    """Σ_k p_k z^{-k} for each z^{-1} in ``zinv``."""
    out = np.zeros(zinv.shape, dtype=complex)
    for c in np.asarray(p)[::-1]:
        out = out * zinv + c
    return out


def _monic(p, name: str) -> np.ndarray:
    p = np.atleast_1d(np.asarray(p, dtype=float))
    if p.size == 0 or p[0] != 1.0:
        raise ValueError(f"polynomial {name} must be monic (leading coefficient 1), got {p}")
    return p


@dataclass(frozen=True, eq=False)
class PolyModel:
    """A(q) y = Σ B_i/F_i u_i + C/D e; see the module docstring for conventions.

    Attributes:
        a, c, d: monic polynomials in q⁻¹.
        b: per input, nk_i zeros then nb_i coefficients.
        f: per input, monic.
        nk: per input delay [samples].
        Ts: sample time [s].
        noise_variance: λ̂ (variance of e), NaN if unknown.
        covariance: Cov θ (P, P) or None for a model without uncertainty.
        input_names, output_name: signal names.
        report: how it was estimated.
        uid: identity of this estimate in uncertain frequency-response algebra (see FreqResp).
    """

    a: np.ndarray
    b: tuple[np.ndarray, ...]
    c: np.ndarray
    d: np.ndarray
    f: tuple[np.ndarray, ...]
    nk: tuple[int, ...]
    Ts: float
    noise_variance: float = float("nan")
    covariance: np.ndarray | None = None
    input_names: tuple[str, ...] = ()
    output_name: str = "y"
    report: EstimationReport | None = None
    uid: str = field(default_factory=lambda: uuid.uuid4().hex[:16])

    def __post_init__(self) -> None:
        b = tuple(np.atleast_1d(np.asarray(x, dtype=float)) for x in self.b)
        nu = len(b)
        f = tuple(_monic(x, f"F_{i + 1}") for i, x in enumerate(self.f)) if self.f else tuple(
            np.ones(1) for _ in range(nu)
        )
        nk = tuple(int(k) for k in self.nk)
        if len(f) != nu or len(nk) != nu:
            raise ValueError(f"{nu} B polynomials but {len(f)} F polynomials and {len(nk)} delays")
        for i, (bi, k) in enumerate(zip(b, nk)):
            if k < 0 or bi.size < k or np.any(bi[:k] != 0):
                raise ValueError(f"B_{i + 1} = {bi} must start with nk = {k} zeros")
        names = tuple(self.input_names) or tuple(f"u{i + 1}" for i in range(nu))
        object.__setattr__(self, "a", _monic(self.a, "A"))
        object.__setattr__(self, "c", _monic(self.c, "C"))
        object.__setattr__(self, "d", _monic(self.d, "D"))
        object.__setattr__(self, "b", b)
        object.__setattr__(self, "f", f)
        object.__setattr__(self, "nk", nk)
        object.__setattr__(self, "Ts", float(self.Ts))
        object.__setattr__(self, "input_names", names)
        if self.covariance is not None:
            cov = np.asarray(self.covariance, dtype=float)
            p = self.n_params
            if cov.shape != (p, p):
                raise ValueError(f"covariance shape {cov.shape} does not match {p} parameters")
            object.__setattr__(self, "covariance", cov)

    # ----------------------------------------------------------------- structure
    @property
    def nu(self) -> int:
        return len(self.b)

    @property
    def na(self) -> int:
        return self.a.size - 1

    @property
    def nb(self) -> tuple[int, ...]:
        return tuple(bi.size - k for bi, k in zip(self.b, self.nk))

    @property
    def nc(self) -> int:
        return self.c.size - 1

    @property
    def nd(self) -> int:
        return self.d.size - 1

    @property
    def nf(self) -> tuple[int, ...]:
        return tuple(fi.size - 1 for fi in self.f)

    @property
    def n_params(self) -> int:
        return self.na + sum(self.nb) + self.nc + self.nd + sum(self.nf)

    def slices(self) -> dict:
        """Positions of the parameter blocks in θ: keys "a", ("b", i), "c", "d", ("f", i)."""
        out: dict = {}
        i = 0
        for key, n in [("a", self.na), *((("b", j), m) for j, m in enumerate(self.nb)),
                       ("c", self.nc), ("d", self.nd), *((("f", j), m) for j, m in enumerate(self.nf))]:
            out[key] = slice(i, i + n)
            i += n
        return out

    @property
    def theta(self) -> np.ndarray:
        """Parameter vector [a, b_1..b_nu, c, d, f_1..f_nu] without the fixed 1s and nk zeros."""
        parts = [self.a[1:], *(bi[k:] for bi, k in zip(self.b, self.nk)), self.c[1:], self.d[1:],
                 *(fi[1:] for fi in self.f)]
        return np.concatenate(parts)

    @property
    def sd(self) -> np.ndarray:
        """Standard deviations of θ (NaN without covariance)."""
        if self.covariance is None:
            return np.full(self.n_params, np.nan)
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    def with_theta(self, theta: np.ndarray, **kw) -> PolyModel:
        """Same structure with new parameter values (new uid; covariance dropped unless given)."""
        theta = np.asarray(theta, dtype=float)
        if theta.shape != (self.n_params,):
            raise ValueError(f"theta must have {self.n_params} elements, got {theta.shape}")
        s = self.slices()
        b = tuple(np.concatenate((np.zeros(k), theta[s[("b", i)]])) for i, k in enumerate(self.nk))
        f = tuple(np.concatenate(([1.0], theta[s[("f", i)]])) for i in range(self.nu))
        args = dict(a=np.concatenate(([1.0], theta[s["a"]])), b=b, c=np.concatenate(([1.0], theta[s["c"]])),
                    d=np.concatenate(([1.0], theta[s["d"]])), f=f, covariance=None, report=None,
                    uid=uuid.uuid4().hex[:16])
        args.update(kw)
        return replace(self, **args)

    def param_names(self) -> list[str]:
        names = [f"a{k}" for k in range(1, self.na + 1)]
        tag = (lambda i: f"{i + 1}_") if self.nu > 1 else (lambda i: "")
        for i, (m, k) in enumerate(zip(self.nb, self.nk)):
            names += [f"b{tag(i)}{k + j}" for j in range(m)]
        names += [f"c{k}" for k in range(1, self.nc + 1)] + [f"d{k}" for k in range(1, self.nd + 1)]
        for i, m in enumerate(self.nf):
            names += [f"f{tag(i)}{k}" for k in range(1, m + 1)]
        return names

    def _input(self, input: int | str) -> int:
        if isinstance(input, str):
            if input not in self.input_names:
                raise KeyError(f"no input named {input!r}; inputs are {self.input_names}")
            return self.input_names.index(input)
        if not -self.nu <= input < self.nu:
            raise IndexError(f"input {input} out of range for {self.nu} inputs")
        return int(input) % self.nu

    def tf(self, input: int | str = 0) -> tuple[np.ndarray, np.ndarray]:
        """(num, den) in z⁻¹ of G_i = B_i/(A F_i); ``input="noise"`` gives H = C/(A D)."""
        if input == "noise":
            return self.c.copy(), np.convolve(self.a, self.d)
        i = self._input(input)
        return self.b[i].copy(), np.convolve(self.a, self.f[i])

    def is_stable(self) -> bool:
        """All of A·F_i, C and D have their roots strictly inside the unit circle."""
        polys = [self.a, self.c, self.d, *self.f]
        return all(p.size == 1 or np.max(np.abs(np.roots(p))) < 1.0 for p in polys)

    # ----------------------------------------------------------------- time domain
    def _u_segments(self, u) -> tuple[list[np.ndarray], IdData | None]:
        if isinstance(u, IdData):
            if u.nu != self.nu:
                raise ValueError(f"data has {u.nu} inputs, the model {self.nu}")
            return [uu for _, uu in u.segments()], u
        u = np.asarray(u, dtype=float)
        if u.ndim == 1:
            u = u[:, None]
        if u.shape[1] != self.nu:
            raise ValueError(f"u has {u.shape[1]} columns, the model {self.nu} inputs")
        return [u], None

    def simulate(self, u) -> np.ndarray:
        """Noise-free output Σ B_i/(A F_i) u_i, zero initial conditions per experiment.

        ``u`` is an IdData (its inputs are used) or an (N, nu) array. Returns (N,).
        """
        segs, _ = self._u_segments(u)
        out = []
        for us in segs:
            ys = np.zeros(us.shape[0])
            for i in range(self.nu):
                ys += sps.lfilter(self.b[i], np.convolve(self.a, self.f[i]), us[:, i])
            out.append(ys)
        return np.concatenate(out) if out else np.zeros(0)

    def residuals(self, data: IdData) -> np.ndarray:
        """One-step prediction errors ε = (D/C)(A y − Σ B_i/F_i u_i), per experiment, concatenated."""
        if data.nu != self.nu:
            raise ValueError(f"data has {data.nu} inputs, the model {self.nu}")
        out = []
        for y, u in data.segments():
            v = sps.lfilter(self.a, [1.0], y)
            for i in range(self.nu):
                v = v - sps.lfilter(self.b[i], self.f[i], u[:, i])
            out.append(sps.lfilter(self.d, self.c, v))
        return np.concatenate(out)

    def predict(self, data: IdData) -> np.ndarray:
        """One-step-ahead prediction ŷ(t|t−1) = y − ε."""
        return data.y - self.residuals(data)

    # ----------------------------------------------------------------- frequency domain
    def freqresp(self, omega_rad_s, input: int | str = 0) -> FreqResp:
        """G_i(e^{jωTs}) = B_i/(A F_i) (or H = C/(A D) for ``input="noise"``) with its gradient.

        ``omega_rad_s`` in rad/s. The FreqResp carries ∂G/∂θ and this model's covariance, so sd_abs,
        sd_phase and the algebra of uncertain responses work. Without covariance the sd are NaN
        (unknown, as :attr:`sd`), never zero: a zero would read as an exact response.
        """
        omega = np.atleast_1d(np.asarray(omega_rad_s, dtype=float))
        zi = np.exp(-1j * omega * self.Ts)
        A = polyval_zinv(self.a, zi)
        if input == "noise":
            C, D = polyval_zinv(self.c, zi), polyval_zinv(self.d, zi)
            G = C / (A * D)
        else:
            i = self._input(input)
            B, F = polyval_zinv(self.b[i], zi), polyval_zinv(self.f[i], zi)
            G = B / (A * F)

        def jacobian() -> np.ndarray:
            # computed when first asked (FreqResp._make): a search over ω asks most responses only for G
            s = self.slices()
            jac = np.zeros((omega.size, self.n_params), complex)
            powers = np.arange(1, 1 + max(self.na, self.nc, self.nd, *self.nf, 1))
            zk = zi[:, None] ** powers[None, :]
            jac[:, s["a"]] = -(G / A)[:, None] * zk[:, :self.na]
            if input == "noise":
                jac[:, s["c"]] = (1.0 / (A * D))[:, None] * zk[:, :self.nc]
                jac[:, s["d"]] = -(G / D)[:, None] * zk[:, :self.nd]
            else:
                k = self.nk[i]
                bpow = np.arange(k, k + self.nb[i])
                jac[:, s[("b", i)]] = (1.0 / (A * F))[:, None] * zi[:, None] ** bpow[None, :]
                jac[:, s[("f", i)]] = -(G / F)[:, None] * zk[:, :self.nf[i]]
            return jac

        cov = self.covariance if self.covariance is not None else np.full((self.n_params,) * 2, np.nan)
        src = ((self.uid, cov),)
        # checked construction only for what FreqResp would reject (a grid that is not 1-D)
        if omega.ndim != 1:
            return FreqResp(omega, G, jacobian(), src)
        return FreqResp._make(omega, G, jacobian, src)

    def static_gain(self, input: int | str = 0) -> tuple[float, float]:
        """(G_i(1), sd) — the DC gain of input i and its standard deviation."""
        g = self.freqresp([0.0], input=input)
        return float(g.value.real[0]), float(g.sd_real[0])

    def peak_gain(self, input: int | str = 0, n: int = 2000, omega_max: float | None = None):
        """max_ω |G_i| on a log grid up to ``omega_max`` (default Nyquist), refined near the peak."""
        wmax = np.pi / self.Ts if omega_max is None else omega_max
        return uncertain_peak(lambda w: self.freqresp(w, input=input), wmax * 1e-4, wmax, n)
