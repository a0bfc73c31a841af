"""A stepping simulator of the studied unit for a simulated governor device (Modbus/CAN).

:class:`RealtimeSimulator` advances the nonlinear model of :mod:`fcrlive.sim` one controller sample at
a time with the excitation given at that step. With the same seed, noise settings and r it reproduces
:func:`fcrlive.sim.simulate` (same step map, same noise streams drawn in blocks; equal to about 1e-10
relative, the tolerance of simulate's fixed point). The noise is sized as in ``simulate`` without
excitation (r is not known in advance): load for ±0.1 Hz, process noise for ``snr_db`` over the 1800 s
reference window.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fcrlive.errors import ConfigError
from fcrlive.plant.params import Plant
from fcrlive.sim import linear as _lin
from fcrlive.sim import model as _mdl
from fcrlive.sim import nonlinear as _nl

_BLOCK = 4096


@dataclass(frozen=True)
class StepSample:
    """One controller sample n at t = n·dt (values at t, before the step to t + dt)."""

    n: int
    t: float
    """Time [s]."""
    speed_pu: float
    """Rotor speed [pu], 1.0 nominal (unfiltered)."""
    grid_freq_hz: float
    """Centre-of-inertia grid frequency [Hz] (plus meter noise)."""
    pe_mw: float
    """Measured electrical power [MW] (anti-aliased, plus meter noise)."""
    pm_mw: float
    """Mechanical power [MW]."""
    c: float
    """Gate demand [pu of full opening, 0..1]."""
    a: float
    """Gate position [pu of full opening, 0..1]."""
    r: float
    """Excitation applied at this sample [pu]."""
    epsilon: float
    """Governor input error r − y [pu]."""
    y: float
    """Governor's speed signal: filtered speed deviation plus process noise [pu]."""


class RealtimeSimulator:
    """Single-run stepping simulator (module docstring). ``dt`` = the controller sample time Tc [s]."""

    def __init__(self, plant: Plant, *, seed: int = 0, snr_db: float | None = 12.0,
                 load_noise_std: float | None = None, meas_noise_power: float = 0.0,
                 meas_noise_freq_hz: float = 0.0, process_noise_std: float = 0.0):
        self.plant = plant
        self.seed = int(seed)
        self._st = _nl.Stepper(plant)
        m = self._m = self._st.m
        self.dt = float(m.Tc)
        self.f0 = float(plant.grid.f0)
        self.rated_mw = float(plant.unit.rated_mw)
        self.g0 = float(m.tp1.g0)
        self.load_noise_std = _lin.load_noise_std(plant) if load_noise_std is None else float(load_noise_std)
        if snr_db is None:
            self.process_noise_std = float(process_noise_std)
        else:
            try:
                self.process_noise_std = _lin.process_noise_std(plant, float(snr_db), self.load_noise_std)
            except ValueError as exc:
                raise ConfigError(f"snr_db: {exc}") from None
        self.snr_db = snr_db
        self.meas_noise_power = float(meas_noise_power)
        self.meas_noise_freq_hz = float(meas_noise_freq_hz)
        levels = (self.load_noise_std, self.process_noise_std, self.meas_noise_power, self.meas_noise_freq_hz)
        if min(levels) < 0:
            raise ConfigError("noise levels must be >= 0")
        self._sl = self.load_noise_std * math.sqrt(self.dt)
        self._cw1, self._cw2 = float(m.C_coi[_mdl.W1]), float(m.C_coi[_mdl.W2])
        self.reset()

    def reset(self) -> None:
        """Back to the steady state at t = 0 with the noise streams restarted."""
        self._gens = _nl.streams(self.seed)
        self._x = np.zeros((self._st.nx, 1))
        self._i1 = np.zeros(1)
        self._pl = 0.0
        self._nprev: np.ndarray | None = None
        self._n = 0
        self._buf: dict[int, np.ndarray] = {}
        self._pos = _BLOCK

    def _noise(self) -> tuple[float, float, float, float]:
        if self._pos >= _BLOCK:
            self._buf = {k: self._gens[k].standard_normal(_BLOCK) for k, s in (
                (_nl.LOAD, self._sl), (_nl.PROCESS, self.process_noise_std),
                (_nl.MEAS_P, self.meas_noise_power), (_nl.MEAS_F, self.meas_noise_freq_hz)) if s > 0}
            self._pos = 0
        j = self._pos
        self._pos += 1
        b = self._buf
        return tuple(float(b[k][j]) if k in b else 0.0 for k in range(_nl.N_STREAMS))  # type: ignore[return-value]

    @property
    def n(self) -> int:
        """Index of the next sample."""
        return self._n

    def step(self, r: float = 0.0, applied_hz: float | None = None) -> StepSample:
        """Sample n with excitation ``r`` [pu] applied, then advance the plant to n + 1.

        ``applied_hz``: the open-loop industry-test mode for this sample (as ``SimConfig.applied_freq_hz``):
        this applied frequency [Hz] replaces the governor's speed feedback; the unit stays on the grid.
        """
        r = float(r)
        if not math.isfinite(r):
            raise ValueError(f"excitation must be finite, got {r}")
        app = None
        if applied_hz is not None:
            if not math.isfinite(applied_hz):
                raise ValueError(f"applied frequency must be finite, got {applied_hz}")
            app = np.array([float(applied_hz) / self.f0 - 1.0])
        e_l, e_v, e_p, e_f = self._noise()
        x, st, m = self._x, self._st, self._m
        v = self.process_noise_std * e_v
        st.open_loop = app is not None  # the Stepper reads the flag at every control() call
        y, eps, c, dc, i1n = st.control(x, self._i1, r, v, app)
        pl1 = self._pl + self._sl * e_l
        x_next, self._nprev = st.advance(x, dc, np.array([self._pl]), np.array([pl1]), self._nprev)
        xs = x[:, 0]
        u = float(xs[_mdl.PF1]) + self.meas_noise_power * e_p
        f = self.f0 * (1.0 + self._cw1 * float(xs[_mdl.W1]) + self._cw2 * float(xs[_mdl.W2]))
        f += self.meas_noise_freq_hz * e_f
        pm = float(_mdl.pm1_absolute(m, x)[0])
        sample = StepSample(
            n=self._n,
            t=self._n * self.dt,
            speed_pu=1.0 + float(xs[_mdl.W1]),
            grid_freq_hz=f,
            pe_mw=(m.tp1.Pm0 + u) * self.rated_mw,
            pm_mw=pm * self.rated_mw,
            c=float(c[0]),
            a=float(xs[_mdl.G1]) + self.g0,
            r=r,
            epsilon=float(eps[0]),
            y=float(y[0]),
        )
        self._x, self._i1, self._pl = x_next, i1n, pl1
        self._n += 1
        return sample
