"""Fault injection for the simulated governor: what a client sees on a real network when a device misbehaves.

Standing faults (``set``/``clear``) stay until cleared; ``drop_connections`` and ``restart`` act once.

| fault            | what the client sees                                                             |
|------------------|----------------------------------------------------------------------------------|
| ``hang``         | requests are accepted by TCP but never answered (client times out)               |
| ``exception``    | every request answered with a Modbus exception (6 DEVICE_BUSY, 4 DEVICE_FAILURE) |
| ``delay_ms``     | every response is sent that many milliseconds late                               |
| ``freeze``       | the input block stops changing (sample_counter and values stay put)              |
| ``nan``          | measured floats (speed, grid_freq, power, ...) read as NaN; counter and time go on |
| drop_connections | every open TCP connection is closed by the device (client sees EOF / reset)      |
| restart          | listener and connections close, the port refuses connections for the downtime,  |
|                  | then the device comes back with sample_counter, time, setpoints and plant reset  |

Exception codes accept a name (``"busy"``, ``"failure"``, or any ``pymodbus.constants.ExcCodes`` name) or a
number.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

from pymodbus.constants import ExcCodes

from fcrlive.errors import ConfigError

if TYPE_CHECKING:
    from sim_device.device import SimGovernor

EXCEPTION_ALIASES = {
    "busy": ExcCodes.DEVICE_BUSY,
    "device_busy": ExcCodes.DEVICE_BUSY,
    "failure": ExcCodes.DEVICE_FAILURE,
    "device_failure": ExcCodes.DEVICE_FAILURE,
}


def parse_exception_code(value: str | int | ExcCodes | None) -> ExcCodes | None:
    """``"busy"``/``"failure"``/an ExcCodes name/a number -> ExcCodes (ConfigError if unknown)."""
    if value is None or isinstance(value, ExcCodes):
        return value
    if isinstance(value, int):
        try:
            return ExcCodes(value)
        except ValueError:
            raise ConfigError(f"unknown Modbus exception code {value}") from None
    key = str(value).strip().lower()
    if key in EXCEPTION_ALIASES:
        return EXCEPTION_ALIASES[key]
    if key.isdigit():
        return parse_exception_code(int(key))
    for code in ExcCodes:
        if code.name.lower() == key:
            return code
    names = ", ".join(sorted(EXCEPTION_ALIASES) + [c.name.lower() for c in ExcCodes])
    raise ConfigError(f"unknown Modbus exception {value!r}; use a number or one of: {names}")


@dataclass
class FaultState:
    """The standing faults currently injected."""

    hang: bool = False
    exception: ExcCodes | None = None
    delay_ms: float = 0.0
    freeze: bool = False
    nan: bool = False

    @property
    def any(self) -> bool:
        return self.hang or self.exception is not None or self.delay_ms > 0 or self.freeze or self.nan


class FaultInjector:
    """Inject faults into a running :class:`~sim_device.device.SimGovernor` (``device.faults``)."""

    def __init__(self, device: SimGovernor):
        self._device = device
        self.state = FaultState()
        self.drops = 0
        """Connections closed by :meth:`drop_connections` so far."""
        self.restarts = 0

    def set(
        self,
        *,
        hang: bool | None = None,
        exception: str | int | ExcCodes | bool | None = False,
        delay_ms: float | None = None,
        freeze: bool | None = None,
        nan: bool | None = None,
    ) -> FaultState:
        """Change standing faults; arguments left out keep their value (``exception=None`` clears it)."""
        if hang is not None:
            self.state.hang = bool(hang)
        if exception is not False:
            self.state.exception = parse_exception_code(exception)  # type: ignore[arg-type]
        if delay_ms is not None:
            if not delay_ms >= 0:
                raise ConfigError(f"delay_ms must be >= 0, not {delay_ms!r}")
            self.state.delay_ms = float(delay_ms)
        if freeze is not None:
            self.state.freeze = bool(freeze)
        if nan is not None:
            self.state.nan = bool(nan)
        self._device._on_faults_changed()
        return self.state

    def clear(self) -> None:
        """Remove every standing fault."""
        self.state = FaultState()
        self._device._on_faults_changed()

    def drop_connections(self) -> int:
        """Close every open client connection now; returns how many were closed."""
        n = self._device._drop_connections()
        self.drops += n
        return n

    async def restart(self, downtime_s: float = 0.5) -> None:
        """Reboot: close the port, reset counters, setpoints and plant, listen again after ``downtime_s``."""
        await self._device._restart(downtime_s)
        self.restarts += 1

    def as_dict(self) -> dict:
        d = asdict(self.state)
        d["exception"] = self.state.exception.name if self.state.exception is not None else None
        d["drops"] = self.drops
        d["restarts"] = self.restarts
        return d
