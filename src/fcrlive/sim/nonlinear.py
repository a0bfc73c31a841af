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

- :func:`run_batch`: many realisations stepped together in numpy (runs on the trailing axis). With
  ``"exp"`` one sample of all runs is ONE matrix product (:class:`_BatchPlan`: the linear closed loop,
  the residual channels and rows derived from the state for the residual and the limiter checks) plus
  about ten small ufuncs; the outputs are formed afterwards for blocks of samples.
- :func:`run_single`: one realisation as a waveform fixed point: guess the trajectory (the linear
  model), evaluate the step map for ALL samples at once (time on the trailing axis), and solve the
  linear recursion ``z[n+1] = Phi_K z[n] + (S(z[n]) − Phi_K z[n])`` with per-mode IIR filters
  (scipy.signal.lfilter; Phi_K = the closed loop plus the residual's Jacobian at the run's mean state,
  which speeds up the contraction). The fixed point is exactly the stepped trajectory; the iteration
  stops when the estimated remaining difference is below ``tol`` (1e-10 relative). If it does not
  converge (limiters active for long) it falls back to stepping.
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
        if m.ctl1.has_derivative:
            raise _derivative_error()
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
    if mdl.build(plant).ctl1.has_derivative:
        if nonlinear:
            raise _derivative_error()
        return _linear_outputs(plant, inp, open_loop)
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


def _derivative_error():
    from fcrlive.errors import ConfigError

    return ConfigError("a governor with derivative action (Td > 0) is simulated by the linear model only: "
                       "SimConfig(model='linear'), one run at a time")


def _linear_outputs(plant, inp: Inputs, open_loop: bool) -> dict[str, np.ndarray]:
    """The :data:`RAW` signals of the linear closed loop (:func:`linear.run`), for any controller."""
    cl = lin.closed_loop(plant, open_loop)
    o = dict(zip(lin.OUTPUTS, lin.run(cl, _w_matrix(inp)), strict=True))
    m = cl.model
    return {"y": o["y"], "epsilon": o["epsilon"], "c": o["dc"] + m.tp1.g0, "a": o["da"] + m.tp1.g0,
            "u": o["u"], "w_coi": o["w_coi"], "pm": o["dpm"] + m.tp1.Pm0, "omega": o["omega"]}


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
    z[:, 0] = 0.0
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
            j0, j1 = int(jc[0]), int(jc[-1]) + 1
            J = np.ascontiguousarray(J[:, j0:j1])
        else:
            jc = jc[:0]
    # The iteration needs only the rows the residual and the governor read (the turbines, gates,
    # filtered speeds, integrators; the speeds with Dturb): only they are formed and tested, and only
    # the modes that reach them are filtered (not the power-measurement filter's); the rest at the end.
    it_rows = [mdl.Q1, mdl.Q2, mdl.G1, mdl.G2, mdl.F1, mdl.F2, mdl.I2, nx]
    if m.any_dturb:
        it_rows += [mdl.W1, mdl.W2]
    it_rows = sorted(it_rows)
    bsub = np.abs(md.back[it_rows])
    reach = np.max(bsub, axis=0) > 1e-13 * np.max(np.abs(md.back), axis=0)
    for row, _ in md.pairs:
        reach[row] = reach[row] or reach[row + 1]
    md, n_it = lin.reorder_modes(md, reach)
    Pin = _input_projection(md, cl, cache=False)
    back_it = np.ascontiguousarray(md.back[:, :n_it])
    # contiguous runs of it_rows for the products
    runs: list[tuple[int, int]] = []
    for row in it_rows:
        if runs and runs[-1][1] == row:
            runs[-1] = (runs[-1][0], row + 1)
        else:
            runs.append((row, row + 1))
    k, g0 = st.k, st.g0
    ew = inp.r - inp.v  # ε without the speed feedback
    if inp.app is not None and st.open_loop:
        ew = ew - inp.app
    nlim = nw + 2 * nN
    Nn, Np = ch[nw:nw + nN], ch[nw + nN:nlim]
    z_new = np.zeros((nz, N))  # rows outside it_rows stay finite (J is zero there)
    buf = np.empty(N)
    deltas: list[float] = []
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
        lin.filter_modes(md, g, out=q, rows=(0, n_it))
        delta = 0.0
        for r0, r1 in runs:
            np.matmul(back_it[r0:r1], q[:n_it, :-1], out=z_new[r0:r1, 1:])
            for row in range(r0, r1):
                a, b = z_new[row], z[row]
                np.subtract(a, b, out=buf)
                step = max(buf.max(), -buf.min())
                scale = max(a.max(), -a.min()) + 1e-300
                delta = max(delta, step / scale)
        z, z_new = z_new, z
        deltas.append(delta)
        # stop when the estimated remaining error (linear convergence at the observed rate) is below tol
        if delta < tol or (len(deltas) >= 3 and _remaining(deltas) < tol):
            lin.filter_modes(md, g, out=q, rows=(n_it, nz))
            return lin.back_project(md, q, out=z)
    return _step_all(st, inp)


