"""The two-machine test system of the paper (Fig. 3) as equations: state layout, operating point,
linear part, nonlinear residual, exact discretisation and the digital governor of unit 1.

Internal module shared by :mod:`fcrlive.sim.nonlinear`, :mod:`fcrlive.sim.linear` and
:mod:`fcrlive.sim.realtime`; the public API is in :mod:`fcrlive.sim`.

Model (deviations from the steady state at Pm0; per unit on each machine's own base unless noted)
-------------------------------------------------------------------------------------------------
Unit i (1 = studied, 2 = the rest of the grid):

- swing       2 H dΔω/dt = ΔPm − ΔPe − Kd Δω
- turbine     q = g sqrt(h), dq/dt = (h_s − h)/Tw, Pm = At h (q − q_nl) − Dturb g Δω
- servo       Tg dg/dt = c − g, the demand c clipped to [g_min, g_max] (so g stays inside too)
- speed filter Tf df/dt = Δω − f (anti-aliasing / measurement filter)

Unit 1's power measurement goes through the same filter (Tf dp/dt = ΔPe − p): the paper's u[n] is
"obtained in a similar manner" as y[n] (Section 2), and only then is ε/u the G_1 = G_J S of
:mod:`fcrlive.plant.transfer` (F_aa cancels from the path u → ε).

Unit 2's governor is analogue (integrated continuously), unit 1's is the digital PI at Tc with a zero
order hold (:class:`Controller`).

DC power flow on the system base S_b, unit i behind X_i = x'd_i S_b/S_i + x_i to the load bus 5, load
P_L = P_L0 + ΔP_L(t) + D ω_D at bus 5 with ω_D the frequency its damping D sees:

- ``damping_at="coi"``: ω_D = ω_coi = Σ H_i S_i Δω_i / Σ H_i S_i; the bus-5 angle is algebraic and only
  δ12 = δ1 − δ2 is a state (dδ12/dt = ω_b (Δω1 − Δω2), ω_b = 2π f0);
- ``damping_at="load_bus"``: ω_D = ω5 = (P1 + P2 − P_L)/D is the bus-5 frequency; the states are
  φ_i = δ_i − θ5 (dφ_i/dt = ω_b (Δω_i − ω5)), P_i = φ_i/X_i.

Everything is linear except the turbines (and the limiters), so the right-hand side is written as
``A x + B_c Δc1 + B_L ΔP_L + N(x)`` with N the (small) nonlinear residual. The grid frequency reported
is always the centre-of-inertia frequency ω_coi.

State layout (rows of ``x``): see the ``W1 ... PH2`` constants. Unit 1's integrator is a discrete state
kept beside ``x``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.linalg import expm

from fcrlive.blas import single_threaded
from fcrlive.errors import ConfigError
from fcrlive.plant.params import Governor, Plant, Unit

# State rows. Unit-wise pairs are adjacent so the two turbines are computed as one (2, R) block.
W1, W2 = 0, 1  # rotor speed deviations Δω [pu]
Q1, Q2 = 2, 3  # turbine flow deviations Δq [pu]
G1, G2 = 4, 5  # gate position deviations Δg [pu]
F1, F2 = 6, 7  # filtered speed deviations [pu]
PF1 = 8  # filtered electrical power deviation of unit 1 [pu machine base]
I2 = 9  # unit 2's (analogue) integrator [pu gate]
D12 = 10  # δ1 − δ2 [rad] (damping at the COI)
PH1, PH2 = 10, 11  # δ_i − θ5 [rad] (damping at the load bus)

RESIDUAL_ROWS = (W1, W2, Q1, Q2, G2)
"""Rows of the state the nonlinear residual N(x) acts on (in this order)."""


@dataclass(frozen=True)
class Controller:
    """A PI governor with permanent droop as linear maps (module docstring of plant/transfer.py).

    With e the control error [pu], i the integrator [pu gate] and g the gate deviation [pu]:
    ``Δc = ce·e + ci·i + cg·g`` and the integrator input ``ie·e + ii·i + ig·g`` (integrated with gain
    Kp/Ti: continuously for an analogue governor, by forward Euler ``i[n+1] = i[n] + Tc (Kp/Ti)·(...)``
    for a digital one). Covers both droop placements and both droop signals; with the classic placement
    and the demand as droop signal the algebraic loop c = Kp (e − ρ c) + i is solved exactly.
    """

    ce: float
    ci: float
    cg: float
    ie: float
    ii: float
    ig: float
    Ki: float
    """Integral gain Kp/Ti [1/s]."""
    # Derivative action (Governor.Td > 0): a second state ψ with Δc += cd·ψ, the integrator input
    # += id·ψ and ψ[n+1] = de·e + di·i + dd·ψ + dg·g. All zero for a PI.
    cd: float = 0.0
    id: float = 0.0
    de: float = 0.0
    di: float = 0.0
    dd: float = 0.0
    dg: float = 0.0

    @property
    def has_derivative(self) -> bool:
        return self.cd != 0.0

    @staticmethod
    def of(gov: Governor) -> Controller:
        if gov.digital and (gov.integral_method != "forward" or gov.Td > 0):
            return Controller._general(gov)
        Kp, rho = gov.Kp, gov.droop
        if gov.droop_signal == "gate":
            cg = -Kp * rho if gov.droop_placement == "classic" else 0.0
            ce, ci = Kp, 1.0
            ie, ii, ig = 1.0, 0.0, -rho
        else:  # the demand c itself
            if gov.droop_placement == "classic":
                ce, ci = Kp / (1.0 + Kp * rho), 1.0 / (1.0 + Kp * rho)
            else:
                ce, ci = Kp, 1.0
            cg = 0.0
            ie, ii, ig = 1.0 - rho * ce, -rho * ci, 0.0
        return Controller(ce=ce, ci=ci, cg=cg, ie=ie, ii=ii, ig=ig, Ki=Kp / gov.Ti)

    @staticmethod
    def _general(gov: Governor) -> Controller:
        """Any integral discretisation, with or without derivative action (params.Governor).

        With w = e − ρx, e_P = w around the whole PID (classic) or e (integral placement), k = Tc Kp/Ti,
        α the integral's feedthrough and ψ[n] = a D[n−1] − b e_P[n−1] the derivative's state:
        c = Kp e_P + i + α k w + b e_P + ψ, i[n+1] = i + k w, ψ[n+1] = a ψ + (a − 1) b e_P. With the
        demand as droop signal (x = c) the algebraic loop is solved exactly.
        """
        Kp, rho, Ki = gov.Kp, gov.droop, gov.Kp / gov.Ti
        k = gov.Tc * Ki
        al = gov.integral_feedthrough
        a, b = gov.derivative_coefficients
        cls = 1.0 if gov.droop_placement == "classic" else 0.0
        d = 1.0 if gov.Td > 0 else 0.0
        # c = Ae e + Ax x + i + d ψ
        Ae = Kp + al * k + b
        Ax = -rho * al * k - cls * rho * (Kp + b)
        be = (a - 1.0) * b  # ψ[n+1] = a ψ + be e_P
        if gov.droop_signal == "gate":
            return Controller(ce=Ae, ci=1.0, cg=Ax, ie=1.0, ii=0.0, ig=-rho, Ki=Ki, cd=d, id=0.0,
                              de=be, di=0.0, dd=a, dg=-cls * rho * be)
        s = 1.0 / (1.0 - Ax)
        ce, ci, cd = Ae * s, s, d * s
        return Controller(ce=ce, ci=ci, cg=0.0, ie=1.0 - rho * ce, ii=-rho * ci, ig=0.0, Ki=Ki, cd=cd,
                          id=-rho * cd, de=be * (1.0 - cls * rho * ce), di=-be * cls * rho * ci,
                          dd=a - be * cls * rho * cd, dg=0.0)


@dataclass(frozen=True)
class TurbinePoint:
    """Steady state of one unit's turbine at Pm0 (h0 = h_s)."""

    h0: float
    q0: float
    g0: float
    Pm0: float


