"""Prediction-error OE and Box-Jenkins models: y = Σ_i B_i/F_i u_i + C/D e (MISO, shared noise model).

Loss: V(θ) = (1/N) Σ ε², ε = (D/C)(y − Σ B_i/F_i u_i), zero initial conditions per experiment, summed
over experiments. θ = [b_1, ..., b_nu, c, d, f_1, ..., f_nu] (the toolbox's order, A = 1).

Search (what made the prototype robust on a hard closed-loop case, libraries.md):
  1. initial values: a high-order ARX (whitening: its A ≈ D/C), Steiglitz-McBride for each B_i/F_i on
     the ARX's noise-free simulated output (one start) and on the ARX-whitened data (second start),
     then Hannan-Rissanen for C/D on the output residual of B/F;
  2. Gauss-Newton with step halving; a step is rejected (halved) if it moves a root of F_i, C or D
     onto/outside the unit circle or does not lower the loss;
  3. Levenberg-Marquardt (same stability guard) when Gauss-Newton cannot descend;
  4. multi-start when the first search stalls (not converged, or a loss clearly above the
     high-order ARX's): the other initial value and perturbed ones; the lowest loss is kept. A BJ fit
     whose high-order ARX has more than 8 poles always also tries the start from a shorter ARX
     (see ``_pem``).

The Jacobian ∂ε/∂θ is analytic (filters of u, of the simulated outputs, of ε and of v; see
``_jacobian``).
Covariance: Cov θ̂ = λ̂ (JᵀJ)⁻¹ at θ̂, λ̂ = Σε²/(N − p) (Gauss approximation, asymptotically exact when
the model structure contains the true system and the data are informative).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.fft as _sfft
import scipy.linalg as sla
import scipy.signal as sps
import scipy.stats as stats

from fcrlive.constants import Z95
from fcrlive.ident.arx import arx, per_input
from fcrlive.ident.data import IdData
from fcrlive.ident.errors import OrderError, TooFewSamplesError, UnstableModelError
from fcrlive.ident.poly import EstimationReport, PolyModel

try:  # scipy's C filter behind lfilter; lfilter's array-API dispatch and checks cost more than it on
    # the short records here (a search filters ~20 000 times)
    from scipy.signal._sigtools import _linear_filter
except ImportError:  # pragma: no cover - a scipy without it: the public function
    _linear_filter = None


def _filt(b, a, x, axis: int = -1) -> np.ndarray:
    """``scipy.signal.lfilter(b, a, x, axis)`` for float arrays (b, a 1-D numpy), bit for bit the same.

    lfilter hands a denominator of length > 1 to the C filter unchanged; a length-1 one (FIR) takes
    lfilter's convolution path, so that case, and a scipy without the C entry point, use lfilter itself.
    """
    if _linear_filter is None or len(a) == 1:
        return sps.lfilter(b, a, x, axis=axis)
    if type(b) is not np.ndarray:
        b = np.atleast_1d(np.asarray(b, float))
    return _linear_filter(b, a, x, axis)


_ROOT_MAX = 1.0 - 1e-7
"""A polynomial counts as stable when all roots are inside this radius (strictly inside the circle)."""


# ===================================================================== structure and evaluation
@dataclass(frozen=True)
class _Struct:
    nb: tuple[int, ...]
    nc: int
    nd: int
    nf: tuple[int, ...]
    nk: tuple[int, ...]
    ic: bool = False
    """Estimate each experiment's initial state and output offset (variable projection)."""
    drift_pole: float | None = None
    """With ``ic``: also the step response of 1/(1 − p q⁻¹) per experiment (p = 1: a linear trend)."""

    @property
    def nu(self) -> int:
        return len(self.nb)

    @property
    def p(self) -> int:
        return sum(self.nb) + self.nc + self.nd + sum(self.nf)

    def b_sl(self, i: int) -> slice:
        s = sum(self.nb[:i])
        return slice(s, s + self.nb[i])

    @property
    def c_sl(self) -> slice:
        s = sum(self.nb)
        return slice(s, s + self.nc)

    @property
    def d_sl(self) -> slice:
        s = sum(self.nb) + self.nc
        return slice(s, s + self.nd)

    def f_sl(self, i: int) -> slice:
        s = sum(self.nb) + self.nc + self.nd + sum(self.nf[:i])
        return slice(s, s + self.nf[i])

    def polys(self, th: np.ndarray):
        B = [np.concatenate((np.zeros(self.nk[i]), th[self.b_sl(i)])) for i in range(self.nu)]
        F = [np.concatenate(([1.0], th[self.f_sl(i)])) for i in range(self.nu)]
        C = np.concatenate(([1.0], th[self.c_sl]))
        D = np.concatenate(([1.0], th[self.d_sl]))
        return B, F, C, D

    def pack(self, B, F, C, D) -> np.ndarray:
        parts = [np.asarray(B[i])[self.nk[i]:self.nk[i] + self.nb[i]] for i in range(self.nu)]
        parts += [np.asarray(C)[1:1 + self.nc], np.asarray(D)[1:1 + self.nd]]
        parts += [np.asarray(F[i])[1:1 + self.nf[i]] for i in range(self.nu)]
        return np.concatenate(parts).astype(float)


def _max_root(p: np.ndarray) -> float:
    if p.size <= 1:
        return 0.0
    if p.size == 2:
        return abs(p[1])
    if not np.all(np.isfinite(p)):
        return np.inf
    return float(np.max(np.abs(np.roots(p))))


def _roots_inside(p, radius: float) -> bool:
    """True when every root of p (highest power first, p[0] ≠ 0) has modulus < ``radius``.

    Schur-Cohn step-down recursion on the polynomial scaled to the unit circle: O(n²) scalar work with
    no eigenvalue problem. The search asks this a thousand times per fit (np.roots was a quarter of the
    time of a Z_u identification), and on Python floats it is several times faster than on numpy arrays
    of a few elements, with the same arithmetic.
    """
    n = len(p) - 1
    if n <= 0:
        return True
    a = [float(x) / radius**i for i, x in enumerate(p)]
    if not all(map(math.isfinite, a)):
        return False
    a0 = a[0]
    a = [x / a0 for x in a]
    for m in range(n, 0, -1):
        k = a[m]
        if not abs(k) < 1.0:
            return False
        d = 1.0 - k * k
        a = [(a[i] - k * a[m - i]) / d for i in range(m)]
    return True


def _stable(st: _Struct, th: np.ndarray) -> bool:
    t = th.tolist()
    polys = [t[st.f_sl(i)] for i in range(st.nu)] + [t[st.c_sl], t[st.d_sl]]
    return all(_roots_inside([1.0, *q], _ROOT_MAX) for q in polys)


def _reflect(p: np.ndarray, shrink: float = 0.98) -> np.ndarray:
    """Reflect roots outside the unit circle inside (r → 1/r̄), shrink roots on it to radius ``shrink``.

    Reflection keeps |P(e^{jω})| up to a constant factor, so for C and D the noise spectrum shape is kept.
    """
    if p.size <= 1:
        return p
    r = np.roots(p)
    a = np.abs(r)
    if np.all(a < _ROOT_MAX):
        return p
    r = np.where(a > 1.0 + 1e-6, 1.0 / np.conj(r), r)
    a = np.abs(r)
    r = np.where(a >= _ROOT_MAX, r / a * shrink, r)
    q = np.real(np.poly(r))
    return q


def _shifted(dst: np.ndarray, x: np.ndarray, lag: int, sign: float) -> None:
    """dst[t] = sign·x[t − lag] with zeros before (the filters start from rest)."""
    L = x.shape[0]
    lag = min(lag, L)
    dst[:lag] = 0.0
    if sign > 0:
        dst[lag:] = x[:L - lag]
    else:
        np.negative(x[:L - lag], out=dst[lag:])


def _eval(st: _Struct, th: np.ndarray, segs, want_jac: bool):
    """ε and, if asked, J at θ (:func:`_residuals`, :func:`_jacobian`)."""
    eps, aux = _residuals(st, th, segs)
    return eps, (_jacobian(st, segs, aux) if want_jac else None)


def _residuals(st: _Struct, th: np.ndarray, segs):
    """Prediction errors ε (N,), experiments stacked, and what :func:`_jacobian` needs from their
    computation (the search evaluates the loss at a trial point and then, if the step is accepted, the
    Jacobian at the same point).

    ε = (D/C) v, v = y − Σ w_i, w_i = (B_i/F_i) u_i, all filters from rest; with ``st.ic`` the
    estimated free response is taken off (:class:`_IcProjection`).
    """
    B, F, C, D = st.polys(th)
    noise = st.nc > 0 or st.nd > 0
    n = sum(s[0].shape[0] for s in segs)
    eps = np.empty(n)
    parts = []
    r = 0
    for y, u in segs:
        L = y.shape[0]
        v = y.copy()
        ws = []
        for i in range(st.nu):
            w = _filt(B[i], F[i], u[:, i])
            v -= w
            ws.append(w)
        e = _filt(D, C, v) if noise else v
        eps[r:r + L] = e
        ip = None
        if st.ic:
            ip = _IcProjection(st, F, C, D, L)
            ip.project(eps[r:r + L])
        parts.append((v, ws, e, ip))
        r += L
    return eps, (F, C, D, parts)


