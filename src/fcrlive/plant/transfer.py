"""Analytic transfer functions of the studied unit (the paper's Fig. 1, eq. 6-8, 12-13, 15, 17-19).

Units: every transfer function is per unit on the unit's OWN machine base, speed and control error in
pu of f0, power in pu of the rating, time in s, frequencies in rad/s.

Where the anti-aliasing filter sits
-----------------------------------
The paper takes both logged signals through the same measurement chain: y[n] is the filtered, sampled
speed and u[n] the electrical power "obtained in a similar manner" (Section 2). With ``F_aa`` on both,
the filter drops out of the path u → ε and stays in the loop, so it is lumped into ``G_p``:

    G_p = F_aa G_c G_s G_t / (1 + L_d),   S = 1/(1 + G_p G_J),   G_1 = G_J S,   G_p = (1 − S)/G_1 (eq. 15)

This is the reading that reproduces the reference table of plant-model.md (|S| needs the filter in the
loop, arg G_1 does not carry it, arg G_p does). It is also the right ``G_p`` for the TSO: F(s) runs from
the grid frequency to power and includes the frequency measurement, so ``F = ρ G_p / G_t(0)``.
``G_pm`` is the same path without the filter (control error → mechanical power, for the simulator's
point of view).

The droop loop, generalising eq. 6 and 19
-----------------------------------------
The governor output is c = G_c ε − ρ K_ρ x with x = G_x c the droop signal, hence c/ε = G_c/(1 + L_d),
``L_d = ρ K_ρ G_x`` (:func:`droop_feedback`):

- ``droop_placement="integral"``: K_ρ = K_I = Kp/(Ti s), the droop enters the integral channel only;
- ``droop_placement="classic"``:  K_ρ = G_c, the droop closes around the whole PI (eq. 6);
- ``droop_signal="gate"``: G_x = G_s (the measured gate position a[n]); ``"demand"``: G_x = 1 (c itself).

Eq. 19 becomes ``G_p(z) = G_jp(z) G_c(z) / (G_j(z) (1 + L_d(z)))`` with G_jp the ZOH discretisation of
F_aa G_s G_t G_J and G_j that of G_J.

Discrete time (dt = Tc)
-----------------------
The digital PI (``Governor.digital``) runs, with the integral updated by forward Euler::

    c[n]   = Kp·e[n] + I[n]                                   (integral placement)
    I[n+1] = I[n] + Tc·(Kp/Ti)·(e[n] − ρ·(x[n] − x0))
    c[n]   = Kp·(e[n] − ρ·(x[n] − x0)) + I[n]                 (classic placement)
    I[n+1] = I[n] + Tc·(Kp/Ti)·(e[n] − ρ·(x[n] − x0))

so G_c(z) = Kp + Kp Tc/(Ti (z − 1)) and K_I(z) = Kp Tc/(Ti (z − 1)). Other discretisations of the
integral (``Governor.integral_method``: backward Euler, Tustin) give K_I(z) = k (α z + 1 − α)/(z − 1),
k = Kp Tc/Ti; derivative action (``Governor.Td``) adds b (z − 1)/(z − a) to G_c(z) (params.Governor).
x[n] is the sampled gate position a[n] (``"gate"``) or c[n] (``"demand"``; with the classic placement
this is an algebraic loop, solved exactly: c[n] = (Kp e[n] + I[n])/(1 + ρ Kp)). An analogue governor
(``digital=False``) is approximated at Tc by the Tustin transform of its PI, which is what a logger at
1/Tc sees of it.

The continuous parts are ZOH-discretised exactly (matrix exponential): c[n] really is held, so
G_s(z), G_jp(z) are exact. For the path from u[n] to ε[n], u (the filtered electrical power) is treated
as held between samples by default; this is the approximation in the paper's eq. 17 and costs a
half-sample delay, 0.66 % at most up to 0.5 rad/s at Tc = 0.02 s. ``analytic(plant, u_hold="foh")``
takes u linear between samples instead (no delay in G_j, S, G_1, as the paper's Remark 2 has it).

The closed loops in z (S, G_1, G_p) are kept as state-space objects: their poles cluster within 1e-3 of
z = 1 at Tc = 0.02 s, where polynomial coefficients in z lose about three significant digits of the
frequency response. The simple blocks (G_c, K_I, G_s, G_j, L_d) are transfer functions.

``import control`` takes over a second, so it happens inside the functions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, NamedTuple

import numpy as np

from fcrlive.blas import single_threaded
from fcrlive.gridsearch import peak as grid_peak
from fcrlive.plant.params import Plant, Turbine, Unit

if TYPE_CHECKING:
    from control import LTI, StateSpace, TransferFunction


UHold = Literal["zoh", "foh"]


def _control():
    import control

    return control


# ---------------------------------------------------------------------------------------------------
# Scalar constants derived from the parameters (no python-control needed)


class TurbineLinear(NamedTuple):
    """The turbine linearised at Pm0: ΔPm/Δg = gain·(1 − T1 s)/(1 + T2 s)."""

    gain: float
    """Static gain G_t(0) [pu power / pu gate]; At when h_s = 1."""
    T1: float
    """Zero time constant (q0 − q_nl)·Tw/h0 [s] (non-minimum phase)."""
    T2: float
    """Pole time constant q0·Tw/(2 h0) [s]."""
    q0: float
    """Steady-state flow [pu]."""
    g0: float
    """Steady-state gate opening [pu]."""


def turbine_linear(turbine: Turbine) -> TurbineLinear:
    """Linearise q = g·sqrt(h), dq/dt = (h_s − h)/Tw, Pm = At·h·(q − q_nl) at Pm0 (h0 = h_s).

    With h_s = 1 this is the textbook At (1 − (q0 − q_nl) Tw s)/(1 + q0 Tw s / 2), q0 = Pm0/At + q_nl.
    """
    h0 = turbine.h_s
    q0 = turbine.Pm0 / (turbine.At * h0) + turbine.q_nl
    g0 = q0 / math.sqrt(h0)
    T1 = (q0 - turbine.q_nl) * turbine.Tw / h0
    T2 = q0 * turbine.Tw / (2.0 * h0)
    return TurbineLinear(gain=turbine.At * h0 * math.sqrt(h0), T1=T1, T2=T2, q0=q0, g0=g0)


def effective_damping(unit: Unit) -> float:
    """Speed damping seen by the swing equation [pu power / pu speed]: Kd + Dturb·g0.

    The turbine term −Dturb·g·Δω of the HYGOV turbine acts on the rotor exactly like Kd.
    """
    return unit.swing.Kd + unit.turbine.Dturb * turbine_linear(unit.turbine).g0


def synchronising_coefficient(plant: Plant) -> float:
    """K11 of the paper's eq. 4-5 and 13 [pu power (machine base) per pu speed per s].

    ΔPe = (K11/s)·Δω. Taken from the two-machine grid with the rest of the grid (unit 2, about 27 times
    the kinetic energy of unit 1 in the paper) as a stiff source behind its transient reactance: in the
    DC power flow the load bus splits the angle difference, so ΔPe1 = (Δδ1 − Δδ2)/X with
    X = x'd1 + x1 + x2 + x'd2 on the system base. Converting to the machine base (× S_base/S_1) and from
    rad to pu speed (× ω_b = 2π f0) gives K11. For plant 1: X = 3.815, K11 ≈ 906, a 1.8 Hz swing mode.
    """
    unit, grid = plant.unit, plant.grid
    to_sys1 = grid.s_base_mw / unit.rated_mw
    to_sys2 = grid.s_base_mw / grid.other.rated_mw
    X = unit.xd * to_sys1 + grid.x1 + grid.x2 + grid.other.xd * to_sys2
    omega_b = 2.0 * math.pi * grid.f0
    return omega_b * to_sys1 / X


# ---------------------------------------------------------------------------------------------------
# The bundles


@dataclass(frozen=True)
class DiscreteTFs:
    """The paper's discrete-time transfer functions at dt = Tc (see the module docstring).

    Transfer functions are ``control.TransferFunction`` (blocks) or ``control.StateSpace`` (closed
    loops), all with ``dt = Tc``. Evaluate them with :func:`freqresp`.
    """

    Tc: float
    """Sample time [s]."""
    G_c: TransferFunction
    """Digital PI, e[n] → c[n] (droop loop open): Kp + Kp Tc/(Ti (z − 1))."""
    K_I: TransferFunction
    """Integral channel of the PI: Kp Tc/(Ti (z − 1))."""
    G_s: TransferFunction
    """Servo with ZOH, c[n] → a[n] (eq. 18); one sample of delay."""
    G_j: TransferFunction
    """Swing, u[n] → −y[n] (eq. 17), discretised with ``u_hold``."""
    G_jp: StateSpace
    """ZOH discretisation of F_aa G_s G_t G_J, c[n] → y[n] (eq. 17)."""
    L_d: TransferFunction
    """Droop loop ρ K_ρ(z) G_x(z): c/ε = G_c/(1 + L_d)."""
    S: StateSpace
    """Sensitivity, r[n] → ε[n] (eq. 14)."""
    G_1: StateSpace
    """Disturbance rejection, u[n] → ε[n] (eq. 14, 16)."""
    G_p: StateSpace
    """Eq. 15/19: G_jp G_c/(G_j (1 + L_d)) = (1 − S)/G_1."""
    u_hold: UHold
    """How u is taken between samples in G_j(z): ``"zoh"`` held, ``"foh"`` linear (:func:`analytic`)."""


@dataclass(frozen=True)
class PlantTFs:
    """Continuous-time transfer functions of the studied unit (``control.TransferFunction``, dt = 0).

    Inputs and outputs in pu on the machine base; see the module docstring for the filter's place.
    """

    G_J: TransferFunction
    """Swing 1/(2 H s + Kd + Dturb g0), ΔPm − ΔPe → Δω."""
    G_c: TransferFunction
    """PI Kp (1 + 1/(Ti s)), droop loop open."""
    K_I: TransferFunction
    """Integral channel Kp/(Ti s)."""
    F_aa: TransferFunction
    """Anti-aliasing (speed measurement) filter 1/(Tf s + 1)."""
    G_s: TransferFunction
    """Servo 1/(Tg s + 1), c → g."""
    G_t: TransferFunction
    """Turbine linearised at Pm0, g → ΔPm."""
    L_d: TransferFunction
    """Droop loop ρ K_ρ G_x (:func:`droop_feedback`)."""
    G_pm: TransferFunction
    """Control error → ΔPm, droop loop closed, without F_aa."""
    G_p: TransferFunction
    """The paper's G_p: F_aa G_c G_s G_t/(1 + L_d); G_p(0) = G_t(0)/ρ."""
    G_jp: TransferFunction
    """F_aa G_s G_t G_J: c → y (eq. 17)."""
    S: TransferFunction
    """Sensitivity 1/(1 + G_p G_J) (eq. 7), r → ε."""
    G_1: TransferFunction
    """G_J S (eq. 8), u = ΔPe → ε; G_1(0) = 1/(Kd + G_t(0)/ρ)."""
    G_req: TransferFunction
    """What the industry sine test measures (eq. 13): G_p K11/(K11 + s (Kd + 2 H s))."""
    F: TransferFunction
    """TSO-normalised ρ G_p / G_t(0): unit static gain."""
    K11: float
    """Synchronising coefficient used in G_req [pu power per pu speed per s]."""
    droop: float
    """ρ [pu speed / pu gate]."""
    discrete: DiscreteTFs
    """The same at the controller sample time."""

    @property
    def effective_droop(self) -> float:
        """1/G_p(0) = ρ/G_t(0) [pu speed / pu power]: the droop seen from the power output."""
        return 1.0 / static_gain(self.G_p)


