"""Simulated hydro turbine governor speaking Modbus TCP and CAN (filled by the sim-device work)."""