def turbine_point(unit: Unit) -> TurbinePoint:
    t = unit.turbine
    h0 = t.h_s
    q0 = t.Pm0 / (t.At * h0) + t.q_nl
    g0 = q0 / math.sqrt(h0)
    if not unit.servo.g_min < g0 < unit.servo.g_max:
        raise ConfigError(
            f"{unit.name}: steady gate opening {g0:.4g} at Pm0 = {t.Pm0:g} is outside the gate limits "
            f"[{unit.servo.g_min:g}, {unit.servo.g_max:g}]"
        )
    return TurbinePoint(h0=h0, q0=q0, g0=g0, Pm0=t.Pm0)


@dataclass(frozen=True, eq=False)
class Model:
    """The continuous-time model of a plant in its grid and its exact discretisation at Tc.

    ``A, B`` with inputs ``[Δc1, ΔP_L]`` (ΔP_L on the system base); ``Phi`` = exp(A Tc);
    ``Gc`` the ZOH column for Δc1; ``GL0, GL1`` the first-order-hold columns for the load (the load
    moves linearly from ΔP_L[n] to ΔP_L[n+1] within the step: x⁺ = Φx + GL0 ΔP_L[n] + GL1 (ΔP_L[n+1] −
    ΔP_L[n])); ``GN0, GN1`` the same for the residual rows (used by the exponential integrator).
    Output rows (with their direct load feedthrough where there is one): ``C_pe1, D_pe1`` (ΔPe1,
    machine base), ``C_coi`` (ω_coi), ``C_pm1`` (linearised ΔPm1).
    """

    plant: Plant
    Tc: float
    nx: int
    A: np.ndarray
    B: np.ndarray
    Phi: np.ndarray
    Gc: np.ndarray
    GL0: np.ndarray
    GL1: np.ndarray
    GN0: np.ndarray
    GN1: np.ndarray
    C_pe1: np.ndarray
    D_pe1: float
    C_coi: np.ndarray
    C_pm1: np.ndarray
    tp1: TurbinePoint
    tp2: TurbinePoint
    ctl1: Controller
    ctl2: Controller
    c2_row: np.ndarray
    """Δc2 = c2_row @ x (unit 2's analogue demand before its limiter)."""
    # Residual parameters, per unit as (2, 1) columns for the (2, R) turbine block.
    q0: np.ndarray
    g0: np.ndarray
    h0: np.ndarray
    qn0: np.ndarray  # q0 − q_nl
    At: np.ndarray
    Dturb: np.ndarray
    two_h_q0: np.ndarray  # 2 h0 / q0
    two_h_g0: np.ndarray  # 2 h0 / g0
    inv_2H: np.ndarray
    inv_Tw: np.ndarray
    neg_inv_Tw: np.ndarray
    g_lim2: tuple[float, float]
    inv_Tg2: float
    any_dturb: bool