# ---------------------------------------------------------------------------------------------------
# Building blocks. Rational functions are kept as (num, den) coefficient pairs and combined by explicit
# polynomial algebra: the structural cancellations (the PI's integrator in G_c/(1 + L_d), the servo pole
# with gate feedback) are made exactly, not by a tolerance-based minreal.

Poly = np.ndarray
Rat = tuple[Poly, Poly]


def _p(*coeffs: float) -> Poly:
    c = np.trim_zeros(np.asarray(coeffs, dtype=float), "f")
    return c if c.size else np.zeros(1)


def _mul(*rats: Rat) -> Rat:
    num, den = _p(1.0), _p(1.0)
    for n, d in rats:
        num, den = np.polymul(num, n), np.polymul(den, d)
    return num, den


def _scale(r: Rat, k: float) -> Rat:
    return r[0] * k, r[1]


def _closed(fwd: Rat, loop: Rat) -> Rat:
    """fwd/(1 + loop) = N_f D_l / (D_f (D_l + N_l))."""
    (nf, df), (nl, dl) = fwd, loop
    return np.polymul(nf, dl), np.polymul(df, np.polyadd(dl, nl))


def _tf(r: Rat, dt: float = 0) -> TransferFunction:
    num, den = r
    return _control().tf(_p(*num), _p(*den), dt)


