"""The simulated governor over real Modbus TCP on loopback: snapshots, safety, refusals, faults, clients.

Each test starts an in-process SimGovernor on a free port and talks to it with a real pymodbus
AsyncModbusTcpClient (created inside the running loop, short timeout, no retries), a raw socket, or mbpoll.
"""

from __future__ import annotations

import asyncio
import logging
import math
import shlex
import shutil
import socket
import struct

import numpy as np
import pytest
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusIOException

from fcrlive.modbus.registers import RegisterMap
from fcrlive.plant.params import preset
from fcrlive.sim.realtime import RealtimeSimulator
from sim_device import SimGovernor, load_map
from sim_device.device import (
    STATUS_EXCITATION_ACCEPTED,
    STATUS_FCR_N_ACTIVE,
    STATUS_HEARTBEAT_OK,
    STATUS_NORMAL_OPERATION,
)

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

PLANT = preset("paper-plant1")
MAP = load_map()
IN_START, IN_COUNT = MAP.span("input")
UNIT = MAP.unit_id


def make_device(**kw) -> SimGovernor:
    """An in-process device on a free loopback port, driven by the real plant simulator."""
    kw.setdefault("speed", 1.0)
    sim = RealtimeSimulator(PLANT, seed=kw.pop("seed", 3))
    return SimGovernor(PLANT, simulator=sim, **kw)


async def connect(port: int, timeout: float = 0.5) -> AsyncModbusTcpClient:
    client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=timeout, retries=0, reconnect_delay=0)
    assert await client.connect()
    return client


async def read_block(client, rmap: RegisterMap = MAP) -> dict:
    rr = await client.read_input_registers(IN_START, count=IN_COUNT, device_id=UNIT)
    assert not rr.isError(), rr
    return rmap.decode_block("input", IN_START, rr.registers)


async def read_holding(client, rmap: RegisterMap = MAP) -> dict:
    start, count = rmap.span("holding")
    rr = await client.read_holding_registers(start, count=count, device_id=UNIT)
    assert not rr.isError(), rr
    return rmap.decode_block("holding", start, rr.registers)


async def write_cmd(client, offset_hz: float, enable: int, heartbeat: int, rmap: RegisterMap = MAP):
    """Offset, enable and heartbeat in one FC16 write (the way a careful client does it)."""
    p = rmap.point("excitation_offset")
    regs = (
        rmap.encode(p, offset_hz)
        + rmap.encode("excitation_enable", enable)
        + rmap.encode("heartbeat", heartbeat)
    )
    assert rmap.point("heartbeat").address == p.address + 3
    rr = await client.write_registers(p.address, regs, device_id=UNIT)
    return rr


def f32(x: float) -> float:
    return float(np.float32(x))


async def wait_for(pred, timeout: float = 3.0, interval: float = 0.02):
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while loop.time() < end:
        if await pred():
            return True
        await asyncio.sleep(interval)
    return False


# ---------------------------------------------------------------------------------------------- snapshots


async def test_snapshot_is_one_consistent_sample():
    """One FC4 read = one sample: device_time == counter·Tc exactly, values are that sample's (float32)."""
    samples = []
    dev = make_device(speed=20.0, on_sample=samples.append)
    async with dev:
        client = await connect(dev.port)
        seen = set()
        for _ in range(40):
            v = await read_block(client)
            n = v["sample_counter"]
            assert v["device_time"] == n * dev.dt
            s = samples[n]  # sample n since start (no restart here)
            assert v["speed"] == f32(s.speed_pu)
            assert v["grid_freq"] == f32(s.grid_freq_hz)
            assert v["power"] == f32(s.pe_mw)
            assert v["mech_power"] == f32(s.pm_mw)
            assert v["controller_output"] == f32(100.0 * s.c)
            assert v["guide_vane"] == f32(100.0 * s.a)
            assert v["control_error"] == f32(s.epsilon)
            assert v["status"] & (STATUS_FCR_N_ACTIVE | STATUS_NORMAL_OPERATION) == 3
            seen.add(n)
            await asyncio.sleep(0.01)
        client.close()
    assert len(seen) > 10  # the block did move between reads
    # plausible physics: near nominal speed and rated operating point
    assert abs(v["speed"] - 1.0) < 0.01 and 40 < v["guide_vane"] < 100 and 0 < v["power"] < 300


