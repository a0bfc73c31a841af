"""The nonlinear two-machine simulator: one controller sample as a step map, run three ways.

The step map (:class:`Stepper`) takes the state at t_n = n Tc to t_{n+1}:

1. unit 1's digital governor samples y[n] = f1(t_n) + v[n] (filtered speed plus process noise; in the
   open-loop industry test the applied frequency replaces f1), forms ε[n] = r[n] − y[n], computes the
   demand c[n] (clipped to the gate limits, with conditional-integration anti-windup) and updates its
   forward-Euler integral;
2. the continuous plant (both units, network, filters, unit 2's analogue governor) is integrated over
   [t_n, t_n + Tc] with c[n] held (ZOH) and the load moving linearly from ΔP_L[n] to ΔP_L[n+1]
   (plant-model.md: holding it constant across stages gave −23 % in |G_1| at T = 10 s).

Integrators for step 2 (``integrator``):

- ``"exp"`` (default): exponential integrator. The linear part ``A x + B_c Δc + B_L ΔP_L``, which
  carries all the dynamics, is integrated EXACTLY (matrix exponential, the same discretisation as the
  linear model, load with a first-order hold); only the small nonlinear residual N(x) (turbine head
  curvature, limiters) is approximated, by its linear extrapolation from N(x[n−1]) and N(x[n]) over
  the step (second order, the exponential Adams-Bashforth ETD2 scheme; N(x[−1]) := N(x[0])). One
  matrix product and one residual evaluation per step.
- ``"rk4"``: classic RK4 on the full right-hand side with ``substeps`` per controller sample
  (default: enough for h ≤ 0.02 s; the fastest eigenvalues are about −25 1/s). A cross-check.

Three ways to run the same step map:

- :func:`run_batch`: many realisations stepped together in numpy (runs on the trailing axis);
- :func:`run_single`: one realisation as a waveform fixed point: guess the trajectory (the linear
  model), evaluate the step map for ALL samples at once (time on the trailing axis), and solve the
  linear recursion ``z[n+1] = Phi_cl z[n] + (S(z[n]) − Phi_cl z[n])`` with per-mode IIR filters
  (scipy.signal.lfilter). The fixed point is exactly the stepped trajectory; a few iterations bring the
  difference to round-off. If it does not converge (limiters active for long) it falls back to
  stepping.
- :class:`fcrlive.sim.realtime.RealtimeSimulator`: one step at a time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from fcrlive.sim import linear as lin
from fcrlive.sim import model as mdl

Integrator = Literal["exp", "rk4"]


class Stepper:
    """The step map of one controller sample, vectorised over a trailing axis of length R."""

    def __init__(self, plant, *, open_loop: bool = False, integrator: Integrator = "exp",
                 substeps: int | None = None, nonlinear: bool = True):
        self.m = m = mdl.build(plant)
        self.open_loop = open_loop
        self.integrator = integrator
        self.nonlinear = nonlinear
        u1 = plant.unit
        self.g0 = m.tp1.g0
        self.g_min, self.g_max = u1.servo.g_min, u1.servo.g_max
        self.k = m.ctl1
        self.kt = m.Tc * m.ctl1.Ki
        nx = m.nx
        # x[n+1] = P @ [x; Δc; ΔP_L[n]; ΔP_L[n+1] − ΔP_L[n]; N(x[n]); N(x[n]) − N(x[n−1])]
        self.P = np.hstack([m.Phi, m.Gc[:, None], m.GL0[:, None], m.GL1[:, None], m.GN0, m.GN1])
        self.nx = nx
        if integrator == "rk4":
            if substeps is None:
                substeps = max(1, math.ceil(m.Tc / 0.02 - 1e-9))
            self.substeps = int(substeps)
            self.EN = np.zeros((nx, len(mdl.RESIDUAL_ROWS)))
            for j, row in enumerate(mdl.RESIDUAL_ROWS):
                self.EN[row, j] = 1.0
        elif integrator != "exp":
            raise ValueError(f"unknown integrator {integrator!r}")

    # -- unit 1's digital governor ------------------------------------------------------------------
    def control(self, x: np.ndarray, i1: np.ndarray, r, v, app):
        """(y, ε, c, Δc, i1_next) at one sample; ``app`` the applied frequency deviation (open loop)."""
        return self.control_full(x, i1, r, v, app)[:5]

    def control_full(self, x: np.ndarray, i1: np.ndarray, r, v, app):
        """:meth:`control` plus the unlimited Δc and integrator update of the linear governor."""
        k = self.k
        y = (app if self.open_loop else x[mdl.F1]) + v
        eps = r - y
        dcr = k.ce * eps + k.ci * i1
        if k.cg != 0.0:
            dcr = dcr + k.cg * x[mdl.G1]
        inc = k.ie * eps + k.ii * i1
        if k.ig != 0.0:
            inc = inc + k.ig * x[mdl.G1]
        c = dcr + self.g0
        if self.nonlinear and (np.max(c) > self.g_max or np.min(c) < self.g_min):
            c = np.minimum(np.maximum(c, self.g_min), self.g_max)
            dc = c - self.g0
            # Conditional integration: no integrating further into a limit (anti-windup).
            sat = c != dcr + self.g0
            i1n_lin = i1 + self.kt * inc
            inc = np.where(sat & ((dc - dcr) * inc < 0.0), 0.0, inc)
            i1n = i1 + self.kt * inc
        else:
            dc = dcr
            i1n = i1n_lin = i1 + self.kt * inc
        return y, eps, c, dc, i1n, dcr, i1n_lin

    # -- the continuous plant over one sample -------------------------------------------------------
    def advance(self, x: np.ndarray, dc, pl0, pl1, n_prev: np.ndarray | None = None):
        """(x[n+1], N(x[n])): one sample with Δc held and the load linear from pl0 to pl1.

        ``n_prev`` is N(x[n−1]) from the previous call (None at the first step); the second element of
        the result is None for the linear model and for RK4.
        """
        m = self.m
        if self.integrator == "rk4":
            return self._rk4(x, dc, pl0, pl1), None
        R = x.shape[1]
        nx = self.nx
        nN = len(mdl.RESIDUAL_ROWS)
        U = np.empty((nx + 3 + 2 * nN, R))
        U[:nx] = x
        U[nx] = dc
        U[nx + 1] = pl0
        np.subtract(pl1, pl0, out=U[nx + 2])
        if not self.nonlinear:
            U[nx + 3:] = 0.0
            return self.P @ U, None
        N = U[nx + 3:nx + 3 + nN]
        mdl.residual(m, x, out=N)
        if n_prev is None:
            U[nx + 3 + nN:] = 0.0
        else:
            np.subtract(N, n_prev, out=U[nx + 3 + nN:])
        return self.P @ U, N.copy()

    def _f(self, x, dc, pl):
        m = self.m
        f = m.A @ x
        f += np.outer(m.B[:, 0], dc) if np.ndim(dc) else m.B[:, [0]] * dc
        f += m.B[:, [1]] * pl
        if self.nonlinear:
            f += self.EN @ mdl.residual(m, x)
        return f

    def _rk4(self, x, dc, pl0, pl1):
        K = self.substeps
        h = self.m.Tc / K
        dc = np.asarray(dc, float)
        pl0 = np.asarray(pl0, float)
        dpl = (np.asarray(pl1, float) - pl0) / K
        for j in range(K):
            a = pl0 + j * dpl
            b = a + 0.5 * dpl
            c = a + dpl
            k1 = self._f(x, dc, a)
            k2 = self._f(x + 0.5 * h * k1, dc, b)
            k3 = self._f(x + 0.5 * h * k2, dc, b)
            k4 = self._f(x + h * k3, dc, c)
            x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        return x


@dataclass(frozen=True)
class Inputs:
    """Per-sample inputs of one run (length N; ``pl`` has N + 1 knots)."""

    r: np.ndarray
    v: np.ndarray
    pl: np.ndarray
    app: np.ndarray | None


RAW = ("y", "epsilon", "c", "a", "u", "w_coi", "pm", "omega")
"""Signals a run returns: y, ε, c (absolute), a (absolute), u (filtered ΔPe1), ω_coi, Pm1 (absolute),
Δω1."""


def _outputs_from_states(st: Stepper, x: np.ndarray, i1: np.ndarray, inp: Inputs) -> dict[str, np.ndarray]:
    y, eps, c, _dc, _ = st.control(x, i1, inp.r, inp.v, inp.app)
    m = st.m
    if st.nonlinear:
        pm = mdl.pm1_absolute(m, x)
    else:
        pm = m.tp1.Pm0 + m.C_pm1 @ x
    return {
        "y": y,
        "epsilon": eps,
        "c": c,
        "a": x[mdl.G1] + m.tp1.g0,
        "u": x[mdl.PF1].copy(),
        "w_coi": m.C_coi @ x,
        "pm": pm,
        "omega": x[mdl.W1].copy(),
    }


def _w_matrix(inp: Inputs) -> np.ndarray:
    N = len(inp.r)
    w = np.zeros((len(lin.INPUTS), N))
    w[0], w[1] = inp.r, inp.v
    w[2], w[3] = inp.pl[:N], inp.pl[1:N + 1]
    if inp.app is not None:
        w[4] = inp.app
    return w


def run_single(plant, inp: Inputs, *, open_loop: bool = False, nonlinear: bool = True,
               integrator: Integrator = "exp", substeps: int | None = None, tol: float = 1e-10,
               max_iter: int = 40) -> dict[str, np.ndarray]:
    """One run from the steady state (module docstring); returns the :data:`RAW` signals, length N."""
    st = Stepper(plant, open_loop=open_loop, integrator=integrator, substeps=substeps, nonlinear=nonlinear)
    cl = lin.closed_loop(plant, open_loop)
    if integrator == "exp":
        # the linear model (exact when nonlinear=False), then the nonlinear fixed point
        z = _fixed_point_exp(st, cl, inp, tol, max_iter if nonlinear else 0)
    else:
        z = lin.recursion(cl.Phi, cl.Gam @ _w_matrix(inp))  # the linear model as the first guess
        nx = st.nx
        for _ in range(max_iter):
            x, i1 = z[:nx], z[nx]
            _, _, _, dc, i1n = st.control(x, i1, inp.r, inp.v, inp.app)
            xn = st.advance(x, dc, inp.pl[:-1], inp.pl[1:])[0]
            S = np.vstack([xn, i1n[None]])
            d = S - cl.Phi @ z
            z_new = lin.recursion(cl.Phi, d)
            scale = np.max(np.abs(z_new), axis=1) + 1e-300
            delta = float(np.max(np.max(np.abs(z_new - z), axis=1) / scale))
            z = z_new
            if delta < tol:
                break
        else:
            z = _step_all(st, inp)
    return _outputs_from_states(st, z[:st.nx], z[st.nx], inp)


def _fixed_point_exp(st: Stepper, cl, inp: Inputs, tol: float, max_iter: int) -> np.ndarray:
    """The linear run and the waveform fixed point for the exponential integrator.

    Each step is the linear closed-loop step plus δ[n] = GN0 N[n] + GN1 (N[n] − N[n−1]) + Gc Δc_lim +
    e_i Δi_lim (residuals and limiter corrections along the current iterate), so z = recursion(Gam w + δ)
    with δ evaluated for all samples at once (``max_iter`` = 0: the linear run). All inputs go through
    ONE product with the modal projections of their columns, ``[Gam, GN0 + GN1, −GN1, Gc, e_i]``, on
    the stacked channels ``[w; N[n]; N[n−1]; Δc_lim; Δi_lim]`` (the limiter rows only when a limit is
    hit), and every iteration works in preallocated buffers (fresh arrays of this size cost page faults).
    """
    m, nx = st.m, st.nx
    nz, nw, N = cl.nz, len(lin.INPUTS), len(inp.r)
    md = lin.modal(cl.Phi)
    if md is None:
        z = lin.recursion(cl.Phi, cl.Gam @ _w_matrix(inp))
        return z if max_iter == 0 else _step_all(st, inp)
    nN = len(mdl.RESIDUAL_ROWS)
    Pin = _input_projection(md, cl)
    # channel rows: w (nw), N[n] (nN), N[n − 1] (nN), Δc_lim, Δi_lim
    ch = np.empty((nw + 2 * nN + 2, N))
    ch[:nw] = _w_matrix(inp)
    z = np.empty((nz, N))
    q = np.empty((nz, N))
    g = np.empty((nz, N))
    np.matmul(Pin[:, :nw], ch[:nw], out=g)
    lin.back_project(md, lin.filter_modes(md, g, out=q), out=z)
    if max_iter == 0:
        return z
    # Precondition with the residual's Jacobian J at the mean state of the linear run (the deviations
    # drift with the random-walk load): iterate with the LTI operator Phi + A0 J on the channels
    # N[n] − J z[n] instead of N[n] (A0 = [GN0 + GN1; 0] the columns of N[n]). The fixed point, the
    # stepped trajectory, is the same; the contraction is faster.
    J = _residual_jacobian(m, z[:nx].mean(axis=1))
    jc = np.flatnonzero(np.any(J != 0.0, axis=0))
    if len(jc):
        A0 = np.zeros((nz, nN))
        A0[:nx] = m.GN0 + m.GN1
        mdK = lin.modal_form(cl.Phi + A0 @ np.hstack([J, np.zeros((nN, nz - nx))]))
        if mdK is not None:
            md = mdK
            Pin = _input_projection(md, cl, cache=False)
            j0, j1 = int(jc[0]), int(jc[-1]) + 1
            J = np.ascontiguousarray(J[:, j0:j1])
        else:
            jc = jc[:0]
    k, g0 = st.k, st.g0
    ew = inp.r - inp.v  # ε without the speed feedback
    if inp.app is not None and st.open_loop:
        ew = ew - inp.app
    nlim = nw + 2 * nN
    Nn, Np = ch[nw:nw + nN], ch[nw + nN:nlim]
    z_new = np.empty((nz, N))
    dz = np.empty((nz, N))
    buf = np.empty(N)
    for _ in range(max_iter):
        x, i1 = z[:nx], z[nx]
        # unit 1's demand, to see whether it hits a limit anywhere (then the exact limiter corrections)
        if st.open_loop:
            np.multiply(ew, k.ce, out=buf)
        else:
            np.subtract(ew, x[mdl.F1], out=buf)
            buf *= k.ce
        buf += k.ci * i1
        if k.cg != 0.0:
            buf += k.cg * x[mdl.G1]
        buf += g0
        n_ch = nlim
        if buf.max() > st.g_max or buf.min() < st.g_min:
            _, _, _, dc, i1n, dcr, i1n_lin = st.control_full(x, i1, inp.r, inp.v, inp.app)
            if dc is not dcr:
                np.subtract(dc, dcr, out=ch[nlim])
                np.subtract(i1n, i1n_lin, out=ch[nlim + 1])
                n_ch = nlim + 2
        mdl.residual(m, x, out=Nn)
        Np[:, 0] = Nn[:, 0]  # N[−1] := N[0]
        Np[:, 1:] = Nn[:, :-1]
        if len(jc):
            Nn -= J @ x[j0:j1]
        np.matmul(Pin[:, :n_ch], ch[:n_ch], out=g)
        lin.filter_modes(md, g, out=q)
        lin.back_project(md, q, out=z_new)
        np.subtract(z_new, z, out=dz)
        step = np.maximum(dz.max(axis=1), -dz.min(axis=1))
        scale = np.maximum(z_new.max(axis=1), -z_new.min(axis=1)) + 1e-300
        delta = float(np.max(step / scale))
        z, z_new = z_new, z
        if delta < tol:
            return z
    return _step_all(st, inp)


_PIN_CACHE: dict[int, tuple[object, np.ndarray]] = {}


def _residual_jacobian(m: mdl.Model, x: np.ndarray) -> np.ndarray:
    """∂N/∂x (rows :data:`model.RESIDUAL_ROWS`, columns the states) at the state ``x`` (central differences;
    it only preconditions the iteration)."""
    nx = len(x)
    h = 1e-6
    X = np.repeat(x[:, None], 2 * nx, axis=1)
    for j in range(nx):
        X[j, 2 * j] += h
        X[j, 2 * j + 1] -= h
    R = mdl.residual(m, X)
    J = (R[:, 0::2] - R[:, 1::2]) / (2.0 * h)
    J[np.abs(J) < 1e-12] = 0.0
    return J


def _input_projection(md, cl, cache: bool = True) -> np.ndarray:
    """Modal projections of the input columns ``[Gam, GN0 + GN1, −GN1, Gc, e_i]`` (cached per loop)."""
    hit = _PIN_CACHE.get(id(cl)) if cache else None
    if hit is not None and hit[0] is cl:
        return hit[1]
    m, nx = cl.model, cl.model.nx
    nN = len(mdl.RESIDUAL_ROWS)
    cols = np.zeros((cl.nz, len(lin.INPUTS) + 2 * nN + 2))
    nw = len(lin.INPUTS)
    cols[:, :nw] = cl.Gam
    cols[:nx, nw:nw + nN] = m.GN0 + m.GN1
    cols[:nx, nw + nN:nw + 2 * nN] = -m.GN1
    cols[:nx, nw + 2 * nN] = m.Gc
    cols[nx, nw + 2 * nN + 1] = 1.0
    Pin = np.ascontiguousarray(md.proj @ cols)
    if not cache:
        return Pin
    if len(_PIN_CACHE) > 64:
        _PIN_CACHE.clear()
    _PIN_CACHE[id(cl)] = (cl, Pin)
    return Pin


def _step_all(st: Stepper, inp: Inputs) -> np.ndarray:
    """Plain stepping of one run (fallback): states (nz, N)."""
    N = len(inp.r)
    z = np.zeros((st.nx + 1, N))
    x = np.zeros((st.nx, 1))
    i1 = np.zeros(1)
    n_prev = None
    for n in range(N - 1):
        app = None if inp.app is None else inp.app[n:n + 1]
        _, _, _, dc, i1 = st.control(x, i1, inp.r[n:n + 1], inp.v[n:n + 1], app)
        x, n_prev = st.advance(x, dc, inp.pl[n:n + 1], inp.pl[n + 1:n + 2], n_prev)
        z[:st.nx, n + 1] = x[:, 0]
        z[st.nx, n + 1] = i1[0]
    return z


# ---------------------------------------------------------------------------------------------------
# Noise streams and batches


N_STREAMS = 4
LOAD, PROCESS, MEAS_P, MEAS_F = range(N_STREAMS)


def streams(seed: int) -> list[np.random.Generator]:
    """Independent generators of one realisation: load, process noise, power and frequency meter noise.

    Separate streams make a source's draws independent of which other sources are switched on, so runs
    with each source alone (same seed) add up to the run with all of them (the SNR check).
    """
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(N_STREAMS)]


def _draw(gens, stream: int, nb: int, scale: float) -> np.ndarray | None:
    """(nb, R) scaled standard normals of one stream of every realisation; None when scale is 0."""
    if not scale > 0:
        return None
    out = np.stack([g[stream].standard_normal(nb) for g in gens], axis=1)
    out *= scale
    return out


def run_batch(plant, N: int, seeds, *, r: np.ndarray, app: np.ndarray | None, sigma_l: float,
              sigma_v: float, load_det: np.ndarray | None, fields, open_loop: bool = False,
              nonlinear: bool = True, integrator: Integrator = "exp", substeps: int | None = None,
              block: int = 2048) -> dict[str, np.ndarray]:
    """Realisations of ``seeds`` stepped together. Returns the requested :data:`RAW` fields (plus "v",
    "load") as (N, R) arrays. Draws of each stream are made in blocks, which gives the same numbers as
    one draw of N (numpy's Generator is sequential)."""
    seeds = list(seeds)
    R = len(seeds)
    st = Stepper(plant, open_loop=open_loop, integrator=integrator, substeps=substeps, nonlinear=nonlinear)
    m = st.m
    gens = [streams(s) for s in seeds]
    fields = tuple(fields)
    out = {f: np.empty((N, R)) for f in fields}
    sl = sigma_l * math.sqrt(m.Tc)
    x = np.zeros((st.nx, R))
    i1 = np.zeros(R)
    pl = np.zeros(R)  # stochastic part of ΔP_L at the current knot
    c_w1, c_w2 = m.C_coi[mdl.W1], m.C_coi[mdl.W2]
    zeros = np.zeros(R)
    n_prev = None
    for n0 in range(0, N, block):
        nb = min(block, N - n0)
        xi = _draw(gens, LOAD, nb, sl)
        ve = _draw(gens, PROCESS, nb, sigma_v)
        for j in range(nb):
            n = n0 + j
            v = ve[j] if ve is not None else zeros
            a_n = None if app is None else app[n]
            y, eps, c, dc, i1n = st.control(x, i1, r[n], v, a_n)
            pl1 = pl + xi[j] if xi is not None else pl
            if load_det is not None:
                x_next, n_prev = st.advance(x, dc, pl + load_det[n], pl1 + load_det[n + 1], n_prev)
            else:
                x_next, n_prev = st.advance(x, dc, pl, pl1, n_prev)
            for f in fields:
                o = out[f]
                if f == "y":
                    o[n] = y
                elif f == "epsilon":
                    o[n] = eps
                elif f == "c":
                    o[n] = c
                elif f == "a":
                    np.add(x[mdl.G1], st.g0, out=o[n])
                elif f == "u":
                    o[n] = x[mdl.PF1]
                elif f == "w_coi":
                    np.multiply(x[mdl.W1], c_w1, out=o[n])
                    o[n] += c_w2 * x[mdl.W2]
                elif f == "pm":
                    o[n] = mdl.pm1_absolute(m, x) if nonlinear else m.tp1.Pm0 + m.C_pm1 @ x
                elif f == "omega":
                    o[n] = x[mdl.W1]
                elif f == "v":
                    o[n] = v
                elif f == "load":
                    o[n] = pl + (load_det[n] if load_det is not None else 0.0)
            x, i1, pl = x_next, i1n, pl1
    return out


def run_batch_linear(plant, N: int, seeds, *, r: np.ndarray, app: np.ndarray | None, sigma_l: float,
                     sigma_v: float, load_det: np.ndarray | None, fields, open_loop: bool = False,
                     block: int = 2048) -> dict[str, np.ndarray]:
    """The linear model's batch: one matrix product per sample for states and all outputs."""
    seeds = list(seeds)
    R = len(seeds)
    cl = lin.closed_loop(plant, open_loop)
    m = cl.model
    gens = [streams(s) for s in seeds]
    nz, nw = cl.nz, len(lin.INPUTS)
    idx = {"y": 0, "epsilon": 1, "c": 2, "a": 3, "u": 4, "w_coi": 5, "pm": 6, "omega": 7}
    offset = {"c": m.tp1.g0, "a": m.tp1.g0, "pm": m.tp1.Pm0}
    fields = tuple(fields)
    rows = [idx[f] for f in fields if f in idx]
    lin_fields = [f for f in fields if f in idx]
    Pz = np.hstack([cl.Phi, cl.Gam])
    Po = np.hstack([cl.C, cl.D])[rows]
    out = {f: np.empty((N, R)) for f in fields}
    sl = sigma_l * math.sqrt(m.Tc)
    U = np.zeros((nz + nw, R))
    Ux = np.zeros((nz + nw, R))
    pl = np.zeros(R)
    zeros = np.zeros(R)
    for n0 in range(0, N, block):
        nb = min(block, N - n0)
        xi = _draw(gens, LOAD, nb, sl)
        ve = _draw(gens, PROCESS, nb, sigma_v)
        for j in range(nb):
            n = n0 + j
            v = ve[j] if ve is not None else zeros
            pl1 = pl + xi[j] if xi is not None else pl
            U[nz] = r[n]
            U[nz + 1] = v
            ld0 = load_det[n] if load_det is not None else 0.0
            ld1 = load_det[n + 1] if load_det is not None else 0.0
            U[nz + 2] = pl + ld0
            U[nz + 3] = pl1 + ld1
            if app is not None:
                U[nz + 4] = app[n]
            if rows:
                o = Po @ U
                for k, f in enumerate(lin_fields):
                    out[f][n] = o[k]
                    if f in offset:
                        out[f][n] += offset[f]
            if "v" in out:
                out["v"][n] = v
            if "load" in out:
                out["load"][n] = U[nz + 2]
            np.matmul(Pz, U, out=Ux[:nz])
            U[:nz] = Ux[:nz]
            pl = pl1
    return out
