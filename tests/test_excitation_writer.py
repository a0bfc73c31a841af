"""The excitation writer and its configuration, against the real simulated governor (loopback Modbus)."""

from __future__ import annotations

import asyncio
import itertools
import math
import tomllib
from dataclasses import replace

import numpy as np
import pytest
from pydantic import ValidationError
from test_excitation_writer_support import RMAP, governor, make_task, wait_active, wait_zero

from fcrlive.errors import ConfigError
from fcrlive.excitation.config import ExcitationSettings
from fcrlive.excitation.writer import ExcitationFault, ExcitationPoints, ExcitationWriter, ReadbackMismatch
from fcrlive.modbus.client import ModbusParams


def _writer(port, rmap=RMAP, **kw):
    kw = {"max_abs_hz": 0.1, "write_period_s": 0.05, **kw}
    return ExcitationWriter(ModbusParams("127.0.0.1", port, rmap, timeout_s=0.2, backoff_max_s=0.5), **kw)


async def test_zero_first_then_one_fc16_with_enable_and_heartbeat_read_back():
    async with governor() as dev, _writer(dev.port) as w:
        first = await w.write(0.05)
        assert first.ok and first.forced_zero and first.written_hz == 0.0
        values = [0.05, -0.03, 0.1, -0.1, 0.0]
        for v in values:
            res = await w.write(v)
            assert res.ok and not res.forced_zero and res.written_hz == v
        await asyncio.sleep(0.05)
        held = await dev.read_points("holding")
    # one command per write, each carrying offset, enable and heartbeat: one FC16 of registers 100-103
    assert len(dev.commands) == 1 + len(values)
    assert all(None not in c[1:] for c in dev.commands)
    assert dev.commands[0][1:3] == (0.0, 0)
    assert [c[1] for c in dev.commands[1:]] == pytest.approx(values, abs=1e-8)
    assert [c[2] for c in dev.commands[1:]] == [1, 1, 1, 1, 0]  # enable only with a non-zero offset
    hbs = [c[3] for c in dev.commands]
    assert all(b == (a + 1) % 65536 for a, b in itertools.pairwise(hbs))  # every write changes the heartbeat
    assert held["excitation_offset"] == 0.0 and held["heartbeat"] == hbs[-1]
    assert w.stats.readback_checks == len(dev.commands) and w.stats.max_abs_written_hz == 0.1
    assert w.device_limit_hz == pytest.approx(0.1) and w.device_heartbeat_timeout_s == 1.0


@pytest.mark.parametrize("bad", [0.2, -0.1000001, math.nan, math.inf])
async def test_out_of_bounds_values_are_never_sent(bad):
    async with governor() as dev, _writer(dev.port) as w:
        await w.write(0.0)
        assert (await w.write(0.05)).ok
        with pytest.raises(ExcitationFault, match="refused"):
            await w.write(bad)
        held = await dev.read_points("holding")
    assert held["excitation_offset"] == 0.0 and held["excitation_enable"] == 0
    assert all(c[1] is None or (math.isfinite(c[1]) and abs(c[1]) <= 0.1) for c in dev.commands)
    assert dev.nonfinite_writes == 0 and dev.clamped_writes == 0


async def test_device_clamp_below_the_amplitude_is_refused_on_connect():
    async with governor(excitation_limit_hz=0.05) as dev:
        async with _writer(dev.port) as w:
            with pytest.raises(ExcitationFault, match=r"clamps the excitation at 0\.05"):
                await w.write(0.05)
        assert [c[1:3] for c in dev.commands] == [(0.0, 0)]  # refused: only a zero was written
        with pytest.raises(ExcitationFault, match="clamps"):  # the task refuses at once
            async with make_task(dev.port):
                pass
        assert all(c[1:3] == (0.0, 0) for c in dev.commands)


async def test_readback_mismatch_is_a_fault():
    # the device clamps at 0.05 Hz and the writer was told not to read its limit: the read-back catches it
    pts = ExcitationPoints(limit=None)
    async with governor(excitation_limit_hz=0.05) as dev, _writer(dev.port, points=pts) as w:
        await w.write(0.0)
        assert (await w.write(0.04)).ok
        with pytest.raises(ReadbackMismatch, match="holds"):
            await w.write(0.08)
    assert dev.clamped_writes == 1


async def test_wrong_word_order_is_caught_before_any_write():
    wrong = replace(RMAP, word_order="little")
    async with governor() as dev, _writer(dev.port, rmap=wrong) as w:
        with pytest.raises(ExcitationFault):
            await w.write(0.05)
    assert all(c[1:3] == (0.0, 0) for c in dev.commands)  # 0.0 reads the same in either word order


async def test_heartbeat_timeout_too_short_for_the_write_period():
    async with governor(heartbeat_timeout_s=0.15) as dev, _writer(dev.port) as w:
        with pytest.raises(ExcitationFault, match="heartbeat timeout"):
            await w.write(0.0)


async def test_no_device_write_returns_not_ok_and_zero_reports_failure():
    async with governor() as dev:
        port = dev.port
    w = _writer(port)
    res = await w.write(0.05)
    assert not res.ok and res.written_hz is None
    assert await w.zero(deadline_s=0.2) is False
    w.close()


