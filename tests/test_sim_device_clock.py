"""The device clock (device_time over Modbus against wall time) and a recorded log checked against the droop.

The droop check runs two devices with the same seed (common random numbers: the same load and process
noise) at --speed 60, one with a constant excitation offset of +0.08 Hz on its frequency reference, the
other with none, and reads both over Modbus for 12 simulated minutes. Their difference is the unit's
response to the offset alone; in steady state (the droop loop's time constant is Ti/(Kp·ρ) ≈ 114 s here,
so 9-12 min is > 99 % settled) it must equal the droop characteristic
ΔPm = At·rated·(Δoffset − Δf)/(f0·ρ), with Δf the measured frequency difference.
"""

from __future__ import annotations

import asyncio

import numpy as np
from test_sim_device_modbus import MAP, UNIT, connect, make_device, read_block, write_cmd


async def _timed_snapshot(client, loop):
    t0 = loop.time()
    v = await read_block(client)
    return (t0 + loop.time()) / 2, v


async def test_clock_holds_its_speed_factor():
    """device_time advances at speed × wall time within 5 %, over ≥ 2.5 s (accelerated and real time)."""
    loop = asyncio.get_running_loop()
    async with make_device(speed=60.0) as fast, make_device(speed=1.0) as real:
        cf, cr = await connect(fast.port), await connect(real.port)
        await asyncio.sleep(0.3)
        (tf0, vf0), (tr0, vr0) = await _timed_snapshot(cf, loop), await _timed_snapshot(cr, loop)
        await asyncio.sleep(2.5)
        (tf1, vf1), (tr1, vr1) = await _timed_snapshot(cf, loop), await _timed_snapshot(cr, loop)
        cf.close()
        cr.close()
    ratio_fast = (vf1["device_time"] - vf0["device_time"]) / (tf1 - tf0)
    ratio_real = (vr1["device_time"] - vr0["device_time"]) / (tr1 - tr0)
    assert abs(ratio_fast / 60.0 - 1) < 0.05, (ratio_fast, fast.slips)
    assert abs(ratio_real / 1.0 - 1) < 0.05, ratio_real
    assert vf1["device_time"] == vf1["sample_counter"] * fast.dt


async def _record(dev, offset_hz: float, until_s: float, log: list, hb_period_wall: float = 0.25):
    """Enable + heartbeat + offset, then poll the input block until device_time ≥ until_s."""
    client = await connect(dev.port)
    loop = asyncio.get_running_loop()
    hb = 1
    assert not (await write_cmd(client, offset_hz, 1, hb)).isError()
    last_hb = loop.time()
    while True:
        v = await read_block(client)
        log.append(v)
        if v["device_time"] >= until_s:
            break
        if loop.time() - last_hb > hb_period_wall:
            hb += 1
            rr = await client.write_register(MAP.point("heartbeat").address, hb, device_id=UNIT)
            assert not rr.isError()
            last_hb = loop.time()
        await asyncio.sleep(0.005)
    client.close()


async def test_recorded_log_static_power_response_matches_droop():
    speed, offset, t_end, window = 60.0, 0.08, 720.0, (540.0, 720.0)
    logs: dict[str, list] = {"step": [], "base": []}
    async with make_device(speed=speed, seed=11) as a, make_device(speed=speed, seed=11) as b:
        await asyncio.gather(_record(a, offset, t_end, logs["step"]), _record(b, 0.0, t_end, logs["base"]))
        truth = a.truth()
        assert a.heartbeat_timeouts == 0 and b.heartbeat_timeouts == 0

    def window_mean(log, key):
        t = np.array([v["device_time"] for v in log])
        x = np.array([v[key] for v in log], float)
        sel = (t >= window[0]) & (t <= window[1])
        assert sel.sum() > 50, sel.sum()  # enough polls in the window
        return x[sel].mean()

    step, base = logs["step"], logs["base"]
    assert all(v["excitation_applied"] == np.float32(offset) for v in step[3:])
    assert all(v["excitation_applied"] == 0.0 for v in base)
    d_pm = window_mean(step, "mech_power") - window_mean(base, "mech_power")
    d_pe = window_mean(step, "power") - window_mean(base, "power")
    d_f = window_mean(step, "grid_freq") - window_mean(base, "grid_freq")
    d_w = window_mean(step, "speed") - window_mean(base, "speed")
    f0, rho, rated, at = truth["f0"], truth["droop"], truth["rated_mw"], truth["At"]
    expected = at * rated * (offset - f0 * d_w) / (f0 * rho)  # 6 MW for 0.08 Hz at 8 % droop on 300 MW
    assert abs(d_pm / expected - 1) < 0.02, (d_pm, expected)
    assert abs(d_pe / expected - 1) < 0.03, (d_pe, expected)  # electrical: minus Kd·Δω, tiny
    # the grid barely moves for 6 MW in 3.3 GW, and the unit raised its power against the offset's sign
    assert abs(d_f) < 0.005 and d_pm > 0
    # with r = offset/f0 the paired control-error difference is the offset (minus the small Δy)
    d_eps = window_mean(step, "control_error") - window_mean(base, "control_error")
    assert abs(d_eps - (offset / f0 - d_w)) < 2e-5
