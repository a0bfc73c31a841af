"""Simulated hydro turbine governor speaking Modbus TCP and CAN, driven by the plant simulator.

Run it with ``python -m sim_device`` (or ``fcrlive-sim-device``); use it in-process with
:class:`SimGovernor`. The register map is ``registers.toml`` (documented in REGISTERS.md), the CAN
frames are ``fcrlive_sim.dbc``.
"""

from sim_device.device import SimGovernor
from sim_device.faults import FaultInjector, FaultState
from sim_device.registers import load_map

__all__ = ["FaultInjector", "FaultState", "SimGovernor", "load_map"]
