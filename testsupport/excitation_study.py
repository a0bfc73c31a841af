"""Accelerated closed-loop runs against the simulated governor, with and without the excitation written
through the real chain (generator → guard → Modbus writer → device), and their identification.

Used by ``benchmarks/bench_excitation.py`` (the 1-hour run) and the short test. The simulated governor
runs ``speed`` times faster than the wall clock; the guard runs on SIMULATED time (its clock is
``speed·time.monotonic()``), so hold-off and budget mean simulated seconds, while the device's heartbeat
watchdog stays on wall time (it protects the link). The writer ticks every ``period_wall_s`` of wall
time, so r[n] is held for ``speed·period_wall_s`` simulated seconds.

The data for identification is what the device applied, sample by sample (``SimGovernor.on_sample``:
the governor's y, r, power, gate demand and position at the 50 Hz controller rate); r is checked against
the writer's record (every non-zero value the device applied is one the writer wrote), so the r used by
the identification is the guard's output.
"""

from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np

from fcrlive.excitation.task import ExcitationEvent, ExcitationTask, WrittenSample

log = logging.getLogger("testsupport.excitation_study")

KD = 0.1
"""Load damping of paper plant 1 (for droop = 1/(1/G_1(0) − Kd))."""


@dataclass
class RunResult:
    """One accelerated run."""

    speed: float
    excitation: bool
    duration_s: float
    """Simulated seconds recorded."""
    wall_s: float
    t: np.ndarray
    y: np.ndarray
    r: np.ndarray
    """Applied excitation [pu of f0], sample by sample."""
    pe_mw: np.ndarray
    c: np.ndarray
    a: np.ndarray
    f0: float
    rated_mw: float
    truth: dict[str, Any]
    written: list[WrittenSample] = field(default_factory=list)
    events: list[ExcitationEvent] = field(default_factory=list)
    status: dict[str, Any] = field(default_factory=dict)
    """ExcitationTask.status() at the end (maxima, time per reason, writer counters)."""
    task_stats: dict[str, Any] = field(default_factory=dict)
    device: dict[str, Any] = field(default_factory=dict)
    r_consistent: bool | None = None
    """Every non-zero applied value is one the writer wrote (as float32)."""

    def window(self, t0_s: float, t1_s: float) -> RunResult:
        """The part t0 ≤ t < t1 [simulated s] (same run)."""
        m = (self.t >= t0_s) & (self.t < t1_s)
        out = RunResult(**{**self.__dict__})
        for k in ("t", "y", "r", "pe_mw", "c", "a"):
            setattr(out, k, getattr(self, k)[m])
        out.t = out.t - out.t[0]
        out.duration_s = float(np.count_nonzero(m) * (self.t[1] - self.t[0]))
        return out

    def signals(self):
        """The paper's PlantSignals at the controller rate (via a TSO log, as from a file)."""
        from fcrlive.tso.signals import log_from_sim, plant_signals

        res = SimpleNamespace(t=self.t, y=self.y, r=self.r, pe_mw=self.pe_mw, c=self.c, a=self.a, f0=self.f0)
        return plant_signals(log_from_sim(res), rated_mw=self.rated_mw, f0=self.f0)


