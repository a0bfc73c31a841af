"""Health: Prometheus metrics, systemd sd_notify, structured (key=value) logging."""

from __future__ import annotations

import logging
import os
import socket
import sys
import time

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, start_http_server

from fcrlive.daemon.sample import Quality, Sample

# ---------------------------------------------------------------------------------------------------
# sd_notify


def sd_notify(state: str) -> bool:
    """Send ``state`` (e.g. "READY=1", "WATCHDOG=1", "STOPPING=1") to systemd.

    Only when ``NOTIFY_SOCKET`` is set (Type=notify units); returns whether a message was sent.
    """
    addr = os.environ.get("NOTIFY_SOCKET")
    if not addr:
        return False
    if addr.startswith("@"):  # abstract namespace socket
        addr = "\0" + addr[1:]
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC) as s:
        s.connect(addr)
        s.sendall(state.encode())
    return True


def watchdog_interval_s() -> float | None:
    """Half of systemd's ``WATCHDOG_USEC`` [s] (how often to send WATCHDOG=1), None when unset."""
    usec = os.environ.get("WATCHDOG_USEC")
    pid = os.environ.get("WATCHDOG_PID")
    if not usec or (pid and int(pid) != os.getpid()):
        return None
    return int(usec) / 2e6


# ---------------------------------------------------------------------------------------------------
# Logging


class KeyValueFormatter(logging.Formatter):
    """``ts=... level=... logger=... msg="..."`` lines; the message keeps its own ``key=value`` pairs."""

    def format(self, record: logging.LogRecord) -> str:
        msg = record.getMessage().replace('"', "'")
        ts = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(record.created)) + f".{int(record.msecs):03d}Z"
        line = f'ts={ts} level={record.levelname.lower()} logger={record.name} msg="{msg}"'
        if record.exc_info:
            exc = self.formatException(record.exc_info).replace("\n", "\\n").replace('"', "'")
            line += f' exc="{exc}"'
        return line


def setup_logging(level: str = "INFO", stream=None) -> None:
    """Root logger → one key=value line per record on stderr (journald keeps it as is)."""
    h = logging.StreamHandler(stream or sys.stderr)
    h.setFormatter(KeyValueFormatter())
    root = logging.getLogger()
    root.handlers[:] = [h]
    root.setLevel(level)


# ---------------------------------------------------------------------------------------------------
# Prometheus


class Metrics:
    """The daemon's metrics in their own registry (several daemons/tests can coexist in a process)."""

    def __init__(self, unit: str = ""):
        self.registry = CollectorRegistry()
        r = self.registry
        self.poll_latency = Histogram(
            "fcrlive_poll_latency_seconds", "Request-to-response time of one source poll [s]", registry=r,
            buckets=(0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0))
        self.samples = Counter("fcrlive_samples", "Samples by quality", ["quality"], registry=r)
        self.missed_ticks = Counter("fcrlive_missed_ticks", "Poll ticks skipped because a read overran",
                                    registry=r)
        self.reconnects = Counter("fcrlive_reconnects", "Reconnections by link", ["link"], registry=r)
        self.watchdog_resets = Counter("fcrlive_source_watchdog_resets",
                                       "Source clients recreated by the watchdog", registry=r)
        self.connected = Gauge("fcrlive_connected", "1 when the link is up", ["link"], registry=r)
        self.ident_duration = Histogram(
            "fcrlive_identification_duration_seconds", "Wall time of one identification [s]", registry=r,
            buckets=(0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 120, 300))
        self.ident_runs = Counter("fcrlive_identification_runs", "Identification runs by outcome",
                                  ["outcome"], registry=r)
        self.result_levels = Counter("fcrlive_identification_results",
                                     "Identification results by quality level (ok, uncertain, rejected)",
                                     ["level"], registry=r)
        self.last_result_time = Gauge("fcrlive_last_result_timestamp_seconds",
                                      "UNIX time of the last result not rejected (headline topics updated)",
                                      registry=r)
        self.result_age = Gauge("fcrlive_last_result_age_seconds", "Age of the last result not rejected [s]",
                                registry=r)
        self.result_age.set_function(
            lambda: time.time() - self._last_result if self._last_result else float("nan"))
        self.store_committed = Gauge("fcrlive_store_committed_samples", "Samples committed since start",
                                     registry=r)
        self.mqtt_pending = Gauge("fcrlive_mqtt_pending_messages", "Messages waiting for the broker",
                                  registry=r)
        self._last_result = 0.0
        for q in Quality:
            self.samples.labels(q.name.lower())
        for level in ("ok", "uncertain", "rejected"):
            self.result_levels.labels(level)

    def observe_sample(self, s: Sample) -> None:
        """Count one sample (and its poll latency when a read was made)."""
        self.samples.labels(s.quality.name.lower()).inc()
        if s.quality == Quality.MISSING:
            self.missed_ticks.inc()
        elif s.latency_s == s.latency_s:  # not NaN
            self.poll_latency.observe(s.latency_s)

    def result_published(self, t: float) -> None:
        """Record the time of the latest result that updated the headline topics [UNIX s]."""
        self._last_result = t
        self.last_result_time.set(t)

    def serve(self, host: str = "127.0.0.1", port: int = 9108):
        """Start the HTTP endpoint (a daemon thread); returns ``(server, thread)``."""
        return start_http_server(port, addr=host, registry=self.registry)