def _jacobian(st: _Struct, segs, aux) -> np.ndarray:
    """J = ∂ε/∂θ (N, p) from the intermediate results of :func:`_residuals` at the same θ.

    Columns (all filters from rest):
        ∂ε/∂b_{i,j} = −(D/(C F_i)) u_i(t − nk_i − j)
        ∂ε/∂f_{i,k} = +(D/(C F_i)) w_i(t − k)
        ∂ε/∂c_k     = −(1/C) ε(t − k)
        ∂ε/∂d_k     = +(1/C) v(t − k)
    With ``st.ic``, J ← P⊥ J (:class:`_IcProjection`).
    """
    F, C, D, parts = aux
    noise = st.nc > 0 or st.nd > 0
    n = sum(s[0].shape[0] for s in segs)
    J = np.empty((n, st.p), order="F")
    r = 0
    for (_, u), (v, ws, e, ip) in zip(segs, parts):
        L = v.shape[0]
        for i in range(st.nu):
            CF = np.convolve(C, F[i])
            if st.nf[i]:
                xz = _filt(D, CF, np.column_stack((u[:, i], ws[i])), axis=0)
                x, z = xz[:, 0], xz[:, 1]
            else:
                x = _filt(D, CF, u[:, i]) if noise else u[:, i]
            s = st.b_sl(i).start
            for j in range(st.nb[i]):
                _shifted(J[r:r + L, s + j], x, st.nk[i] + j, -1.0)
            s = st.f_sl(i).start
            for k in range(1, st.nf[i] + 1):
                _shifted(J[r:r + L, s + k - 1], z, k, 1.0)
        if st.nc:
            g = _filt(_ONE, C, e)
            for k in range(1, st.nc + 1):
                _shifted(J[r:r + L, st.c_sl.start + k - 1], g, k, -1.0)
        if st.nd:
            h = _filt(_ONE, C, v)
            for k in range(1, st.nd + 1):
                _shifted(J[r:r + L, st.d_sl.start + k - 1], h, k, 1.0)
        if ip is not None:
            ip.kaufman(st, F, C, D, e, J[r:r + L])
            ip.project(J[r:r + L])
        r += L
    return J


_ONE = np.ones(1)


def _unit_impulse(L: int) -> np.ndarray:
    x = np.zeros(L)
    x[0] = 1.0
    return x


class _IcProjection:
    """Variable projection of each experiment's initial filter states and output offset.

    The basis Φ (:meth:`basis`) spans the free responses of every filter's initial state in ε, plus an
    output offset; ε ← P⊥ ε and J ← P⊥ J with P⊥ the projector off its span. For the slow poles of
    governor loops (time constants of minutes) the free response from a not-at-rest start otherwise
    dominates the simulation error of OE/BJ and pulls the fit into wrong minima.

    J ← P⊥ J alone treats Φ as fixed: Jᵀε was 1.5-5 % off the gradient, searches ended in "no descent"
    short of the minimum, and where they ended moved with the rounding of the arithmetic (the same log
    gave Z_u droop 0.0754 or 0.0792 by BLAS kernel). :meth:`kaufman` adds Kaufman's term −P⊥ (∂Φ/∂θ) ĉ,
    which makes the gradient exact (1e-10 against finite differences). The restarts that the stalls used
    to trigger by accident are asked for where they are needed (Z_u: experiments.ZU_MULTISTART).
    """

    RTOL = 1e-10
    """Singular values of Φ below RTOL × the largest count as zero (the basis is then rank-deficient)."""

    def __init__(self, st: _Struct, F, C, D, L: int):
        Phi = self.basis(st, F, C, D, L)
        self.Q, self._coef = self.orthonormal(Phi, coefficients=True,
                                              remake=lambda: self.basis(st, F, C, D, L))

    @classmethod
    def orthonormal(cls, Phi: np.ndarray, coefficients: bool = False, remake=None):
        """An orthonormal basis of Φ's numerical column space (rank by :data:`RTOL`).

        Householder QR (LAPACK geqrf/orgqr directly: their wrapper costs more than these small
        factorisations) is half the time of the SVD that was here, and spans the same space when Φ has
        full rank, which a cheap bound checks first: σ_max/σ_min(R) ≤ ‖R‖_F ‖R⁻¹‖_F. Only when the bound
        fails are R's singular values computed (the same as Φ's); a basis rank-deficient by RTOL takes
        the SVD of Φ as before (its left singular vectors of the kept values). With ``coefficients``
        also M with Φ⁺ = M Qᵀ (R⁻¹, or V S⁻¹ of the kept values): the free-response coefficients of
        Kaufman's term (:meth:`kaufman`). ``remake``: Φ is the caller's to lose, the QR overwrites it
        (no copy of the N×k matrix) and ``remake()`` gives it again for the rare SVD.
        """
        n = Phi.shape[1]
        if n <= Phi.shape[0]:
            qr, tau, _, info = _geqrf(Phi, overwrite_a=int(remake is not None))
            if info == 0:
                R = np.triu(qr[:n])
                Ri = _full_rank_inverse(R, cls.RTOL)
                ok = Ri is not None
                if not ok:
                    sv = np.linalg.svd(R, compute_uv=False)
                    ok = bool(sv[-1] > sv[0] * cls.RTOL)
                if ok:
                    Q, _, info = _orgqr(qr, tau, overwrite_a=1)
                    if info == 0:
                        if not coefficients:
                            return Q
                        if Ri is None:
                            Ri = sla.solve_triangular(R, np.eye(n))
                        return Q, Ri
        if remake is not None:
            Phi = remake()
        U, sv, Vt = np.linalg.svd(Phi, full_matrices=False)
        keep = sv > sv[0] * cls.RTOL
        return (U[:, keep], Vt[keep].T / sv[keep]) if coefficients else U[:, keep]

    def kaufman(self, st: _Struct, F, C, D, e: np.ndarray, J: np.ndarray) -> None:
        """J ← J − ∂(Φ ĉ)/∂θ at fixed ĉ = Φ⁺ e, in place, before the projection: with it Jᵀε is the
        exact gradient of ‖P⊥ e‖² (Kaufman's variable-projection Jacobian).

        Φ ĉ = Σ_i (D/(C F_i)) p_i + (1/C) p_c + const, p the pulse trains with the coefficients ĉ, so
        ∂/∂f_{i,k} = −q⁻ᵏ (1/F_i) s_i with s_i = (D/(C F_i)) p_i; ∂/∂c_k = −q⁻ᵏ (1/C) (Σ s_i + s_c);
        ∂/∂d_k = q⁻ᵏ (1/(C F_i)) p_i summed over i. Without it the search stalled in "no descent" short
        of the minimum at a point that depended on the rounding of the arithmetic (BLAS kernel)."""
        L = e.shape[0]
        coef = self._coef @ (self.Q.T @ e)
        noise = st.nc > 0 or st.nd > 0
        pos = 1
        s_all = np.zeros(L)
        g_all = np.zeros(L)

        def add(col: np.ndarray, x: np.ndarray, lag: int, sign: float) -> None:
            if lag < L:
                col[lag:] += sign * x[:L - lag]

        for i in range(st.nu):
            m = min(max(st.nf[i], st.nk[i] + st.nb[i] - 1), L)
            if m == 0:
                continue
            p = np.zeros(L)
            p[:m] = coef[pos:pos + m]
            pos += m
            g = _filt(_ONE, F[i], p)
            s_i = _filt(D, C, g) if noise else g
            s_all += s_i
            g_all += g
            if st.nf[i]:
                z = _filt(_ONE, F[i], s_i)
                f0 = st.f_sl(i).start
                for k in range(1, st.nf[i] + 1):
                    add(J[:, f0 + k - 1], z, k, 1.0)
        mc = min(max(st.nc, st.nd), L)
        if mc:
            p = np.zeros(L)
            p[:mc] = coef[pos:pos + mc]
            s_all += _filt(_ONE, C, p)
        if st.nc:
            h = _filt(_ONE, C, s_all)
            for k in range(1, st.nc + 1):
                add(J[:, st.c_sl.start + k - 1], h, k, 1.0)
        if st.nd:
            h = _filt(_ONE, C, g_all)
            for k in range(1, st.nd + 1):
                add(J[:, st.d_sl.start + k - 1], h, k, -1.0)

    @staticmethod
    def basis(st: _Struct, F, C, D, L: int) -> np.ndarray:
        """The initial state of B_i/F_i adds to w_i a combination of the responses of 1/F_i to impulses
        at t = 0 .. max(nf_i, nk_i + nb_i − 1) − 1 (seen in ε through D/C); that of D/C adds responses
        of 1/C. A constant column takes the output offset left by removing the means of a not-at-rest
        record."""
        noise = st.nc > 0 or st.nd > 0
        resp = []
        for i in range(st.nu):
            m = min(max(st.nf[i], st.nk[i] + st.nb[i] - 1), L)
            if m == 0:
                continue
            h = _filt(_ONE, F[i], _unit_impulse(L))
            if noise:
                h = _filt(D, C, h)
            resp.append((h, m))
        mc = min(max(st.nc, st.nd), L)
        if mc:
            resp.append((_filt(_ONE, C, _unit_impulse(L)), mc))
        # Fortran order: the columns are written one by one and the QR/SVD take their input column-major
        # (a C-order matrix costs them a transposing copy); the values are the same
        drift = st.drift_pole is not None
        Phi = np.empty((L, 1 + sum(m for _, m in resp) + drift), order="F")
        Phi[:, 0] = 1.0
        if drift:
            # last, so that the impulse columns keep the indices kaufman reads their coefficients from;
            # it does not depend on θ: no Kaufman term
            Phi[:, -1] = _filt(_ONE, np.array([1.0, -float(st.drift_pole)]), np.ones(L))
        c = 1
        for h, m in resp:
            # the responses to impulses at t = 0 .. m−1 of a filter starting from rest are delayed copies
            # of ONE impulse response
            for j in range(m):
                Phi[:j, c + j] = 0.0
                Phi[j:, c + j] = h[:L - j]
            c += m
        return Phi

    def project(self, X: np.ndarray) -> None:
        """X ← P⊥ X in place.

        Not by a dgemm with β = 1 written into X (0.28 → 0.18 ms for Z_ur's 3590×24 J): its rounding
        differs from this form's, and a Z_ur search on the identify bench's window (seed 100) then
        stopped at a point 0.1 % away in the droop under one BLAS kernel and not under the other."""
        X -= self.Q @ (self.Q.T @ X)


