"""MQTT publisher (aiomqtt 2.5): retained results, birth/will status, queue while the broker is away.

``async with MqttPublisher(cfg, unit="G1") as pub: pub.publish("droop", payload)`` never blocks
and never fails: messages wait in memory until a connection is up. Retained topics keep only the
newest message per topic (that is all a retained topic can show anyway), the others a bounded FIFO
(oldest dropped and counted). aiomqtt has no reconnect of its own: :meth:`_run` loops on
``aiomqtt.MqttError`` with bounded exponential backoff.

On connect: retained ``status`` = "online" (the will, set at CONNECT, is a retained "offline"),
the last ``excitation`` state again (:data:`STICKY`: a restarted broker may have lost it), Home Assistant
discovery configs when enabled, then the queue is flushed. On a clean exit the
publisher flushes (briefly), publishes "offline" itself and disconnects.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import re
import ssl
from collections import OrderedDict, deque
from dataclasses import dataclass

import aiomqtt
from pydantic import BaseModel

from fcrlive.backoff import backoff_delays
from fcrlive.daemon.payloads import TOPICS, to_bytes
from fcrlive.errors import ConfigError

log = logging.getLogger("fcrlive.mqtt")

_RETAINED = {t.suffix: t.retained for t in TOPICS}
_QOS = {t.suffix: t.qos for t in TOPICS}


@dataclass
class PublisherStats:
    """Counters since start (exported as metrics)."""

    connects: int = 0
    connect_failures: int = 0
    published: int = 0
    dropped: int = 0
    connected: bool = False


def tls_context(tls) -> ssl.SSLContext:
    """An SSL context from ``config.TlsConfig`` (CA bundle, optional client certificate)."""
    ctx = ssl.create_default_context(cafile=str(tls.ca) if tls.ca else None)
    if tls.cert is not None:
        ctx.load_cert_chain(str(tls.cert), str(tls.key))
    if tls.insecure:
        ctx.check_hostname = False
    return ctx


LIVE_SENSOR_CLASSES = {"power": ("MW", "power"), "grid_freq": ("Hz", "frequency")}
"""Home Assistant ``(unit_of_measurement, device_class)`` of the live signals (the simulated governor's
register map units; HA's power and frequency device classes accept MW and Hz)."""

STICKY = ("excitation",)
"""Retained topics published again on every (re)connect: a broker restarted without persistence has lost
them, and the excitation's state (writing to the governor or not) must always be visible."""


def discovery_configs(prefix: str, unit: str, discovery_prefix: str = "homeassistant",
                      live_signals: tuple[str, ...] = ("power", "grid_freq")) -> dict[str, dict]:
    """Home Assistant MQTT discovery configs: ``{config topic: payload}`` (retained sensors)."""
    dev_id = re.sub(r"[^A-Za-z0-9_-]", "_", f"fcrlive_{unit}")
    device = {"identifiers": [dev_id], "name": f"fcrlive {unit}", "manufacturer": "fcrlive",
              "model": "governor identification"}
    avail = f"{prefix}/status"
    sensors = {
        "droop": (f"{prefix}/droop", "{{ value_json.value }}", "%", "Droop"),
        "max_abs_s": (f"{prefix}/max_abs_s", "{{ value_json.value }}", None, "Peak sensitivity max|S|"),
        "ok_fraction": (f"{prefix}/quality", "{{ (value_json.ok_fraction * 100) | round(1) }}", "%",
                        "Data quality"),
        "max_abs_g1": (f"{prefix}/max_abs_g1", "{{ value_json.value }}", None, "Peak max|G_1|"),
        "result_quality": (f"{prefix}/result_quality", "{{ value_json.level }}", None, "Result quality"),
        "tso_fcrn": (f"{prefix}/tso/fcrn", "{{ value_json.verdict }}", None, "FCR-N verdict"),
        "tso_fcrd": (f"{prefix}/tso/fcrd", "{{ value_json.verdict }}", None, "FCR-D verdict"),
        "tso_fcrd_up": (f"{prefix}/tso/fcrd_up", "{{ value_json.verdict }}", None, "FCR-D upwards verdict"),
        "tso_fcrd_down": (f"{prefix}/tso/fcrd_down", "{{ value_json.verdict }}", None,
                          "FCR-D downwards verdict"),
    }
    for s in live_signals:
        template = f"{{{{ value_json.signals.{s}.mean }}}}"
        unit_of_measurement, _ = LIVE_SENSOR_CLASSES.get(s, (None, None))
        sensors[f"live_{s}"] = (f"{prefix}/live", template, unit_of_measurement, f"{s} (mean)")
    out = {}
    for key, (topic, template, unit_of_measurement, name) in sensors.items():
        object_id = f"{dev_id}_{key}"
        cfg = {"name": name, "unique_id": object_id, "object_id": object_id, "state_topic": topic,
               "value_template": template, "availability_topic": avail, "payload_available": "online",
               "payload_not_available": "offline", "device": device}
        if unit_of_measurement:
            cfg["unit_of_measurement"] = unit_of_measurement
            cfg["state_class"] = "measurement"
        if key.startswith("live_"):
            _, device_class = LIVE_SENSOR_CLASSES.get(key.removeprefix("live_"), (None, None))
            if device_class:
                cfg["device_class"] = device_class
        out[f"{discovery_prefix}/sensor/{object_id}/config"] = cfg
    return out


class MqttPublisher:
    """Keeps a connection to the broker and publishes queued messages; see the module docstring.

    ``cfg`` is a ``config.MqttConfig``; topics are ``<base_topic>/<unit>/<suffix>``.
    """

    def __init__(self, cfg, unit: str, live_signals: tuple[str, ...] = ("power", "grid_freq")):
        self.cfg = cfg
        self.unit = unit
        self.prefix = f"{cfg.base_topic}/{unit}"
        self.status_topic = f"{self.prefix}/status"
        self.live_signals = live_signals
        self.stats = PublisherStats()
        self._retained: OrderedDict[str, tuple[int, bytes, int]] = OrderedDict()
        self._sticky_topics = {f"{self.prefix}/{t}" for t in STICKY}
        self._sticky: dict[str, tuple[bytes, int]] = {}
        self._fifo: deque[tuple[str, bytes, int]] = deque()
        self._version = itertools.count()
        self._wake = asyncio.Event()
        self._idle = asyncio.Event()
        self._idle.set()
        self.connected = asyncio.Event()
        self._stopping = False
        self._task: asyncio.Task | None = None

    # -- public API -------------------------------------------------------------------------------

    def publish(self, suffix: str, payload: BaseModel | str, retain: bool | None = None,
                qos: int | None = None) -> None:
        """Queue ``payload`` for ``<prefix>/<suffix>`` (non-blocking). Retained by default for the
        topics of :data:`payloads.TOPICS` that are retained."""
        self.publish_raw(f"{self.prefix}/{suffix}", to_bytes(payload),
                         _RETAINED.get(suffix, False) if retain is None else retain,
                         _QOS.get(suffix, 0) if qos is None else qos)

    def publish_raw(self, topic: str, data: bytes, retain: bool, qos: int = 1) -> None:
        """Queue bytes for an absolute ``topic``."""
        if retain:
            if topic in self._sticky_topics:
                self._sticky[topic] = (data, qos)
            self._retained[topic] = (next(self._version), data, qos)
            self._retained.move_to_end(topic)
        else:
            if len(self._fifo) >= self.cfg.queue_max:
                self._fifo.popleft()
                self.stats.dropped += 1
            self._fifo.append((topic, data, qos))
        self._idle.clear()
        self._wake.set()

    @property
    def pending(self) -> int:
        """Messages waiting for the broker."""
        return len(self._retained) + len(self._fifo)

    async def drain(self, timeout: float | None = None) -> None:
        """Wait until every queued message has been handed to the broker."""
        await asyncio.wait_for(self._idle.wait(), timeout)

    async def __aenter__(self) -> MqttPublisher:
        self._task = asyncio.create_task(self._run(), name="mqtt-publisher")
        return self

    async def __aexit__(self, *exc) -> None:
        self._stopping = True
        self._wake.set()
        if self._task is None:
            return
        if self.connected.is_set():
            # give the sender a moment to flush and say "offline" itself
            with contextlib.suppress(asyncio.TimeoutError, asyncio.CancelledError):
                await asyncio.wait_for(asyncio.shield(self._task), timeout=5.0)
        if not self._task.done():
            self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._task

    # -- connection loop --------------------------------------------------------------------------

    def _client(self) -> aiomqtt.Client:
        c = self.cfg
        return aiomqtt.Client(
            c.host, c.port, username=c.username, password=c.secret(), identifier=c.client_id,
            will=aiomqtt.Will(self.status_topic, b"offline", qos=1, retain=True),
            keepalive=c.keepalive_s, timeout=10.0,
            tls_context=tls_context(c.tls) if c.tls is not None else None,
            tls_insecure=(c.tls.insecure or None) if c.tls is not None else None,
        )

    async def _run(self) -> None:
        delays = backoff_delays(0.2, self.cfg.backoff_max_s)
        while not self._stopping:
            try:
                async with self._client() as client:
                    await client.publish(self.status_topic, b"online", qos=1, retain=True)
                    self._requeue_sticky()
                    self.stats.connects += 1
                    self.stats.connected = True
                    self.connected.set()
                    log.info("mqtt connected host=%s port=%d connects=%d pending=%d", self.cfg.host,
                             self.cfg.port, self.stats.connects, self.pending)
                    delays = backoff_delays(0.2, self.cfg.backoff_max_s)
                    await self._session(client)
                    if self._stopping:
                        await client.publish(self.status_topic, b"offline", qos=1, retain=True)
                        return
            except ConfigError as exc:  # the password file went away after the start checks
                self.stats.connect_failures += 1
                if self.stats.connect_failures in (1, 10) or self.stats.connect_failures % 100 == 0:
                    log.error("mqtt cannot connect: %s", exc)
                if self._stopping:
                    return
                await asyncio.sleep(next(delays))
            except aiomqtt.MqttError as exc:
                was = self.stats.connected
                self.stats.connected = False
                self.connected.clear()
                self.stats.connect_failures += 1
                if was or self.stats.connect_failures in (1, 10) or self.stats.connect_failures % 100 == 0:
                    log.warning("mqtt connection lost/failed host=%s port=%d error=%r pending=%d",
                                self.cfg.host, self.cfg.port, str(exc), self.pending)
                if self._stopping:
                    return
                await asyncio.sleep(next(delays))
            finally:
                self.stats.connected = False
                self.connected.clear()

    def _requeue_sticky(self) -> None:
        """Queue the last message of each :data:`STICKY` topic again (unless a newer one is waiting)."""
        for topic, (data, qos) in self._sticky.items():
            if topic not in self._retained:
                self._retained[topic] = (next(self._version), data, qos)
                self._idle.clear()
                self._wake.set()

    async def _session(self, client: aiomqtt.Client) -> None:
        """Run sender and listener until the connection drops (MqttError) or we stop."""
        tasks = [asyncio.create_task(self._sender(client), name="mqtt-sender"),
                 asyncio.create_task(self._listener(client), name="mqtt-listener")]
        try:
            done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for t in tasks:
                t.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
        for t in done:
            if t.exception() is not None:
                raise t.exception()

    async def _announce(self, client: aiomqtt.Client) -> None:
        for topic, cfg in discovery_configs(self.prefix, self.unit, self.cfg.discovery_prefix,
                                            self.live_signals).items():
            await client.publish(topic, json.dumps(cfg).encode(), qos=1, retain=True)

    async def _listener(self, client: aiomqtt.Client) -> None:
        # Iterating the messages is also how a dropped connection surfaces (MqttError) while idle
        if self.cfg.homeassistant_discovery:
            await client.subscribe(f"{self.cfg.discovery_prefix}/status", qos=1)
            await self._announce(client)
        async for msg in client.messages:
            if msg.topic.matches(f"{self.cfg.discovery_prefix}/status") and msg.payload == b"online":
                log.info("mqtt: Home Assistant came online, announcing discovery again")
                await self._announce(client)

    async def _sender(self, client: aiomqtt.Client) -> None:
        while True:
            while self._retained or self._fifo:
                if self._retained:
                    topic, (ver, data, qos) = next(iter(self._retained.items()))
                    await client.publish(topic, data, qos=qos, retain=True)
                    # a newer value may have arrived meanwhile: only drop what was sent
                    if self._retained.get(topic, (None,))[0] == ver:
                        del self._retained[topic]
                else:
                    topic, data, qos = self._fifo[0]
                    await client.publish(topic, data, qos=qos, retain=False)
                    self._fifo.popleft()
                self.stats.published += 1
            self._idle.set()
            if self._stopping:
                return
            self._wake.clear()
            await self._wake.wait()