async def test_word_order_little_swaps_words_only():
    dev = make_device(word_order="little")
    async with dev:
        client = await connect(dev.port)
        rr = await client.read_input_registers(IN_START, count=IN_COUNT, device_id=UNIT)
        big = MAP.decode_block("input", IN_START, rr.registers)
        little = dev.register_map.decode_block("input", IN_START, rr.registers)
        client.close()
    assert dev.register_map.word_order == "little"
    assert abs(little["speed"] - 1.0) < 0.01 and little["sample_counter"] < 1000
    assert not abs(big["speed"] - 1.0) < 0.01  # read with the wrong order it is garbage


# ---------------------------------------------------------------------------------------------- safety


async def test_excitation_is_clamped_and_applied():
    async with make_device(excitation_limit_hz=0.1) as dev:
        client = await connect(dev.port)
        assert not (await write_cmd(client, 0.5, 1, 1)).isError()
        h = await read_holding(client)
        assert h["excitation_offset"] == f32(0.1)  # the register holds the accepted value
        assert h["excitation_enable"] == 1 and h["heartbeat"] == 1
        assert await wait_for(lambda: _applied_is(client, f32(0.1)))
        v = await read_block(client)
        assert v["clamped_writes"] == 1
        assert v["status"] & STATUS_EXCITATION_ACCEPTED and v["status"] & STATUS_HEARTBEAT_OK
        assert not (await write_cmd(client, -7.0, 1, 2)).isError()
        assert await wait_for(lambda: _applied_is(client, f32(-0.1)))
        # within the limit: taken as is; the control error carries r = offset/f0
        assert not (await write_cmd(client, 0.04, 1, 3)).isError()
        assert await wait_for(lambda: _applied_is(client, f32(0.04)))
        assert dev._offset_hz == f32(0.04) and (await read_block(client))["clamped_writes"] == 2
        client.close()


async def _applied_is(client, value: float) -> bool:
    return (await read_block(client))["excitation_applied"] == value


async def _nonfinite_count_is(client, n: int) -> bool:
    return (await read_block(client))["nonfinite_writes"] == n


async def test_nonfinite_writes_count_as_zero():
    async with make_device() as dev:
        client = await connect(dev.port)
        assert not (await write_cmd(client, 0.05, 1, 1)).isError()
        assert await wait_for(lambda: _applied_is(client, f32(0.05)))
        for i, bad in enumerate((math.nan, math.inf, -math.inf)):
            assert not (await write_cmd(client, bad, 1, 2 + i)).isError()
            assert (await read_holding(client))["excitation_offset"] == 0.0
        assert dev.nonfinite_writes == 3
        # the input block is written once a sample: wait for the one after the third write (the applied 0
        # alone was already there after the first, and a read could see the count at 2)
        assert await wait_for(lambda: _nonfinite_count_is(client, 3))
        assert (await read_block(client))["excitation_applied"] == 0.0
        client.close()


async def test_writes_with_enable_off_are_ignored():
    async with make_device() as dev:
        client = await connect(dev.port)
        n_ok = 0
        for hb in range(1, 11):  # heartbeat alive, offset written, enable = 0
            assert not (await write_cmd(client, 0.08, 0, hb)).isError()
            v = await read_block(client)
            assert v["excitation_applied"] == 0.0
            assert not v["status"] & STATUS_EXCITATION_ACCEPTED
            n_ok += bool(v["status"] & STATUS_HEARTBEAT_OK)  # status is updated with the next sample
            await asyncio.sleep(0.05)
        assert n_ok >= 8
        # enabling alone (FC6 on the enable register) makes the stored offset take effect
        enable_addr = MAP.point("excitation_enable").address
        assert not (await client.write_register(enable_addr, 1, device_id=UNIT)).isError()
        assert await wait_for(lambda: _applied_is(client, f32(0.08)))
        assert not (await client.write_register(enable_addr, 0, device_id=UNIT)).isError()
        assert await wait_for(lambda: _applied_is(client, 0.0))
        # enable must be 0 or 1
        rr = await client.write_register(enable_addr, 2, device_id=UNIT)
        assert rr.isError() and rr.exception_code == 3  # ILLEGAL_DATA_VALUE
        client.close()


