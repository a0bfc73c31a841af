"""Every way out of the excitation ends with the DEVICE applying zero within its heartbeat timeout.

Real simulated governor (sim_device.SimGovernor on loopback, paper plant 1, speed 1, heartbeat timeout
1 s), real pymodbus client, no mocks. Each test first waits until the device applies a non-zero
excitation, then takes one way out and polls the device's ``excitation_applied`` input register. Where
fcrlive itself must have written the zero (everything but SIGKILL and a hung link), the test also checks
that the device's heartbeat watchdog did NOT fire (``heartbeat_timeouts == 0``) and that the zero came
well inside the timeout.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import sys
import time

import pytest
from test_excitation_writer_support import (
    HEARTBEAT_TIMEOUT_S,
    MAP_PATH,
    ROOT,
    GridEventSimulator,
    applied,
    governor,
    make_task,
    stays_zero,
    wait_active,
    wait_zero,
)

from fcrlive.excitation.guard import FREQUENCY_OUT_OF_BAND, HOLDOFF, INVALID_MEASUREMENT, STALE_MEASUREMENT
from fcrlive.excitation.task import LINK_DOWN

FAST_S = 0.5
"""fcrlive's own zero must reach the device this fast (half the heartbeat timeout)."""


async def test_normal_stop_ramps_to_zero_and_the_writer_zeroes():
    async with governor() as dev:
        events = []
        async with make_task(dev.port, on_event=events.append) as task:
            run = asyncio.create_task(task.run())
            await wait_active(dev)
            t0 = time.monotonic()
            await task.stop_and_wait()
            took = await wait_zero(dev)
            await run
        assert time.monotonic() - t0 < FAST_S and took < FAST_S
        assert await stays_zero(dev, 0.2)
        assert dev.heartbeat_timeouts == 0
        held = await dev.read_points("holding")
        assert held["excitation_offset"] == 0.0 and held["excitation_enable"] == 0
        st = task.stats
        assert st.exit_reason == "stopped" and st.exit_zero_ok and st.exit_applied_zero
        states = [e.state for e in events]
        assert states[0] == "inhibited" and "active" in states and states[-1] == "stopped"


async def test_context_exit_while_running_elsewhere_zeroes():
    async with governor() as dev:
        async with make_task(dev.port) as task:
            run = asyncio.create_task(task.run())
            await wait_active(dev)
        # __aexit__ stopped run() gracefully and wrote the final zero
        assert run.done() and not run.cancelled() and run.exception() is None
        assert await applied(dev) == 0.0 and dev.heartbeat_timeouts == 0


async def test_exception_in_a_sibling_task_zeroes():
    async with governor() as dev:
        async with make_task(dev.port) as task:

            async def sibling():
                await wait_active(dev)
                raise RuntimeError("boom in the sampler")

            t0 = time.monotonic()
            with pytest.raises(ExceptionGroup) as eg:
                async with asyncio.TaskGroup() as tg:
                    tg.create_task(task.run(), name="excitation")
                    tg.create_task(sibling(), name="sampler")
            t_exc = time.monotonic()
            assert eg.group_contains(RuntimeError, match="boom")
            took = await wait_zero(dev)
        assert t_exc - t0 < 5 and took < FAST_S
        assert dev.heartbeat_timeouts == 0
        assert task.stats.exit_reason == "cancelled" and task.stats.exit_zero_ok


async def test_exception_in_the_task_itself_zeroes():
    async with governor() as dev:
        n = {"active": 0}

        def on_written(s):  # the recorder fails: a value that cannot be stored must not be written
            n["active"] += s.active
            if n["active"] > 5:
                raise OSError("store is gone")

        async with make_task(dev.port, on_written=on_written) as task:
            with pytest.raises(OSError, match="store is gone"):
                await task.run()
            took = await wait_zero(dev)
        assert took < FAST_S and dev.heartbeat_timeouts == 0
        assert task.stats.exit_reason.startswith("OSError") and task.stats.exit_zero_ok
        assert task.last_event is not None and task.last_event.state == "fault"


async def test_repeated_cancellation_does_not_interrupt_the_zero_write():
    async with governor() as dev:
        async with make_task(dev.port) as task:
            run = asyncio.create_task(task.run())
            await wait_active(dev)
            run.cancel()
            for _ in range(5):  # an impatient caller cancelling again and again
                await asyncio.sleep(0)
                run.cancel()
            with pytest.raises(asyncio.CancelledError):
                await run
            assert await applied(dev) == 0.0 or await wait_zero(dev) < FAST_S
        assert dev.heartbeat_timeouts == 0 and task.stats.exit_zero_ok