def _remaining(deltas: list[float]) -> float:
    """Estimated distance to the fixed point after steps ``deltas`` of a linearly converging iteration:
    δ ρ/(1 − ρ) with ρ the larger of the last two step ratios (infinite unless ρ < 0.5)."""
    rho = max(deltas[-1] / deltas[-2], deltas[-2] / deltas[-3])
    return deltas[-1] * rho / (1.0 - rho) if rho < 0.5 else math.inf


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
    if mdl.build(plant).ctl1.has_derivative:
        raise _derivative_error()
    if integrator == "exp":
        return _run_batch_exp(plant, N, seeds, r=r, app=app, sigma_l=sigma_l, sigma_v=sigma_v,
                              load_det=load_det, fields=fields, open_loop=open_loop, nonlinear=nonlinear,
                              chunk=block)
    return _run_batch_stepper(plant, N, seeds, r=r, app=app, sigma_l=sigma_l, sigma_v=sigma_v,
                              load_det=load_det, fields=fields, open_loop=open_loop, nonlinear=nonlinear,
                              integrator=integrator, substeps=substeps, block=block)


def run_batch_linear(plant, N: int, seeds, *, r: np.ndarray, app: np.ndarray | None, sigma_l: float,
                     sigma_v: float, load_det: np.ndarray | None, fields, open_loop: bool = False,
                     block: int = 2048) -> dict[str, np.ndarray]:
    """The linear model's batch: one matrix product per sample (:func:`run_batch` without the residual)."""
    if mdl.build(plant).ctl1.has_derivative:
        raise _derivative_error()
    return _run_batch_exp(plant, N, seeds, r=r, app=app, sigma_l=sigma_l, sigma_v=sigma_v,
                          load_det=load_det, fields=fields, open_loop=open_loop, nonlinear=False, chunk=block)


