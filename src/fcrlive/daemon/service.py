"""The daemon: source → store → periodic identification in a worker → MQTT, with health reporting.

``await Service(cfg).run(stop)`` runs until ``stop`` is set (SIGTERM/SIGINT in :func:`main`). The
asyncio layer only moves data and schedules work:

* sampler: every sample goes to the store writer queue, the metrics and the live statistics;
* every ``stats_interval_s``: ``live`` statistics to MQTT, gauges refreshed;
* every ``every_min``: the last ``window_min`` of samples is read back (in a thread), judged for
  data quality, identified in the worker process (an :class:`~fcrlive.analysis.report.IdentifyReport`),
  judged by the result-quality rule (:mod:`fcrlive.daemon.result_quality`), stored as JSON and published
  (retained; a rejected result only on ``result/latest`` and ``result_quality``);
* systemd: READY=1 once running, WATCHDOG=1 only while samples keep flowing (a stuck sampler lets
  systemd restart us), STOPPING=1 on the way out.

Shutdown order: stop the sampler, flush and close the store (marks the run clean), publish
"offline", close the links.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import time
from collections.abc import Callable
from typing import Any

from fcrlive.daemon.config import FcrliveConfig
from fcrlive.daemon.health import Metrics, sd_notify, watchdog_interval_s
from fcrlive.daemon.livestats import LiveStats
from fcrlive.daemon.payloads import (
    SKIPPED_TOO_LITTLE_DATA,
    DataQuality,
    ExcitationEventPayload,
    ResultPayload,
    Window,
    iso,
    result_topics,
)
from fcrlive.daemon.result_quality import failed, judge
from fcrlive.daemon.sample import Quality
from fcrlive.daemon.store import ResultRow, SampleWriter, connect, read_window

log = logging.getLogger("fcrlive.service")


def make_source(cfg: FcrliveConfig):
    """The configured source object (an async context manager with ``samples()`` and ``stats``)."""
    if cfg.source.kind == "modbus":
        from fcrlive.daemon.modbus_source import ModbusSource
        from fcrlive.modbus.client import ModbusParams

        if buffered(cfg):  # every controller sample from the governor's ring buffer
            from fcrlive.daemon.buffered_source import BufferedModbusSource

            return BufferedModbusSource(ModbusParams.from_config(cfg.source.modbus))
        return ModbusSource(ModbusParams.from_config(cfg.source.modbus))
    from fcrlive.daemon.can_source import CanParams, CanSource

    c = cfg.source.can
    if c.acquisition == "per_sample":  # every controller sample: one CAN FD frame each
        from fcrlive.daemon.can_sample_source import CanSampleSource

        return CanSampleSource(c.interface, c.channel, c.dbc, c.controller_tc_s, c.bitrate)
    return CanSource(CanParams.from_config(c))


def buffered(cfg: FcrliveConfig) -> bool:
    """True when every controller sample is acquired: the register map says ``acquisition = "buffered"``,
    or CAN ``acquisition = "per_sample"`` (docs/buffered-acquisition.md)."""
    if cfg.source.kind == "can":
        return cfg.source.can.acquisition == "per_sample"
    return cfg.source.modbus.load_map().acquisition == "buffered"


def samples_retention_hours(cfg: FcrliveConfig) -> float:
    """How long samples are kept [h]: buffered controller-rate data only for the identification windows."""
    if not buffered(cfg):
        return cfg.store.retention_hours
    return cfg.store.controller_rate_hours or max(1.0, 2.0 * cfg.identification.window_min / 60.0)


def poll_hz(cfg: FcrliveConfig) -> float:
    """Configured sampling rate [Hz]."""
    return cfg.source.modbus.poll_hz if cfg.source.kind == "modbus" else cfg.source.can.poll_hz


def window_quality(w, expected: int) -> DataQuality:
    """Data quality of a window read back from the store (pure)."""
    gaps = w.gaps()
    return DataQuality(
        ok_fraction=min(1.0, w.ok_fraction(expected)), samples=len(w), expected=expected,
        counts=w.quality_counts(), gaps=len(gaps), gap_s=float(sum(b - a for a, b in gaps)))


class Service:
    """One daemon instance. ``identify`` overrides ``[identification] function`` (a dotted path or a
    picklable callable)."""

    def __init__(self, cfg: FcrliveConfig, identify: str | Callable | None = None, version: str = ""):
        self.cfg = cfg
        self.identify = identify or cfg.identification.function
        self.version = version
        self.metrics = Metrics(cfg.unit.name)
        self.signals = cfg.signals
        self.last_sample_mono = 0.0
        self.results = 0
        self.source: Any = None
        self.writer: SampleWriter | None = None
        self.publisher: Any = None
        self.excitation: Any = None
        self.written_hz = 0.0
        """The excitation value last written to the device [Hz] (NaN when a write failed)."""
        self.oplog: Any = None
        """The operation log writer (``[store] oplog_enabled``; fcrlive.daemon.oplog)."""

    # -- tasks ------------------------------------------------------------------------------------

    async def _sampler(self, live: LiveStats) -> None:
        from dataclasses import replace

        from fcrlive.daemon.config import WRITTEN_SIGNAL

        # buffered: every slot carries the r the governor applied to that very sample
        with_r = self.excitation is not None and not buffered(self.cfg)
        async for s in self.source.samples():
            if with_r:  # the r actually written, stored with the sample it was in force for
                s = replace(s, values={**s.values, WRITTEN_SIGNAL: self.written_hz})
            self.writer.add(s)
            if self.oplog is not None:
                self.oplog.add(s)
            self.metrics.observe_sample(s)
            live.add(s)
            if s.quality != Quality.MISSING:
                self.last_sample_mono = time.monotonic()

    async def _stats(self, live: LiveStats) -> None:
        period = self.cfg.mqtt.stats_interval_s
        prev = {"reconnects": 0, "watchdog": 0, "mqtt": 0}
        while True:
            await asyncio.sleep(period)
            payload = live.snapshot(time.time())
            if self.publisher is not None:
                self.publisher.publish("live", payload)
                self.metrics.mqtt_pending.set(self.publisher.pending)
                st = self.publisher.stats
                self.metrics.connected.labels("mqtt").set(1 if st.connected else 0)
                self.metrics.reconnects.labels("mqtt").inc(max(0, st.connects - 1 - prev["mqtt"]))
                prev["mqtt"] = max(prev["mqtt"], st.connects - 1)
            ss = self.source.stats
            self.metrics.connected.labels("source").set(1 if ss.connected else 0)
            self.metrics.reconnects.labels("source").inc(ss.reconnects - prev["reconnects"])
            self.metrics.watchdog_resets.inc(ss.watchdog_resets - prev["watchdog"])
            prev["reconnects"], prev["watchdog"] = ss.reconnects, ss.watchdog_resets
            self.metrics.store_committed.set(self.writer.committed)
            log.info("stats samples=%d rate_hz=%.2f ok=%d comm_error=%d missed=%d committed=%d",
                     payload.samples, payload.rate_hz, payload.quality["ok"], payload.quality["comm_error"],
                     payload.missed_ticks, self.writer.committed)

    def _power_chain(self) -> dict[str, float]:
        """The power transducer's figures for the plug-in, only where configured (a plug-in written before
        them need not take them)."""
        u = self.cfg.unit
        return {k: v for k, v in (("power_lag_s", u.power_lag_s), ("power_delay_s", u.power_delay_s))
                if v is not None}

    def _on_written(self, w) -> None:
        self.written_hz = float("nan") if w.written_hz is None else float(w.written_hz)

    def _on_excitation_event(self, ev) -> None:
        """Publish every change of the excitation's state (the task logs it too)."""
        if self.publisher is not None:
            self.publisher.publish("excitation", ExcitationEventPayload(
                t_wall=ev.t_wall, state=ev.state, reasons=list(ev.reasons), detail=ev.detail))

    async def _excite(self) -> None:
        await self.excitation.run()
        await asyncio.Event().wait()  # stopped on purpose (budget, stop()): keep sampling

    async def _report_unreachable(self) -> None:
        """Say once, clearly, when the device cannot be reached at start (the source keeps retrying)."""
        from fcrlive.daemon.reach import probe_tcp

        m = self.cfg.source.modbus
        why = await probe_tcp(m.host, m.port, timeout=3.0)
        if why is not None and not self.source.stats.connected:
            log.warning("cannot reach %s:%d (%s); retrying with backoff up to %g s", m.host, m.port, why,
                        m.backoff_max_s)
        await asyncio.Event().wait()  # stays in the task list without ending it

    async def _check_rating(self) -> None:
        """Once the device answers: its ``rated_power`` register against ``[unit] rated_mw``; a mismatch
        stops the daemon (ConfigError), as a wrong rating scales every published droop."""
        from fcrlive.daemon.reach import RATED_POINT, rating_problem, read_rated_power
        from fcrlive.errors import ConfigError

        while True:
            await self.source.wait_connected()
            try:
                device_mw = await read_rated_power(self.source)
                break
            except ConnectionError:
                await asyncio.sleep(1.0)
        problem = rating_problem(self.cfg.unit.rated_mw, device_mw)
        if problem is not None:
            raise ConfigError(problem, where="unit.rated_mw")
        if device_mw is not None:
            log.info("rated power checked: unit.rated_mw %g MW, device %s %g MW", self.cfg.unit.rated_mw,
                     RATED_POINT, device_mw)
        await asyncio.Event().wait()

    async def _watchdog(self, interval: float) -> None:
        while True:
            await asyncio.sleep(interval)
            # pet only while samples flow: a hung sampler must end in a restart
            if time.monotonic() - self.last_sample_mono < max(10.0, 4 * interval):
                sd_notify("WATCHDOG=1")

    async def identify_once(self, worker) -> ResultPayload:
        """Identify the last ``window_min`` of data now; store and publish the outcome."""
        ic = self.cfg.identification
        t2 = time.time()
        t1 = t2 - ic.window_min * 60.0
        w = await asyncio.to_thread(self._read, t1, t2)
        if buffered(self.cfg):
            from fcrlive.daemon.buffered_source import expected_samples

            expected = expected_samples(w, t1, t2)
        else:
            expected = round((t2 - t1) * poll_hz(self.cfg))
        quality = window_quality(w, expected)
        result, error, dt = None, None, 0.0
        if quality.ok_fraction < ic.min_ok_fraction:
            error = f"{SKIPPED_TOO_LITTLE_DATA}: {quality.ok_fraction:.0%} ok < {ic.min_ok_fraction:.0%}"
            self.metrics.ident_runs.labels("skipped").inc()
        else:
            from fcrlive.daemon.worker import window_signals

            plant = str(self.cfg.unit.plant) if self.cfg.unit.plant else None
            t0 = time.monotonic()
            try:
                result, _ = await worker.run(window_signals(w), self.cfg.unit.rated_mw, self.cfg.unit.f0,
                                             plant=plant, method=ic.method, kd=self.cfg.unit.kd,
                                             **self._power_chain())
                self.metrics.ident_runs.labels("ok").inc()
            except Exception as exc:  # the plug-in's failure is data for the user, not a daemon crash
                error = f"{type(exc).__name__}: {exc}"
                self.metrics.ident_runs.labels("error").inc()
                log.warning("identification failed error=%r", error)
            dt = time.monotonic() - t0
            self.metrics.ident_duration.observe(dt)
        t = time.time()
        verdict = judge(result, ic.result_quality) if result is not None else failed(error)
        payload = ResultPayload(unit=self.cfg.unit.name, t=t, t_iso=iso(t), window=Window.of(t1, t2),
                                method=ic.method, ok=error is None, error=error, duration_s=dt,
                                quality=quality, result=result, result_quality=verdict)
        self.writer.add_result(ResultRow(t=t, t1=t1, t2=t2, method=ic.method,
                                         ok_fraction=quality.ok_fraction, quality=quality.model_dump(),
                                         result=None if result is None else result.to_json_dict(),
                                         duration_s=dt, error=error,
                                         result_quality=verdict.model_dump()))
        self.metrics.result_levels.labels(verdict.level).inc()  # a skipped or failed run is rejected too
        if result is not None:
            if verdict.level != "rejected":
                self.metrics.result_published(t)
            self.results += 1
        if self.publisher is not None:
            for topic, p in result_topics(payload).items():
                self.publisher.publish(topic, p)
        log.info("identification ok=%s ok_fraction=%.3f duration_s=%.2f error=%r", error is None,
                 quality.ok_fraction, dt, error)
        if result is not None and verdict.level != "ok":
            log.warning("identification result %s, headline topics %s: %s", verdict.level,
                        "kept" if verdict.level == "rejected" else "updated", "; ".join(verdict.reasons))
        return payload

    def _read(self, t1: float, t2: float):
        con = connect(self.cfg.store.path, readonly=True)
        try:
            return read_window(con, t1, t2, self.signals)
        finally:
            con.close()

    async def _identifier(self, worker) -> None:
        period = self.cfg.identification.every_min * 60.0
        loop = asyncio.get_running_loop()
        next_t = loop.time() + period
        while True:
            await asyncio.sleep(max(0.0, next_t - loop.time()))
            next_t += period
            if next_t < loop.time():  # an identification overran: skip, do not queue up
                next_t = loop.time() + period
            try:
                await self.identify_once(worker)
            except Exception:
                log.exception("identification round failed")

    # -- lifecycle --------------------------------------------------------------------------------

    async def run(self, stop: asyncio.Event) -> None:
        """Run until ``stop`` is set."""
        import sqlite3

        from fcrlive.errors import ConfigError

        cfg = self.cfg
        for w in cfg.warnings:
            log.warning("configuration: %s", w)
        if cfg.metrics.enabled:
            try:
                self.metrics.serve(cfg.metrics.host, cfg.metrics.port)
            except OSError as exc:
                raise ConfigError(f"cannot listen on {cfg.metrics.host}:{cfg.metrics.port} "
                                  f"({(exc.strerror or str(exc)).lower()})", where="metrics") from None
        self.writer = SampleWriter(cfg.store.path, self.signals, cfg.store.commit_interval_s,
                                   samples_retention_hours(cfg), version=self.version,
                                   info={"unit": cfg.unit.name, "source": cfg.source.kind,
                                         "poll_hz": poll_hz(cfg), "signals": list(self.signals)})
        try:
            await asyncio.to_thread(self.writer.open)
        except (OSError, sqlite3.Error) as exc:
            raise ConfigError(f"cannot open the store {cfg.store.path} ({exc})", where="store.path") from None
        if cfg.store.oplog_enabled:
            from fcrlive.daemon.oplog import OplogWriter

            st = cfg.store
            self.oplog = OplogWriter(st.path, st.oplog_interval_s, st.oplog_retention_days)
            await asyncio.to_thread(self.oplog.open)
        live = LiveStats(time.time(), self.signals)
        async with contextlib.AsyncExitStack() as stack:
            if cfg.mqtt.enabled:
                from fcrlive.daemon.mqtt import MqttPublisher

                live_signals = tuple(s for s in ("power", "grid_freq") if s in self.signals)
                self.publisher = await stack.enter_async_context(
                    MqttPublisher(cfg.mqtt, cfg.unit.name, live_signals=live_signals))
            self.source = await stack.enter_async_context(make_source(cfg))
            if cfg.excitation.enabled:
                from fcrlive.modbus.client import ModbusParams

                # entered after the source: left before it, with a verified zero written on the way out
                task = cfg.excitation.make_task(ModbusParams.from_config(cfg.source.modbus), f0=cfg.unit.f0,
                                                on_written=self._on_written,
                                                on_event=self._on_excitation_event)
                self.excitation = await stack.enter_async_context(task)
                log.warning("excitation ON: writing %s r[n] every %g s through the safety guard",
                            cfg.excitation.generator.kind, cfg.excitation.period_s)
            tasks = [asyncio.create_task(self._sampler(live), name="sampler"),
                     asyncio.create_task(self._stats(live), name="stats")]
            if self.excitation is not None:
                tasks.append(asyncio.create_task(self._excite(), name="excitation"))
            if (interval := watchdog_interval_s()) is not None:
                tasks.append(asyncio.create_task(self._watchdog(interval), name="sd-watchdog"))
            if cfg.identification.enabled:
                from fcrlive.daemon.worker import IdentificationWorker

                worker = await stack.enter_async_context(
                    IdentificationWorker(self.identify, cfg.identification.timeout_s))
                tasks.append(asyncio.create_task(self._identifier(worker), name="identifier"))
            sd_notify("READY=1")
            log.info("running unit=%s source=%s signals=%d store=%s", cfg.unit.name, cfg.source.kind,
                     len(self.signals), cfg.store.path)
            if cfg.source.kind == "modbus":
                tasks.append(asyncio.create_task(self._report_unreachable(), name="reach"))
                tasks.append(asyncio.create_task(self._check_rating(), name="rating"))
            stopper = asyncio.create_task(stop.wait())
            done, _ = await asyncio.wait([stopper, *tasks], return_when=asyncio.FIRST_COMPLETED)
            sd_notify("STOPPING=1")
            for t in [stopper, *tasks]:
                t.cancel()
            await asyncio.gather(stopper, *tasks, return_exceptions=True)
            await asyncio.to_thread(self.writer.close)
            if self.oplog is not None:
                await asyncio.to_thread(self.oplog.close)
            failed = [t for t in done if t is not stopper and not t.cancelled() and t.exception()]
            for t in failed:
                if isinstance(t.exception(), ConfigError):  # the user's to fix: one line, no traceback
                    log.error("stopping: %s", t.exception())
                    continue
                log.error("task %s failed: %r", t.get_name(), t.exception(), exc_info=t.exception())
            log.info("stopped committed=%d", self.writer.committed)
            # leaving the stack: worker, source, then the publisher says "offline"
        if failed:
            raise failed[0].exception()


async def run_service(cfg: FcrliveConfig, identify: str | Callable | None = None, version: str = "") -> None:
    """Run until SIGTERM/SIGINT."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    await Service(cfg, identify, version).run(stop)


def main(config_path: str, log_level: str = "INFO") -> int:
    """Entry point for ``fcrlive run --config FILE`` (wired by the CLI command)."""
    from fcrlive import __version__
    from fcrlive.daemon.config import load_config
    from fcrlive.daemon.health import setup_logging

    cfg = load_config(config_path)
    setup_logging(log_level)
    asyncio.run(run_service(cfg, version=__version__))
    return 0