async def test_stopped_heartbeat_zeroes_excitation_within_timeout():
    timeout = 0.4
    async with make_device(heartbeat_timeout_s=timeout) as dev:
        client = await connect(dev.port)
        hb_addr = MAP.point("heartbeat").address
        assert not (await write_cmd(client, 0.06, 1, 1)).isError()
        # a live heartbeat keeps the offset applied for longer than the timeout
        for hb in range(2, 12):
            await asyncio.sleep(timeout / 4)
            assert not (await client.write_register(hb_addr, hb, device_id=UNIT)).isError()
            assert (await read_block(client))["excitation_applied"] == f32(0.06)
        # writing the SAME value is no heartbeat
        loop = asyncio.get_running_loop()
        t_stop = loop.time()
        zeroed_at = None
        while loop.time() - t_stop < 3 * timeout:
            assert not (await client.write_register(hb_addr, 11, device_id=UNIT)).isError()
            v = await read_block(client)
            if v["excitation_applied"] == 0.0:
                zeroed_at = loop.time() - t_stop
                break
            await asyncio.sleep(0.02)
        assert zeroed_at is not None, "offset never reset"
        # reset no later than the timeout plus one publish tick and a poll (generous for loaded CI)
        assert zeroed_at < timeout + 0.25
        assert not v["status"] & STATUS_HEARTBEAT_OK
        assert v["heartbeat_age"] >= timeout - 0.05
        assert (await read_holding(client))["excitation_offset"] == 0.0  # reset, not just masked
        assert dev.heartbeat_timeouts == 1
        # a resumed heartbeat does not bring the old offset back
        assert not (await client.write_register(hb_addr, 12, device_id=UNIT)).isError()
        await asyncio.sleep(0.1)
        assert (await read_block(client))["excitation_applied"] == 0.0
        client.close()


async def test_refused_writes_and_functions():
    """Input table, read-only points, partial floats, unknown addresses, coils: exception responses."""
    async with make_device() as dev:
        client = await connect(dev.port)
        for addr in (0, 8, 26):  # FC6 cannot reach the input table: those addresses are not holding registers
            rr = await client.write_register(addr, 1, device_id=UNIT)
            assert rr.isError() and rr.exception_code == 2, (addr, rr)
        for name in ("excitation_limit", "heartbeat_timeout", "rated_power", "nominal_freq"):
            p = MAP.point(name)
            rr = await client.write_registers(p.address, MAP.encode(p, 1.0), device_id=UNIT)
            assert rr.isError() and rr.exception_code == 2, (name, rr)
        # a write spanning writable and read-only points is refused whole
        rr = await client.write_registers(100, [0] * 6, device_id=UNIT)
        assert rr.isError() and rr.exception_code == 2
        # half a float
        rr = await client.write_register(MAP.point("excitation_offset").address, 0x3F80, device_id=UNIT)
        assert rr.isError() and rr.exception_code == 2
        for addr in (99, 118, 500, 65000):  # 112-117: the test-profile registers
            rr = await client.write_register(addr, 1, device_id=UNIT)
            assert rr.isError() and rr.exception_code == 2, addr
        rr = await client.read_input_registers(IN_START, count=IN_COUNT + 1, device_id=UNIT)
        assert rr.isError() and rr.exception_code == 2
        rr = await client.read_holding_registers(0, count=2, device_id=UNIT)
        assert rr.isError() and rr.exception_code == 2
        rr = await client.read_coils(0, count=1, device_id=UNIT)
        assert rr.isError() and rr.exception_code == 1
        rr = await client.write_coil(0, True, device_id=UNIT)
        assert rr.isError() and rr.exception_code == 1
        rr = await client.read_input_registers(IN_START, count=2, device_id=UNIT + 1)
        assert rr.isError() and rr.exception_code == 11  # no such unit behind this "gateway"
        # nothing changed on the device
        h = await read_holding(client)
        assert (
            h["excitation_limit"] == f32(0.1) and h["rated_power"] == 300.0 and h["excitation_offset"] == 0.0
        )
        client.close()