_potrf, _potrs = sla.lapack.dpotrf, sla.lapack.dpotrs
_geqrf, _orgqr, _trtri = sla.lapack.dgeqrf, sla.lapack.dorgqr, sla.lapack.dtrtri


def _column_scale(X: np.ndarray) -> np.ndarray:
    """The Euclidean norms of X's columns, 1 for a zero column: the scaling of every least-squares solve
    and factorisation here (equilibrated columns; a zero column is left as it is)."""
    scale = np.sqrt(np.einsum("ij,ij->j", X, X))
    scale[scale == 0] = 1.0
    return scale


def _ls(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least squares by column-scaled normal equations (fast; used for initial values and GN directions).

    Falls back to an SVD solution when the scaled Gram matrix is not numerically positive definite.
    """
    scale = _column_scale(X)
    G = (X.T @ X) / np.outer(scale, scale)
    g = (X.T @ y) / scale
    # LAPACK's Cholesky directly, with the arguments cho_factor/cho_solve(check_finite=False) pass it (the
    # same routines, bit for bit; their wrappers cost more than the solve of these small systems)
    c, info = _potrf(G, lower=0, overwrite_a=0, clean=0)
    if info == 0 and not np.min(np.abs(np.diag(c))) < 1e-7:
        sol, info = _potrs(c, g, lower=0, overwrite_b=0)
        if info == 0:
            return sol / scale
    return np.linalg.lstsq(X / scale, y, rcond=None)[0] / scale


# ===================================================================== search
@dataclass(frozen=True)
class _SearchResult:
    theta: np.ndarray
    ssr: float
    iterations: int
    converged: bool | None
    """The statistical verdict (:func:`_final_verdict`); None while not yet judged (:func:`_judged`)."""
    stop_reason: str
    algorithm: str
    eps: np.ndarray
    """ε at ``theta``, and below what :func:`_jacobian` needs there: the multistart's tests and the
    covariance use them instead of evaluating that point again."""
    aux: tuple
    jac: np.ndarray | None = None
    """J at ``theta`` when the search or the verdict computed it (None: not computed), for the covariance."""


def _gn_step(J: np.ndarray, eps: np.ndarray) -> np.ndarray:
    """Gauss-Newton direction: least-squares solution of J δ ≈ −ε, by an SVD of the column-scaled J.

    Not by the normal equations (:func:`_ls`): they square J's condition number, and in the flat valley
    of a slow pole-zero pair (the drift a power meter's noise leaves in Z_cu's w) the direction's
    component along the valley then carried a rounding error of ~1e-16·cond(J)² that differed by BLAS
    kernel; the searches followed it into different basins. Measured on 13 excited 15-min logs at 0.1 %
    meter noise (held-out-2, -4, -6, -9, seeds 0-2; E, seed 0), SkylakeX vs Haswell: numbers more than
    1e-4 apart 52 → 24 of 507, shown under one kernel only 42 → 3 (the rest: :data:`GUARD_PINNED`). The
    SVD costs 5-10× the normal equations' solve: Z_cu +11 %, Z_ur +27 % CPU on `./dev bench identify`'s
    window (docs/identify.md, session 20).
    """
    scale = _column_scale(J)
    return np.linalg.lstsq(J / scale, -eps, rcond=None)[0] / scale


STAT_TOL = 1e-3
"""A search counts as converged when the loss decrease a full Gauss-Newton step still predicts is below
STAT_TOL·V/N: it would change the likelihood-ratio statistic N·ΔV/V by less than STAT_TOL, which is
statistically nothing, and it is orders of magnitude above the rounding of V (~1e-13·V). The search
itself runs on to ``tol``; only the verdict uses this, so a verdict (and with it the multistart's
restarts) does not hinge on whether the last step lowered the loss by a rounding error."""
SAME_LOSS = 1e-2
"""Two searches whose N·log(V_a/V_b) is below this reached the same loss to statistical accuracy: the
multistart keeps the earlier start (a deterministic tie-break instead of a rounding coin toss)."""


def _predicted(J: np.ndarray, eps: np.ndarray) -> float:
    """Loss decrease a full Gauss-Newton step predicts at the point of (J, eps); inf if it cannot."""
    try:
        delta = _gn_step(J, eps)
    except (np.linalg.LinAlgError, ValueError):
        return np.inf
    return float(np.sum((J @ delta) ** 2)) if np.all(np.isfinite(delta)) else np.inf


def _final_verdict(st: _Struct, th: np.ndarray, eps: np.ndarray, aux, segs, V: float,
                   J: np.ndarray | None = None) -> tuple[bool, np.ndarray | None]:
    """Converged to statistical accuracy (:data:`STAT_TOL`): the Gauss-Newton predicted decrease at θ.

    Returns the verdict and J at θ (``J`` when given, computed otherwise; None if that failed)."""
    if not (np.isfinite(V) and V > 0):
        return False, J
    if J is None:
        try:
            J = _jacobian(st, segs, aux)
        except (np.linalg.LinAlgError, ValueError):
            return False, None
    return _predicted(J, eps) <= STAT_TOL * V / eps.shape[0], J


def _search(st: _Struct, th0: np.ndarray, segs, maxiter: int = 100, tol: float = 1e-10,
            beat: float | None = None) -> _SearchResult:
    """Gauss-Newton with step halving and stability guard; Levenberg-Marquardt fallback.

    ``converged`` of the result is True when the iteration stopped on "predicted relative loss decrease
    below tolerance" (or :data:`BEATEN`), otherwise None: the statistical verdict of
    :func:`_final_verdict` at the end point is computed by :func:`_judged` only for the search the
    multistart keeps (it costs a Jacobian).

    ``beat``: the sum of squares another start already reached. A search whose point is converged to
    statistical accuracy (:data:`STAT_TOL`) with a loss above it by more than :data:`SAME_LOSS` stops
    there (:func:`_beaten`): it cannot become the start the multistart keeps, and the last decades of
    the loss that ``tol`` asks for are wasted on it (Z_ur's seven searches on two bench windows: 269 → 223
    and 344 → 236 Jacobians, the identification unchanged)."""
    r = _search_iter(st, th0, segs, maxiter, tol, beat)
    if st.drift_pole is not None and not r.stop_reason.startswith(("predicted", BEATEN)):
        r = _polish_on_guard(st, r, segs, maxiter, tol)
    # "predicted decrease below tol·V" implies the verdict (tol·V ≪ STAT_TOL·V/N); every other stop
    # (a last step that lowered V by ~1e-10 relative, LM without descent, the iteration limit) is judged
    # at the end point, not by how the last step's rounding fell
    ok = True if r.stop_reason.startswith(("predicted", BEATEN)) else None
    return _SearchResult(r.theta, r.ssr, r.iterations, ok, r.stop_reason, r.algorithm, r.eps, r.aux, r.jac)


def _halving(st: _Struct, th: np.ndarray, delta: np.ndarray, segs, V: float, tries: int,
             project: Callable[[np.ndarray], np.ndarray] | None = None):
    """Step halving along ``delta`` from θ (each candidate through ``project`` when given): the first
    stable candidate with a loss below V as (θ', ε', aux', V', μ), or None after ``tries`` halvings."""
    mu = 1.0
    for _ in range(tries):
        cand = th + mu * delta
        if project is not None:
            cand = project(cand)
        if _stable(st, cand):
            e2, aux2 = _residuals(st, cand, segs)
            V2 = float(e2 @ e2)
            if V2 < V:
                return cand, e2, aux2, V2, mu
        mu *= 0.5
    return None


GUARD_PINNED = 1e-4
"""A real root within this of the unit circle (|r| ≥ 1 − GUARD_PINNED; the guard is at 1 − 1e-7) counts as
pinned at the stability guard by a search that stopped without converging (:func:`_polish_on_guard`).
Why 1e-4 (1e-6 until session 20): Levenberg-Marquardt stops with "no descent even with maximal damping"
where every step it can take pushes the root through the guard, leaving the root 1e-7 … 1e-5 inside it,
where the rounding had taken it, and the other parameters unconverged. At 1e-6 whether such a root was
held (and the rest polished) was a coin toss: a jackknife refit of held-out-4 (Kd = 0, 0.1 % meter noise,
15 min, seed 1) ended at 1 − 1e-7, held, under SkylakeX and at 1 − 1.2e-6, not held, under Haswell
(max|S|'s interval [1.01, 1.71] vs [0.89, 1.82]). With the Gauss-Newton step by SVD (:func:`_gn_step`) and
1e-4, the zoo's seven plants and held-out-0 … 11 (excited, ideal and 0.1 % meter noise, 15/30 min, seeds
0-2; 228 logs, 8892 numbers), SkylakeX vs Haswell: 2 numbers more than 1e-4 apart (4e-4), none more than
1 %, none shown under one kernel only (normal equations and 1e-6: 80 more than 1e-4, 45 more than 1 %,
42 shown under one kernel only). Haswell vs Sandybridge: 33 / 12 / 0 → 3 / 2 / 27, the 27 on one log
(held-out-9, 15 min, seed 0: a start that finds a lower basin under one rounding only). Before the SVD
step, 1e-5 had not helped (the zoo's G, 0.1 %, 30 min, seed 3: a jackknife refit stalled over a zero next
to the root, held or not)."""
_GUARD_HOLD = _ROOT_MAX * (1.0 - 1e-8)
"""Where :func:`_polish_on_guard` holds a pinned root: just inside the guard, so every point it tries is
stable by :func:`_stable`'s test. Not at the root's own place: on the zoo's G (0.1 % meter noise, 30 min,
seed 2) a root between 1 − 1e-6 and the guard, held where each kernel's search had left it, put the
intervals of the peaks 1.7e-3 apart (held at the guard: 1e-4)."""


_MULTI_HOLD = 1.0 - 1e-5
"""Where :func:`_polish_on_guard` holds two or more real roots pinned at the guard on the same side: an
m-fold root there. Deeper inside than :data:`_GUARD_HOLD` because a multiple root's computed roots
spread by ~(rounding)^(1/m) (1e-8 for a double root), and the stability test must pass at every point
the held search tries; still within :data:`GUARD_PINNED`, so such a fit still counts as pinned."""
GUARD_ROUNDS = 4
"""How many times :func:`_polish_on_guard` adds the roots that reached the guard while it ran and holds
them too (an active set: a held search stopped "no descent" by a second root pressing against the
guard)."""


def _pinned(st: _Struct, th: np.ndarray) -> list[tuple[slice, float, int]]:
    """The F polynomials of θ with real roots pinned at the guard: (slice, where to hold them, how many),
    one entry per polynomial and side; one root is held at ±:data:`_GUARD_HOLD`, several as a multiple root
    at ±:data:`_MULTI_HOLD`. Not C and D: Z_u's noise models press a root of C against the
    guard on most windows, and continuing those searches (to losses up to 20 % lower, each to its
    iteration limit) made Z_u 2.9× slower on `bench identify`'s window (0.65 → 1.86 s) with its
    identifications not yet validated on the zoo; they stay as they were (docs/identify.md)."""
    out = []
    for sl in [st.f_sl(i) for i in range(st.nu)]:
        a = th[sl]
        if a.size == 0:
            continue
        r = np.roots(np.r_[1.0, a])
        for sign in (1.0, -1.0):
            m = int(np.sum((np.abs(r.imag) <= 1e-6) & (sign * r.real >= 1.0 - GUARD_PINNED)))
            if m:
                out.append((sl, sign * (_GUARD_HOLD if m == 1 else _MULTI_HOLD), m))
    return out


def _pin_constraints(pins: list[tuple[slice, float, int]], p: int) -> tuple[np.ndarray, np.ndarray]:
    """A θ = b: each pinned polynomial P(z) = zⁿ + a₁zⁿ⁻¹ + … + aₙ has an m-fold root at z, i.e.
    P⁽ʲ⁾(z) = 0 for j < m, linear in a; rows scaled to unit norm."""
    rows, rhs = [], []
    for sl, z, m in pins:
        n = sl.stop - sl.start
        for j in range(m):
            row = np.zeros(p)
            row[sl] = [math.perm(n - k, j) * z ** (n - k - j) if n - k >= j else 0.0 for k in range(1, n + 1)]
            nrm = float(np.linalg.norm(row))
            rows.append(row / nrm)
            rhs.append(-math.perm(n, j) * z ** (n - j) / nrm)
    return np.array(rows), np.array(rhs)


def _held_search(st: _Struct, th: np.ndarray, A: np.ndarray, b: np.ndarray, segs, maxiter: int, tol: float):
    """Gauss-Newton from θ on A θ = b (in the null space of A, each candidate projected back: the
    null-space steps drift off it by rounding): (θ, ε, aux, V, J, iterations, why it stopped), or None
    where θ's projection is not stable."""
    AAt = A @ A.T

    def project(x: np.ndarray) -> np.ndarray:
        return x + A.T @ np.linalg.solve(AAt, b - A @ x)

    th = project(th)
    Z = np.linalg.qr(A.T, mode="complete")[0][:, A.shape[0]:]
    if not _stable(st, th):
        return None
    eps, aux = _residuals(st, th, segs)
    V = float(eps @ eps)
    J = _jacobian(st, segs, aux)
    it = 0
    why = f"maximum number of iterations ({maxiter}) reached"
    while it < maxiter:
        it += 1
        JZ = J @ Z
        eta = _gn_step(JZ, eps)
        if not np.all(np.isfinite(eta)):
            why = "no Gauss-Newton direction"
            break
        if float(np.sum((JZ @ eta) ** 2)) <= tol * V:
            why = "predicted relative loss decrease below tolerance"
            break
        step = _halving(st, th, Z @ eta, segs, V, 30, project)
        if step is None:
            why = "no descent"
            break
        th, eps, aux, V = step[:4]
        J = _jacobian(st, segs, aux)
    return th, eps, aux, V, J, it, why