async def accelerated_run(duration_s: float, *, speed: float = 60.0, excitation: bool = True, seed: int = 0,
                          period_wall_s: float = 0.02, exc_seed: int = 1, limits: dict | None = None,
                          heartbeat_timeout_s: float = 2.0) -> RunResult:
    """Run the simulated governor for ``duration_s`` simulated seconds at ``speed``; with ``excitation``
    the real ExcitationTask writes white noise (0.1 Hz, the paper's) through Modbus."""
    from fcrlive.excitation.generators import WhiteNoiseGenerator
    from fcrlive.excitation.guard import GuardLimits, SafetyGuard
    from fcrlive.excitation.writer import ExcitationWriter, _f32
    from fcrlive.modbus.client import ModbusParams
    from fcrlive.modbus.mapfile import load_register_map
    from fcrlive.plant.params import preset
    from sim_device import SimGovernor
    from sim_device.registers import DEFAULT_MAP_PATH

    plant = preset("paper-plant1")
    n_want = round(duration_s / plant.unit.governor.Tc)
    rec: list[Any] = []
    done = asyncio.Event()

    def on_sample(s) -> None:
        if not done.is_set():
            rec.append(s)
            if len(rec) >= n_want:
                done.set()

    dev = SimGovernor(plant, speed=speed, seed=seed, heartbeat_timeout_s=heartbeat_timeout_s,
                      on_sample=on_sample)
    written: list[WrittenSample] = []
    events: list[ExcitationEvent] = []
    task: ExcitationTask | None = None
    t_wall0 = time.monotonic()
    async with dev:
        if excitation:
            lim = {"holdoff_s": 30.0, "stale_after_s": 5.0, **(limits or {})}
            guard = SafetyGuard(GuardLimits(**lim))
            amp = guard.limits.amplitude_hz
            gen = WhiteNoiseGenerator(amplitude_hz=amp, sample_time_s=period_wall_s * speed, seed=exc_seed)
            rmap = load_register_map(DEFAULT_MAP_PATH)
            params = ModbusParams("127.0.0.1", dev.port, rmap, timeout_s=0.2, backoff_max_s=1.0)
            writer = ExcitationWriter(params, max_abs_hz=amp, write_period_s=period_wall_s)
            task = ExcitationTask(writer, guard, gen, period_s=period_wall_s,
                                  clock=lambda: speed * time.monotonic(), on_written=written.append,
                                  on_event=events.append)
            async with task:
                run = asyncio.create_task(task.run())
                waiter = asyncio.create_task(done.wait())
                finished, _ = await asyncio.wait({run, waiter}, return_when=asyncio.FIRST_COMPLETED)
                if run in finished:  # the excitation ended by itself: a fault; record it and go on
                    log.error("excitation ended early: %r", run.exception())
                    await done.wait()
                else:
                    await task.stop_and_wait()
                    await run
        else:
            await done.wait()
        device = {"heartbeat_timeouts": dev.heartbeat_timeouts, "clamped_writes": dev.clamped_writes,
                  "nonfinite_writes": dev.nonfinite_writes, "slips": dev.slips,
                  "excitation_limit_hz": dev.excitation_limit_hz}
        truth = dev.truth(analytic=True)
    wall = time.monotonic() - t_wall0
    rec = rec[:n_want]
    arr = lambda k: np.array([getattr(s, k) for s in rec], dtype=float)  # noqa: E731
    res = RunResult(speed=speed, excitation=excitation, duration_s=len(rec) * dev.dt, wall_s=wall,
                    t=arr("t"), y=arr("y"), r=arr("r"), pe_mw=arr("pe_mw"), c=arr("c"), a=arr("a"),
                    f0=dev.f0, rated_mw=dev.rated_mw, truth=truth, written=written, events=events,
                    device=device)
    if task is not None:
        res.status = task.status()
        res.task_stats = dict(task.stats.__dict__)
        wrote = {_f32(w.written_hz) for w in written if w.written_hz}
        applied = {_f32(float(x)) for x in np.unique(res.r * res.f0) if x != 0.0}
        res.r_consistent = all(any(abs(a - w) <= 1e-6 for w in wrote) for a in applied)
    return res