# ---------------------------------------------------------------------------------------------- faults


async def test_fault_hang_times_out_then_recovers():
    async with make_device() as dev:
        client = await connect(dev.port, timeout=0.3)
        dev.faults.set(hang=True)
        with pytest.raises(ModbusIOException):
            await client.read_input_registers(IN_START, count=IN_COUNT, device_id=UNIT)
        dev.faults.set(hang=False)
        if not client.connected:
            client.close()
            client = await connect(dev.port)
        assert (await read_block(client))["sample_counter"] > 0
        client.close()


@pytest.mark.parametrize(("code", "number"), [("busy", 6), ("failure", 4), (11, 11)])
async def test_fault_exception_codes(code, number):
    async with make_device() as dev:
        client = await connect(dev.port)
        dev.faults.set(exception=code)
        rr = await client.read_input_registers(IN_START, count=IN_COUNT, device_id=UNIT)
        assert rr.isError() and rr.exception_code == number
        rr = await write_cmd(client, 0.05, 1, 1)
        assert rr.isError() and rr.exception_code == number
        assert dev._offset_hz == 0.0  # a refused write has no effect
        dev.faults.set(exception=None)
        assert not (await client.read_input_registers(IN_START, count=IN_COUNT, device_id=UNIT)).isError()
        client.close()


async def test_fault_delay():
    async with make_device() as dev:
        client = await connect(dev.port, timeout=1.0)
        loop = asyncio.get_running_loop()
        dev.faults.set(delay_ms=200)
        t0 = loop.time()
        await read_block(client)
        assert loop.time() - t0 >= 0.19
        dev.faults.set(delay_ms=0)
        client.close()


async def test_fault_freeze_and_nan():
    async with make_device(speed=5.0) as dev:
        client = await connect(dev.port)
        dev.faults.set(freeze=True)
        a = await read_block(client)
        await asyncio.sleep(0.2)
        b = await read_block(client)
        assert a == b  # counter and values stuck while the plant runs on
        assert dev.sample_counter > b["sample_counter"]
        dev.faults.set(freeze=False, nan=True)
        assert await wait_for(lambda: _counter_above(client, b["sample_counter"]))
        v = await read_block(client)
        assert math.isnan(v["speed"]) and math.isnan(v["power"]) and math.isnan(v["guide_vane"])
        assert v["device_time"] == v["sample_counter"] * dev.dt  # counter and time stay valid
        dev.faults.clear()
        assert await wait_for(lambda: _speed_finite(client))
        client.close()


async def _counter_above(client, n) -> bool:
    return (await read_block(client))["sample_counter"] > n


async def _speed_finite(client) -> bool:
    return math.isfinite((await read_block(client))["speed"])


async def test_fault_drop_connections():
    async with make_device() as dev:
        client = await connect(dev.port)
        await read_block(client)
        assert await wait_for(lambda: _true(dev.connections == 1))
        assert dev.faults.drop_connections() == 1
        with pytest.raises((ConnectionException, ModbusIOException)):
            await asyncio.sleep(0.05)
            await client.read_input_registers(IN_START, count=IN_COUNT, device_id=UNIT)
        client.close()
        client = await connect(dev.port)  # the listener is still there
        await read_block(client)
        client.close()


async def _true(x):
    return x


async def test_fault_restart_resets_counter_and_setpoints():
    async with make_device(speed=10.0) as dev:
        client = await connect(dev.port)
        assert not (await write_cmd(client, 0.05, 1, 1)).isError()
        await asyncio.sleep(0.3)
        before = await read_block(client)
        assert before["sample_counter"] > 100
        task = asyncio.create_task(dev.faults.restart(downtime_s=0.5))
        await asyncio.sleep(0.2)
        # connection closed and port refusing while down
        with pytest.raises((ConnectionException, ModbusIOException)):
            await client.read_input_registers(IN_START, count=IN_COUNT, device_id=UNIT)
        client.close()
        with pytest.raises(OSError):
            socket.create_connection(("127.0.0.1", dev.port), timeout=0.5).close()
        await task
        client = await connect(dev.port)
        after = await read_block(client)
        assert after["sample_counter"] < before["sample_counter"]
        assert after["device_time"] == after["sample_counter"] * dev.dt
        h = await read_holding(client)
        assert h["excitation_offset"] == 0.0 and h["excitation_enable"] == 0 and h["heartbeat"] == 0
        assert after["excitation_applied"] == 0.0 and dev.faults.restarts == 1
        client.close()


