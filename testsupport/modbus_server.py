"""A small real Modbus TCP server serving a :class:`RegisterMap` (pymodbus 3.16 ``SimDevice``).

For tests and benchmarks of the Modbus source when the full ``sim_device.SimGovernor`` is not
wanted: values are set with :meth:`RegisterServer.set`; the server can be stopped and restarted on
the same port, and made to stop answering (``hang``) to exercise timeouts and the watchdog.
"""

from __future__ import annotations

import asyncio
from collections.abc import Mapping

from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from fcrlive.modbus.registers import RegisterMap, encode_point, plan_reads

_FC = {"input": 4, "holding": 3}


class RegisterServer:
    """``async with RegisterServer(rmap) as srv:`` listens on ``srv.port`` (loopback, free port)."""

    def __init__(self, rmap: RegisterMap, host: str = "127.0.0.1", port: int = 0):
        self.map = rmap
        self.host = host
        self.port = port
        self.hang = False
        """While True the server swallows requests without answering (the client times out)."""
        self.requests = 0
        self._server: ModbusTcpServer | None = None
        self._values: dict[str, float] = {}
        self._internal = False

    def _device(self) -> SimDevice:
        blocks = {"input": [], "holding": []}
        # pymodbus needs a SimData per contiguous block; cover each planned read block plus one
        # spare register so a holding point can be written past the map's end without errors
        for b in plan_reads(self.map.points):
            blocks[b.table].append(SimData(b.address, values=[0] * b.count, datatype=DataType.REGISTERS))
        for t in blocks:
            if not blocks[t]:
                blocks[t].append(SimData(60000, values=[0], datatype=DataType.REGISTERS))
        bits = [SimData(0, values=[False] * 16, datatype=DataType.BITS)]
        return SimDevice(id=self.map.unit_id, simdata=(bits, list(bits), blocks["holding"], blocks["input"]),
                         action=self._action)

    async def _action(self, function_code, start_address, address, count, current_registers, set_values):
        if self._internal:  # our own set(): the hook sees it too, never hang on it
            return None
        self.requests += 1
        while self.hang:
            await asyncio.sleep(0.01)
        return None

    async def start(self) -> None:
        """Start listening (again, on the same port after :meth:`stop`), restoring the values."""
        self._server = ModbusTcpServer(self._device(), address=(self.host, self.port))
        await self._server.serve_forever(background=True)
        self.port = self._server.transport.sockets[0].getsockname()[1]
        if self._values:
            await self.set(dict(self._values))

    async def stop(self) -> None:
        """Close the listener and every client connection."""
        if self._server is not None:
            await self._server.shutdown()
            self._server = None

    async def __aenter__(self) -> RegisterServer:
        await self.start()
        return self

    async def __aexit__(self, *exc) -> None:
        self.hang = False
        await self.stop()

    async def set(self, values: Mapping[str, float]) -> None:
        """Set points by engineering value (encoded with the map's type, scale, word/byte order)."""
        self._values.update(values)
        if self._server is None:
            return
        for name, v in values.items():
            p = self.map.point(name)
            regs = encode_point(p, v, self.map.word_order, self.map.byte_order)
            self._internal = True
            try:
                await self._server.async_setValues(self.map.unit_id, _FC[p.table], p.address, regs)
            finally:
                self._internal = False

    async def get_registers(self, table: str, address: int, count: int) -> list[int]:
        """Raw registers as the server holds them."""
        return await self._server.async_getValues(self.map.unit_id, _FC[table], address, count)