def replay(r_pu: np.ndarray, *, seed: int = 0, snr_db: float = 12.0) -> dict[str, np.ndarray]:
    """The plant's samples for the excitation ``r_pu`` [pu of f0], one value per controller sample, from
    the same simulator and noise streams the simulated governor steps (``RealtimeSimulator``, same seed).

    What a chain run recorded must equal this for its own r: then every difference between two chain runs
    is the excitation's timing (the writer ticks on the loaded wall clock), not lost or altered samples.
    """
    from fcrlive.plant.params import preset
    from fcrlive.sim.realtime import RealtimeSimulator

    sim = RealtimeSimulator(preset("paper-plant1"), seed=seed, snr_db=snr_db)
    out = {k: np.empty(len(r_pu)) for k in ("t", "y", "r", "pe_mw", "c", "a")}
    for i, r in enumerate(r_pu):
        s = sim.step(float(r))
        for k in out:
            out[k][i] = getattr(s, k)
    return out


def scheduled_run(duration_s: float, *, seed: int = 0, exc_seed: int = 1, holdoff_s: float = 30.0,
                  hold_s: float = 1.2) -> RunResult:
    """The excited run as the chain would make it on an idle machine, without the wall clock: the same
    generator (0.1 Hz truncated white noise, ``exc_seed``), each value held ``hold_s`` simulated seconds
    (speed 60 × the writer's 20 ms), zero during the guard's hold-off. Deterministic: for the accuracy of
    the estimates, which must not depend on how loaded the machine running the test is."""
    from fcrlive.excitation.generators import WhiteNoiseGenerator
    from fcrlive.plant.params import preset

    plant = preset("paper-plant1")
    dt = plant.unit.governor.Tc
    n = round(duration_s / dt)
    hold = round(hold_s / dt)
    n0 = round(holdoff_s / dt)
    gen = WhiteNoiseGenerator(amplitude_hz=0.1, sample_time_s=hold_s, seed=exc_seed)
    steps = gen.next_block(-(-(n - n0) // hold))
    r = np.zeros(n)
    r[n0:] = np.repeat(steps, hold)[: n - n0] / plant.grid.f0
    rec = replay(r, seed=seed)
    from fcrlive.plant import transfer

    tf = transfer.analytic(plant)
    truth = {"g1_static": transfer.static_gain(tf.G_1), "max_S": transfer.peak(tf.S)[0],
             "max_G1": transfer.peak(tf.G_1)[0]}
    return RunResult(speed=0.0, excitation=True, duration_s=n * dt, wall_s=0.0, f0=plant.grid.f0,
                     rated_mw=plant.unit.rated_mw, truth=truth, **rec)


def truth_figures(truth: dict[str, Any]) -> dict[str, float]:
    """droop (with Kd), max|S|, max|G_1| of the analytic plant."""
    return {"droop": 1.0 / (1.0 / truth["g1_static"] - KD), "max_s": truth["max_S"],
            "max_g1": truth["max_G1"]}


def identify(run: RunResult, method: str = "auto"):
    """identify_signals on the run's data (Kd of the plant, 50 Hz); the IdentifyReport."""
    from fcrlive.analysis.identify import identify_signals

    return identify_signals(run.signals(), rated_mw=run.rated_mw, f0=run.f0, kd=KD, method=method)


def compare(report, truth: dict[str, float]) -> dict[str, Any]:
    """Errors against the truth: droop in percentage points, peaks in %; CI widths."""
    out: dict[str, Any] = {"method": report.method}
    d = report.droop
    if d is not None and d.value is not None:
        out["droop"] = d.value
        out["droop_err_pp"] = 100.0 * (d.value - truth["droop"])
        lo, hi = d.ci95
        out["droop_ci_width_pp"] = 100.0 * (hi - lo) if lo is not None and hi is not None else None
    else:  # withheld: the identification says why (e.g. its interval is wider than the value)
        out["droop_reason"] = getattr(d, "reason", None) or "droop not given"
    for key, name in (("max_abs_s", "max_s"), ("max_abs_g1", "max_g1")):
        v = getattr(report, key)
        if v is not None and v.value is not None:
            out[name] = v.value
            out[f"{name}_err_pct"] = 100.0 * (v.value / truth[name] - 1.0)
    return out
