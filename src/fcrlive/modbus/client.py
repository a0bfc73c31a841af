"""Parameters of a Modbus TCP client: where the device is, its register map, timeouts, retries, backoff.

Both Modbus clients of fcrlive take a :class:`ModbusParams`: the daemon's poller
(``fcrlive.daemon.modbus_source``) and the excitation writer (``fcrlive.excitation.writer``), which keeps
its own pymodbus client (docs/excitation-writer.md says why).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from fcrlive.modbus.registers import RegisterMap


def quiet_pymodbus() -> None:
    """Silence pymodbus's own logging: it logs an ERROR per timed-out request (50 lines/s at 50 Hz)."""
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL + 1)


@dataclass(frozen=True)
class ModbusParams:
    """Connection and polling parameters (see ``config.ModbusConfig`` for meanings and units)."""

    host: str
    port: int
    register_map: RegisterMap
    poll_hz: float = 20.0
    timeout_s: float = 0.2
    retries: int = 0
    watchdog_failures: int = 10
    backoff_min_s: float = 0.1
    backoff_max_s: float = 5.0
    sample_tables: tuple[str, ...] = ("input",)
    """Tables sampled at ``poll_hz``: the measurements. Holding registers are settings/commands
    (excitation offset, limits) read on demand with ``ModbusSource.read_points``."""

    @classmethod
    def from_config(cls, cfg) -> ModbusParams:
        """From a validated ``config.ModbusConfig``."""
        return cls(host=cfg.host, port=cfg.port, register_map=cfg.load_map(), poll_hz=cfg.poll_hz,
                   timeout_s=cfg.timeout_s, retries=cfg.retries, watchdog_failures=cfg.watchdog_failures,
                   backoff_max_s=cfg.backoff_max_s)