def _check(plant: Plant) -> None:
    u1, u2 = plant.unit, plant.grid.other
    if not u1.governor.digital:
        raise ConfigError("the simulator needs a digital governor on the studied unit (governor.digital)")
    if u2.governor.digital:
        raise ConfigError("the simulator models the rest of the grid (grid.other) with an analogue governor")
    for u in (u1, u2):
        g, s = u.governor, u.servo
        for name, value in (("Tf", g.Tf), ("Ti", g.Ti), ("Tg", s.Tg), ("Tw", u.turbine.Tw),
                            ("H", u.swing.H), ("rated_mw", u.rated_mw)):
            if not value > 0:
                raise ConfigError(f"{u.name}: {name} must be positive, got {value}")
    if u1.governor.Td > 0 and not u1.governor.Tdf > 0:
        raise ConfigError(f"{u1.name}: derivative action (Td > 0) needs a filter time constant Tdf > 0")
    if u2.governor.Td > 0:
        raise ConfigError("the simulator models the rest of the grid (grid.other) without derivative action")
    if not plant.unit.governor.Tc > 0:
        raise ConfigError(f"controller sample time Tc must be positive, got {plant.unit.governor.Tc}")
    if plant.grid.damping_at == "load_bus" and not plant.grid.D > 0:
        raise ConfigError("damping_at='load_bus' needs a positive load damping D")