class _Blocks(NamedTuple):
    """One governor's blocks as rationals in s (dt = 0) or z (dt = Tc)."""

    G_c: Rat
    K_I: Rat
    G_s: Rat
    L_d: Rat
    C: Rat
    """c/ε = G_c/(1 + L_d)."""
    CG_s: Rat
    """g/ε = C G_s, with the servo pole cancelled when the droop comes from the gate."""


def _governor_blocks(unit: Unit, G_c: Rat, K_I: Rat, G_s: Rat) -> _Blocks:
    gov = unit.governor
    K_rho = K_I if gov.droop_placement == "integral" else G_c
    G_x = G_s if gov.droop_signal == "gate" else (_p(1.0), _p(1.0))
    L_d = _scale(_mul(K_rho, G_x), gov.droop)
    # G_c and K_ρ share the integrator's denominator, so it cancels exactly in G_c/(1 + L_d):
    # C = N_c D_x / (D_c D_x + ρ N_ρ N_x).
    if not np.array_equal(G_c[1], K_rho[1]):
        raise AssertionError("G_c and K_ρ must share the denominator")
    n_x, d_x = G_x
    C_den = np.polyadd(np.polymul(G_c[1], d_x), gov.droop * np.polymul(K_rho[0], n_x))
    C = (np.polymul(G_c[0], d_x), C_den)
    if gov.droop_signal == "gate":
        CG_s = (np.polymul(G_c[0], G_s[0]), C_den)
    else:
        CG_s = _mul(C, G_s)
    return _Blocks(G_c=G_c, K_I=K_I, G_s=G_s, L_d=L_d, C=C, CG_s=CG_s)