class _BatchPlan:
    """The exponential step of :class:`Stepper` for many runs as ONE matrix product per sample.

    Per sample n a column block (rows, runs) holds ``[E; z; w; s; s_prev]``: E derived rows of z (the
    absolute turbine flows and gates, the linearised head change, unit 1's demand without its input
    part, unit 2's demand), z = [x; i1], w = [ε_w = r − v (− y_app), ΔP_L[n], ΔP_L[n+1], 1], s = the
    residual channels [dd; hh·Δq; limiter of unit 2] at n (the residual N = Kmap s), s_prev those at
    n − 1. Then ``[E; z]`` at n + 1 = ``M @ [z; w; s; s_prev]`` at n: the closed loop of the linear
    governor (Phi, Gam of :func:`linear.closed_loop`) plus the ETD2 residual terms (GN0 + GN1) N[n] −
    GN1 N[n−1]. Unit 1's limiter (rare) is applied as a correction of that product.
    """

    def __init__(self, plant, open_loop: bool, nonlinear: bool):
        cl = lin.closed_loop(plant, open_loop)
        m = cl.model
        self.m, self.cl = m, cl
        nx, nz = m.nx, cl.nz
        self.nonlinear = nonlinear
        self.dturb = bool(nonlinear and m.any_dturb)
        # derived rows E (as rows over z, plus offsets through the row of ones)
        E: list[np.ndarray] = []
        e_off: list[float] = []
        if nonlinear:
            for rows, off in (((mdl.Q1, mdl.Q2), m.q0[:, 0]), ((mdl.G1, mdl.G2), m.g0[:, 0])):
                for j, row in enumerate(rows):
                    e = np.zeros(nz)
                    e[row] = 1.0
                    E.append(e)
                    e_off.append(float(off[j]))
            for j, (q, g) in enumerate(((mdl.Q1, mdl.G1), (mdl.Q2, mdl.G2))):
                e = np.zeros(nz)
                e[q] = m.two_h_q0[j, 0]
                e[g] = -m.two_h_g0[j, 0]
                E.append(e)
                e_off.append(0.0)
            e = np.zeros(nz)
            e[:nx] = m.c2_row
            E.append(e)
            e_off.append(m.tp2.g0)
        e_dc = cl.C[lin.OUTPUTS.index("dc")].copy()  # Δc without the ε_w part
        E.append(e_dc)
        e_off.append(0.0)
        self.ne = ne = len(E)
        Ez = np.array(E)
        self.QA, self.GA, self.LH, self.C2 = 0, 2, 4, 6
        self.DCR = ne - 1
        # the columns [z; w; s; s_prev]
        nw = 4
        ns = (5 + (2 if self.dturb else 0)) if nonlinear else 0
        self.nz, self.nw, self.ns = nz, nw, ns
        ncol = nz + nw + 2 * ns
        Z = np.zeros((nz, ncol))
        Z[:, :nz] = cl.Phi
        iw = lin.INPUTS.index
        Z[:, nz] = cl.Gam[:, iw("r")]  # ε_w (r, −v and −y_app enter alike)
        Z[:, nz + 1] = cl.Gam[:, iw("pl0")]
        Z[:, nz + 2] = cl.Gam[:, iw("pl1")]
        if ns:
            # N = Kmap s: turbines from dd and hh·Δq (and Δg·Δω), unit 2's limiter as it is
            Kmap = np.zeros((5, ns))
            a = (m.At * m.inv_2H)[:, 0]
            for j in range(2):
                Kmap[j, j] = a[j] * m.qn0[j, 0]
                Kmap[j, 2 + j] = a[j]
                Kmap[2 + j, j] = m.neg_inv_Tw[j, 0]
                if self.dturb:
                    Kmap[j, 5 + j] = -m.inv_2H[j, 0] * m.Dturb[j, 0]
            Kmap[4, 4] = 1.0
            Z[:nx, nz + nw:nz + nw + ns] = (m.GN0 + m.GN1) @ Kmap
            Z[:nx, nz + nw + ns:] = -m.GN1 @ Kmap
        Mtop = Ez @ Z
        Mtop[:, nz + 3] += np.array(e_off)  # offsets through the row of ones
        self.M = np.ascontiguousarray(np.vstack([Mtop, Z]))
        self.e_off = np.array(e_off)
        # unit 1's limiter corrections Δc (column Gc) and Δi1 (the integrator row) of the product
        Cz = np.zeros((nz, 2))
        Cz[:nx, 0] = m.Gc
        Cz[nx, 1] = 1.0
        self.Mc = np.vstack([Ez @ Cz, Cz])
        self.rows = ne + nz + nw + 2 * ns