# ---------------------------------------------------------------------------------------------- other clients


def _raw_fc4(port: int, start: int, count: int, unit: int = UNIT) -> list[int]:
    """Read input registers with a hand-built Modbus TCP frame (MBAP + PDU), no pymodbus involved."""
    with socket.create_connection(("127.0.0.1", port), timeout=2.0) as s:
        s.sendall(struct.pack(">HHHBBHH", 0x1234, 0, 6, unit, 4, start, count))
        buf = b""
        while len(buf) < 9 or len(buf) < 6 + struct.unpack(">H", buf[4:6])[0]:
            chunk = s.recv(512)
            assert chunk, "connection closed"
            buf += chunk
    tid, proto, length, u, fc, nbytes = struct.unpack(">HHHBBB", buf[:9])
    assert (tid, proto, u, fc) == (0x1234, 0, unit, 4), buf
    assert nbytes == 2 * count and length == 3 + nbytes
    return list(struct.unpack(f">{count}H", buf[9 : 9 + nbytes]))


async def test_raw_socket_read_matches_documented_map():
    """The REGISTERS.md layout, checked by a client that is not pymodbus (always runs)."""
    async with make_device() as dev:
        regs = await asyncio.to_thread(_raw_fc4, dev.port, IN_START, IN_COUNT)
        # decode by hand, big-endian words: the layout in REGISTERS.md
        counter = (regs[0] << 16) | regs[1]
        (t,) = struct.unpack(">d", struct.pack(">4H", *regs[2:6]))
        (speed,) = struct.unpack(">f", struct.pack(">2H", *regs[8:10]))
        (freq,) = struct.unpack(">f", struct.pack(">2H", *regs[10:12]))
        (power,) = struct.unpack(">f", struct.pack(">2H", *regs[12:14]))
        assert counter >= 0 and t == counter * dev.dt
        assert abs(speed - 1.0) < 0.01 and abs(freq - 50.0) < 0.5 and 0 < power < 300
        assert regs[6] & 0b11 == 0b11  # status: FCR-N active, normal operation


@pytest.mark.skipif(shutil.which("mbpoll") is None, reason="no mbpoll (the raw-socket test covers the map)")
async def test_mbpoll_command_from_registers_md():
    async with make_device() as dev:
        # exactly the documented command: floats from reference 9 (= address 8, speed), big-endian words
        cmd = f"mbpoll -m tcp -a 1 -t 3:float -B -r 9 -c 7 -1 -o 2 127.0.0.1 -p {dev.port}"
        proc = await asyncio.create_subprocess_exec(
            *shlex.split(cmd), stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT
        )
        out, _ = await asyncio.wait_for(proc.communicate(), 10)
        text = out.decode()
        assert proc.returncode == 0, text
        vals = {}
        for line in text.splitlines():
            if line.startswith("[") and "]:" in line:
                ref, val = line.split("]:")
                vals[int(ref[1:])] = float(val.split()[0])
        assert sorted(vals) == [9, 11, 13, 15, 17, 19, 21]
        assert abs(vals[9] - 1.0) < 0.01  # speed
        assert abs(vals[11] - 50.0) < 0.5  # grid_freq
        assert 0 < vals[13] < 300  # power, MW
        # and a refused write is reported by mbpoll as well (reference 105 = address 104, read-only)
        cmd = f"mbpoll -m tcp -a 1 -t 4 -r 105 -1 127.0.0.1 -p {dev.port} 5"
        proc = await asyncio.create_subprocess_exec(
            *shlex.split(cmd), stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT
        )
        out, _ = await asyncio.wait_for(proc.communicate(), 10)
        assert proc.returncode != 0 and "Illegal data address" in out.decode()
