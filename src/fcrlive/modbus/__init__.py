"""Modbus: register maps, their codec and files, and client parameters, shared by every Modbus user.

- :mod:`fcrlive.modbus.registers`: points, maps, read planning and the value codec (pure, no I/O);
- :mod:`fcrlive.modbus.ringlayout`: the device's ring buffer of controller samples, its register layout and
  slot codec (docs/buffered-acquisition.md; pure, no I/O);
- :mod:`fcrlive.modbus.mapfile`: the register map file's models and its one loader/validator;
- :mod:`fcrlive.modbus.client`: the parameters of a Modbus TCP client (:class:`ModbusParams`).

The daemon's poller, the excitation writer and the simulated governor (``sim_device``) all build on this
package; it imports nothing from them, and the numerical core imports nothing from it.
"""