def _run_batch_exp(plant, N: int, seeds, *, r: np.ndarray, app: np.ndarray | None, sigma_l: float,
                   sigma_v: float, load_det: np.ndarray | None, fields, open_loop: bool, nonlinear: bool,
                   chunk: int = 2048, nb: int = 128) -> dict[str, np.ndarray]:
    """:func:`run_batch` with the exponential integrator (:class:`_BatchPlan`): per sample one matrix
    product and a dozen small ufuncs; the outputs are formed afterwards for ``nb`` samples at once."""
    seeds = list(seeds)
    R = len(seeds)
    pln = _BatchPlan(plant, open_loop, nonlinear)
    m = pln.m
    nz, nw, ns, ne = pln.nz, pln.nw, pln.ns, pln.ne
    k = m.ctl1
    g0 = m.tp1.g0
    u1 = plant.unit
    g_min, g_max = u1.servo.g_min, u1.servo.g_max
    dc_hi, dc_lo = g_max - g0, g_min - g0
    lo2, hi2 = m.g_lim2
    kt = m.Tc * k.Ki
    gens = [streams(s) for s in seeds]
    fields = tuple(fields)
    out = {f: np.empty((N, R)) for f in fields}
    sl = sigma_l * math.sqrt(m.Tc)
    chunk = max(nb, chunk - chunk % nb)
    # row offsets in a sample's column block
    oZ = ne
    oW = oZ + nz
    oS = oW + nw
    oP = oS + ns
    K = pln.rows
    buf = np.zeros((nb + 1, K, R))
    buf[:, oW + 3] = 1.0
    M = pln.M
    # per-sample views, made once: (block, product input, product output, Δc row, ε_w row,
    # g, q, Δh_lin, unit 2's demand, dd, hh·Δq, Δq, Δg, Δω, limiter channel, s, s_prev, previous s)
    V = []
    for j in range(nb if ns else 0):
        b = buf[j]
        V.append((b, b[oZ:oP + ns], buf[j + 1, :oW], b[pln.DCR], b[oW], b[2:4], b[0:2], b[4:6], b[6],
                  b[oS:oS + 2], b[oS + 2:oS + 4], b[oZ + mdl.Q1:oZ + mdl.Q2 + 1],
                  b[oZ + mdl.G1:oZ + mdl.G2 + 1], b[oZ + mdl.W1:oZ + mdl.W2 + 1], b[oS + 4],
                  b[oS:oS + ns], b[oP:oP + ns], buf[j - 1, oS:oS + ns] if j else None, b[oS + 5:oS + 7]))
    xi_raw = np.empty((R, chunk))
    ve_raw = np.empty((R, chunk))
    ve = np.empty((chunk, R))
    knots = np.empty((chunk + 1, R))
    pl = np.zeros(R)
    s_prev = np.zeros((ns, R))
    hh = np.empty((2, R))
    ce, h0, inv_tg2, dturb = k.ce, m.h0, m.inv_Tg2, pln.dturb
    for c0 in range(0, N, chunk):
        cn = min(chunk, N - c0)
        # noise of this chunk: the same numbers as one draw of N per stream and run
        if sl > 0:
            for i, g in enumerate(gens):
                g[LOAD].standard_normal(cn, out=xi_raw[i, :cn])
            knots[0] = pl
            np.multiply(xi_raw[:, :cn].T, sl, out=knots[1:cn + 1])
            np.cumsum(knots[:cn + 1], axis=0, out=knots[:cn + 1])  # sequential: pl[n+1] = pl[n] + ξ[n]
            pl = knots[cn].copy()
        else:
            knots[:cn + 1] = pl
        if sigma_v > 0:
            for i, g in enumerate(gens):
                g[PROCESS].standard_normal(cn, out=ve_raw[i, :cn])
            np.multiply(ve_raw[:, :cn].T, sigma_v, out=ve[:cn])
        else:
            ve[:cn] = 0.0
        for b0 in range(0, cn, nb):
            bn = min(nb, cn - b0)
            n0 = c0 + b0
            blk = buf[:bn]
            v_b = ve[b0:b0 + bn]
            # inputs of the block's samples
            np.subtract(r[n0:n0 + bn, None], v_b, out=blk[:, oW])
            if app is not None and open_loop:
                blk[:, oW] -= app[n0:n0 + bn, None]
            blk[:, oW + 1] = knots[b0:b0 + bn]
            blk[:, oW + 2] = knots[b0 + 1:b0 + bn + 1]
            if load_det is not None:
                blk[:, oW + 1] += load_det[n0:n0 + bn, None]
                blk[:, oW + 2] += load_det[n0 + 1:n0 + bn + 1, None]
            if ns:
                blk[:, oS + 4] = 0.0  # unit 2's limiter channel, set where it acts
            if n0 == 0:
                buf[0, :oW] = 0.0
                buf[0, :ne] = pln.e_off[:, None]
            if not ns:  # the linear model: the product alone
                for j in range(bn):
                    np.matmul(M, buf[j, oZ:oS], out=buf[j + 1, :oW])
            for j in range(bn if ns else 0):
                (b, inp, nxt, dcr, ew, ga, qa, lh, c2, s_dd, s_hq, dq, dg, dw, lim, s_all, s_p, s_pj,
                 s_dw) = V[j]
                # unit 1's demand: the derived row plus its ε_w part
                dcr += ce * ew
                sat = dcr.max() > dc_hi or dcr.min() < dc_lo
                # turbines: h = (q/g)², dd = h − h0 − Δh_lin, hh·Δq; unit 2's limiter
                np.maximum(ga, 1e-6, out=ga)
                np.divide(qa, ga, out=hh)
                np.multiply(hh, hh, out=hh)
                hh -= h0
                np.subtract(hh, lh, out=s_dd)
                np.multiply(hh, dq, out=s_hq)
                if dturb:
                    np.multiply(dg, dw, out=s_dw)
                if c2.max() > hi2 or c2.min() < lo2:
                    np.maximum(c2, lo2, out=lim)
                    np.minimum(lim, hi2, out=lim)
                    lim -= c2
                    lim *= inv_tg2
                if j:
                    s_p[...] = s_pj
                else:
                    if n0 == 0:
                        s_prev[...] = s_all  # N[−1] := N[0]
                    s_p[...] = s_prev
                np.matmul(M, inp, out=nxt)
                if sat:
                    _batch_limit(pln, b, buf[j + 1], dcr, k, kt, g0, g_min, g_max, open_loop)
            if ns:
                s_prev[...] = buf[bn - 1, oS:oS + ns]
            _batch_outputs(pln, blk, out, n0, bn, r, v_b, app, load_det, open_loop, nonlinear, g_min,
                           g_max)
            buf[0, :oW] = buf[bn, :oW]
    return out