def _polish_on_guard(st: _Struct, r: _SearchResult, segs, maxiter: int, tol: float) -> _SearchResult:
    """A search that stopped without converging, with real roots of F pinned at the stability guard (the
    turbine path of Z_cu following the meter noise's random walk), continued
    with those roots held just inside the guard: Gauss-Newton in the null space of the linear constraints
    P(±ρ) = 0 (and P⁽ʲ⁾(±ρ) = 0 for a root held m-fold) on the polynomial's coefficients, to ``tol``.
    Where that stops "no descent" with more roots at the guard than it holds, it holds those too and goes
    on (:data:`GUARD_ROUNDS`).

    Why: at the guard every step with an outward part is refused, Levenberg-Marquardt damps the steps
    until no decrease registers and stops ("no descent even with maximal damping") where the rounding
    of the refused steps took the other parameters. On the zoo's A (0.1 % meter noise, 15 min, seed 1) the
    two-rate check's fit at 0.125 s ended 1e-2 apart in θ (loss 7e-4 apart) under two BLAS kernels and
    the interval ends of max|S| 1.4 % apart. Held, the rest of θ is a smooth problem with one minimum
    that both reach. Several roots (session 21): a fit with two drift poles (the (5, 4) drift refit) had
    both at the guard and only one held, the other pressing on it; the held search stopped "no descent"
    where the rounding left it, and held-out-30 (0.1 % meter noise, 30 min, seed 1) showed max|S|, max|G_1|
    and G_p more than 1 % apart under SkylakeX and Haswell (20 numbers). Held as a double root, both
    kernels' searches converge to one point. Only in the fits with a drift pole (Z_cu's G_t with the swing
    pole held, :class:`fcrlive.analysis.experiments.SwingPole`), where it was measured: on Z_u's 10-min
    0-dB record of tests/test_identify_quality.py it took the droop's interval from [0, 11.8] % to none
    (no covariance at the held point); Z_u's fits are left as they were until validated. The verdict is
    left to :func:`_judged` (a point on the guard is not a converged fit: the meter-noise replicates leave
    such refits out); kept only where its loss is not above the stalled point's."""
    pins = _pinned(st, r.theta)
    th, held, its, why = r.theta, None, 0, ""
    for _ in range(GUARD_ROUNDS):
        if not pins:
            break
        A, b = _pin_constraints(pins, th.size)
        if A.shape[0] >= th.size:
            break
        out = _held_search(st, th, A, b, segs, maxiter - its, tol)
        if out is None:
            break
        held = out
        th, its, why = out[0], its + out[5], out[6]
        more = _pinned(st, th)
        if why != "no descent" or sum(m for *_, m in more) <= sum(m for *_, m in pins):
            break
        pins = more
    if held is None or r.ssr < held[3]:
        return r
    th, eps, aux, V, J = held[:5]
    return _SearchResult(th, V, r.iterations + its, None,
                         f"{r.stop_reason}; held on the stability guard: {why}", r.algorithm + "+held", eps,
                         aux, J)


def _judged(st: _Struct, r: _SearchResult, segs) -> _SearchResult:
    """``r`` with its verdict (:func:`_final_verdict`) and J at its end point."""
    if r.converged is not None:
        return r
    ok, J = _final_verdict(st, r.theta, r.eps, r.aux, segs, r.ssr, r.jac)
    return _SearchResult(r.theta, r.ssr, r.iterations, bool(ok), r.stop_reason, r.algorithm, r.eps, r.aux, J)


BEATEN = "statistically converged above another start's loss"
"""Stop reason of a search ended by :func:`_beaten`."""


def _beaten(V: float, pred, n: int, beat: float | None) -> bool:
    """A search at loss V whose full Gauss-Newton step predicts a decrease ``pred`` cannot end below
    ``beat`` by :data:`SAME_LOSS`: N·log(V/beat) > SAME_LOSS and pred ≤ STAT_TOL·V/N (converged to
    statistical accuracy). Even a remaining decrease ten times the predicted one changes N·log V by at
    most 10·STAT_TOL = SAME_LOSS, so the multistart's choice is the same as if the search had run on to
    ``tol``. ``pred`` may be a function giving it: called only when the loss test passes (a prediction
    costs Levenberg-Marquardt a least-squares solve)."""
    if not (beat is not None and beat > 0.0 and V > 0.0 and n * math.log(V / beat) > SAME_LOSS):
        return False
    return (pred() if callable(pred) else pred) <= STAT_TOL * V / n


def _search_iter(st: _Struct, th0: np.ndarray, segs, maxiter: int, tol: float,
                 beat: float | None = None) -> _SearchResult:
    th = th0.copy()
    eps, aux = _residuals(st, th, segs)
    J = _jacobian(st, segs, aux)
    V = float(eps @ eps)
    it = 0
    algorithm = "gn"
    reason = f"maximum number of iterations ({maxiter}) reached"
    converged = False
    use_lm = False
    while it < maxiter:
        it += 1
        if not use_lm:
            delta = _gn_step(J, eps)
            pred = float(np.sum((J @ delta) ** 2))
            if not np.all(np.isfinite(delta)):
                use_lm = True
                continue
            if pred <= tol * V:
                converged, reason = True, "predicted relative loss decrease below tolerance"
                break
            if _beaten(V, pred, eps.shape[0], beat):
                converged, reason = True, BEATEN
                break
            step = _halving(st, th, delta, segs, V, 20)
            if step is None:
                use_lm = True
                algorithm = "gn+lm"
                it -= 1
                continue
            cand, e2, aux2, V2, mu = step
            rel = (V - V2) / V
            th = cand
            eps, V, aux = e2, V2, aux2
            J = _jacobian(st, segs, aux)
            if rel <= tol and mu * np.linalg.norm(delta) <= 1e-8 * (1 + np.linalg.norm(th)):
                if _predicted(J, eps) <= STAT_TOL * V / eps.shape[0]:
                    converged, reason = True, "relative loss decrease and step below tolerance"
                    break
                # a short step in a curved valley, not a minimum: where it stopped here depended on
                # the rounding of the step halving (BLAS kernel); Levenberg-Marquardt walks the valley
                use_lm = True
                algorithm = "gn+lm"
        else:
            th, V, k, converged, reason, eps, aux, J = _lm(st, th, eps, aux, J, V, segs, maxiter - it + 1,
                                                           tol, beat)
            it += k
            break
    return _SearchResult(th, V, it, converged, reason, algorithm, eps, aux, J)


