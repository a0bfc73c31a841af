"""Uncertain frequency responses and their algebra (Gauss approximation, first order).

A :class:`FreqResp` is the value of a transfer function on a grid of angular frequencies together with
its gradient with respect to the parameters of the estimates it came from, and their covariances:

    value     G(e^{jωTs})                                   complex (n_omega,)
    jacobian  ∂G/∂θ                                         complex (n_omega, P)
    sources   ((key, Cov θ_key), ...)                       the P columns, block by block

Each estimated model is one *source* (its ``uid`` is the key). Sources are independent estimates, so
the joint covariance is block-diagonal; two responses of the *same* model (e.g. S and G_1 from one MISO
fit) share a key and therefore share columns, so their correlation is kept exactly. Arithmetic
(+, −, ·, /, 1 − x, inverse, scalars, known responses) propagates the gradients by the chain rule: for a
holomorphic f, ∂f(G)/∂θ = f'(G)·∂G/∂θ. That gives the variance of |G| and of arg G as gᵀ Cov g with
g = Re(Ḡ ∂G/∂θ)/|G| and Im(Ḡ ∂G/∂θ)/|G|² (the paper's eqs. 15 and 19 are built this way).

This is the first-order (Gauss) approximation: accurate when the relative sd of every factor is small;
near a zero of a denominator the bands of a quotient are not to be trusted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fcrlive.constants import Z95


@dataclass(frozen=True)
class PeakGain:
    """max over the grid of |G| with the frequency where it is reached and the sd of the maximum.

    The sd uses the gradient of |G| at the maximiser: to first order the maximiser's own shift does not
    change the maximum (envelope theorem). Refine the grid near ``omega`` if the peak is sharp.
    """

    value: float
    omega: float
    sd: float

    def ci95(self) -> tuple[float, float]:
        return (max(self.value - Z95 * self.sd, 0.0), self.value + Z95 * self.sd)


def _as_cols(jac: np.ndarray, n: int) -> np.ndarray:
    jac = np.asarray(jac, dtype=complex)
    if jac.ndim == 1:
        jac = jac[:, None]
    if jac.shape[0] != n:
        raise ValueError(f"jacobian has {jac.shape[0]} rows for {n} frequencies")
    return jac


@dataclass(frozen=True, eq=False)
class FreqResp:
    """Frequency response with first-order uncertainty. Build it with ``model.freqresp(omega)``.

    Attributes:
        omega: angular frequencies [rad/s] (the response is evaluated at z = e^{jωTs}).
        value: complex response (n_omega,).
        jacobian: ∂value/∂θ, complex (n_omega, P), θ the stacked parameters of all sources.
        sources: ((key, covariance), ...) in column order; each covariance is real (p_k, p_k).
    """

    omega: np.ndarray
    value: np.ndarray
    jacobian: np.ndarray
    sources: tuple[tuple[str, np.ndarray], ...] = ()

    # numpy arrays on the left of +, −, ·, / defer to FreqResp's reflected operators
    __array_ufunc__ = None

    def __post_init__(self) -> None:
        omega = np.atleast_1d(np.asarray(self.omega, dtype=float))
        value = np.atleast_1d(np.asarray(self.value, dtype=complex))
        if value.shape != omega.shape:
            raise ValueError(f"value shape {value.shape} does not match omega shape {omega.shape}")
        jac = _as_cols(self.jacobian, omega.shape[0]) if np.size(self.jacobian) else np.zeros(
            (omega.shape[0], 0), complex
        )
        p = sum(c.shape[0] for _, c in self.sources)
        if jac.shape[1] != p:
            raise ValueError(f"jacobian has {jac.shape[1]} columns, the sources have {p} parameters")
        object.__setattr__(self, "omega", omega)
        object.__setattr__(self, "value", value)
        object.__setattr__(self, "jacobian", jac)

    # ----------------------------------------------------------------- construction
    @classmethod
    def _make(cls, omega: np.ndarray, value: np.ndarray, jac, sources: tuple) -> FreqResp:
        """The constructor without :meth:`__post_init__`'s conversions and checks, for the algebra below,
        whose operands are valid FreqResp already (omega float (n,), value complex (n,), jac complex
        (n, P) matching the sources): the assessment builds ~20 000 responses per identification, most on
        one ω, where the checks cost as much as the arithmetic. An empty grid takes the checked path.

        ``jac`` may be a function returning it: it is then computed on the first access of ``jacobian``
        (:meth:`__getattr__`). Most responses the TSO checks' searches build are asked only for their
        value; the value never depends on the jacobian, and the jacobian, when asked, is the same
        arithmetic on the same arrays as if computed at once."""
        if omega.shape[0] == 0:
            return cls(omega, value, jac() if callable(jac) else jac, sources)
        obj = object.__new__(cls)
        object.__setattr__(obj, "omega", omega)
        object.__setattr__(obj, "value", value)
        if callable(jac):
            object.__setattr__(obj, "_jac_fn", jac)
        else:
            object.__setattr__(obj, "jacobian", jac)
        object.__setattr__(obj, "sources", sources)
        return obj

    def __getattr__(self, name: str):
        # only reached when normal lookup fails: a jacobian made lazily by _make, on its first access
        if name == "jacobian":
            fn = self.__dict__.pop("_jac_fn", None)
            if fn is not None:
                jac = fn()
                object.__setattr__(self, "jacobian", jac)
                return jac
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @classmethod
    def known(cls, omega: np.ndarray, value: np.ndarray | complex) -> FreqResp:
        """A response known exactly (e.g. the controller G_c): no parameters, zero variance."""
        omega = np.atleast_1d(np.asarray(omega, dtype=float))
        value = np.broadcast_to(np.asarray(value, dtype=complex), omega.shape).copy()
        return cls._make(omega, value, np.zeros((omega.shape[0], 0), complex), ())

    # ----------------------------------------------------------------- statistics
    @property
    def n_params(self) -> int:
        # the columns of the jacobian, from the sources (equal by construction; no lazy jacobian computed)
        return int(sum(c.shape[0] for _, c in self.sources))

    @property
    def covariance(self) -> np.ndarray:
        """Block-diagonal covariance of the stacked parameters (P, P)."""
        p = self.n_params
        cov = np.zeros((p, p))
        i = 0
        for _, c in self.sources:
            k = c.shape[0]
            cov[i:i + k, i:i + k] = c
            i += k
        return cov

    def _quad(self, g: np.ndarray) -> np.ndarray:
        """Row-wise gᵀ Cov g for a real gradient g (n_omega, P), using the block structure."""
        out = np.zeros(g.shape[0])
        i = 0
        for _, c in self.sources:
            k = c.shape[0]
            gi = g[:, i:i + k]
            out += np.einsum("ij,jk,ik->i", gi, c, gi)
            i += k
        # a response that depends on estimated parameters but gets no variance from them (their
        # covariance is missing, or does not reach this direction) has an UNKNOWN sd, not a zero one:
        # NaN, so that no interval of zero width is ever shown
        moves = np.any(g != 0.0, axis=1) if g.shape[1] else np.zeros(g.shape[0], bool)
        return np.where(moves & ~(out > 0.0), np.nan, np.maximum(out, 0.0))

    @property
    def abs(self) -> np.ndarray:
        return np.abs(self.value)

    @property
    def phase(self) -> np.ndarray:
        """Phase [rad], unwrapped along the frequency grid."""
        return np.unwrap(np.angle(self.value))

    @property
    def db(self) -> np.ndarray:
        return 20.0 * np.log10(np.abs(self.value))

    def _grad_abs(self) -> np.ndarray:
        a = np.abs(self.value)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.real(np.conj(self.value)[:, None] * self.jacobian) / a[:, None]

    def _grad_phase(self) -> np.ndarray:
        a2 = np.abs(self.value) ** 2
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.imag(np.conj(self.value)[:, None] * self.jacobian) / a2[:, None]

    def _cached(self, name: str, compute) -> np.ndarray:
        """A copy of the value of ``compute()`` kept on this (immutable) response: the TSO checks ask the
        sd of one response several times (value and bounds, both products)."""
        c = self.__dict__.get("_sd_cache")
        if c is None:
            c = {}
            object.__setattr__(self, "_sd_cache", c)
        v = c.get(name)
        if v is None:
            v = c[name] = compute()
        return v.copy()

    @property
    def sd_abs(self) -> np.ndarray:
        """Standard deviation of |G| (same units as |G|)."""
        return self._cached("abs", lambda: np.sqrt(self._quad(np.nan_to_num(self._grad_abs()))))

    @property
    def sd_phase(self) -> np.ndarray:
        """Standard deviation of arg G [rad]."""
        return self._cached("phase", lambda: np.sqrt(self._quad(np.nan_to_num(self._grad_phase()))))

    @property
    def sd_real(self) -> np.ndarray:
        return self._cached("real", lambda: np.sqrt(self._quad(np.real(self.jacobian))))

    @property
    def sd_imag(self) -> np.ndarray:
        return self._cached("imag", lambda: np.sqrt(self._quad(np.imag(self.jacobian))))

    def ci95_abs(self) -> tuple[np.ndarray, np.ndarray]:
        """95 % band of |G|: |G| ∓ Z95·sd (lower edge clipped at 0)."""
        a, s = self.abs, self.sd_abs
        return np.maximum(a - Z95 * s, 0.0), a + Z95 * s

    def ci95_phase(self) -> tuple[np.ndarray, np.ndarray]:
        p, s = self.phase, self.sd_phase
        return p - Z95 * s, p + Z95 * s

    def max_abs(self) -> PeakGain:
        """Largest |G| on the grid, its ω [rad/s] and its sd (gradient at the maximiser)."""
        i = int(np.argmax(self.abs))
        return PeakGain(float(self.abs[i]), float(self.omega[i]), float(self.sd_abs[i]))

    def __getitem__(self, idx) -> FreqResp:
        """Sub-grid: ``G[3]``, ``G[2:5]`` or ``G[mask]`` keep the parameter columns."""
        idx = np.atleast_1d(np.arange(self.omega.shape[0])[idx])
        return FreqResp(self.omega[idx], self.value[idx], self.jacobian[idx], self.sources)

    def __len__(self) -> int:
        return int(self.omega.shape[0])

    # ----------------------------------------------------------------- algebra
    def _coerce(self, other) -> FreqResp:
        if isinstance(other, FreqResp):
            if other.omega is self.omega or np.array_equal(other.omega, self.omega):
                return other
            if other.omega.shape != self.omega.shape or not np.allclose(other.omega, self.omega,
                                                                         rtol=1e-12, atol=0):
                raise ValueError("frequency responses on different frequency grids cannot be combined")
            return other
        val = np.asarray(other, dtype=complex)
        if val.ndim > 1 or (val.ndim == 1 and val.shape != self.omega.shape):
            raise ValueError(f"cannot combine a response on {self.omega.shape[0]} frequencies with "
                             f"an array of shape {val.shape}")
        return FreqResp.known(self.omega, val)

    @staticmethod
    def _union(x: FreqResp, y: FreqResp) -> tuple:
        """The sources of a combination of x and y (:meth:`_align`'s third result)."""
        if x.sources == () and y.sources == ():
            return ()
        keys = {k for k, _ in x.sources}
        return (*x.sources, *(kc for kc in y.sources if kc[0] not in keys))

    @staticmethod
    def _align(x: FreqResp, y: FreqResp) -> tuple[np.ndarray, np.ndarray, tuple]:
        """Both jacobians on the union of the sources (shared keys share columns)."""
        if x.sources == () and y.sources == ():
            return x.jacobian, y.jacobian, ()
        keys = [k for k, _ in x.sources]
        sources = list(x.sources)
        pos = {}
        i = 0
        for k, c in x.sources:
            pos[k] = (i, c.shape[0])
            i += c.shape[0]
        for k, c in y.sources:
            if k not in pos:
                pos[k] = (i, c.shape[0])
                i += c.shape[0]
                keys.append(k)
                sources.append((k, c))
        n = x.omega.shape[0]
        jx = np.zeros((n, i), complex)
        jx[:, :x.n_params] = x.jacobian
        jy = np.zeros((n, i), complex)
        j = 0
        for k, c in y.sources:
            s, m = pos[k]
            jy[:, s:s + m] = y.jacobian[:, j:j + c.shape[0]]
            j += c.shape[0]
        return jx, jy, tuple(sources)

    def _binary(self, other, f, dfx, dfy) -> FreqResp:
        o = self._coerce(other)
        x, y = self.value, o.value
        val = f(x, y)

        def jac():
            jx, jy, _ = self._align(self, o)
            return dfx(x, y)[:, None] * jx + dfy(x, y)[:, None] * jy

        return FreqResp._make(self.omega, val, jac, self._union(self, o))

    def __add__(self, other) -> FreqResp:
        return self._binary(other, lambda x, y: x + y, lambda x, y: np.ones_like(x),
                            lambda x, y: np.ones_like(y))

    __radd__ = __add__

    def __sub__(self, other) -> FreqResp:
        return self._binary(other, lambda x, y: x - y, lambda x, y: np.ones_like(x),
                            lambda x, y: -np.ones_like(y))

    def __rsub__(self, other) -> FreqResp:
        return self._coerce(other) - self

    def __neg__(self) -> FreqResp:
        return FreqResp._make(self.omega, -self.value, lambda: -self.jacobian, self.sources)

    def __mul__(self, other) -> FreqResp:
        return self._binary(other, lambda x, y: x * y, lambda x, y: y, lambda x, y: x)

    __rmul__ = __mul__

    def __truediv__(self, other) -> FreqResp:
        return self._binary(other, lambda x, y: x / y, lambda x, y: 1.0 / y, lambda x, y: -x / y**2)

    def __rtruediv__(self, other) -> FreqResp:
        return self._coerce(other) / self

    def inv(self) -> FreqResp:
        """1 / G."""
        return FreqResp._make(self.omega, 1.0 / self.value, lambda: -self.jacobian / self.value[:, None] ** 2,
                              self.sources)

    def one_minus(self) -> FreqResp:
        """1 − G (same as ``1 - G``)."""
        return 1.0 - self

    def conj(self) -> FreqResp:
        """Complex conjugate (not holomorphic: ∂Ḡ/∂θ = conj(∂G/∂θ) because θ is real)."""
        return FreqResp._make(self.omega, np.conj(self.value), lambda: np.conj(self.jacobian), self.sources)