def _batch_limit(pln: _BatchPlan, b, nxt, dcr, k, kt, g0, g_min, g_max, open_loop) -> None:
    """Unit 1's limiter and anti-windup at one sample (as :meth:`Stepper.control_full`): corrects the
    next sample's rows ``nxt`` for Δc − Δc_lin and i1⁺ − i1⁺_lin."""
    oZ = pln.ne
    x_f1 = b[oZ + mdl.F1]
    x_g1 = b[oZ + mdl.G1]
    i1 = b[oZ + pln.m.nx]
    eps = b[oZ + pln.nz] if open_loop else b[oZ + pln.nz] - x_f1
    inc = k.ie * eps + k.ii * i1
    if k.ig != 0.0:
        inc = inc + k.ig * x_g1
    c = np.minimum(np.maximum(dcr + g0, g_min), g_max)
    dc = c - g0
    sat = c != dcr + g0
    inc_lim = np.where(sat & ((dc - dcr) * inc < 0.0), 0.0, inc)
    corr = np.vstack([dc - dcr, kt * inc_lim - kt * inc])
    nxt[:oZ + pln.nz] += pln.Mc @ corr


def _batch_outputs(pln: _BatchPlan, blk, out, n0, bn, r, v_b, app, load_det, open_loop, nonlinear, g_min,
                   g_max) -> None:
    """The requested RAW fields of ``bn`` samples from their column blocks ``blk`` (bn, rows, R)."""
    m = pln.m
    oZ = pln.ne
    x = blk[:, oZ:oZ + m.nx].transpose(1, 0, 2)  # (nx, bn, R)
    i1 = blk[:, oZ + m.nx]
    sl = slice(n0, n0 + bn)
    k = m.ctl1
    need = set(out)
    y = eps = None
    if need & {"y", "epsilon", "c"}:
        y = (app[sl, None] if open_loop else x[mdl.F1]) + v_b
        eps = r[sl, None] - y
    for f in out:
        o = out[f][sl]
        if f == "y":
            o[...] = y
        elif f == "epsilon":
            o[...] = eps
        elif f == "c":
            dcr = k.ce * eps + k.ci * i1
            if k.cg != 0.0:
                dcr = dcr + k.cg * x[mdl.G1]
            np.add(dcr, m.tp1.g0, out=o)
            if nonlinear:
                np.clip(o, g_min, g_max, out=o)
        elif f == "a":
            np.add(x[mdl.G1], m.tp1.g0, out=o)
        elif f == "u":
            o[...] = x[mdl.PF1]
        elif f == "w_coi":
            np.multiply(x[mdl.W1], m.C_coi[mdl.W1], out=o)
            o += m.C_coi[mdl.W2] * x[mdl.W2]
        elif f == "pm":
            if nonlinear:
                o[...] = mdl.pm1_absolute(m, x)
            else:
                np.add(np.tensordot(m.C_pm1, x, axes=1), m.tp1.Pm0, out=o)
        elif f == "omega":
            o[...] = x[mdl.W1]
        elif f == "v":
            o[...] = v_b
        elif f == "load":
            o[...] = blk[:, oZ + pln.nz + 1]


def _run_batch_stepper(plant, N: int, seeds, *, r: np.ndarray, app: np.ndarray | None, sigma_l: float,
                       sigma_v: float, load_det: np.ndarray | None, fields, open_loop: bool = False,
                       nonlinear: bool = True, integrator: Integrator = "exp", substeps: int | None = None,
                       block: int = 2048) -> dict[str, np.ndarray]:
    """:func:`run_batch` with :class:`Stepper` (any integrator; the RK4 cross-check)."""
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