async def _start_driver(port: int) -> asyncio.subprocess.Process:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    return await asyncio.create_subprocess_exec(
        sys.executable, "-m", "fcrlive.excitation", "--port", str(port), "--register-map", str(MAP_PATH),
        "--i-understand-this-writes", "--amplitude-hz", "0.1",
        "--period-s", "0.05", "--holdoff-s", "1", "--log-level", "ERROR",
        stdout=asyncio.subprocess.PIPE, cwd=str(ROOT), env=env)


async def _events_until(proc, pred, timeout_s: float = 20.0) -> list[dict]:
    seen = []
    end = time.monotonic() + timeout_s
    while True:
        line = await asyncio.wait_for(proc.stdout.readline(), max(0.1, end - time.monotonic()))
        if not line:
            raise AssertionError(f"driver ended early; events {seen}")
        ev = json.loads(line)
        seen.append(ev)
        if pred(ev):
            return seen


async def test_sigterm_zeroes_before_the_process_exits():
    async with governor() as dev:
        proc = await _start_driver(dev.port)
        try:
            await _events_until(proc, lambda e: e.get("state") == "active")
            await wait_active(dev)
            t0 = time.monotonic()
            proc.send_signal(signal.SIGTERM)
            took = await wait_zero(dev)
            rest = await _events_until(proc, lambda e: e["event"] == "exit")
            rc = await asyncio.wait_for(proc.wait(), 10)
        finally:
            if proc.returncode is None:
                proc.kill()
                await proc.wait()
        assert took < FAST_S, f"SIGTERM → device zero took {took:.3f} s"
        assert dev.heartbeat_timeouts == 0  # fcrlive wrote the zero, not the watchdog
        assert rc == 0
        exit_ev = rest[-1]
        assert exit_ev["zero_written"] is True and exit_ev["device_applies_zero"] is True
        assert exit_ev["reason"] == "stopped"
        assert any(e.get("signal") == "SIGTERM" for e in rest)
        print(f"SIGTERM → device applies 0 after {took * 1e3:.0f} ms; exit {time.monotonic() - t0:.2f} s")


async def test_sigkill_is_covered_by_the_device_heartbeat_watchdog():
    async with governor() as dev:
        proc = await _start_driver(dev.port)
        try:
            await _events_until(proc, lambda e: e.get("state") == "active")
            await wait_active(dev)
            held = await applied(dev)
            proc.kill()  # SIGKILL: no code of ours runs
            took = await wait_zero(dev, timeout_s=HEARTBEAT_TIMEOUT_S + 0.1)
        finally:
            if proc.returncode is None:
                proc.kill()
            await proc.wait()
        assert held != 0.0
        assert dev.heartbeat_timeouts == 1  # the watchdog did it
        # the heartbeat was last changed ≤ one write period before the kill
        assert took <= HEARTBEAT_TIMEOUT_S + 0.1
        print(f"SIGKILL → device applies 0 after {took * 1e3:.0f} ms (timeout {HEARTBEAT_TIMEOUT_S} s)")


async def test_dropped_link_first_write_on_reconnect_is_zero():
    async with governor() as dev:
        samples = []
        async with make_task(dev.port, on_written=samples.append) as task:
            run = asyncio.create_task(task.run())
            await wait_active(dev)
            await asyncio.sleep(0.2)
            before = dev.commands[-1]
            t_drop = time.monotonic()
            assert dev.faults.drop_connections() >= 1
            took = await wait_zero(dev)
            after = dev.commands_after(t_drop)
            await wait_active(dev, timeout_s=5)  # resumes after the hold-off
            t_active = time.monotonic()
            await task.stop_and_wait()
            await run
        assert before[1] != 0.0 and before[2] == 1
        first = after[0]
        assert first[1] == 0.0 and first[2] == 0, f"first command after reconnect {first}"
        assert took < FAST_S and dev.heartbeat_timeouts == 0
        # the guard saw the link problem: zero and a new hold-off before resuming
        assert t_active - t_drop >= 1.0
        assert task.writer.stats.connects == 2 and task.writer.stats.forced_zero_writes >= 1
        assert any(LINK_DOWN in s.reasons for s in samples)
        post = [s for s in samples if s.t_mono > t_drop]
        assert any(HOLDOFF in s.reasons for s in post)