def _continuous_blocks(unit: Unit) -> tuple[_Blocks, Rat, Rat, Rat]:
    gov = unit.governor
    lin = turbine_linear(unit.turbine)
    G_c = (_p(gov.Kp * gov.Ti, gov.Kp), _p(gov.Ti, 0.0))
    K_I = (_p(gov.Kp), _p(gov.Ti, 0.0))
    if gov.Td > 0:
        # PID Kp (1 + 1/(Ti s) + Td s/(1 + Tdf s)) over the common denominator Ti s (1 + Tdf s).
        lag = _p(gov.Tdf, 1.0)
        K_I = (np.polymul(K_I[0], lag), np.polymul(K_I[1], lag))
        num = np.polyadd(np.polymul(G_c[0], lag), _p(gov.Kp * gov.Ti * gov.Td, 0.0, 0.0))
        G_c = (num, K_I[1])
    G_s = (_p(1.0), _p(unit.servo.Tg, 1.0))
    G_J = (_p(1.0), _p(2.0 * unit.swing.H, effective_damping(unit)))
    F_aa = (_p(1.0), _p(gov.Tf, 1.0))
    G_t = (_p(-lin.gain * lin.T1, lin.gain), _p(lin.T2, 1.0))
    return _governor_blocks(unit, G_c, K_I, G_s), G_J, F_aa, G_t


