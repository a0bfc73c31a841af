"""Typed parameters of a hydro unit and of the paper's two-machine test grid.

All per-unit values are on the unit's OWN machine base (the paper's numbers only come out there:
plant-model.md); speed and frequency in pu of f0. Times in seconds.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

DroopPlacement = Literal["integral", "classic"]
DroopSignal = Literal["gate", "demand"]
IntegralMethod = Literal["forward", "backward", "tustin"]
DampingAt = Literal["coi", "load_bus"]


@dataclass(frozen=True)
class Swing:
    """Swing equation G_J(s) = 1/(2 H s + Kd), from ΔPm − ΔPe [pu] to rotor speed Δω [pu]."""

    H: float = 3.5
    """Inertia constant [s] on the machine base."""
    Kd: float = 0.1
    """Speed damping [pu power / pu speed]."""


@dataclass(frozen=True)
class Governor:
    """Governor: PI on the control error, with a permanent droop ρ.

    ``droop_placement``:
    - ``"integral"``: the droop is fed back from the gate into the INTEGRAL channel only, as in the
      Simulink model of the paper's first author: u = Kp·e + (Kp/Ti)∫(e − ρ·(g − g0)) dt.
    - ``"classic"``: the droop closes a loop around the whole PI: PI acts on (e − ρ·(x − x0)),
      the textbook G_p = G_c G_s G_t / (1 + ρ G_c G_s) when x is the gate position.

    ``droop_signal`` picks x: ``"gate"`` (servo/guide-vane position g, measured as a[n]) or
    ``"demand"`` (the controller output c, as in a classic HYGOV temporary-droop governor).
    ``digital`` governors run at the controller sample time Tc with a zero-order hold on c;
    analogue ones (the paper's plant 2) are integrated continuously.

    A digital governor's integral is discretised by ``integral_method`` with k = Kp Tc/Ti and w the
    integral channel's input (e − ρ(x − x0)):

    - ``"forward"`` (forward Euler, the paper's plant and the default): I[n+1] = I[n] + k w[n];
    - ``"backward"`` (backward Euler): I[n] = I[n−1] + k w[n];
    - ``"tustin"`` (trapezoid): I[n] = I[n−1] + (k/2)(w[n] + w[n−1]).

    ``Td > 0`` adds derivative action Kp Td s/(1 + Tdf s) on the PID's input (e with the droop in the
    integral channel, e − ρ(x − x0) around the whole PID), discretised by backward differences:
    D[n] = a D[n−1] + b (e[n] − e[n−1]), a = Tdf/(Tdf + Tc), b = Kp Td/(Tdf + Tc). The simulator runs a
    governor with derivative action on its linear model only (``SimConfig(model="linear")``).
    """

    Kp: float = 1.0
    """Proportional gain [pu gate / pu speed]."""
    Ti: float = 9.1
    """Integral time [s]."""
    droop: float = 0.08
    """Permanent droop ρ [pu speed / pu gate], e.g. 0.08 = 8 %."""
    Tf: float = 0.05
    """Anti-aliasing / measurement filter time constant on the speed signal [s]."""
    Tc: float = 0.02
    """Controller sample time [s] (also the rate of every logged signal of Fig. 1)."""
    droop_placement: DroopPlacement = "integral"
    droop_signal: DroopSignal = "gate"
    digital: bool = True
    integral_method: IntegralMethod = "forward"
    """Discretisation of a digital governor's integral (class docstring)."""
    Td: float = 0.0
    """Derivative time [s]; 0: a PI governor."""
    Tdf: float = 0.0
    """Time constant of the derivative's filter [s] (needed, > 0, when Td > 0)."""

    @property
    def integral_feedthrough(self) -> float:
        """α with I[n] = (state) + α k w[n]: 0 forward Euler, 1 backward Euler, 1/2 Tustin (and for an
        analogue governor, which the discrete-time view approximates by Tustin)."""
        if not self.digital:
            return 0.5
        return {"forward": 0.0, "backward": 1.0, "tustin": 0.5}[self.integral_method]

    @property
    def derivative_coefficients(self) -> tuple[float, float]:
        """(a, b) of the digital derivative D[n] = a D[n−1] + b (e[n] − e[n−1]); (0, 0) without it."""
        if not self.Td > 0:
            return 0.0, 0.0
        return self.Tdf / (self.Tdf + self.Tc), self.Kp * self.Td / (self.Tdf + self.Tc)


@dataclass(frozen=True)
class Servo:
    """Servo G_s(s) = 1/(Tg s + 1) from controller output c to gate (guide vane) position g."""

    Tg: float = 0.2
    """Servo time constant [s]."""
    g_min: float = 0.0
    """Gate limits [pu of full opening]."""
    g_max: float = 1.0


@dataclass(frozen=True)
class Turbine:
    """Non-elastic water column hydro turbine (IEEE WG 1992; PSS/E HYGOV turbine).

    q = g·sqrt(h), dq/dt = (h_s − h)/Tw, Pm = At·h·(q − q_nl) − Dturb·g·Δω.
    Linearised at Pm0: ΔPm/Δg = At (1 − T1 s)/(1 + T2 s), T1 = (q0 − q_nl) Tw, T2 = q0 Tw / 2.
    """

    Tw: float = 1.0
    """Water starting time [s]."""
    q_nl: float = 0.1
    """No-load flow [pu]."""
    At: float = 1.0
    """Turbine gain [pu]."""
    h_s: float = 1.0
    """Static head [pu]."""
    Pm0: float = 0.75
    """Operating point: mechanical power [pu machine base]. A stated assumption (plant-model.md)."""
    Dturb: float = 0.0
    """Turbine damping [pu]."""

    @property
    def q0(self) -> float:
        """Steady-state flow [pu] at Pm0 with h0 = h_s = 1."""
        return self.Pm0 / self.At + self.q_nl

    @property
    def g0(self) -> float:
        """Steady-state gate opening [pu] at Pm0 (h0 = 1, so g0 = q0)."""
        return self.q0


@dataclass(frozen=True)
class Unit:
    """One hydro unit: generator swing, governor, servo and turbine, with its rating."""

    name: str = "plant1"
    rated_mw: float = 300.0
    swing: Swing = field(default_factory=Swing)
    governor: Governor = field(default_factory=Governor)
    servo: Servo = field(default_factory=Servo)
    turbine: Turbine = field(default_factory=Turbine)
    xd: float = 0.15
    """Transient reactance x'd [pu machine base]."""


@dataclass(frozen=True)
class Grid:
    """The paper's two-machine test system (Fig. 3, Table A.3): unit 1 (studied), unit 2 (the rest).

    DC power flow; x1 between bus 3 and the load bus 5, x2 between bus 4 and bus 5, on the system base.
    Load damping D [system base] acts on the centre-of-inertia frequency (``damping_at="coi"``, as in
    the author's Simulink) or at the load bus (``"load_bus"``, which damps the 1.8 Hz inter-machine
    mode heavily). G_1 is the same either way; the data are not.
    """

    s_base_mw: float = 3300.0
    x1: float = 1.0
    x2: float = 1.0
    D: float = 50.0
    damping_at: DampingAt = "coi"
    f0: float = 50.0
    """Nominal frequency [Hz]."""
    other: Unit = field(
        default_factory=lambda: Unit(
            name="plant2",
            rated_mw=3000.0,
            swing=Swing(H=9.6, Kd=0.1),
            # Classic temporary-droop hydro governor: Kp = 1/r, Ki = 1/(r Tr) -> Ti = Tr.
            governor=Governor(
                Kp=1.0 / 0.3,
                Ti=5.0,
                droop=0.08,
                Tf=0.05,
                droop_placement="classic",
                droop_signal="demand",
                digital=False,
            ),
            servo=Servo(Tg=0.2),
            turbine=Turbine(Tw=1.0, q_nl=0.1, At=1.0, Pm0=0.75),
        )
    )


@dataclass(frozen=True)
class Plant:
    """The studied unit in its grid: what the simulator runs and the analytic model describes."""

    unit: Unit = field(default_factory=Unit)
    grid: Grid = field(default_factory=Grid)

    def with_unit(self, **changes) -> Plant:
        return replace(self, unit=replace(self.unit, **changes))


PRESETS: dict[str, Plant] = {
    # Appendix A of the paper, droop in the integral channel, turbine linearised at Pm0 = 0.75:
    # G_1(0) = 0.0794, max|G_1| = 1.011 at 0.142 rad/s, max|S| = 1.287 (plant-model.md).
    "paper-plant1": Plant(),
    # The same unit with the textbook droop around the whole PI, fed back from the gate.
    "paper-plant1-classic": Plant(
        unit=Unit(governor=Governor(droop_placement="classic", droop_signal="gate"))
    ),
}


def preset(name: str) -> Plant:
    """The named preset plant; raises ConfigError listing the known names."""
    from fcrlive.errors import ConfigError

    try:
        return PRESETS[name]
    except KeyError:
        known = ", ".join(sorted(PRESETS))
        raise ConfigError(f"unknown preset {name!r}; known presets: {known}") from None