async def test_applied_mismatch_ends_the_excitation_with_zero():
    # enable not mapped: the device never applies the offset although it holds it; after 5 fresh reads
    # that disagree with what was written, the task stops with a fault and writes zero
    pts = ExcitationPoints(enable=None)
    async with governor() as dev:
        async with make_task(dev.port, points=pts) as task:
            with pytest.raises(ExcitationFault, match=r"the device applies 0\.0 Hz"):
                await task.run()
        held = await dev.read_points("holding")
    assert held["excitation_offset"] == 0.0
    assert task.stats.applied_mismatch_ticks == 5 and task.stats.exit_zero_ok


async def test_written_samples_are_the_guard_output_and_the_device_applies_them():
    async with governor() as dev:
        samples = []
        lim = {"rate_limit_hz_per_s": 0.5}
        async with make_task(dev.port, on_written=samples.append, limits=lim) as task:
            run = asyncio.create_task(task.run())
            await wait_active(dev)
            await asyncio.sleep(1.0)
            await task.stop_and_wait()
            await run
            await wait_zero(dev)
    desc = task.description
    from fcrlive.excitation.generators import replay

    req = replay(desc, 0, len(samples))
    assert [s.n for s in samples] == list(range(len(samples)))
    assert [s.requested_hz for s in samples] == pytest.approx(list(req))  # r[n] replayable from the record
    written = [s.written_hz for s in samples]
    assert written == [s.value_hz for s in samples]  # the writer wrote the guard's output, nothing else
    # the rate limit (0.5 Hz/s · 0.05 s = 25 mHz per tick) made the guard's output differ from the request
    active = [s for s in samples if s.active]
    assert any(s.value_hz != s.requested_hz for s in active)
    # every non-zero value the device applied is one the writer wrote, as the float32 register holds it
    # (compared exactly: rounding both to 7 decimals once split a value at a rounding boundary)
    applied = {s.applied_hz for s in samples if s.applied_hz}
    assert applied and applied <= {float(np.float32(w)) for w in written}
    assert task.stats.max_abs_written_hz <= 0.1 and task.status()["max_abs_written_hz"] > 0


# ---- configuration -------------------------------------------------------------------------------------

def test_writing_is_off_unless_enabled():
    s = ExcitationSettings()
    assert s.enabled is False
    with pytest.raises(ConfigError, match="disabled"):
        s.make_task(ModbusParams("127.0.0.1", 502, RMAP))


@pytest.mark.parametrize(("limits", "field", "words"), [
    ({"amplitude_hz": 0.2}, "amplitude_hz", "above its safe maximum 0.1"),
    ({"rate_limit_hz_per_s": 10}, "rate_limit_hz_per_s", "above its safe maximum 5.0"),
    ({"band_hz": 0.2}, "band_hz", "FCR-D"),
    ({"budget_s_per_day": 86400}, "budget_s_per_day", "safe maximum"),
    ({"stale_after_s": 30}, "stale_after_s", "safe maximum"),
    ({"amplitud_hz": 0.05}, "amplitud_hz", "unknown excitation guard limit"),
])
def test_limits_above_safe_maxima_are_rejected_with_a_clear_message(limits, field, words):
    with pytest.raises(ValidationError) as ei:
        ExcitationSettings(enabled=True, limits=limits)
    msg = str(ei.value)
    assert field in msg and words in msg and "limits" in msg


def test_generator_settings_are_checked():
    with pytest.raises(ValidationError, match=r"exceeds limits\.amplitude_hz"):
        ExcitationSettings(limits={"amplitude_hz": 0.05}, generator={"amplitude_hz": 0.08})
    with pytest.raises(ValidationError, match="unknown prbs parameter"):
        ExcitationSettings(generator={"kind": "prbs", "params": {"sigma_factor": 3}})
    with pytest.raises(ValidationError, match="order = 40"):
        ExcitationSettings(generator={"kind": "prbs", "params": {"order": 40}})
    with pytest.raises(ValidationError, match="stale_after_s"):
        ExcitationSettings(period_s=0.5, limits={"stale_after_s": 0.4})


def test_settings_from_toml_build_the_chain():
    doc = tomllib.loads("""
        enabled = true
        period_s = 0.05
        [limits]
        amplitude_hz = 0.08
        holdoff_s = 10
        [generator]
        kind = "prbs"
        seed = 7
        params = { order = 9 }
    """)
    s = ExcitationSettings.model_validate(doc)
    task = s.make_task(ModbusParams("127.0.0.1", 502, RMAP))
    assert task.guard.limits.amplitude_hz == 0.08 and task.guard.limits.holdoff_s == 10
    assert task.generator.kind == "prbs" and task.generator.amplitude_hz == 0.08 and task.period_s == 0.05
    assert task.description["seed"] == 7 and task.writer.max_abs_hz == 0.08
    random_seed = ExcitationSettings(enabled=True, limits={"amplitude_hz": 0.1}).make_generator().seed
    assert isinstance(random_seed, int)  # no seed configured: a random one, recorded in the description


def test_points_must_exist_in_the_register_map():
    with pytest.raises(ConfigError, match="no point 'hb'"):
        _writer(502, points=ExcitationPoints(heartbeat="hb"))
    with pytest.raises(ConfigError, match="must be writable"):
        _writer(502, points=ExcitationPoints(offset="excitation_limit"))
    with pytest.raises(ConfigError, match="input register"):
        _writer(502, points=ExcitationPoints(grid_freq="excitation_offset"))
