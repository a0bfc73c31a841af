"""Prequalification test profiles on the simulated governor: the applied-frequency (open-loop test) mode.

A client selects a profile of :mod:`fcrlive.prequal.profiles` (the TR v1.1 test signals) in the holding
registers and starts it; from the next controller sample on, the profile's frequency replaces the
governor's speed feedback, as the artificial signal of a real prequalification test does (TR Section
5, Figure 30), while the unit stays on the grid. The profile runs in SIMULATED time (one controller
sample per step), so ``--speed 60`` runs the 21-min FCR-N step test in 21 s of wall time. When it ends
the governor is back on its measured frequency; a test can be rehearsed against the daemon this way.

Registers (REGISTERS.md): ``test_profile`` (a number of :data:`PROFILES`), ``test_period`` (sine
period [s]), ``test_options`` (bits: 1 endurance, 2 FCR-N/FCR-D combination ramps 7-8, 4 LER static
test), ``test_command`` (1 start, 0 stop); read back ``test_state``, ``applied_freq`` and
``test_time`` in the input block.

Safety, as for the excitation offset: a start needs a live heartbeat, and the test is aborted (back to
the measured frequency) when the heartbeat is lost, on a stop command and on a device restart.
"""

from __future__ import annotations

import logging
import math

from pymodbus.constants import ExcCodes

from fcrlive.prequal import profiles as pf

log = logging.getLogger("sim_device")

PROFILES: dict[int, str] = {
    1: "fcrn-steps",
    2: "fcrd-up-ramps",
    3: "fcrd-down-ramps",
    4: "fcrd-static-up",
    5: "fcrd-static-down",
    6: "linearity-fcrn",
    7: "linearity-fcrd-up",
    8: "linearity-fcrd-down",
    9: "sine-fcrn",
    10: "sine-fcrd-up",
    11: "sine-fcrd-down",
}
"""``test_profile`` register value -> profile name (:func:`fcrlive.prequal.profiles.profile`)."""

OPTION_ENDURANCE = 1 << 0
OPTION_COMBINATION = 1 << 1
OPTION_LER = 1 << 2

STATE_IDLE = 0
STATE_RUNNING = 1
STATE_FINISHED = 2
STATE_ABORTED = 3

HOLDING_POINTS = ("test_profile", "test_command", "test_period", "test_options")
"""Holding registers of the test mode (writable)."""


class TestProfileRunner:
    """The test mode of one device: the selected profile and where it is (sample count since start)."""

    __test__ = False  # not a pytest class

    def __init__(self, dt: float, f0: float = 50.0):
        self.dt = float(dt)
        self.f0 = float(f0)
        self.selected = 0
        self.period_s = 40.0
        self.options = 0
        self.state = STATE_IDLE
        self.profile: pf.Profile | None = None
        self._n = 0
        self._stop_n = 0
        self.last_applied_hz = 0.0
        self.last_t_s = 0.0

    @property
    def active(self) -> bool:
        return self.state == STATE_RUNNING


    def build(self) -> pf.Profile:
        """The profile of the selected number, period and options (ValueError if not valid)."""
        name = PROFILES.get(self.selected)
        if name is None:
            raise ValueError(f"test_profile {self.selected} is not one of {sorted(PROFILES)}")
        return pf.profile(
            name,
            endurance=bool(self.options & OPTION_ENDURANCE),
            combination=bool(self.options & OPTION_COMBINATION),
            ler=bool(self.options & OPTION_LER),
            period_s=self.period_s,
        )

    def write(self, new: dict[str, float], heartbeat_ok: bool) -> ExcCodes | None:
        """Apply a Modbus write of the test registers; an exception code refuses the whole write."""
        selected = int(new.get("test_profile", self.selected))
        period = float(new.get("test_period", self.period_s))
        options = int(new.get("test_options", self.options))
        if selected != 0 and selected not in PROFILES:
            return ExcCodes.ILLEGAL_VALUE
        if not (math.isfinite(period) and period > 0) or options & ~(OPTION_ENDURANCE | OPTION_COMBINATION
                                                                      | OPTION_LER):
            return ExcCodes.ILLEGAL_VALUE
        command = new.get("test_command")
        if command is not None and command not in (0, 1):
            return ExcCodes.ILLEGAL_VALUE
        if command == 1 and (not heartbeat_ok or selected == 0):
            return ExcCodes.ILLEGAL_VALUE  # a test starts only with a live heartbeat and a profile
        old = (self.selected, self.period_s, self.options)
        self.selected, self.period_s, self.options = selected, period, options
        if command == 1:
            try:
                self.start()
            except ValueError:
                self.selected, self.period_s, self.options = old
                return ExcCodes.ILLEGAL_VALUE
        elif command == 0 and self.active:
            self.abort("stop command")
        return None

    def start(self) -> None:
        self.profile = self.build()
        self._n = 0
        self.last_t_s = 0.0
        self._stop_n = round(self.profile.duration_s / self.dt)
        self.state = STATE_RUNNING
        log.info("test profile %s started (%.0f s simulated)", self.profile.name, self.profile.duration_s)

    def abort(self, why: str) -> None:
        if self.active:
            log.warning("test profile %s aborted: %s", self.profile.name if self.profile else "?", why)
            self.state = STATE_ABORTED

    def check_heartbeat(self, ok: bool) -> None:
        if self.active and not ok:
            self.abort("heartbeat lost")

    def next_applied_hz(self) -> float | None:
        """The applied frequency for the next controller sample [Hz], None when no test runs (the
        governor then sees its measured frequency). Advances the test by one sample."""
        if not self.active:
            return None
        assert self.profile is not None
        if self._n >= self._stop_n:
            self.state = STATE_FINISHED
            log.info("test profile %s finished", self.profile.name)
            return None
        t = self._n * self.dt
        f = float(self.profile.frequency(t)[0])
        self._n += 1
        self.last_applied_hz, self.last_t_s = f, t
        return f

    def values(self) -> dict[str, float]:
        """The input-register values of the test mode (``applied_freq`` 0 when no test runs)."""
        return {
            "test_state": self.state,
            "applied_freq": self.last_applied_hz if self.active else 0.0,
            "test_time": self.last_t_s,
        }