async def test_device_restart_first_write_is_zero():
    async with governor() as dev:
        async with make_task(dev.port) as task:
            run = asyncio.create_task(task.run())
            await wait_active(dev)
            t_restart = time.monotonic()
            await dev.faults.restart(0.3)  # setpoints reset by the device itself; port refused 0.3 s
            await wait_active(dev, timeout_s=5)
            await task.stop_and_wait()
            await run
        after = dev.commands_after(t_restart)
        assert after and after[0][1] == 0.0 and after[0][2] == 0
        assert task.writer.stats.connects >= 2


async def test_hung_link_device_watchdog_then_zero_first():
    async with governor() as dev:
        async with make_task(dev.port) as task:
            run = asyncio.create_task(task.run())
            await wait_active(dev)
            dev.faults.set(hang=True)  # requests accepted by TCP, never answered: nothing of ours lands
            t_hang = time.monotonic()
            took = await wait_zero(dev, timeout_s=HEARTBEAT_TIMEOUT_S + 0.1)
            dev.faults.clear()
            t_clear = time.monotonic()
            await wait_active(dev, timeout_s=8)
            await task.stop_and_wait()
            await run
        assert took <= HEARTBEAT_TIMEOUT_S + 0.1 and dev.heartbeat_timeouts == 1
        assert not dev.commands_after(t_hang + 0.01) or dev.commands_after(t_hang + 0.01)[0][0] >= t_clear
        first = dev.commands_after(t_clear)[0]
        assert first[1] == 0.0 and first[2] == 0


async def test_out_of_band_grid_frequency_zeroes_at_once_and_resumes_after_holdoff():
    sim = GridEventSimulator()
    async with governor(simulator=sim) as dev:
        samples = []
        async with make_task(dev.port, on_written=samples.append) as task:
            run = asyncio.create_task(task.run())
            await wait_active(dev)
            sim.event_hz = -0.15  # the grid drops to 49.85 Hz: outside the FCR-N band (FCR-D territory)
            t_event = time.monotonic()
            took = await wait_zero(dev)
            assert await stays_zero(dev, 0.5)
            sim.event_hz = 0.0
            t_back = time.monotonic()
            await wait_active(dev, timeout_s=5)
            t_resumed = time.monotonic()
            await task.stop_and_wait()
            await run
        assert took < FAST_S and dev.heartbeat_timeouts == 0
        assert t_resumed - t_back >= 1.0  # hold-off after the frequency came back
        during = [s for s in samples if t_event + took < s.t_mono < t_back]
        assert during and all(s.value_hz == 0.0 and FREQUENCY_OUT_OF_BAND in s.reasons for s in during)
        c = task.guard.counters
        assert c.trips_by_reason[FREQUENCY_OUT_OF_BAND] == 1
        assert c.time_by_reason_s[FREQUENCY_OUT_OF_BAND] > 0.4


@pytest.mark.parametrize(("fault", "reason"), [("nan", INVALID_MEASUREMENT), ("freeze", STALE_MEASUREMENT)])
async def test_bad_measurements_zero(fault, reason):
    async with governor() as dev:
        samples = []
        # stale_after_s 0.5 s: a frozen device must be noticed well inside the 1 s heartbeat timeout
        async with make_task(dev.port, on_written=samples.append, limits={"stale_after_s": 0.5}) as task:
            run = asyncio.create_task(task.run())
            await wait_active(dev)
            dev.faults.set(**{fault: True})
            t0 = time.monotonic()
            if fault == "freeze":  # the published block (applied too) is frozen: look at the setpoint
                while (await dev.read_points("holding"))["excitation_offset"] != 0.0:
                    assert time.monotonic() - t0 < HEARTBEAT_TIMEOUT_S
                    await asyncio.sleep(0.005)
                took = time.monotonic() - t0
            else:
                took = await wait_zero(dev)
            await asyncio.sleep(0.2)
            dev.faults.clear()
            await task.stop_and_wait()
            await run
        assert dev.heartbeat_timeouts == 0
        # NaN: the next tick; frozen: after stale_after_s (0.5 s) without a new sample
        assert took < (FAST_S if fault == "nan" else 0.5 + FAST_S)
        assert any(reason in s.reasons and s.value_hz == 0.0 for s in samples)