def _lm(st, th, eps, aux, J, V, segs, maxiter, tol, beat=None):
    """Levenberg-Marquardt (Marquardt diagonal scaling) with the same stability guard; ``beat`` as in
    :func:`_search` (judged after each accepted step, by the Gauss-Newton prediction there)."""
    H = J.T @ J
    g = J.T @ eps
    dg = np.diag(H).copy()
    dg[dg == 0] = 1.0
    lam = 1e-3
    k = 0
    while k < maxiter:
        k += 1
        try:
            delta = -np.linalg.solve(H + lam * np.diag(dg), g)
        except np.linalg.LinAlgError:
            lam *= 10
            continue
        cand = th + delta
        ok = _stable(st, cand)
        if ok:
            e2, aux2 = _residuals(st, cand, segs)
            V2 = float(e2 @ e2)
            ok = V2 < V
        if ok:
            rel = (V - V2) / V
            th, V, eps, aux = cand, V2, e2, aux2
            J = _jacobian(st, segs, aux)
            if rel <= tol and _predicted(J, eps) <= STAT_TOL * V / eps.shape[0]:
                return (th, V, k, True, "Levenberg-Marquardt: relative loss decrease below tolerance", eps,
                        aux, J)
            if _beaten(V, lambda J=J, eps=eps: _predicted(J, eps), eps.shape[0], beat):
                return th, V, k, True, BEATEN, eps, aux, J
            H = J.T @ J
            g = J.T @ eps
            dg = np.diag(H).copy()
            dg[dg == 0] = 1.0
            lam = max(lam / 5, 1e-12)
        else:
            lam *= 8
            if lam > 1e12:
                # no direction lowers the loss even with tiny steps: a (local) minimum to working accuracy
                gn = float(np.abs(g).max() / np.sqrt(V + 1e-300))
                return th, V, k, gn < 1e-6 * np.sqrt(np.diag(H).max()), (
                    "Levenberg-Marquardt: no descent even with maximal damping"
                ), eps, aux, J
    return (th, V, k, False, f"Levenberg-Marquardt: maximum number of iterations ({maxiter}) reached", eps,
            aux, J)


