"""CAN source: python-can bus + cantools DBC decoding into the same :class:`Sample` shape as Modbus.

Frames are decoded as they arrive (python-can ``Notifier`` on the event loop). The device sends one
controller sample as a burst of frames opened by the frame carrying ``sample_counter``; a burst is
taken as a consistent snapshot once every measurement frame of the DBC has arrived after that
opening frame. Without a ``sample_counter`` signal in the DBC the latest value of every signal is
used. The sampler then reads the latest snapshot at ``poll_hz`` on absolute deadlines, like the
Modbus poller, so both sources give the store the same regular grid:

* COMM_ERROR: the bus could not be opened, or nothing was received for ``stale_after_s``;
* STALE: no new burst (or some signal older than ``stale_after_s``) since the previous tick;
* DECODE_ERROR: NaN/inf values; MISSING: a skipped tick.

``t_wall`` is the arrival time of the snapshot's last frame [UNIX s].
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path

from fcrlive.canbus import close_bus, open_bus_retrying
from fcrlive.daemon.pacing import SourceStats, paced_ticks
from fcrlive.daemon.sample import (
    COUNTER_NAME,
    DEVICE_TIME_NAME,
    Quality,
    Sample,
    classify,
    empty_values,
)

log = logging.getLogger("fcrlive.can")

OWN_NODE = "FCRLIVE"
"""DBC node name of the daemon: messages it sends (commands) are not sampled."""


def load_dbc(path: str | Path):
    """cantools database from ``path``."""
    import cantools

    return cantools.database.load_file(str(path))


def rx_messages(db) -> list:
    """Messages the daemon samples: all except those sent by the node ``FCRLIVE`` and the CAN FD
    per-sample frames (one per controller sample, docs/buffered-acquisition.md: not snapshot bursts)."""
    return [m for m in db.messages if OWN_NODE not in (m.senders or []) and not m.is_fd]


def dbc_signal_names(path: str | Path) -> tuple[str, ...]:
    """Names of the sampled signals in a DBC file (in message order)."""
    return tuple(s.name for m in rx_messages(load_dbc(path)) for s in m.signals)


@dataclass(frozen=True)
class CanParams:
    """Bus and sampling parameters (see ``config.CanConfig``)."""

    interface: str
    channel: str
    dbc: Path
    poll_hz: float = 20.0
    stale_after_s: float = 0.5
    bitrate: int | None = None
    backoff_max_s: float = 5.0

    @classmethod
    def from_config(cls, cfg) -> CanParams:
        return cls(interface=cfg.interface, channel=cfg.channel, dbc=cfg.dbc, poll_hz=cfg.poll_hz,
                   stale_after_s=cfg.stale_after_s, bitrate=cfg.bitrate)


class CanSource:
    """``async with CanSource(params) as src: async for s in src.samples(): ...``"""

    def __init__(self, params: CanParams):
        self.p = params
        self.db = load_dbc(params.dbc)
        self.rx = {m.frame_id: m for m in rx_messages(self.db)}
        self.names = tuple(s.name for m in self.rx.values() for s in m.signals)
        self._counter_id = next((fid for fid, m in self.rx.items()
                                 if COUNTER_NAME in m.signal_tree), None)
        self.stats = SourceStats()
        self.bus = None
        self._notifier = None
        self._burst: dict[str, float] = {}
        self._burst_ids: set[int] = set()
        self._snapshot: dict[str, float] = {}
        self._snapshot_t = math.nan  # loop time of the last complete snapshot
        self._snapshot_wall = math.nan
        self._snapshot_no = 0
        self._signal_t: dict[str, float] = {}
        self.decode_errors = 0
        self._opener: asyncio.Task | None = None

    async def __aenter__(self) -> CanSource:
        self._opener = asyncio.create_task(self._open_loop(), name="can-open")
        return self

    async def __aexit__(self, *exc) -> None:
        if self._opener is not None:
            self._opener.cancel()
            await asyncio.gather(self._opener, return_exceptions=True)
        self._close()

    def _close(self) -> None:
        close_bus(self._notifier, self.bus)
        self._notifier = self.bus = None
        self.stats.connected = False

    async def _open_loop(self) -> None:
        self.bus, self._notifier = await open_bus_retrying(
            self.p.interface, self.p.channel, self.p.bitrate, self._on_message, self.stats, log,
            backoff_max_s=self.p.backoff_max_s,
        )
        log.info("can open interface=%s channel=%s signals=%d", self.p.interface, self.p.channel,
                 len(self.names))

    def _on_message(self, msg) -> None:
        """Runs on the event loop (Notifier with ``loop``): decode and assemble bursts."""
        m = self.rx.get(msg.arbitration_id)
        if m is None or msg.is_error_frame:
            return
        try:
            decoded = m.decode(msg.data, decode_choices=False)
        except Exception:  # malformed frame: count, never crash the reader
            self.decode_errors += 1
            return
        now = asyncio.get_running_loop().time()
        for k in decoded:
            self._signal_t[k] = now
        if self._counter_id is None:
            self._snapshot.update({k: float(v) for k, v in decoded.items()})
            self._publish_snapshot(now)
            return
        if msg.arbitration_id == self._counter_id:
            self._burst, self._burst_ids = {}, set()
        self._burst.update({k: float(v) for k, v in decoded.items()})
        self._burst_ids.add(msg.arbitration_id)
        if len(self._burst_ids) == len(self.rx) and self._counter_id in self._burst_ids:
            self._snapshot = dict(self._burst)
            self._publish_snapshot(now)
            self._burst_ids = set()

    def _publish_snapshot(self, now: float) -> None:
        self._snapshot_t = now
        self._snapshot_wall = time.time()
        self._snapshot_no += 1

    async def samples(self) -> AsyncIterator[Sample]:
        """One sample per tick at ``poll_hz`` from the latest complete snapshot."""
        loop = asyncio.get_running_loop()
        last_no = 0
        prev_counter: float | None = None
        async for idx in paced_ticks(self.p.poll_hz, self.stats, self.names):
            if isinstance(idx, Sample):
                yield idx
                continue
            now = loop.time()
            self.stats.polls += 1
            if self.bus is None or not self._snapshot or now - self._snapshot_t > self.p.stale_after_s:
                q = Quality.COMM_ERROR
                s = Sample(time.time(), math.nan, idx, empty_values(self.names), q,
                           detail="bus closed" if self.bus is None else "no frames")
            else:
                values = {n: self._snapshot.get(n, math.nan) for n in self.names}
                q = classify(values, prev_counter)
                if q == Quality.OK and (self._snapshot_no == last_no or any(
                        now - self._signal_t.get(n, -math.inf) > self.p.stale_after_s for n in self.names)):
                    q = Quality.STALE
                prev_counter = values.get(COUNTER_NAME, prev_counter)
                last_no = self._snapshot_no
                s = Sample(self._snapshot_wall, values.get(DEVICE_TIME_NAME, math.nan), idx, values, q,
                           latency_s=now - self._snapshot_t)
            self.stats.samples[q] += 1
            yield s

    async def send(self, message: str, values: dict[str, float]) -> None:
        """Send DBC message ``message`` with all its signal ``values`` (e.g. an excitation command)."""
        import can

        if self.bus is None:
            raise ConnectionError("CAN bus not open")
        m = self.db.get_message_by_name(message)
        frame = can.Message(arbitration_id=m.frame_id, data=m.encode(values, strict=False),
                            is_extended_id=m.is_extended_frame)
        try:
            self.bus.send(frame)
        except can.CanError as exc:
            raise ConnectionError(f"CAN send {message}: {exc}") from exc