def _discrete_governor(unit: Unit) -> _Blocks:
    gov = unit.governor
    Tc = gov.Tc
    if gov.digital and gov.integral_method == "forward" and not gov.Td > 0:
        # Forward-Euler integral: I[n+1] uses e[n], one sample of delay in K_I.
        K_I = (_p(gov.Kp * Tc / gov.Ti), _p(1.0, -1.0))
    elif not gov.digital and not gov.Td > 0:
        k = gov.Kp * Tc / (2.0 * gov.Ti)
        K_I = (_p(k, k), _p(1.0, -1.0))
    elif not gov.Td > 0:
        # I[n] = I[n−1] + k (α w[n] + (1 − α) w[n−1]): backward Euler α = 1, Tustin α = 1/2.
        k, al = gov.Kp * Tc / gov.Ti, gov.integral_feedthrough
        K_I = (_p(k * al, k * (1.0 - al)), _p(1.0, -1.0))
    else:
        # PID: K_I, and the derivative b (z − 1)/(z − a), over the common denominator (z − 1)(z − a).
        k, al = gov.Kp * Tc / gov.Ti, gov.integral_feedthrough
        a, b = gov.derivative_coefficients
        den = np.polymul(_p(1.0, -1.0), _p(1.0, -a))
        K_I = (np.polymul(_p(k * al, k * (1.0 - al)), _p(1.0, -a)), den)
        num = np.polyadd(np.polyadd(gov.Kp * den, K_I[0]), b * np.polymul(_p(1.0, -1.0), _p(1.0, -1.0)))
        return _governor_blocks(unit, (num, den), K_I, _servo_z(unit, Tc))
    G_c = (np.polyadd(gov.Kp * K_I[1], K_I[0]), K_I[1])
    return _governor_blocks(unit, G_c, K_I, _servo_z(unit, Tc))


def governor_z(gov) -> tuple[Rat, Rat]:
    """(G_c(z), K_ρ(z)) of a digital governor as (num, den) in descending powers of z at dt = Tc, sharing
    the denominator: the controller c = G_c ε − ρ K_ρ x with the droop signal x (gate or demand), K_ρ = K_I
    (integral placement) or G_c (classic). Used by analysis.controller for the exact c/ε."""
    unit = Unit(name="governor", rated_mw=1.0, governor=gov)
    b = _discrete_governor(unit)
    return b.G_c, (b.K_I if gov.droop_placement == "integral" else b.G_c)


def _servo_z(unit: Unit, Tc: float) -> Rat:
    zs = _control().sample_system(_tf((_p(1.0), _p(unit.servo.Tg, 1.0))), Tc, method="zoh")
    return _p(*zs.num[0][0]), _p(*zs.den[0][0])


def droop_feedback(plant: Plant) -> TransferFunction:
    """The continuous droop loop L_d(s), with c/ε = G_c/(1 + L_d) (module docstring).

    Integral placement: ρ (Kp/(Ti s)) G_x; classic: ρ G_c G_x; G_x = G_s (gate) or 1 (demand).
    """
    return _tf(_continuous_blocks(plant.unit)[0].L_d)


def droop_feedback_z(plant: Plant) -> TransferFunction:
    """L_d(z) at dt = Tc (module docstring): eq. 19's ρ G_c(z) G_s(z), generalised to both placements."""
    return _tf(_discrete_governor(plant.unit).L_d, plant.unit.governor.Tc)


