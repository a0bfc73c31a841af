"""The linearised closed loop at the controller rate: exact discretisation, fast runs, noise sizing.

The continuous plant of :mod:`fcrlive.sim.model` (both units, network, filters) is discretised
exactly at Tc (matrix exponential; the load with a first-order hold, i.e. linearly interpolated like in
the nonlinear simulator, unit 1's demand with a zero-order hold), and closed with unit 1's digital PI.
State ``z = [x; i1]``; inputs ``w[n] = [r, v, ΔP_L[n], ΔP_L[n+1], y_app]``:

- r: excitation [pu] added to the reference; v: process noise [pu] on the governor's speed signal;
- ΔP_L: load change at bus 5 [pu system base] at the knots n and n+1;
- y_app: in open-loop mode (industry sine test) the applied frequency deviation [pu] that replaces the
  speed feedback.

``z[n+1] = Phi z[n] + Gam w[n]``, outputs ``o[n] = C z[n] + D w[n]`` in the order of :data:`OUTPUTS`.
Linearised and nonlinear models share the discretisation, so at small amplitude they differ only by
the turbines' curvature (and limiters, which the linear model does not have).

Noise sizing (used by :func:`fcrlive.sim.simulate`):

- :func:`load_noise_std`: the stochastic load is integrated white noise (a random walk), so the grid
  frequency is a random walk too. Rule: 3 standard deviations of the centre-of-inertia frequency after
  :data:`REFERENCE_WINDOW_S` (1800 s, the paper's dataset length) from the steady state equal 0.1 Hz.
- :func:`process_noise_std`: the paper's SNR (Section 7.1) ``10 log10(var u from load and r / var u from
  process noise)``, with var the EXPECTED SAMPLE VARIANCE (what ``np.var`` of a run estimates, mean
  removed) over a run of :data:`REFERENCE_WINDOW_S` from the steady state. Exact: discrete Lyapunov sums
  of the exact discretisation, evaluated in O(log N) by doubling. A fixed window (not each run's length)
  keeps the noise level of an SNR the same for 30 and 10 min datasets, as in the paper's Figs. 9-10.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.signal import lfilter

from fcrlive.blas import single_threaded
from fcrlive.plant.params import Plant
from fcrlive.sim import model as mdl

REFERENCE_WINDOW_S = 1800.0
"""Window [s] of the load-noise rule and of the SNR definition (the paper's 30 min datasets)."""

FREQ_BAND_HZ = 0.1
"""The frequency band the load noise is sized for (3σ after REFERENCE_WINDOW_S) [Hz]."""

INPUTS = ("r", "v", "pl0", "pl1", "app")
OUTPUTS = ("y", "epsilon", "dc", "da", "u", "w_coi", "dpm", "omega")
"""Linear outputs: y (governor's speed signal incl. process noise), ε = r − y, Δc, Δa (gate), u
(filtered ΔPe1, machine base), ω_coi, ΔPm1 (linearised), Δω1 (rotor speed) — all pu deviations."""


@dataclass(frozen=True, eq=False)
class ClosedLoop:
    """Unit 1's digital closed loop at Tc (module docstring). ``open_loop``: the industry test set-up."""

    model: mdl.Model
    open_loop: bool
    Phi: np.ndarray
    Gam: np.ndarray
    C: np.ndarray
    D: np.ndarray

    @property
    def nz(self) -> int:
        return self.Phi.shape[0]

    @property
    def Tc(self) -> float:
        return self.model.Tc


@lru_cache(maxsize=64)
@single_threaded
def closed_loop(plant: Plant, open_loop: bool = False) -> ClosedLoop:
    """The :class:`ClosedLoop` of ``plant`` (cached)."""
    m = mdl.build(plant)
    k = m.ctl1
    # A derivative action's state ψ (model.Controller) is the row after the integrator's.
    nx, nz, nw = m.nx, m.nx + (2 if k.has_derivative else 1), len(INPUTS)
    I1 = nx
    e_F1, e_G1, e_I1 = np.eye(nz)[mdl.F1], np.eye(nz)[mdl.G1], np.eye(nz)[I1]
    # ε = E_z z + E_w w; Δc = ce ε + ci i1 + cg Δa; i1⁺ = i1 + Tc Ki (ie ε + ii i1 + ig Δa).
    E_z = np.zeros(nz) if open_loop else -e_F1
    E_w = np.array([1.0, -1.0, 0.0, 0.0, -1.0 if open_loop else 0.0])
    Dc_z = k.ce * E_z + k.ci * e_I1 + k.cg * e_G1
    if k.has_derivative:
        Dc_z = Dc_z + k.cd * np.eye(nz)[I1 + 1]
    Dc_w = k.ce * E_w
    Phi = np.zeros((nz, nz))
    Gam = np.zeros((nz, nw))
    Phi[:nx, :nx] = m.Phi
    Phi[:nx] += np.outer(m.Gc, Dc_z)
    Gam[:nx] += np.outer(m.Gc, Dc_w)
    Gam[:nx, 2] += m.GL0 - m.GL1
    Gam[:nx, 3] += m.GL1
    kt = m.Tc * k.Ki
    Phi[I1] = e_I1 + kt * (k.ie * E_z + k.ii * e_I1 + k.ig * e_G1)
    Gam[I1] = kt * k.ie * E_w
    if k.has_derivative:
        e_D = np.eye(nz)[I1 + 1]
        Phi[I1] += kt * k.id * e_D
        Phi[I1 + 1] = k.de * E_z + k.di * e_I1 + k.dd * e_D + k.dg * e_G1
        Gam[I1 + 1] = k.de * E_w
    C = np.zeros((len(OUTPUTS), nz))
    D = np.zeros((len(OUTPUTS), nw))
    C[0] = -E_z  # y = y_gov + v
    D[0] = [0.0, 1.0, 0.0, 0.0, 1.0 if open_loop else 0.0]
    C[1], D[1] = E_z, E_w
    C[2], D[2] = Dc_z, Dc_w
    C[3] = e_G1
    C[4, mdl.PF1] = 1.0
    C[5, :nx] = m.C_coi
    C[6, :nx] = m.C_pm1
    C[7, mdl.W1] = 1.0
    for a in (Phi, Gam, C, D):
        a.setflags(write=False)
    return ClosedLoop(model=m, open_loop=open_loop, Phi=Phi, Gam=Gam, C=C, D=D)


# ---------------------------------------------------------------------------------------------------
# Running the recursion z[n+1] = Phi z[n] + d[n] fast for one long run


@dataclass(frozen=True, eq=False)
class _Modal:
    """Real-arithmetic modal form of Phi: ``proj`` maps z to one row per real mode and two rows (real,
    imaginary part of the projection) per complex pair; ``back`` maps the filtered rows back."""

    proj: np.ndarray
    back: np.ndarray
    real: tuple[tuple[int, float], ...]  # (row, λ)
    pairs: tuple[tuple[int, complex], ...]  # (first of two rows, λ with Im λ > 0)


_MODAL_CACHE: dict[int, tuple[np.ndarray, _Modal | None]] = {}


def _modal(Phi: np.ndarray) -> _Modal | None:
    key = id(Phi)
    hit = _MODAL_CACHE.get(key)
    if hit is not None and hit[0] is Phi:
        return hit[1]
    res = modal_form(Phi)
    if len(_MODAL_CACHE) > 256:
        _MODAL_CACHE.clear()
    _MODAL_CACHE[key] = (Phi, res)
    return res


def modal_form(Phi: np.ndarray) -> _Modal | None:
    """The real modal form of ``Phi`` (uncached; None if Phi is nearly defective)."""
    lam, V = np.linalg.eig(Phi)
    res: _Modal | None = None
    if np.linalg.cond(V) < 1e8:  # otherwise nearly defective: the modal form would lose accuracy
        Vinv = np.linalg.inv(V)
        proj, back, real, pairs = [], [], [], []
        tiny = 1e-12 * np.abs(lam)
        for j in range(len(lam)):
            if abs(lam[j].imag) <= tiny[j]:
                real.append((len(proj), float(lam[j].real)))
                proj.append(Vinv[j].real)
                back.append(V[:, j].real)
            elif lam[j].imag > 0:
                pairs.append((len(proj), complex(lam[j])))
                proj += [Vinv[j].real, Vinv[j].imag]
                # x += 2 Re(v ξ) = 2 Re v Re ξ − 2 Im v Im ξ
                back += [2.0 * V[:, j].real, -2.0 * V[:, j].imag]
        if len(proj) == len(lam):
            res = _Modal(proj=np.array(proj), back=np.array(back).T, real=tuple(real), pairs=tuple(pairs))
    return res


def recursion(Phi: np.ndarray, d: np.ndarray) -> np.ndarray:
    """States z[0..N−1] of z[n+1] = Phi z[n] + d[:, n] with z[0] = 0; ``d`` shape (nz, N).

    Diagonalises Phi and runs one first-order IIR filter per mode (scipy.signal.lfilter, compiled; a
    complex pair λ, λ̄ as ONE complex filter of the projection on λ's left eigenvector, whose real and
    imaginary parts are the pair's two real rows): about 10 ms for 90 000 samples. Falls back to a plain
    loop if Phi is nearly defective.
    """
    nz, N = d.shape
    md = _modal(Phi)
    if md is None:
        z = np.zeros((nz, N))
        for n in range(N - 1):
            z[:, n + 1] = Phi @ z[:, n] + d[:, n]
        return z
    return filter_projected(md, md.proj @ d)


def reorder_modes(md: _Modal, first: np.ndarray) -> tuple[_Modal, int]:
    """``md`` with the modes whose rows are flagged in ``first`` (a pair counts by its first row) moved
    to the front; returns it and the number of rows they take."""
    groups = [(row, 1) for row, _ in md.real] + [(row, 2) for row, _ in md.pairs]
    groups.sort(key=lambda t: (not first[t[0]], t[0]))
    order, new_row, n_first = [], {}, 0
    for row, size in groups:
        new_row[row] = len(order)
        order += list(range(row, row + size))
        if first[row]:
            n_first += size
    order_a = np.array(order)
    res = _Modal(proj=md.proj[order_a], back=md.back[:, order_a],
                 real=tuple(sorted((new_row[r], lam) for r, lam in md.real)),
                 pairs=tuple(sorted(((new_row[r], lam) for r, lam in md.pairs), key=lambda t: t[0])))
    return res, n_first


def modal(Phi: np.ndarray) -> _Modal | None:
    """The real modal form used by :func:`recursion` (None if Phi is nearly defective)."""
    return _modal(Phi)


def filter_modes(md: _Modal, g: np.ndarray, out: np.ndarray | None = None,
                 rows: tuple[int, int] = (0, 1 << 30)) -> np.ndarray:
    """Modal states one sample early: ``q[n] = λ q[n−1] + g[n]`` per mode (q[−1] = 0), in the real rows
    of :class:`_Modal` (a complex pair's rows hold the real and imaginary part of its complex state).

    The states of z[n+1] = Phi z[n] + d[n] are then ``z[n] = md.back @ q[:, n−1]`` (z[0] = 0) for
    ``g = md.proj @ d``: see :func:`back_project`. ``rows``: only the modes in these rows [start, end).
    """
    q = np.empty_like(g) if out is None else out
    one = np.ones(1)
    for row, lam in md.real:
        if rows[0] <= row < rows[1]:
            q[row] = lfilter(one, np.array([1.0, -lam]), g[row])
    for row, lam in md.pairs:
        if not rows[0] <= row < rows[1]:
            continue
        gc = np.empty(g.shape[1], dtype=complex)
        gc.real = g[row]
        gc.imag = g[row + 1]
        qc = lfilter(one, np.array([1.0, -lam]), gc)
        q[row] = qc.real
        q[row + 1] = qc.imag
    return q


def back_project(md: _Modal, q: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """States ``z[:, 0] = 0, z[:, n] = md.back @ q[:, n−1]`` from :func:`filter_modes`' output."""
    nz, N = md.back.shape[0], q.shape[1]
    z = np.empty((nz, N)) if out is None else out
    z[:, 0] = 0.0
    np.matmul(md.back, q[:, :-1], out=z[:, 1:])
    return z


def filter_projected(md: _Modal, g: np.ndarray) -> np.ndarray:
    """:func:`recursion` with the input already projected on the modes (``g = md.proj @ d``)."""
    return back_project(md, filter_modes(md, g))


def run(cl: ClosedLoop, w: np.ndarray) -> np.ndarray:
    """Outputs (len(OUTPUTS), N) of one linear run with inputs ``w`` (len(INPUTS), N) from steady state."""
    z = recursion(cl.Phi, cl.Gam @ w)
    return cl.C @ z + cl.D @ w


# ---------------------------------------------------------------------------------------------------
# Expected (sample) variances by doubling


def _sums(A: np.ndarray, Q: np.ndarray, M: int) -> tuple[np.ndarray, np.ndarray]:
    """R_M = Σ_{k<M} A^k Q A'^k and W_M = Σ_{k<M} k A^k Q A'^k, in O(log M) products."""
    n = A.shape[0]
    # accumulated result over m_acc steps, and the current power-of-two block
    m_acc, P_acc, R_acc, W_acc = 0, np.eye(n), np.zeros((n, n)), np.zeros((n, n))
    m_blk, P_blk, R_blk, W_blk = 1, A.copy(), Q.copy(), np.zeros((n, n))
    while M:
        if M & 1:
            # append the block after the accumulated steps
            R_acc = R_acc + P_acc @ R_blk @ P_acc.T
            W_acc = W_acc + P_acc @ (W_blk + m_acc * R_blk) @ P_acc.T
            P_acc = P_blk @ P_acc
            m_acc += m_blk
        M >>= 1
        if M:
            R_blk, W_blk = (R_blk + P_blk @ R_blk @ P_blk.T,
                            W_blk + P_blk @ (W_blk + m_blk * R_blk) @ P_blk.T)
            P_blk = P_blk @ P_blk
            m_blk *= 2
    return R_acc, W_acc


def state_covariance(A: np.ndarray, G: np.ndarray, N: int) -> np.ndarray:
    """Covariance of z[N] for z[n+1] = A z[n] + G e[n], e white with unit covariance, z[0] = 0."""
    return _sums(A, G @ G.T, N)[0]


def expected_sample_variance(A: np.ndarray, G: np.ndarray, c: np.ndarray, N: int) -> float:
    """E[np.var(o[0..N−1])] for o[n] = c z[n], z[n+1] = A z[n] + G e[n], e unit white, z[0] = 0.

    E[var] = (1/N) Σ E o[n]² − (1/N²) E (Σ o[n])²; the first sum is c (M R_M − W_M) c' (M = N − 1),
    the second the covariance of an accumulator s[n+1] = s[n] + c z[n+1] appended to the state.
    """
    M = N - 1
    Q = G @ G.T
    R, W = _sums(A, Q, M)
    sum_sq = float(c @ (M * R - W) @ c)
    n = A.shape[0]
    Aa = np.zeros((n + 1, n + 1))
    Aa[:n, :n] = A
    Aa[n, :n] = c @ A
    Aa[n, n] = 1.0
    Ga = np.vstack([G, c @ G])
    Ra = _sums(Aa, Ga @ Ga.T, M)[0]
    return sum_sq / N - float(Ra[n, n]) / N**2


def _load_system(cl: ClosedLoop) -> tuple[np.ndarray, np.ndarray]:
    """Closed loop with the random-walk load as an extra state: unit increments per sample."""
    nz = cl.nz
    A = np.zeros((nz + 1, nz + 1))
    A[:nz, :nz] = cl.Phi
    A[:nz, nz] = cl.Gam[:, 2] + cl.Gam[:, 3]
    A[nz, nz] = 1.0
    G = np.zeros((nz + 1, 1))
    G[:nz, 0] = cl.Gam[:, 3]
    G[nz, 0] = 1.0
    return A, G


def _n(Tc: float, seconds: float) -> int:
    return max(2, round(seconds / Tc))


@lru_cache(maxsize=64)
@single_threaded
def load_noise_std(plant: Plant) -> float:
    """Intensity σ_L [pu system base / sqrt(s)] of the random-walk load: ΔP_L(t+Tc) = ΔP_L(t) + σ_L √Tc ξ.

    3σ of the centre-of-inertia frequency after REFERENCE_WINDOW_S equals FREQ_BAND_HZ (module doc).
    """
    cl = closed_loop(plant)
    A, G = _load_system(cl)
    c = np.append(cl.C[OUTPUTS.index("w_coi")], 0.0)
    var = float(c @ state_covariance(A, G, _n(cl.Tc, REFERENCE_WINDOW_S)) @ c)  # per unit increment²
    f0 = plant.grid.f0
    target = FREQ_BAND_HZ / 3.0 / f0  # pu
    return target / math.sqrt(var) / math.sqrt(cl.Tc)


@dataclass(frozen=True)
class UVariances:
    """Expected sample variances of u [pu²] over REFERENCE_WINDOW_S, per source."""

    load: float
    """From the random-walk load of the given intensity."""
    r: float
    """From the excitation."""
    per_unit_v: float
    """From process noise of unit standard deviation (scale with std²)."""


def u_variances(plant: Plant, load_std: float, r_std: float = 0.0, r: np.ndarray | None = None,
                open_loop: bool = False) -> UVariances:
    """Variance contributions to u used by the SNR (module docstring).

    ``r`` given: its own deterministic contribution (np.var of the linear response over its length);
    otherwise white excitation of standard deviation ``r_std``.
    """
    cl = closed_loop(plant, open_loop)
    N = _n(cl.Tc, REFERENCE_WINDOW_S)
    iu = OUTPUTS.index("u")
    cu = cl.C[iu]
    A, G = _load_system(cl)
    v_load = 0.0
    if load_std > 0:
        v_load = expected_sample_variance(A, G, np.append(cu, 0.0), N) * load_std**2 * cl.Tc
    v_v = expected_sample_variance(cl.Phi, cl.Gam[:, [1]], cu, N)
    if r is not None:
        w = np.zeros((len(INPUTS), len(r)))
        w[0] = r
        v_r = float(np.var(run(cl, w)[iu]))
    elif r_std > 0:
        v_r = expected_sample_variance(cl.Phi, cl.Gam[:, [0]], cu, N) * r_std**2
    else:
        v_r = 0.0
    return UVariances(load=v_load, r=v_r, per_unit_v=v_v)


def process_noise_std(plant: Plant, snr_db: float, load_std: float, r_std: float = 0.0,
                      r: np.ndarray | None = None) -> float:
    """Standard deviation [pu] of the white process noise on unit 1's speed signal giving ``snr_db``.

    SNR = 10 log10((var u from load + var u from r)/var u from process noise), expected sample
    variances over REFERENCE_WINDOW_S (module docstring). Raises ValueError when there is no load and
    no excitation (nothing to compare with).
    """
    v = u_variances(plant, load_std, r_std, r)
    signal = v.load + v.r
    if not signal > 0:
        raise ValueError("an SNR needs load noise or excitation: both are zero")
    return math.sqrt(signal / (v.per_unit_v * 10.0 ** (snr_db / 10.0)))


# ---------------------------------------------------------------------------------------------------
# Frequency responses of the exact discretisation


def frequency_response(plant: Plant, omega, inp: str, out: str, open_loop: bool = False) -> np.ndarray:
    """Discrete-time frequency response from input ``inp`` to output ``out`` at ω [rad/s].

    ``inp="load"`` is the load at bus 5 with the first-order hold (both knot columns). The exact
    discrete G_1 is ``frequency_response(p, w, "load", "epsilon") / frequency_response(p, w, "load", "u")``.
    """
    cl = closed_loop(plant, open_loop)
    w = np.atleast_1d(np.asarray(omega, float))
    z = np.exp(1j * w * cl.Tc)
    io = OUTPUTS.index(out)
    if inp == "load":
        b0, b1 = cl.Gam[:, 2], cl.Gam[:, 3]
        d0, d1 = cl.D[io, 2], cl.D[io, 3]
    else:
        j = INPUTS.index(inp)
        b0, b1 = cl.Gam[:, j], np.zeros(cl.nz)
        d0, d1 = cl.D[io, j], 0.0
    res = np.empty(w.shape, complex)
    eye = np.eye(cl.nz)
    for k, zk in enumerate(z):
        x = np.linalg.solve(zk * eye - cl.Phi, b0 + zk * b1)
        res[k] = cl.C[io] @ x + d0 + zk * d1
    return res.reshape(np.shape(omega)) if np.ndim(omega) else res[0]


def slowest_time_constant(plant: Plant, open_loop: bool = False) -> float:
    """Largest time constant [s] of the closed (or open-loop test) loop: −Tc / ln max|λ(Phi)|."""
    cl = closed_loop(plant, open_loop)
    r = float(np.max(np.abs(np.linalg.eigvals(cl.Phi))))
    if r >= 1.0:
        return math.inf
    return -cl.Tc / math.log(r)