@lru_cache(maxsize=64)
@single_threaded
def build(plant: Plant) -> Model:
    """The :class:`Model` of ``plant`` (cached: plants are frozen and hashable)."""
    _check(plant)
    u1, u2, grid = plant.unit, plant.grid.other, plant.grid
    Tc = u1.governor.Tc
    coi = grid.damping_at == "coi"
    nx = 11 if coi else 12
    tp1, tp2 = turbine_point(u1), turbine_point(u2)
    ctl1, ctl2 = Controller.of(u1.governor), Controller.of(u2.governor)
    A = np.zeros((nx, nx))
    B = np.zeros((nx, 2))  # inputs: Δc1, ΔP_L

    # Network: electrical power deviations on the system base as rows over x plus load feedthrough.
    Sb = grid.s_base_mw
    s1, s2 = u1.rated_mw / Sb, u2.rated_mw / Sb
    X1 = u1.xd / s1 + grid.x1
    X2 = u2.xd / s2 + grid.x2
    Y = 1.0 / X1 + 1.0 / X2
    wb = 2.0 * math.pi * grid.f0
    m1, m2 = u1.swing.H * u1.rated_mw, u2.swing.H * u2.rated_mw
    C_coi = np.zeros(nx)
    C_coi[W1], C_coi[W2] = m1 / (m1 + m2), m2 / (m1 + m2)
    P1, P2 = np.zeros(nx), np.zeros(nx)
    if coi:
        # P1 = (δ12/X2 + ΔP_L + D ω_coi)/(X1 Y), P2 = (−δ12/X1 + ΔP_L + D ω_coi)/(X2 Y)
        P1[D12] = 1.0 / (X2 * X1 * Y)
        P1 += grid.D * C_coi / (X1 * Y)
        P2[D12] = -1.0 / (X1 * X2 * Y)
        P2 += grid.D * C_coi / (X2 * Y)
        dP1, dP2 = 1.0 / (X1 * Y), 1.0 / (X2 * Y)
        A[D12, W1], A[D12, W2] = wb, -wb
    else:
        P1[PH1], P2[PH2] = 1.0 / X1, 1.0 / X2
        dP1 = dP2 = 0.0
        # ω5 = (P1 + P2 − ΔP_L)/D, dφ_i/dt = ω_b (Δω_i − ω5)
        w5 = (P1 + P2) / grid.D
        for ph, w in ((PH1, W1), (PH2, W2)):
            A[ph] -= wb * w5
            A[ph, w] += wb
            B[ph, 1] += wb / grid.D
    C_pe1, D_pe1 = P1 / s1, dP1 / s1  # machine base
    C_pe2, D_pe2 = P2 / s2, dP2 / s2

    # Turbines, linearised: ΔPm = At (h0 Δq + (q0 − q_nl) Δh) − Dturb g0 Δω, Δh = 2 h0 (Δq/q0 − Δg/g0).
    C_pm = {}
    for u, tp, W, Q, G in ((u1, tp1, W1, Q1, G1), (u2, tp2, W2, Q2, G2)):
        t = u.turbine
        dh = np.zeros(nx)
        dh[Q], dh[G] = 2.0 * tp.h0 / tp.q0, -2.0 * tp.h0 / tp.g0
        pm = t.At * (tp.q0 - t.q_nl) * dh
        pm[Q] += t.At * tp.h0
        pm[W] -= t.Dturb * tp.g0
        C_pm[W] = pm
        A[Q] = -dh / t.Tw
    # Swing equations.
    for u, W, C_pe, D_pe in ((u1, W1, C_pe1, D_pe1), (u2, W2, C_pe2, D_pe2)):
        row = C_pm[W] - C_pe
        row[W] -= u.swing.Kd
        A[W] = row / (2.0 * u.swing.H)
        B[W, 1] = -D_pe / (2.0 * u.swing.H)
    # Measurement filters.
    A[F1, W1], A[F1, F1] = 1.0 / u1.governor.Tf, -1.0 / u1.governor.Tf
    A[F2, W2], A[F2, F2] = 1.0 / u2.governor.Tf, -1.0 / u2.governor.Tf
    A[PF1] = C_pe1 / u1.governor.Tf
    A[PF1, PF1] -= 1.0 / u1.governor.Tf
    B[PF1, 1] = D_pe1 / u1.governor.Tf
    # Servo of unit 1, driven by the held demand Δc1.
    A[G1, G1] = -1.0 / u1.servo.Tg
    B[G1, 0] = 1.0 / u1.servo.Tg
    # Unit 2's analogue governor on e2 = −f2.
    c2 = np.zeros(nx)
    c2[F2], c2[I2], c2[G2] = -ctl2.ce, ctl2.ci, ctl2.cg
    A[G2] = c2 / u2.servo.Tg
    A[G2, G2] -= 1.0 / u2.servo.Tg
    A[I2, F2], A[I2, I2], A[I2, G2] = -ctl2.Ki * ctl2.ie, ctl2.Ki * ctl2.ii, ctl2.Ki * ctl2.ig

    # Exact discretisation with zero-order (column block 1) and first-order (block 2) hold inputs:
    # expm([[A, B, 0], [0, 0, I/h], [0, 0, 0]] h) = [[Φ, Γ0, Γ1], ...].
    EN = np.zeros((nx, len(RESIDUAL_ROWS)))
    for j, row in enumerate(RESIDUAL_ROWS):
        EN[row, j] = 1.0
    Ball = np.hstack([B, EN])
    m = Ball.shape[1]
    M = np.zeros((nx + 2 * m, nx + 2 * m))
    M[:nx, :nx] = A * Tc
    M[:nx, nx:nx + m] = Ball * Tc
    M[nx:nx + m, nx + m:] = np.eye(m)
    E = expm(M)
    Phi = E[:nx, :nx]
    Gam0 = E[:nx, nx:nx + m]
    Gam1 = E[:nx, nx + m:]

    col = lambda a: np.array(a, dtype=float).reshape(2, 1)  # noqa: E731
    t1, t2 = u1.turbine, u2.turbine
    return Model(
        plant=plant,
        Tc=Tc,
        nx=nx,
        A=A,
        B=B,
        Phi=Phi,
        Gc=Gam0[:, 0].copy(),
        GL0=Gam0[:, 1].copy(),
        GL1=Gam1[:, 1].copy(),
        GN0=Gam0[:, 2:].copy(),
        GN1=Gam1[:, 2:].copy(),
        C_pe1=C_pe1,
        D_pe1=D_pe1,
        C_coi=C_coi,
        C_pm1=C_pm[W1],
        tp1=tp1,
        tp2=tp2,
        ctl1=ctl1,
        ctl2=ctl2,
        c2_row=c2,
        q0=col([tp1.q0, tp2.q0]),
        g0=col([tp1.g0, tp2.g0]),
        h0=col([tp1.h0, tp2.h0]),
        qn0=col([tp1.q0 - t1.q_nl, tp2.q0 - t2.q_nl]),
        At=col([t1.At, t2.At]),
        Dturb=col([t1.Dturb, t2.Dturb]),
        two_h_q0=col([2 * tp1.h0 / tp1.q0, 2 * tp2.h0 / tp2.q0]),
        two_h_g0=col([2 * tp1.h0 / tp1.g0, 2 * tp2.h0 / tp2.g0]),
        inv_2H=col([1 / (2 * u1.swing.H), 1 / (2 * u2.swing.H)]),
        inv_Tw=col([1 / t1.Tw, 1 / t2.Tw]),
        neg_inv_Tw=-col([1 / t1.Tw, 1 / t2.Tw]),
        g_lim2=(u2.servo.g_min, u2.servo.g_max),
        inv_Tg2=1.0 / u2.servo.Tg,
        any_dturb=bool(t1.Dturb != 0 or t2.Dturb != 0),
    )


