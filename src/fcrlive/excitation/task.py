"""The excitation task: generator → safety guard → writer, once per tick, with zero on every way out.

``ExcitationTask`` runs the loop that the issue asks for and nothing else: at every tick (absolute
deadlines, ``period_s`` apart; missed ticks are skipped and counted)

1. read the device's grid frequency, status word, sample counter and applied excitation (one FC4);
2. take the generator's next r[n] (the generator advances every tick, inhibited or not, so sample n of
   the stored description is the request of tick n);
3. pass both through :meth:`SafetyGuard.step`: a failed read or write at this or the previous tick, or
   a new connection (the writer's first write on it is a forced zero), is given to the guard as "status
   unknown", a hard interlock, so every link problem zeroes at once and restarts the hold-off; an
   unchanged sample counter means the frequency is not new (a frozen device becomes
   ``stale_measurement``);
4. write ``decision.value_hz`` (and only that) with :class:`ExcitationWriter` (zero first after every
   (re)connect, FC16, read-back, heartbeat);
5. record a :class:`WrittenSample` (``on_written``) and, when the state changes (active / inhibited and
   why / link), an :class:`ExcitationEvent` (``on_event``, and the log);
6. check that the device applies what was written (``applied`` point): ``verify_applied_ticks``
   consecutive fresh disagreements raise :class:`ExcitationFault`.

Ways out, each ending with a verified zero write (or, if the link is down, a CRITICAL log line and the
device's heartbeat watchdog):

- :meth:`stop` (or leaving the ``async with`` normally): the guard ramps to zero at its rate limit, then
  a final zero with enable 0;
- cancellation (SIGTERM through the daemon's shutdown, a failing sibling task in a TaskGroup), or an
  exception inside the loop (a read-back mismatch, a failing ``on_written``): zero at once, then the
  exception propagates; repeated cancellation does not interrupt the zero write;
- SIGKILL / power loss: the heartbeat stops changing and the device resets the offset itself.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections import deque
from collections.abc import Callable, Coroutine
from dataclasses import asdict, dataclass, field
from typing import Any

from fcrlive.excitation.generators import ExcitationGenerator
from fcrlive.excitation.guard import GuardDecision, SafetyGuard
from fcrlive.excitation.writer import ExcitationFault, ExcitationWriter, Measurement, WriteResult, matches_any

log = logging.getLogger("fcrlive.excitation")

LINK_DOWN = "link_down"
"""Task-level reason (next to the guard's reasons) while the Modbus link fails."""


@dataclass(frozen=True)
class WrittenSample:
    """One tick: what was asked, what the guard allowed, what the device holds and applies.

    ``written_hz`` is the r[n] to store with the samples and to use for identification (None when the
    write failed and the device's value is unknown; the device's heartbeat watchdog then bounds it).
    """

    n: int
    """Tick index = generator sample index of ``requested_hz``."""
    t_wall: float
    """UNIX time of the write [s]."""
    t_mono: float
    """time.monotonic() of the write [s]."""
    t_guard: float
    """The guard's clock at this tick [s] (``clock``; simulated seconds in accelerated runs)."""
    requested_hz: float
    value_hz: float
    """The guard's output."""
    written_hz: float | None
    applied_hz: float | None
    """The device's applied excitation read at the start of this tick (of an earlier write) [Hz]."""
    grid_freq_hz: float | None
    active: bool
    inhibited: bool
    reasons: tuple[str, ...]
    link_ok: bool
    forced_zero: bool


@dataclass(frozen=True)
class ExcitationEvent:
    """A change of state: published (retained) and logged."""

    t_wall: float
    state: str
    """"active", "inhibited", "ramping" (stop or budget ramp), "stopped", "link_down", "fault"."""
    reasons: tuple[str, ...]
    detail: str = ""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class TaskStats:
    """Counters of the task since start (the guard keeps the time per reason: ``guard.counters``)."""

    ticks: int = 0
    missed_ticks: int = 0
    link_down_ticks: int = 0
    link_down_s: float = 0.0
    max_abs_requested_hz: float = 0.0
    max_abs_value_hz: float = 0.0
    max_abs_written_hz: float = 0.0
    max_abs_applied_hz: float = 0.0
    applied_mismatch_ticks: int = 0
    events: int = 0
    exit_reason: str = ""
    exit_zero_ok: bool | None = None
    exit_applied_zero: bool | None = None
    exit_reasons: list[str] = field(default_factory=list)


def _state(d: GuardDecision, link_ok: bool) -> str:
    if not link_ok:
        return "link_down"
    if d.active:
        return "active"
    if "stopped" in d.reasons:
        return "stopped"
    if d.inhibited:
        return "inhibited"
    return "ramping"


async def run_to_completion(coro: Coroutine[Any, Any, Any]) -> Any:
    """Await ``coro`` even if this task is cancelled meanwhile (it must be bounded in time itself);
    re-raise the cancellation afterwards."""
    inner = asyncio.ensure_future(coro)
    cancelled = False
    while not inner.done():
        try:
            await asyncio.shield(inner)
        except asyncio.CancelledError:
            if inner.done():
                break
            cancelled = True
    if cancelled:
        raise asyncio.CancelledError
    return inner.result()


class ExcitationTask:
    """Async context manager around the excitation loop (module docstring).

    ``async with ExcitationTask(writer, guard, generator) as task: await task.run()`` — ``__aenter__``
    connects and writes a verified zero before anything else (raises ExcitationFault if the device is
    unsafe to drive, e.g. its clamp is below the guard's amplitude); ``run()`` loops until :meth:`stop`
    finished the ramp (returns) or until it fails or is cancelled (zero, then re-raise); ``__aexit__``
    stops gracefully if ``run()`` is still going elsewhere, writes a final zero and closes the link.

    ``period_s``: the tick [s] (default: the generator's sample time). ``clock``: the guard's monotonic
    clock [s] (default ``time.monotonic``; accelerated simulations pass ``lambda: speed·monotonic()`` so
    that hold-off and budget are in simulated seconds). ``on_written(sample)`` is called at every tick
    and ``on_event(event)`` at every change of state; an exception in either ends the excitation (a
    value that cannot be recorded must not be written).
    """

    def __init__(self, writer: ExcitationWriter, guard: SafetyGuard, generator: ExcitationGenerator, *,
                 period_s: float | None = None, clock: Callable[[], float] = time.monotonic,
                 on_written: Callable[[WrittenSample], None] | None = None,
                 on_event: Callable[[ExcitationEvent], None] | None = None,
                 verify_applied_ticks: int = 5, exit_verify_s: float = 1.0, zero_deadline_s: float = 1.0):
        if generator.amplitude_hz > guard.limits.amplitude_hz:
            raise ExcitationFault(f"generator amplitude {generator.amplitude_hz!r} Hz exceeds the guard's "
                                  f"{guard.limits.amplitude_hz!r} Hz")
        if writer.max_abs_hz < guard.limits.amplitude_hz:
            raise ExcitationFault("the writer's bound is below the guard's amplitude")
        self.writer = writer
        self.guard = guard
        self.generator = generator
        self.period_s = float(period_s if period_s is not None else generator.sample_time_s)
        if not (math.isfinite(self.period_s) and 0.005 <= self.period_s <= guard.limits.stale_after_s):
            raise ExcitationFault(f"period_s = {self.period_s!r} s must be within [0.005, stale_after_s = "
                                  f"{guard.limits.stale_after_s!r}] s")
        self.clock = clock
        self.on_written = on_written
        self.on_event = on_event
        self.verify_applied_ticks = int(verify_applied_ticks)
        self.exit_verify_s = float(exit_verify_s)
        self.zero_deadline_s = float(zero_deadline_s)
        self.stats = TaskStats()
        self.last: WrittenSample | None = None
        self.last_event: ExcitationEvent | None = None
        self._running = False
        self._done = asyncio.Event()
        self._entered = False
        self._written_recent: deque[float] = deque(maxlen=max(2, self.verify_applied_ticks + 2))
        self._armed_ticks = 0
        self._mismatch_streak = 0
        self._link_ok_prev = True
        self._last_counter: int | None = None

    @property
    def description(self) -> dict[str, Any]:
        """The generator's description (store it with the samples: r[n] = replay(description, n))."""
        return self.generator.description.to_dict()

    @property
    def stop_timeout_s(self) -> float:
        """How long a graceful stop may take: the guard's ramp plus a few ticks and the zero write [s]."""
        return self.guard.limits.stop_time_bound_s + 4 * self.period_s + self.zero_deadline_s + 1.0

    # ---- lifecycle ----------------------------------------------------------------------------------------

    async def __aenter__(self) -> ExcitationTask:
        self._entered = True
        try:
            ok = await self.writer.zero(deadline_s=max(self.zero_deadline_s, 2.0))
        except ExcitationFault:
            self.writer.close()
            raise
        if not ok:
            log.warning("excitation: the device did not take a zero at start (%s); will keep trying",
                        self.writer.last_error)
        else:
            log.info("excitation: zero written at start (device clamp %s Hz, heartbeat timeout %s s)",
                     self.writer.device_limit_hz, self.writer.device_heartbeat_timeout_s)
        return self

    async def __aexit__(self, exc_type, exc, tb) -> None:
        try:
            if self._running:  # run() is going in another task: stop it gracefully, bounded
                self.stop()
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._done.wait(), self.stop_timeout_s)
            if self.stats.exit_applied_zero and not self._running:
                # run() ended with a verified zero: one more zero write, quietly (belt and braces)
                await run_to_completion(self.writer.zero(deadline_s=self.zero_deadline_s))
            else:
                if not self.stats.exit_reason:
                    self.stats.exit_reason = ("context exit" if exc_type is None
                                              else f"context exit: {exc_type.__name__}")
                await run_to_completion(self._final_zero())
        finally:
            self.writer.close()

    def stop(self) -> None:
        """Ramp to zero at the guard's rate limit; ``run()`` returns once zero is written."""
        self.guard.stop()

    async def stop_and_wait(self) -> None:
        """:meth:`stop` and wait (at most :attr:`stop_timeout_s`) until ``run()`` has finished."""
        self.stop()
        if self._running:
            await asyncio.wait_for(self._done.wait(), self.stop_timeout_s)

    # ---- the loop -----------------------------------------------------------------------------------------

    async def run(self) -> None:
        """The loop (module docstring). Returns after a graceful :meth:`stop`; re-raises anything else."""
        if self._running:
            raise RuntimeError("ExcitationTask.run() is already running")
        self._running = True
        self._done.clear()
        loop = asyncio.get_running_loop()
        anchor = loop.time()
        k = 0
        reason = "stopped"
        try:
            while True:
                await self._tick()
                if self.guard.stopped:
                    break
                k += 1
                now = loop.time()
                due = anchor + k * self.period_s
                if now > due + self.period_s:  # overran: skip the missed ticks, flag them
                    missed = int((now - due) / self.period_s)
                    self.stats.missed_ticks += missed
                    k += missed
                    due = anchor + k * self.period_s
                await asyncio.sleep(max(0.0, due - loop.time()))
        except asyncio.CancelledError:
            reason = "cancelled"
            raise
        except BaseException as exc:
            reason = f"{type(exc).__name__}: {exc}"
            self._emit("fault", (), detail=reason)
            raise
        finally:
            self.stats.exit_reason = reason
            try:
                await run_to_completion(self._final_zero())
            finally:
                self._running = False
                self._done.set()

    async def _tick(self) -> None:
        m = await self.writer.read_measurements()
        now = self.clock()
        # A failed read now or a failed write at the previous tick, or a link that is not armed (a new
        # connection: this tick's write will be a forced zero) is "status unknown" for the guard: a hard
        # interlock, so the guard's value is 0.0 like the device's and the hold-off starts again (no jump
        # from the forced zero back to r, no rate-limit violation seen by the device).
        link_ok = m is not None and self._link_ok_prev and self.writer.armed
        grid: float | None = None
        if m is not None and (m.counter is None or m.counter != self._last_counter):
            grid = m.grid_freq_hz
            self._last_counter = m.counter
        status = m.status_word if link_ok and m is not None else None
        fcrd = m.fcrd_active if m is not None else (False if self.writer.points.fcrd is None else None)
        req = float(self.generator.next_block(1)[0])
        n = self.generator.index - 1
        d = self.guard.step(now, req, grid, status, fcrd, measured_at_s=now if grid is not None else None)
        res: WriteResult = await self.writer.write(d.value_hz)
        self._link_ok_prev = res.ok
        link_ok = link_ok and res.ok
        self._account(m, d, res, link_ok, fresh=grid is not None)
        sample = WrittenSample(
            n=n, t_wall=time.time(), t_mono=time.monotonic(), t_guard=d.t_s, requested_hz=req,
            value_hz=d.value_hz, written_hz=res.written_hz, applied_hz=m.applied_hz if m else None,
            grid_freq_hz=m.grid_freq_hz if m else None, active=d.active and res.ok and not res.forced_zero,
            inhibited=d.inhibited, reasons=d.reasons if link_ok else (*d.reasons, LINK_DOWN),
            link_ok=link_ok, forced_zero=res.forced_zero)
        self.last = sample
        state = _state(d, link_ok)
        prev = self.last_event
        if prev is None or prev.state != state or prev.reasons != sample.reasons:
            self._emit(state, sample.reasons, detail=res.error)
        if self.on_written is not None:
            self.on_written(sample)

    def _account(self, m: Measurement | None, d: GuardDecision, res: WriteResult, link_ok: bool,
                 fresh: bool) -> None:
        st = self.stats
        st.ticks += 1
        if math.isfinite(d.requested_hz):
            st.max_abs_requested_hz = max(st.max_abs_requested_hz, abs(d.requested_hz))
        st.max_abs_value_hz = max(st.max_abs_value_hz, abs(d.value_hz))
        if res.written_hz is not None:
            st.max_abs_written_hz = max(st.max_abs_written_hz, abs(res.written_hz))
        if not link_ok:
            st.link_down_ticks += 1
            st.link_down_s += self.period_s
        if m is not None and m.applied_hz is not None and math.isfinite(m.applied_hz):
            st.max_abs_applied_hz = max(st.max_abs_applied_hz, abs(m.applied_hz))
        # the device must apply what we wrote (one of the last few writes: it applies them a batch later);
        # checked on fresh reads once the recent writes all come from the current armed link
        full = self._armed_ticks > (self._written_recent.maxlen or 0)
        if m is not None and m.applied_hz is not None and fresh and full:
            if matches_any(m.applied_hz, self._written_recent):
                self._mismatch_streak = 0
            else:
                self._mismatch_streak += 1
                st.applied_mismatch_ticks += 1
                if self.verify_applied_ticks and self._mismatch_streak >= self.verify_applied_ticks:
                    raise ExcitationFault(
                        f"the device applies {m.applied_hz!r} Hz, but the last writes were "
                        f"{list(self._written_recent)} Hz ({self._mismatch_streak} fresh reads in a row)")
        if res.ok:
            self._armed_ticks += 1
            assert res.written_hz is not None
            self._written_recent.append(res.written_hz)
        else:
            self._armed_ticks = 0
            self._mismatch_streak = 0
            self._written_recent.clear()

    def _emit(self, state: str, reasons: tuple[str, ...], detail: str = "") -> None:
        ev = ExcitationEvent(t_wall=time.time(), state=state, reasons=tuple(reasons), detail=detail)
        self.last_event = ev
        self.stats.events += 1
        level = logging.INFO if state in ("active", "stopped", "ramping") else logging.WARNING
        log.log(level, "excitation %s reasons=%s%s", state, ",".join(reasons) or "-",
                f" detail={detail!r}" if detail else "")
        if self.on_event is not None:
            self.on_event(ev)

    async def _final_zero(self) -> None:
        """Zero (enable 0), read back, then wait until the device applies zero (bounded)."""
        st = self.stats
        ok = await self.writer.zero(deadline_s=self.zero_deadline_s)
        st.exit_zero_ok = ok if st.exit_zero_ok is None else (st.exit_zero_ok and ok)
        applied_zero: bool | None = None
        if ok and self.writer.points.applied is not None and self.exit_verify_s > 0:
            end = time.monotonic() + self.exit_verify_s
            applied_zero = False
            while time.monotonic() < end:
                a = await self.writer.read_applied()
                if a is not None and a == 0.0:
                    applied_zero = True
                    break
                await asyncio.sleep(0.01)
        st.exit_applied_zero = applied_zero
        if st.exit_reason and (not st.exit_reasons or st.exit_reasons[-1] != st.exit_reason):
            st.exit_reasons.append(st.exit_reason)
        level = logging.INFO if ok and applied_zero is not False else logging.CRITICAL
        log.log(level, "excitation stopped reason=%r zero_written=%s device_applies_zero=%s",
                st.exit_reason, ok, applied_zero)

    # ---- reporting ----------------------------------------------------------------------------------------

    def status(self) -> dict[str, Any]:
        """JSON-able snapshot for publishing: state, reasons, maxima, time per reason, budget."""
        c = self.guard.counters
        last = self.last
        return {
            "state": self.last_event.state if self.last_event else "starting",
            "reasons": list(last.reasons) if last else [],
            "value_hz": last.value_hz if last else 0.0,
            "written_hz": last.written_hz if last else None,
            "applied_hz": last.applied_hz if last else None,
            "amplitude_hz": self.guard.limits.amplitude_hz,
            "max_abs_written_hz": self.stats.max_abs_written_hz,
            "max_abs_applied_hz": self.stats.max_abs_applied_hz,
            "active_s": c.active_s,
            "inhibited_s": c.inhibited_s,
            "time_by_reason_s": c.time_by_reason_s,
            "trips_by_reason": c.trips_by_reason,
            "budget_remaining_s": self.guard.budget_remaining_s(),
            "ticks": self.stats.ticks,
            "missed_ticks": self.stats.missed_ticks,
            "link_down_s": self.stats.link_down_s,
            "writer": asdict(self.writer.stats),
            "generator": self.description,
        }