def _discrete(unit: Unit, G_J: Rat, G_jp: Rat, u_hold: UHold) -> DiscreteTFs:
    ct = _control()
    Tc = unit.governor.Tc
    gb = _discrete_governor(unit)
    G_j = ct.sample_system(_tf(G_J), Tc, method=u_hold)
    G_jp_z = ct.sample_system(ct.ss(_tf(G_jp)), Tc, method="zoh")
    # Closed loops in state space: their poles crowd z = 1 (module docstring).
    C = ct.ss(_tf(gb.C, Tc))
    L = G_jp_z * C
    one = ct.ss([], [], [], [[1.0]], Tc)
    S = ct.feedback(one, L)
    G_1 = ct.ss(G_j) * S
    # Eq. 19 needs 1/G_j(z) = (z − a)/(b0 z + b1) (b0 = 0 with the ZOH), improper with the ZOH;
    # (z − a) G_jp(z) is proper because G_jp is strictly proper:
    # (z − a) C (zI − A)⁻¹ B = C B + C (A − a I)(zI − A)⁻¹ B.
    den = np.asarray(G_j.den[0][0], float)
    num = np.asarray(G_j.num[0][0], float) / den[0]
    a = -den[1] / den[0]
    A, B, Cm, D = G_jp_z.A, G_jp_z.B, G_jp_z.C, G_jp_z.D
    if np.any(D != 0):
        raise AssertionError("G_jp(z) must be strictly proper (ZOH of a strictly proper system)")
    lead = float(num[0])
    ratio = ct.ss(A, B, Cm @ (A - a * np.eye(A.shape[0])) / lead, Cm @ B / lead, Tc)
    if num.size == 2:
        # The triangle hold's zero of G_j sits near z = −1: G_p(z) then has a pole near Nyquist.
        ratio = ratio * ct.ss(_tf((_p(1.0), _p(1.0, num[1] / lead)), Tc))
    G_p = ratio * C
    return DiscreteTFs(
        Tc=Tc,
        G_c=_tf(gb.G_c, Tc),
        K_I=_tf(gb.K_I, Tc),
        G_s=_tf(gb.G_s, Tc),
        G_j=G_j,
        G_jp=G_jp_z,
        L_d=_tf(gb.L_d, Tc),
        S=S,
        G_1=G_1,
        G_p=G_p,
        u_hold=u_hold,
    )


@single_threaded
def analytic(plant: Plant, *, u_hold: UHold = "zoh") -> PlantTFs:
    """All transfer functions of ``plant.unit`` in its grid, continuous and at dt = Tc.

    ``u_hold`` says how u (the filtered ΔPe) is assumed to move between samples in the discrete
    u[n] → ε[n] path: ``"zoh"`` held (eq. 17 as written; G_j(z), G_1(z) get one sample of delay) or
    ``"foh"`` linear between samples (triangle hold: no delay, as the paper's Remark 2 says of G_j, S
    and G_1). Largest |G_1(z)/G_1(jω) − 1| up to 0.5 rad/s, plant 1 at Tc = 0.02 s: 0.66 % with
    ``"zoh"``, 0.27 % with ``"foh"`` (the rest is the digital control itself). With ``"foh"`` the
    G_j zero near z = −1 puts a pole near the Nyquist frequency into G_p(z).

    About 10 ms (plus python-control's import, over a second, on first use).
    """
    unit = plant.unit
    gov, sw = unit.governor, unit.swing
    gb, G_J, F_aa, G_t = _continuous_blocks(unit)
    G_pm = _mul(gb.CG_s, G_t)
    G_p = _mul(F_aa, G_pm)
    (n_p, d_p), (n_j, d_j) = G_p, G_J
    loop_den = np.polyadd(np.polymul(d_p, d_j), np.polymul(n_p, n_j))
    S = (np.polymul(d_p, d_j), loop_den)
    G_1 = (np.polymul(n_j, d_p), loop_den)
    K11 = synchronising_coefficient(plant)
    G_req = _mul(G_p, (_p(K11), _p(2.0 * sw.H, effective_damping(unit), K11)))
    F = _scale(G_p, gov.droop / turbine_linear(unit.turbine).gain)
    G_jp = _mul(F_aa, gb.G_s, G_t, G_J)
    return PlantTFs(
        G_J=_tf(G_J),
        G_c=_tf(gb.G_c),
        K_I=_tf(gb.K_I),
        F_aa=_tf(F_aa),
        G_s=_tf(gb.G_s),
        G_t=_tf(G_t),
        L_d=_tf(gb.L_d),
        G_pm=_tf(G_pm),
        G_p=_tf(G_p),
        G_jp=_tf(G_jp),
        S=_tf(S),
        G_1=_tf(G_1),
        G_req=_tf(G_req),
        F=_tf(F),
        K11=K11,
        droop=gov.droop,
        discrete=_discrete(unit, G_J, G_jp, u_hold),
    )