def residual(m: Model, x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Nonlinear residual N(x) = f(x) − (linear part) on :data:`RESIDUAL_ROWS`, shape (5, R).

    Turbines: with h = (q/g)², dd = h − h0 − Δh_lin the curvature of the head,
    ΔPm − ΔPm_lin = At ((q0 − q_nl) dd + (h − h0) Δq) − Dturb Δg Δω and dΔq/dt − lin = −dd/Tw.
    Unit 2's limiter: (clip(c2) − c2)/Tg on its servo.
    """
    R = x.shape[1]
    if out is None:
        out = np.empty((5, R))
    dq = x[Q1:Q2 + 1]
    dg = x[G1:G2 + 1]
    # in place, three temporaries (the same operations in the same order as the formulas above)
    a = np.add(dq, m.q0)  # q
    b = np.add(dg, m.g0)
    np.maximum(b, 1e-6, out=b)  # g: a closed gate would make the head infinite
    np.divide(a, b, out=a)
    np.multiply(a, a, out=a)  # h
    np.subtract(a, m.h0, out=a)  # hh = h − h0
    np.multiply(m.two_h_q0, dq, out=b)
    c = np.multiply(m.two_h_g0, dg)
    np.subtract(b, c, out=b)  # Δh_lin
    np.subtract(a, b, out=b)  # dd
    np.multiply(m.qn0, b, out=c)
    if m.any_dturb:
        pm_d = m.Dturb * dg * x[W1:W2 + 1]
    np.multiply(a, dq, out=a)
    c += a
    c *= m.At  # pm
    if m.any_dturb:
        c -= pm_d
    np.multiply(c, m.inv_2H, out=out[0:2])
    np.multiply(b, m.neg_inv_Tw, out=out[2:4])
    c2 = m.c2_row[F2] * x[F2] + m.c2_row[I2] * x[I2]
    if m.c2_row[G2] != 0.0:
        c2 += m.c2_row[G2] * x[G2]
    c2 += m.tp2.g0
    lo, hi = m.g_lim2
    # (clip(c2) − c2)/Tg with two plain ufuncs (np.clip's Python wrapper costs more than the work)
    np.maximum(c2, lo, out=out[4])
    np.minimum(out[4], hi, out=out[4])
    out[4] -= c2
    out[4] *= m.inv_Tg2
    return out


def pm1_absolute(m: Model, x: np.ndarray) -> np.ndarray:
    """Unit 1's mechanical power Pm [pu machine base] from the state (nonlinear turbine)."""
    t = m.plant.unit.turbine
    q = x[Q1] + m.tp1.q0
    g = np.maximum(x[G1] + m.tp1.g0, 1e-6)
    h = (q / g) ** 2
    pm = t.At * h * (q - t.q_nl)
    if t.Dturb:
        pm = pm - t.Dturb * g * x[W1]
    return pm
