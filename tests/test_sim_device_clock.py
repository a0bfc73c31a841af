"""The device clock (device_time over Modbus against wall time) and a recorded log checked against the droop.

The droop check runs two device processes with the same seed (common random numbers: the same load
and process noise) at --speed 60, one with a constant excitation offset of +0.08 Hz on its frequency
reference, the other with none, and reads both over Modbus. Their difference is the unit's response to
the offset alone; in steady state (the droop loop's time constant is Ti/(Kp·ρ) ≈ 114 s here, so 9-12
simulated minutes after the step it is > 99 % settled) it must equal the droop characteristic
ΔPm = At·rated·(Δoffset − Δf)/(f0·ρ), with Δf the measured frequency difference.
"""

from __future__ import annotations

import asyncio
import math
import os
import sys

import numpy as np
from test_sim_device_modbus import MAP, UNIT, connect, make_device, read_block, write_cmd

from fcrlive.plant.params import preset


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


async def _start_cli(*args: str):
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sim_device", "--port", "0", "--log-level", "WARNING", *args,
        stdout=asyncio.subprocess.PIPE, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"},
    )  # fmt: skip
    line = (await asyncio.wait_for(proc.stdout.readline(), 30)).decode()
    assert line.startswith("listening on "), line
    return proc, int(line.rsplit(":", 1)[1])


async def _record(port: int, offset_hz: float, state: dict, log: list, hb_period_wall: float = 0.25):
    """Enable + heartbeat + offset, then poll the input block until device_time ≥ state["until"].

    The stepped device sets ``state["t_on"]`` (device time at which the offset was first applied) and
    ``state["until"]``; the base device records the same absolute stretch (same noise, same samples).
    """
    client = await connect(port)
    loop = asyncio.get_running_loop()
    hb = 1
    assert not (await write_cmd(client, offset_hz, 1, hb)).isError()
    last_hb = loop.time()
    while True:
        v = await read_block(client)
        log.append(v)
        if offset_hz and "t_on" not in state and v["excitation_applied"] != 0.0:
            state["t_on"] = v["device_time"]
            state["until"] = v["device_time"] + state["settle"] + state["span"]
        if v["device_time"] >= state.get("until", math.inf):
            break
        if loop.time() - last_hb > hb_period_wall:
            hb += 1
            rr = await client.write_register(MAP.point("heartbeat").address, hb, device_id=UNIT)
            assert not rr.isError()
            last_hb = loop.time()
        await asyncio.sleep(0.005)
    client.close()


async def test_recorded_log_static_power_response_matches_droop():
    """Two `python -m sim_device --speed 60 --seed 11` processes (one core each), read over Modbus."""
    offset = 0.08
    state = {"settle": 540.0, "span": 180.0}  # compare the 9th to 12th simulated minute after the step
    logs: dict[str, list] = {"step": [], "base": []}
    procs = await asyncio.gather(*(_start_cli("--speed", "60", "--seed", "11") for _ in range(2)))
    try:
        await asyncio.wait_for(
            asyncio.gather(
                _record(procs[0][1], offset, state, logs["step"]),
                _record(procs[1][1], 0.0, state, logs["base"]),
            ),
            timeout=120,  # ~13 s at full speed; generous for a loaded machine (the check uses device time)
        )
    finally:
        for proc, _ in procs:
            proc.terminate()
            await proc.wait()
    window = (state["t_on"] + state["settle"], state["until"])
    plant = preset("paper-plant1")
    f0, rho, rated, at = plant.grid.f0, plant.unit.governor.droop, plant.unit.rated_mw, plant.unit.turbine.At

    def window_mean(log, key):
        t = np.array([v["device_time"] for v in log])
        x = np.array([v[key] for v in log], float)
        sel = (t >= window[0]) & (t <= window[1])
        assert sel.sum() >= 20, sel.sum()  # enough polls in the window (~300 on an idle machine)
        return x[sel].mean()

    def window_se(log, key):
        t = np.array([v["device_time"] for v in log])
        x = np.array([v[key] for v in log], float)[(t >= window[0]) & (t <= window[1])]
        return x.std(ddof=1) / math.sqrt(len(x))

    step, base = logs["step"], logs["base"]
    assert all(
        v["excitation_applied"] == np.float32(offset) for v in step if v["device_time"] >= state["t_on"]
    )
    assert all(v["excitation_applied"] == 0.0 for v in base)
    d_pm = window_mean(step, "mech_power") - window_mean(base, "mech_power")
    d_pe = window_mean(step, "power") - window_mean(base, "power")
    d_f = window_mean(step, "grid_freq") - window_mean(base, "grid_freq")
    d_w = window_mean(step, "speed") - window_mean(base, "speed")
    expected = at * rated * (offset - f0 * d_w) / (f0 * rho)  # 6 MW for 0.08 Hz at 8 % droop on 300 MW
    print(f"paired step {offset} Hz: dPm {d_pm:.3f} MW, dPe {d_pe:.3f} MW, droop predicts {expected:.3f} MW")
    assert abs(d_pm / expected - 1) < 0.02, (d_pm, expected)
    # electrical power: the same minus Kd·Δω (tiny), but it carries the 1.8 Hz inter-machine swing and
    # meter noise that two devices polled at different instants do not share: a looser bound
    assert abs(d_pe / expected - 1) < 0.1, (d_pe, expected)
    # the grid barely moves for 6 MW in 3.3 GW, and the unit raised its power against the offset's sign
    assert abs(d_f) < 0.005 and d_pm > 0
    # with r = offset/f0 the paired control-error difference is the offset (minus the small Δy)
    # (ε carries the white process noise, not shared by polls at different instants: 4 standard errors)
    d_eps = window_mean(step, "control_error") - window_mean(base, "control_error")
    se = math.hypot(window_se(step, "control_error"), window_se(base, "control_error"))
    assert abs(d_eps - (offset / f0 - d_w)) < 4 * se + 1e-5, (d_eps, offset / f0 - d_w, se)