# ---------------------------------------------------------------------------------------------------
# Evaluation helpers


def _is_discrete(sys: LTI) -> bool:
    dt = sys.dt
    return dt is not None and dt is not False and dt != 0


def _points(sys: LTI, omega: np.ndarray) -> np.ndarray:
    if _is_discrete(sys):
        # dt=True is python-control's "discrete, unspecified period": evaluate per sample.
        dt = 1.0 if sys.dt is True else float(sys.dt)
        return np.exp(1j * omega * dt)
    return 1j * omega


def freqresp(sys: LTI, omega) -> np.ndarray:
    """Complex frequency response of a SISO ``TransferFunction`` or ``StateSpace`` at ω [rad/s].

    Continuous systems are evaluated at s = jω, discrete ones at z = exp(jω dt). State-space systems go
    through a linear solve per frequency (accurate near z = 1). Returns an array shaped like ``omega``.
    """
    w = np.asarray(omega, dtype=float)
    x = _points(sys, w.ravel())
    with np.errstate(divide="ignore", invalid="ignore"):
        if hasattr(sys, "num") and hasattr(sys, "den"):
            num = np.asarray(sys.num[0][0], dtype=float)
            den = np.asarray(sys.den[0][0], dtype=float)
            h = np.polyval(num, x) / np.polyval(den, x)
        else:
            A, B, C, D = (np.asarray(m, dtype=float) for m in (sys.A, sys.B, sys.C, sys.D))
            n = A.shape[0]
            if n == 0:
                h = np.full(x.shape, D[0, 0], dtype=complex)
            else:
                M = x[:, None, None] * np.eye(n) - A
                try:
                    X = np.linalg.solve(M, np.broadcast_to(B.astype(complex), (x.size, n, 1)))
                    h = (C @ X)[:, 0, 0] + D[0, 0]
                except np.linalg.LinAlgError:
                    h = np.array([_ss_point(A, B, C, D, xi) for xi in x])
    return h.reshape(w.shape)


def _ss_point(A, B, C, D, x) -> complex:
    try:
        return complex((C @ np.linalg.solve(x * np.eye(A.shape[0]) - A, B))[0, 0] + D[0, 0])
    except np.linalg.LinAlgError:
        return complex(np.inf)


def static_gain(sys: LTI) -> float:
    """Real static gain (s = 0 or z = 1) [units of the system]; inf for an integrator.

    A state-space system may carry a pole at s = 0 / z = 1 that its zeros cancel (non-minimal
    realisations from series connections, e.g. G_J(z) with Kd = 0): then the limit is taken from
    ω = 1e-7 rad/s, where the real part differs from the static gain by O(ω²).
    """
    if hasattr(sys, "A") and np.asarray(sys.A).size:
        A = np.asarray(sys.A, dtype=float)
        x = complex(_points(sys, np.zeros(1))[0])
        if np.linalg.cond(x * np.eye(A.shape[0]) - A) > 1e12:
            return float(complex(freqresp(sys, 1e-7)).real)
    h = complex(freqresp(sys, 0.0))
    if not np.isfinite(h):
        return float("inf")
    return float(h.real)


class Peak(NamedTuple):
    """Largest |H(jω)| over a band and where it is."""

    value: float
    omega_rad_s: float

    @property
    def period_s(self) -> float:
        return 2.0 * math.pi / self.omega_rad_s


def peak(sys: LTI, omega_min: float = 1e-4, omega_max: float | None = None, n: int = 3000) -> Peak:
    """max |H| over [omega_min, omega_max] rad/s: a dense log grid, then a bounded 1-D refinement.

    ``omega_max`` defaults to 1e3 rad/s for continuous systems and the Nyquist frequency π/dt for
    discrete ones.
    """
    if omega_max is None:
        omega_max = math.pi / float(sys.dt) if _is_discrete(sys) else 1e3
    if not 0 < omega_min < omega_max:
        raise ValueError(f"need 0 < omega_min < omega_max, got {omega_min}, {omega_max}")
    return Peak(*grid_peak(lambda w: np.abs(freqresp(sys, w)), omega_min, omega_max, n, xatol=1e-9))
