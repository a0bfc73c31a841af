"""The simulated governor's CAN side: DBC-decoded bursts on a `virtual` bus, excitation frames applied.

Also the DBC itself (every published signal has a register of the same name) and a cross-process check
over `udp_multicast` with the CLI.
"""

from __future__ import annotations

import asyncio
import os
import random
import sys
import uuid

import can
import numpy as np
from test_sim_device_modbus import MAP, UNIT, connect, make_device, read_block, read_holding

from sim_device.can_io import CMD_MESSAGE, TX_ORDER, load_dbc
from sim_device.registers import load_map

DB = load_dbc()


def f32(x: float) -> float:
    return float(np.float32(x))


def test_dbc_signals_match_register_names():
    rmap = load_map()
    tx = [DB.get_message_by_name(n) for n in TX_ORDER]
    assert [m.frame_id for m in tx] == list(range(0x180, 0x186))
    names = {s.name for m in tx for s in m.signals}
    inputs = {p.name for p in rmap.table("input")}
    assert names <= inputs
    assert {"sample_counter", "device_time", "speed", "grid_freq", "power", "guide_vane"} <= names
    cmd = DB.get_message_by_name(CMD_MESSAGE)
    assert {s.name for s in cmd.signals} == {"excitation_offset", "excitation_enable", "heartbeat"}
    assert all(m.length == 8 and not m.is_extended_frame for m in [*tx, cmd])


def _recv_burst(bus: can.BusABC, timeout: float = 2.0) -> dict:
    """Frames of one burst (GOV_Counter first), decoded with the DBC."""
    got: dict = {}
    ids = [DB.get_message_by_name(n).frame_id for n in TX_ORDER]
    loop_end = 50
    while loop_end:
        loop_end -= 1
        msg = bus.recv(timeout)
        assert msg is not None, "no CAN frame received"
        if msg.arbitration_id == ids[0]:
            got = {}
        if msg.arbitration_id in ids and (got or msg.arbitration_id == ids[0]):
            got[msg.arbitration_id] = DB.decode_message(msg.arbitration_id, msg.data)
            if len(got) == len(ids):
                out: dict = {}
                for fid in ids:  # in burst order
                    out.update(got[fid])
                return out
    raise AssertionError("no complete burst")


def _cmd_frame(offset_hz: float, enable: int, heartbeat: int) -> can.Message:
    m = DB.get_message_by_name(CMD_MESSAGE)
    data = m.encode({"excitation_offset": offset_hz, "excitation_enable": enable, "heartbeat": heartbeat})
    return can.Message(arbitration_id=m.frame_id, data=data, is_extended_id=False)


async def test_can_bursts_decode_and_excitation_frame_is_applied():
    channel = f"sim-device-test-{uuid.uuid4().hex[:8]}"
    async with make_device(can_channel=channel, can_interface="virtual", heartbeat_timeout_s=0.5) as dev:
        bus = can.Bus(channel=channel, interface="virtual")
        try:
            burst = await asyncio.to_thread(_recv_burst, bus)
            n = burst["sample_counter"]
            assert n >= 0 and burst["device_time"] == n * dev.dt  # float64 on the wire: exact
            assert abs(burst["speed"] - 1.0) < 0.01 and abs(burst["grid_freq"] - 50.0) < 0.5
            assert 0 < burst["power"] < 300 and 0 < burst["guide_vane"] <= 100
            assert burst["status"] & 0b11 == 0b11 and burst["excitation_applied"] == 0.0

            # an out-of-limit excitation frame: clamped like a Modbus write, visible on both sides
            client = await connect(dev.port)
            bus.send(_cmd_frame(0.5, 1, 1))
            for _ in range(100):
                b = await asyncio.to_thread(_recv_burst, bus)
                if b["excitation_applied"] != 0.0:
                    break
            assert b["excitation_applied"] == f32(0.1) and b["status"] & 0b1100 == 0b1100
            v = await read_block(client)
            assert v["excitation_applied"] == f32(0.1) and v["clamped_writes"] == 1
            h = await read_holding(client)
            assert h["excitation_offset"] == f32(0.1) and h["excitation_enable"] == 1 and h["heartbeat"] == 1
            assert dev.can.commands_received == 1

            # frames stop: the wall-clock heartbeat timeout zeroes the offset
            for _ in range(200):
                b = await asyncio.to_thread(_recv_burst, bus)
                if b["excitation_applied"] == 0.0:
                    break
            assert b["excitation_applied"] == 0.0 and not b["status"] & 0b1000
            assert (await read_holding(client))["excitation_offset"] == 0.0
            client.close()
        finally:
            bus.shutdown()


async def test_cli_speaks_can_over_udp_multicast_across_processes():
    """`python -m sim_device --can GROUP --can-interface udp_multicast`: another process decodes it."""
    group = f"239.{random.randint(1, 254)}.{random.randint(1, 254)}.{random.randint(1, 254)}"
    cport = random.randint(40000, 49000)
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sim_device", "--port", "0", "--speed", "5", "--duration", "20",
        "--can", group, "--can-interface", "udp_multicast", "--can-port", str(cport),
        "--log-level", "WARNING",
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
        env={**os.environ, "OPENBLAS_NUM_THREADS": "1"},
    )  # fmt: skip
    try:
        line = (await asyncio.wait_for(proc.stdout.readline(), 30)).decode()
        assert line.startswith("listening on"), line + (await proc.stderr.read()).decode()
        port = int(line.rsplit(":", 1)[1])
        bus = can.Bus(channel=group, interface="udp_multicast", port=cport)
        try:
            b1 = await asyncio.to_thread(_recv_burst, bus)
            bus.send(_cmd_frame(-0.03, 1, 42))
            for _ in range(100):
                b2 = await asyncio.to_thread(_recv_burst, bus)
                if b2["excitation_applied"] != 0.0:
                    break
        finally:
            bus.shutdown()
        assert b2["sample_counter"] > b1["sample_counter"]
        assert b2["excitation_applied"] == f32(-0.03)
        client = await connect(port)
        h = await read_holding(client)
        assert h["heartbeat"] == 42 and h["excitation_enable"] == 1
        rr = await client.read_input_registers(0, count=2, device_id=UNIT)
        assert MAP.decode("sample_counter", rr.registers) >= b2["sample_counter"]
        client.close()
    finally:
        if proc.returncode is None:
            proc.terminate()
        await asyncio.wait_for(proc.wait(), 10)
