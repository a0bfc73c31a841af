"""Test and benchmark support: real servers and harnesses that tests and benchmarks share, not shipped.

- :mod:`testsupport.modbus_server`: a small real Modbus TCP server serving a register map;
- :mod:`testsupport.mqtt`: waiting for the daemon's first identification over MQTT, as a dashboard would;
- :mod:`testsupport.excitation_study`: accelerated closed-loop runs of the simulated governor with the
  excitation written through the real chain, and their identification;
- :mod:`testsupport.daemon_config`: the daemon's TOML configuration the end-to-end tests and benchmarks write.

This package sits beside ``sim_device`` at the repository root and is not part of the fcrlive wheel;
``src/`` never imports it (the import contract in pyproject.toml says so).
"""