# ===================================================================== initial values
def _sm(segs_target, nb: int, nf: int, nk: int, iters: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """Steiglitz-McBride for y ≈ B/F u (SISO). ``segs_target`` = list of (u_seg, y_seg)."""
    F = np.ones(1)
    B = np.zeros(nk + nb)
    p = nb + nf
    for _ in range(iters if nf else 1):
        rows = []
        for us, ys in segs_target:
            uf = _filt([1.0], F, us)
            yf = _filt([1.0], F, ys)
            L = ys.shape[0]
            n0 = max(nf, nk + nb - 1)
            if L - n0 <= 0:
                continue
            X = np.empty((L - n0, p + 1))
            for k in range(1, nf + 1):
                X[:, k - 1] = -yf[n0 - k:L - k]
            for j in range(nb):
                X[:, nf + j] = uf[n0 - nk - j:L - nk - j]
            X[:, p] = yf[n0:]
            rows.append(X)
        X = np.vstack(rows)
        sol = _ls(X[:, :p], X[:, p])
        if not np.all(np.isfinite(sol)):
            break
        Fn = _reflect(np.concatenate(([1.0], sol[:nf])))
        Bn = np.concatenate((np.zeros(nk), sol[nf:]))
        done = Fn.size == F.size and np.max(np.abs(Fn - F)) < 1e-9
        F, B = Fn, Bn
        if done:
            break
    return B, F


def _hannan_rissanen(v_segs, nc: int, nd: int, n_ar: int) -> tuple[np.ndarray, np.ndarray]:
    """C, D of v = C/D e: long AR for ê, then least squares of v on past v and past ê."""
    if nc == 0 and nd == 0:
        return np.ones(1), np.ones(1)
    ehat = []
    rows = []
    # long AR fitted on all experiments together
    Xs = []
    for v in v_segs:
        L = v.shape[0]
        if n_ar >= L:
            continue
        X = np.empty((L - n_ar, n_ar + 1))
        for k in range(1, n_ar + 1):
            X[:, k - 1] = -v[n_ar - k:L - k]
        X[:, n_ar] = v[n_ar:]
        Xs.append(X)
    X = np.vstack(Xs)
    a = _ls(X[:, :-1], X[:, -1])
    Aar = np.concatenate(([1.0], a))
    for v in v_segs:
        ehat.append(_filt(Aar, [1.0], v))
    m = max(nc, nd)
    for v, e in zip(v_segs, ehat):
        L = v.shape[0]
        n0 = n_ar + m
        if n0 >= L:
            continue
        X = np.empty((L - n0, nc + nd + 1))
        for k in range(1, nc + 1):
            X[:, k - 1] = e[n0 - k:L - k]
        for k in range(1, nd + 1):
            X[:, nc + k - 1] = -v[n0 - k:L - k]
        X[:, -1] = v[n0:] - e[n0:]
        rows.append(X)
    X = np.vstack(rows)
    sol = _ls(X[:, :-1], X[:, -1])
    C = _reflect(np.concatenate(([1.0], sol[:nc])))
    D = _reflect(np.concatenate(([1.0], sol[nc:])))
    return C, D


def _add_noise_model(st: _Struct, segs, Bs, Fs, n_ar: int) -> np.ndarray:
    """θ from B_i/F_i plus Hannan-Rissanen C/D on the output residual v = y − Σ B_i/F_i u_i."""
    v_segs = []
    for y, u in segs:
        v = y.copy()
        for i in range(st.nu):
            v -= _filt(Bs[i], Fs[i], u[:, i])
        v_segs.append(v)
    C, D = _hannan_rissanen(v_segs, st.nc, st.nd, n_ar)
    return st.pack(Bs, Fs, C, D)


START_CACHE_SETS = 2
"""Data sets whose high-order ARX models, Steiglitz-McBride starts and first searches :func:`_pem` keeps
(Z_u fits five candidate orders on one data set: the same ARX for each, the same B/F start for equal nb,
nf; Z_ur's pre-check searches from the first start once, its multistart reuses that search)."""
_START_CACHE: OrderedDict = OrderedDict()


def _start_cache(data: IdData) -> dict:
    """The cache of start models for ``data``, by content (the arrays as bytes: a data set equal sample
    for sample gets the same starts, a changed one never the old ones), the last START_CACHE_SETS."""
    key = (data.Ts, data.starts, data.u.shape, data.y.tobytes(), data.u.tobytes())
    c = _START_CACHE.get(key)
    if c is None:
        c = _START_CACHE[key] = {}
        while len(_START_CACHE) > START_CACHE_SETS:
            _START_CACHE.popitem(last=False)
    else:
        _START_CACHE.move_to_end(key)
    return c


def _cached(cache: dict | None, key, make):
    """``cache[key]``, made by ``make()`` on a miss (no cache: ``make()``)."""
    if cache is None:
        return make()
    v = cache.get(key)
    if v is None:
        v = cache[key] = make()
    return v


def _start_simulated(st: _Struct, segs, ha: PolyModel, n_ar: int, cache: dict | None = None,
                     tag=None) -> np.ndarray:
    """Start 1: Steiglitz-McBride of each B_i/F_i on the high-order ARX's noise-free output of u_i.

    ``cache``/``tag``: :func:`_start_cache` and the key of ``ha`` in it (the B_i/F_i are kept by orders)."""
    Bs, Fs = [], []
    # a high-order ARX fitted in closed loop can have an unstable A: simulate with A's roots reflected
    # inside (|A| scaled by 1/Π|r|, compensated on B) so the noise-free output stays bounded
    A = ha.a
    gain = 1.0
    if _max_root(A) >= _ROOT_MAX:
        r = np.roots(A)
        gain = float(np.prod(np.maximum(np.abs(r), 1.0)))
        A = _reflect(A)
    for i in range(st.nu):
        def sm(i=i):
            tgt = [(u[:, i], _filt(ha.b[i] / gain, A, u[:, i])) for _, u in segs]
            return _sm(tgt, st.nb[i], st.nf[i], st.nk[i])
        B, F = _cached(cache, ("sm", tag, i, st.nb[i], st.nf[i], st.nk[i]), sm)
        Bs.append(B)
        Fs.append(F)
    return _add_noise_model(st, segs, Bs, Fs, n_ar)


def _start_whitened(st: _Struct, segs, ha: PolyModel, n_ar: int, cache: dict | None = None,
                    tag=None) -> np.ndarray:
    """Start 2: Steiglitz-McBride on the ARX-whitened data (A_h y, A_h u); inputs in turn (backfitting).
    ``cache``/``tag`` as :func:`_start_simulated`."""
    Bs, Fs = _cached(cache, ("whitened", tag, st.nb, st.nf, st.nk), lambda: _whitened_bf(st, segs, ha))
    return _add_noise_model(st, segs, list(Bs), list(Fs), n_ar)


def _whitened_bf(st: _Struct, segs, ha: PolyModel) -> tuple[list, list]:
    nu = st.nu
    wsegs = [(_filt(ha.a, [1.0], y), _filt(ha.a, [1.0], u, axis=0)) for y, u in segs]
    Bs = [np.zeros(st.nk[i] + st.nb[i]) for i in range(nu)]
    Fs = [np.ones(1) for _ in range(nu)]
    for _sweep in range(2 if nu > 1 else 1):
        for i in range(nu):
            tgt = []
            for yw, uw in wsegs:
                t = yw.copy()
                for j in range(nu):
                    if j != i:
                        t -= _filt(Bs[j], Fs[j], uw[:, j])
                tgt.append((uw[:, i], t))
            Bs[i], Fs[i] = _sm(tgt, st.nb[i], st.nf[i], st.nk[i])
    return Bs, Fs


def _real_roots(st: _Struct, th: np.ndarray) -> np.ndarray:
    """A restart with every complex pair of F_i replaced by two real roots ρ and ρ⁸ (ρ its radius).

    A lightly damped complex pair near z = 1 is a typical local minimum when the true slow poles are
    real (seen on the hard closed-loop case); the static gain is kept.
    """
    B, F, C, D = st.polys(th)
    B2, F2 = [], []
    for i in range(st.nu):
        r = np.roots(F[i]) if F[i].size > 1 else np.zeros(0)
        cplx = r[np.abs(r.imag) > 1e-9]
        if cplx.size == 0:
            B2.append(B[i])
            F2.append(F[i])
            continue
        real = list(r[np.abs(r.imag) <= 1e-9].real)
        for z in cplx[cplx.imag > 0]:
            rho = min(abs(z), 0.995)
            real += [rho, rho**8]
        Fi = np.real(np.poly(real))
        B2.append(B[i] * (np.sum(Fi) / np.sum(F[i]) if np.sum(F[i]) != 0 else 1.0))
        F2.append(Fi)
    return st.pack(B2, F2, C, D)


def _perturbed(st: _Struct, th: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A restart near ``th``: F_i, C and D roots moved radially (kept inside), B rescaled to keep DC."""
    B, F, C, D = st.polys(th)

    def move(p):
        if p.size <= 1:
            return p
        r = np.roots(p)
        rad = np.abs(r)
        # scale the log-distance of every root to the unit circle by a random factor in [1/e, e]
        dist = -np.log(np.maximum(1 - rad, 1e-6))
        # one factor per polynomial keeps complex-conjugate pairs conjugate
        dist *= np.exp(rng.uniform(-1.0, 1.0))
        new_rad = np.clip(1 - np.exp(-dist), 0.0, 0.995)
        r = np.where(rad > 0, r / np.where(rad > 0, rad, 1) * new_rad, r)
        return np.real(np.poly(r))

    F2, B2 = [], []
    for i in range(st.nu):
        Fi = move(F[i])
        g_old = np.sum(F[i])
        g_new = np.sum(Fi)
        B2.append(B[i] * (g_new / g_old if g_old != 0 else 1.0))
        F2.append(Fi)
    return st.pack(B2, F2, move(C), move(D))


# ===================================================================== public estimators
def _check_orders(data: IdData, nb, nc, nd, nf, nk, method: str, ic: str = "zero",
                  drift_pole: float | None = None) -> _Struct:
    nu = data.nu
    nb = per_input(nb, nu, "nb")
    nf = per_input(nf, nu, "nf")
    nk = per_input(nk, nu, "nk")
    nc, nd = int(nc), int(nd)
    if nc < 0 or nd < 0:
        raise OrderError(f"nc = {nc} and nd = {nd} must be non-negative")
    for i, m in enumerate(nb):
        if m < 1:
            raise OrderError(
                f"nb = {m} for input {data.input_names[i]!r}: {method} needs at least one B coefficient "
                "per input (drop the input instead)"
            )
    if ic not in ("zero", "estimate"):
        raise ValueError(f"ic = {ic!r}: use 'zero' or 'estimate'")
    if drift_pole is not None:
        if ic != "estimate":
            raise ValueError("drift_pole needs ic='estimate' (it is one more column of that projection)")
        if not 0.0 <= drift_pole <= 1.0:
            raise ValueError(f"drift_pole = {drift_pole}: must be in [0, 1]")
    st = _Struct(nb, nc, nd, nf, nk, ic == "estimate", None if drift_pole is None else float(drift_pole))
    return st


def _ordered_model(st: _Struct, th: np.ndarray, data: IdData, cov, lam, report) -> PolyModel:
    B, F, C, D = st.polys(th)
    return PolyModel(a=np.ones(1), b=tuple(B), c=C, d=D, f=tuple(F), nk=st.nk, Ts=data.Ts,
                     noise_variance=lam, covariance=cov, input_names=data.input_names,
                     output_name=data.output_name, report=report)


def _from_init(st: _Struct, init: PolyModel) -> np.ndarray:
    if init.na != 0:
        raise OrderError(f"initial model has na = {init.na}; OE/BJ models have A = 1")
    if init.nb != st.nb or init.nf != st.nf or init.nc != st.nc or init.nd != st.nd or init.nk != st.nk:
        raise OrderError(
            f"initial model orders nb={init.nb} nc={init.nc} nd={init.nd} nf={init.nf} nk={init.nk} differ "
            f"from nb={st.nb} nc={st.nc} nd={st.nd} nf={st.nf} nk={st.nk}"
        )
    B, F, C, D = list(init.b), list(init.f), init.c, init.d
    names = [*(f"F_{i + 1}" for i in range(st.nu)), "C", "D"]
    polys = [*F, C, D]
    fixed = []
    for name, p in zip(names, polys):
        if not np.all(np.isfinite(p)):
            raise UnstableModelError(f"initial {name} = {p} has non-finite coefficients")
        if p.size > 1:
            r = np.abs(np.roots(p))
            if np.any(np.abs(r - 1.0) <= 1e-6):
                raise UnstableModelError(
                    f"initial {name} has a root on the unit circle (|z| = {r.max():.6f}, e.g. an "
                    "integrator): it cannot be stabilised by reflection; give a stable initial model"
                )
        fixed.append(_reflect(p))
    F = fixed[:st.nu]
    C, D = fixed[st.nu], fixed[st.nu + 1]
    return st.pack(B, F, C, D)


def _pem(data: IdData, st: _Struct, method: str, *, init: PolyModel | None, multistart: bool | str,
         n_high: int | None, maxiter: int, tol: float, seed: int, covariance: str = "gauss",
         beat: float | None = None) -> PolyModel:
    if covariance not in ("gauss", "sandwich"):
        raise ValueError(f"covariance = {covariance!r}: use 'gauss' or 'sandwich'")
    data.require_finite()
    data.require_exciting()
    n = data.N
    if n <= st.p + 1:
        raise TooFewSamplesError(
            f"{n} samples for {st.p} parameters of {method.upper()}(nb={list(st.nb)}, nc={st.nc}, "
            f"nd={st.nd}, nf={list(st.nf)}, nk={list(st.nk)})",
            where=f"output {data.output_name!r}",
        )
    segs = list(data.segments())
    lmin = min(data.lengths)
    if n_high is None:
        # long enough to whiten slow noise and capture slow poles, short enough for the data
        n_high = int(np.clip(n // (40 * (data.nu + 1)), 4, 30))
    n_high = int(min(n_high, max(1, (n - 1) // (2 * (data.nu + 1)) - 1), max(1, lmin // 3)))
    arx_loss = np.nan
    arx_rows = np.zeros(0, int)
    lr_limit = np.inf
    n_ar = int(min(n_high, max(2, lmin // 4)))
    lazy = []
    shorter = None
    if init is not None:
        starts = [_from_init(st, init)]
    else:
        cache = _start_cache(data)

        def arx_cached(na: int, nb: int):
            key = ("arx", na, nb, st.nk)
            return key, _cached(cache, key, lambda: arx(data, na, nb, st.nk))

        tag, ha = arx_cached(max(n_high, max(st.nf) + max(st.nb), 2), max(n_high, max(st.nb) + 1))
        arx_loss = ha.report.loss
        # the rows the ARX loss is computed on (its initial samples of each experiment left out)
        n0 = max(ha.na, *(k + m - 1 for k, m in zip(ha.nk, ha.nb)))
        arx_rows = np.concatenate([np.arange(a + n0, b) for a, b in data.bounds])
        lr_limit = float(stats.chi2.ppf(0.95, max(ha.n_params - st.p, 1)))
        starts = [_start_simulated(st, segs, ha, n_ar, cache, tag)]
        lazy.append(lambda: _start_whitened(st, segs, ha, n_ar, cache, tag))
        if ha.na > 8:
            # a shorter whitening ARX leads the Steiglitz-McBride start into another basin at times
            def shorter():
                tag_s, ha_s = arx_cached(max(ha.na // 2, max(st.nf) + max(st.nb), 2),
                                         max(ha.nb[0] // 2, max(st.nb) + 1))
                return _start_simulated(st, segs, ha_s, n_ar, cache, tag_s)
            lazy.append(shorter)
    if not np.all(np.isfinite(starts[0])) or not _stable(st, starts[0]):
        raise UnstableModelError(f"initial {method.upper()} model could not be stabilised")
    # The first search is kept with the starts: a caller that fits the same data and orders once with
    # one start and again with every start (analysis.experiments.zur's pre-check) searches from this start
    # once; the search is a function of the start, so the result is the same either way.
    beat_ssr = None if beat is None else beat * n
    first = lambda: _search(st, starts[0], segs, maxiter, tol, beat_ssr)  # noqa: E731
    key = ("search", st, starts[0].tobytes(), maxiter, tol, beat_ssr)
    results: list[_SearchResult] = [first() if init is not None else _cached(cache, key, first)]
    best = results[0]

    def run(s: np.ndarray) -> None:
        nonlocal best
        if not (np.all(np.isfinite(s)) and _stable(st, s)):
            return
        r = _search(st, s, segs, maxiter, tol, beat=best.ssr if beat_ssr is None else min(best.ssr, beat_ssr))
        results.append(r)
        # a later start replaces the best only when its loss is lower to statistical accuracy
        # (SAME_LOSS), so which of two equally good end points is kept does not depend on rounding
        if r.ssr < best.ssr and n * math.log(best.ssr / r.ssr) > SAME_LOSS:
            best = r

    def stalled(r: _SearchResult) -> bool:
        nonlocal best
        if r is best:
            r = best = _judged(st, best, segs)
        if not r.converged:
            return True
        # a root pinned at the stability boundary: the search was stopped by the guard, not by a minimum
        _, F, C, D = st.polys(r.theta)
        if max(_max_root(q) for q in (*F, C, D)) > 1.0 - 1e-4:
            return True
        if not (np.isfinite(arx_loss) and method == "bj"):
            return False
        # likelihood-ratio test of the BJ fit against the high-order ARX on the same rows: at the global
        # minimum of a right structure N·log(V_bj/V_arx) ~ χ²(p_arx − p_bj); far above it means a local
        # minimum (or too low orders, in which case the restarts only cost time)
        v_bj = float(np.mean(r.eps[arx_rows] ** 2))
        return bool(arx_rows.size * np.log(v_bj / arx_loss) > lr_limit)

    if multistart == "auto" and method == "bj" and shorter is not None:
        # A BJ fit's wrong basin can pass every test of stalled(): converged, and the LR test against
        # the high-order ARX is weak when that ARX itself fits poorly. Z_u (five BJ orders, 15 min,
        # paper-plant1, 12 dB) reached the right basin on seed 0 only through restarts that ran because
        # a first search happened to end in "no descent" rather than in a last step that lowered the
        # loss by a rounding error: a coin toss that a mathematically neutral change of the arithmetic
        # flipped (droop −1 pp). Trying this start always (one search more per fit) kept Z_u's droop on
        # seeds 0-19 (15 min) and Z_ur's as they were, and held seed 0 under either arithmetic.
        lazy.remove(shorter)
        run(shorter())
    if multistart is True or (multistart == "auto" and stalled(best)):
        rng = np.random.default_rng(seed)
        extra = [lambda: _real_roots(st, best.theta), *lazy,
                 *(lambda: _perturbed(st, best.theta, rng) for _ in range(3))]
        for make in extra:
            run(make())
            if multistart == "auto" and not stalled(best) and len(results) >= 2:
                break
    best = _judged(st, best, segs)
    th = best.theta
    eps = best.eps
    J = best.jac if best.jac is not None else _jacobian(st, segs, best.aux)
    ssr = float(eps @ eps)
    lam = ssr / (n - st.p)
    cov = _covariance(J, lam) if covariance == "gauss" else _sandwich(J, eps, data.bounds)
    rep = EstimationReport(
        method=method, n_samples=n, loss=ssr / n, iterations=best.iterations, converged=best.converged,
        stop_reason=best.stop_reason, algorithm=best.algorithm,
        start_losses=tuple(r.ssr / n for r in results),
    )
    return _ordered_model(st, th, data, cov, lam, rep)


RANK_RTOL = 1e-7
"""Singular values of the column-scaled Jacobian below RANK_RTOL × the largest count as zero in the
covariance (:func:`_cov_factor`): far above rounding (1e-16 × the condition number), so the rank does not
depend on the BLAS kernel."""


def _cov_factor(J: np.ndarray) -> np.ndarray:
    """L with (JᵀJ)⁺ = L Lᵀ (column-scaled SVD, rank by :data:`RANK_RTOL`).

    An over-parameterised model (a near pole-zero cancellation, e.g. MISO BJ(4,4,4,4)) has a Jacobian of
    numerically deficient rank. The inverse by QR/triangular solve then amplified rounding by the
    condition number (~1e12): the sandwich came out indefinite and some response variances negative, shown
    as zero-width intervals on one BLAS kernel and not on another. Along a direction with J v ≈ 0 the
    predictor, and hence every transfer function of the model, does not change, so the pseudo-inverse on
    the identifiable subspace gives the right variance of the responses; as a factor it is PSD exactly.
    """
    scale = _column_scale(J)
    R = np.linalg.qr(J / scale, mode="r")
    _, sv, Vt = np.linalg.svd(R)
    keep = sv > RANK_RTOL * sv[0] if sv.size else sv.astype(bool)
    return (Vt[keep].T / sv[keep]) / scale[:, None]


def _covariance(J: np.ndarray, lam: float) -> np.ndarray:
    """λ̂ (JᵀJ)⁺ (:func:`_cov_factor`)."""
    L = _cov_factor(J)
    return lam * (L @ L.T)


def _hac_lag(eps: np.ndarray, bounds) -> int:
    """Newey-West truncation lag: twice the lag after which the residual autocorrelation stays inside
    ±2/√N for 5 lags, within [10, N/8]."""
    n = eps.shape[0]
    kmax = max(10, n // 8)
    acf = np.zeros(kmax + 1)
    for a, b in bounds:
        e = eps[a:b]
        L = e.shape[0]
        f = np.fft.rfft(e, 2 * L)
        c = np.fft.irfft(f * np.conj(f))[:min(L, kmax + 1)]
        acf[:c.shape[0]] += c
    acf /= acf[0] if acf[0] > 0 else 1.0
    thr = 2.0 / np.sqrt(n)
    inside = np.abs(acf) < thr
    for k in range(1, kmax - 4):
        if inside[k:k + 5].all():
            return int(np.clip(2 * k, 10, kmax))
    return kmax


def _full_rank_inverse(R: np.ndarray, rtol: float) -> np.ndarray | None:
    """R⁻¹ of an upper-triangular R when a cheap bound proves every singular value above rtol × the
    largest, else None (the caller then looks at the singular values): σ_max/σ_min ≤ ‖R‖_F ‖R⁻¹‖_F."""
    Ri, info = _trtri(R, lower=0)
    if info != 0 or not np.all(np.isfinite(Ri)):
        return None
    return Ri if math.sqrt(np.vdot(R, R) * np.vdot(Ri, Ri)) * rtol < 1.0 else None


def _hac_sum(h: np.ndarray, bounds, M: int) -> np.ndarray:
    """Σ_{|τ|≤M} w_τ Σ_n h[n] h[n−τ]ᵀ within each experiment, Bartlett weights w_τ = 1 − |τ|/(M + 1).

    By FFT: the weighted lag sum is Σ_k Ŵ_k H_kᴴ H_k / n over the frequencies of an n-point DFT H of h
    (n ≥ L + M + 1: no lag folds onto another), Ŵ the DFT of the weights (the Fejér kernel, ≥ 0). It is
    a sum of PSD terms, so it is PSD and suffers no cancellation, where the direct lag sum (M + 1 products
    h[τ:]ᵀ h[:−τ], M up to N/8) took ~M times longer and lost digits. The whole triangle of weights even
    when an experiment is shorter than M (n ≥ 2M + 1): cut at L − 1 lags its DFT would not be ≥ 0.
    """
    r = h.shape[1]
    Om = np.zeros((r, r))
    for a, b in bounds:
        L = b - a
        n = _sfft.next_fast_len(max(L, M) + M + 1, real=True)
        w = np.zeros(n)
        w[:M + 1] = 1.0 - np.arange(M + 1) / (M + 1.0)
        w[n - M:] = w[M:0:-1]
        c = np.maximum(_sfft.rfft(w).real, 0.0) / n  # clips rounding only
        c[1:(n + 1) // 2] *= 2.0  # each of these rfft bins stands for itself and its conjugate
        H = _sfft.rfft(h[a:b], n, axis=0)
        sc = np.sqrt(c)[:, None]
        Hs = np.concatenate((H.real * sc, H.imag * sc))
        Om += Hs.T @ Hs
    return Om


FIXED_B = (2.9694, 0.4160, -0.5324)
"""Coefficients of the fixed-b critical value of a Bartlett-kernel HAC t statistic at 95 % two-sided,
cv(b) = 1.96 + a₁b + a₂b² + a₃b³ with b = (M + 1)/N (Kiefer and Vogelsang 2005, Econometric Theory 21,
polynomial fit to their simulated fixed-b limit). Why: the Newey-West covariance with the lag
:func:`_hac_lag` picks (M = 100-430 of N ≈ 3500 on the zoo's 30-min excited logs, b = 0.03-0.12) is
itself a noisy estimate with few effective degrees of freedom, so ±1.96 sd covered less than 95 %: on
the zoo's excited 30-min logs with 0.1 % meter noise (7 plants × 20 seeds, Z_cu with H) the droop's
z-scores had sd 1.10 and 12 of 136 beyond 1.96 (91 %). With cv(b): 127/136 (93 %), all 276 fits 95.3 →
96.7 %, the peaks and G_p unchanged (their intervals are the jackknife's there), lowband's droop
unchanged (its jackknife inflation dominates). A Monte Carlo of the location model (N = 600, 20000
draws, Bartlett weights 1 − τ/(M + 1)) gave cv 1.995, 2.071, 2.214, 2.372, 2.522 at b = 0.02, 0.05, 0.1,
0.15, 0.2 against the polynomial's 2.020, 2.109, 2.261, 2.413, 2.566."""


def fixed_b_factor(M: int, n: int) -> float:
    """cv(b)/1.96 (:data:`FIXED_B`) for a Bartlett lag M on n samples: the sandwich covariance is scaled by
    its square, so that value ± 1.96 sd is the fixed-b 95 % interval wherever it is used."""
    b = min((M + 1.0) / max(n, 1), 1.0)
    a1, a2, a3 = FIXED_B
    return (Z95 + b * (a1 + b * (a2 + b * a3))) / Z95


def _sandwich(J: np.ndarray, eps: np.ndarray, bounds) -> np.ndarray:
    """Heteroscedasticity- and autocorrelation-consistent covariance of a prediction-error estimate.

    P = H⁻¹ Ω H⁻¹, H = JᵀJ, Ω = Σ_{|τ|≤M} w_τ Σ_n g[n] g[n−τ]ᵀ, g[n] = J[n] ε[n] (within experiments),
    Bartlett weights w_τ = 1 − |τ|/(M + 1), M from the residual correlation (:func:`_hac_lag`), scaled by
    :func:`fixed_b_factor`² (the fixed-b critical value of the lag M on these N samples).

    Computed as P = L (Lᵀ Ω L) Lᵀ with (JᵀJ)⁺ = L Lᵀ (:func:`_cov_factor`), and Lᵀ Ω L as the lag sum
    (:func:`_hac_sum`) of the scores of J L = Q U (Q from the QR of the column-scaled J, U from the SVD
    of its R; U = I when a cheap bound shows full rank): orthonormal columns, so nothing is amplified by
    the condition number of J, as Lᵀ Ω L from Ω was (on Z_cu fits at cond 1e6-4e6, P's diagonal was off
    by 1e-4 to 9e-2 relative vs an extended-precision reference; now ≤ 3e-10).
    """
    M = _hac_lag(eps, bounds)
    scale = _column_scale(J)
    # economic QR (more samples than parameters: _pem checks it), by LAPACK as in _IcProjection
    qr, tau, _, _ = _geqrf(J / scale, overwrite_a=1)
    R = np.triu(qr[:J.shape[1]])
    Z, _, _ = _orgqr(qr, tau, overwrite_a=1)
    Ri = _full_rank_inverse(R, RANK_RTOL)
    if Ri is not None:
        L = Ri / scale[:, None]
    else:  # as _cov_factor: the pseudo-inverse on the identifiable subspace
        U_, sv, Vt = np.linalg.svd(R)
        keep = sv > RANK_RTOL * sv[0] if sv.size else sv.astype(bool)
        L = (Vt[keep].T / sv[keep]) / scale[:, None]
        Z = Z @ U_[:, keep]
    M_ = _hac_sum(Z * eps[:, None], bounds, M)
    w, U = np.linalg.eigh(M_)
    K = L @ (U * (np.sqrt(np.maximum(w, 0.0)) * fixed_b_factor(M, eps.shape[0])))
    return K @ K.T


def bj(data: IdData, nb: int | Sequence[int], nc: int, nd: int, nf: int | Sequence[int],
       nk: int | Sequence[int] = 1, *, init: PolyModel | None = None, multistart: bool | str = "auto",
       n_high: int | None = None, maxiter: int = 100, tol: float = 1e-10, seed: int = 0,
       ic: str = "zero", covariance: str = "gauss", beat: float | None = None,
       drift_pole: float | None = None) -> PolyModel:
    """Box-Jenkins model y = Σ B_i/F_i u_i + C/D e by prediction-error minimisation.

    Args:
        data: IdData (one or several experiments, finite samples, every input exciting).
        nb, nf, nk: per input (or one int for all): number of B coefficients, order of F, delay [samples].
        nc, nd: orders of the shared noise model C/D.
        init: initial model (same orders, A = 1); roots outside the unit circle are reflected inside.
        multistart: "auto" (restart when the first search stalls; BJ also always tries the start
            from a shorter ARX when the high-order one has more than 8 poles), True (always try every
            start), False (one start).
        n_high: order of the high-order ARX used for initial values (default from N, at most 30).
        maxiter, tol: iteration limit and relative loss tolerance of the search.
        seed: seed of the perturbed restarts (the result is deterministic for a given seed).
        ic: "zero" (every filter starts from rest) or "estimate" (each experiment's initial states and an
            output offset are estimated by variable projection; use it for records that do not start at
            rest, above all with slow poles).
        drift_pole: with ``ic="estimate"``, also a drift per experiment: the response of 1/(1 − p q⁻¹)
            to a step (p = 1: a linear trend). For an output that integrates (through a KNOWN pole p that
            the caller has applied to the input) a constant offset the model cannot see: a unit without
            damping (Kd = 0) turns a constant power mismatch into a ramp of its speed
            (:func:`fcrlive.analysis.experiments.zcu_swing`).
        covariance: "gauss" (λ̂(JᵀJ)⁻¹, white residuals) or "sandwich" (Newey-West HAC,
            (JᵀJ)⁻¹ [Σ_τ w_τ Σ_n ψ[n]ε[n]ε[n−τ]ψ[n−τ]ᵀ] (JᵀJ)⁻¹, honest with coloured residuals:
            Ljung 1999, §9.3).
        beat: a loss (1/N)Σε² another fit of the same data already reached (a caller's own multistart):
            a search converged to statistical accuracy above it stops there, its stop reason
            :data:`BEATEN` (its loss is then not below ``beat`` to statistical accuracy, and it is not
            worth the last decades of ``tol``).

    Returns:
        PolyModel with covariance λ̂(JᵀJ)⁻¹ and a report (iterations, loss, stop reason, start losses).
    """
    st = _check_orders(data, nb, nc, nd, nf, nk, "bj", ic, drift_pole)
    return _pem(data, st, "bj", init=init, multistart=multistart, n_high=n_high, maxiter=maxiter, tol=tol,
                seed=seed, covariance=covariance, beat=beat)


def oe(data: IdData, nb: int | Sequence[int], nf: int | Sequence[int], nk: int | Sequence[int] = 1, *,
       init: PolyModel | None = None, multistart: bool | str = "auto", n_high: int | None = None,
       maxiter: int = 100, tol: float = 1e-10, seed: int = 0, ic: str = "zero",
       covariance: str = "gauss", beat: float | None = None, drift_pole: float | None = None) -> PolyModel:
    """Output-error model y = Σ B_i/F_i u_i + e (a BJ model with C = D = 1). Arguments as :func:`bj`.

    The covariance λ̂(JᵀJ)⁻¹ assumes white output noise; with coloured noise OE stays consistent in
    open loop but that covariance is not the true one: use ``covariance="sandwich"`` (or bj).
    """
    st = _check_orders(data, nb, 0, 0, nf, nk, "oe", ic, drift_pole)
    return _pem(data, st, "oe", init=init, multistart=multistart, n_high=n_high, maxiter=maxiter, tol=tol,
                seed=seed, covariance=covariance, beat=beat)


# ===================================================================== one exact Newton step
@dataclass(frozen=True, eq=False)
class NewtonStep:
    """One Gauss-Newton step from a fitted model (:func:`newton_step`)."""

    model: PolyModel
    """The model at the end of the step (the start's covariance: it says how far the step went in
    standard errors, it is not re-estimated); the start model itself when no step lowered the loss."""
    loss_before: float
    loss_after: float
    """V = (1/N)Σε² at the start and at the end of the step."""
    step: np.ndarray
    """The parameter step taken (θ_after − θ_before, the toolbox's order, :func:`bj`)."""
    predicted_decrease: float
    """N·(V_before − V_quadratic model's minimum)/V_before: the likelihood-ratio gain the step promised."""


def newton_step(model: PolyModel, data: IdData, *, ic: str = "zero") -> NewtonStep:
    """One Gauss-Newton step from ``model`` on ``data`` with the EXACT Jacobian of the prediction errors.

    Why: a search can stop (iteration limit, a root held at the stability guard) short of the minimum.
    J is the search's own, exact with the projection of the initial responses included
    (:meth:`_IcProjection.kaufman`; central differences of ε agreed to 1e-10),
    so Jᵀε is the gradient of the loss the search minimises and JᵀJ its Gauss-Newton Hessian. The step is
    the minimum-norm least-squares solution on the identifiable subspace
    (:data:`RANK_RTOL`; along J v ≈ 0 no transfer function changes), halved (at most 10 times) until it
    keeps every root inside the unit circle and lowers the loss. How far the step moves a quantity, in
    its standard errors, tells how much of the search's stop short of the minimum matters
    (:mod:`fcrlive.analysis.quality`). ``ic`` as in :func:`bj` (the fit's own choice)."""
    if model.na != 0:
        raise OrderError(f"model has na = {model.na}; OE/BJ models have A = 1")
    st = _check_orders(data, list(model.nb), model.nc, model.nd, list(model.nf), list(model.nk), "bj", ic)
    th0 = st.pack(list(model.b), list(model.f), model.c, model.d)
    segs = list(data.segments())
    n = data.N
    eps0, aux0 = _residuals(st, th0, segs)
    V0 = float(eps0 @ eps0)
    J = _jacobian(st, segs, aux0)
    L = _cov_factor(J)
    delta = -(L @ (L.T @ (J.T @ eps0)))
    pred = float(np.sum((J @ delta) ** 2))
    best_th, best_V = th0, V0
    if np.all(np.isfinite(delta)) and pred > 0.0:
        mu = 1.0
        for _ in range(11):
            cand = th0 + mu * delta
            if _stable(st, cand):
                e2, _ = _residuals(st, cand, segs)
                V2 = float(e2 @ e2)
                if V2 < V0:
                    best_th, best_V = cand, V2
                    break
            mu *= 0.5
    rep = model.report
    if rep is not None:
        rep = EstimationReport(
            method=rep.method, n_samples=rep.n_samples, loss=best_V / n, iterations=rep.iterations + 1,
            converged=rep.converged, stop_reason=rep.stop_reason + "; then one exact Newton step",
            algorithm=rep.algorithm, start_losses=rep.start_losses, notes=rep.notes,
        )
    B, F, C, D = st.polys(best_th)
    stepped = PolyModel(a=np.ones(1), b=tuple(B), c=C, d=D, f=tuple(F), nk=st.nk, Ts=model.Ts,
                        noise_variance=model.noise_variance, covariance=model.covariance,
                        input_names=model.input_names, output_name=model.output_name, report=rep)
    return NewtonStep(stepped, V0 / n, best_V / n, best_th - th0, n * pred / V0 if V0 > 0 else 0.0)
