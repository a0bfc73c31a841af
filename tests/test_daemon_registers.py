"""Register decoding: every type × word order × byte order round-trips against pymodbus."""

from __future__ import annotations

import math
import struct

import pytest
from pymodbus.client import ModbusTcpClient

from fcrlive.modbus.registers import (
    ReadBlock,
    RegisterPoint,
    decode_block,
    decode_point,
    decode_raw,
    encode_point,
    encode_raw,
    find_overlap,
    plan_reads,
)

DT = ModbusTcpClient.DATATYPE
TYPES = {"int16": DT.INT16, "uint16": DT.UINT16, "int32": DT.INT32, "uint32": DT.UINT32,
         "float32": DT.FLOAT32, "float64": DT.FLOAT64}
VALUES = {
    "int16": [-32768, -1, 0, 1234, 32767], "uint16": [0, 1, 0xBEEF, 65535],
    "int32": [-(2**31), -123456789, 0, 2**31 - 1], "uint32": [0, 70000, 0xDEADBEEF, 2**32 - 1],
    "float32": [0.0, -1.5, 49.987, 3.4e38, -1e-30], "float64": [0.0, -1.5, 49.98712345678, 1e300, 5e-324],
}


def _swap(regs):
    return [((r & 0xFF) << 8) | (r >> 8) for r in regs]


@pytest.mark.parametrize("type_", list(TYPES))
@pytest.mark.parametrize("word_order", ["big", "little"])
def test_roundtrip_against_pymodbus(type_, word_order):
    for v in VALUES[type_]:
        regs = ModbusTcpClient.convert_to_registers(v, TYPES[type_], word_order=word_order)
        assert encode_raw(v, type_, word_order) == regs
        got = decode_raw(regs, type_, word_order)
        assert got == ModbusTcpClient.convert_from_registers(regs, TYPES[type_], word_order=word_order)
        if type_ == "float32":
            assert got == struct.unpack("f", struct.pack("f", v))[0]
        else:
            assert got == v
        # byte-swapped devices: pymodbus has no byte order, the bytes inside each register are swapped
        assert decode_raw(_swap(regs), type_, word_order, "little") == got
        assert encode_raw(v, type_, word_order, "little") == _swap(regs)


def test_known_layouts():
    # 0x41200000 = 10.0f: big words [0x4120, 0x0000]; little words [0x0000, 0x4120]; byte swapped 0x2041
    assert decode_raw([0x4120, 0x0000], "float32") == 10.0
    assert decode_raw([0x0000, 0x4120], "float32", "little") == 10.0
    assert decode_raw([0x2041, 0x0000], "float32", "big", "little") == 10.0
    assert decode_raw([0x0001, 0x0002], "uint32") == 0x00010002
    assert decode_raw([0x0001, 0x0002], "uint32", "little") == 0x00020001


def test_scale_offset_and_nan():
    p = RegisterPoint("f", "input", 0, "int16", scale=0.01, offset=45.0, unit="Hz")
    regs = encode_point(p, 50.02)
    assert regs == [502]
    assert decode_point(p, regs) == pytest.approx(50.02)
    q = RegisterPoint("x", "input", 0, "float32")
    assert math.isnan(decode_point(q, encode_point(q, math.nan)))


def test_plan_reads_groups_contiguous_blocks():
    pts = [RegisterPoint("a", "input", 0, "uint32"), RegisterPoint("b", "input", 2, "float64"),
           RegisterPoint("c", "input", 10, "int16"), RegisterPoint("h", "holding", 100, "float32"),
           RegisterPoint("big", "input", 11, "uint16")]
    blocks = plan_reads(pts)
    assert [(b.table, b.address, b.count) for b in blocks] == [("input", 0, 6), ("input", 10, 2),
                                                               ("holding", 100, 2)]
    many = [RegisterPoint(f"p{i}", "input", 2 * i, "float32") for i in range(100)]
    blocks = plan_reads(many)
    assert [b.count for b in blocks] == [124, 76]  # never more than 125 registers per request
    assert sum(len(b.points) for b in blocks) == 100


def test_decode_block_short_read_gives_nan():
    b = ReadBlock("input", 0, 4, (RegisterPoint("a", "input", 0, "float32"),
                                  RegisterPoint("b", "input", 2, "float32")))
    out = decode_block(b, [0x4120, 0, 0x4120])
    assert out["a"] == 10.0 and math.isnan(out["b"])


def test_find_overlap():
    a = RegisterPoint("a", "input", 0, "float64")
    assert find_overlap([a, RegisterPoint("b", "input", 3, "int16")]) is not None
    assert find_overlap([a, RegisterPoint("b", "input", 4, "int16")]) is None
    assert find_overlap([a, RegisterPoint("b", "holding", 0, "int16")]) is None
