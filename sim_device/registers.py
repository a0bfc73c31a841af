"""The simulated governor's register map: ``registers.toml`` beside this module (documented in REGISTERS.md).

The map is read and validated by :mod:`fcrlive.modbus.mapfile`, the loader the fcrlive daemon uses, so a
map the simulator serves is a map the daemon accepts.
"""

from __future__ import annotations

from pathlib import Path

from fcrlive.modbus.mapfile import load_register_map
from fcrlive.modbus.registers import RegisterMap

DEFAULT_MAP_PATH = Path(__file__).with_name("registers.toml")


def load_map(path: str | Path | None = None) -> RegisterMap:
    """Load and validate a register map; ``None`` loads the one shipped with sim_device."""
    return load_register_map(DEFAULT_MAP_PATH if path is None else path)
