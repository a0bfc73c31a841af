"""python-can bus lifecycle shared by the daemon's CAN sources and the simulated governor's CAN side.

Kept outside ``fcrlive.daemon`` so that ``sim_device`` (which must not import the daemon) can use it.
python-can is imported lazily: the rest of fcrlive runs without it.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any, Protocol

from fcrlive.backoff import backoff_delays


class _ConnectStats(Protocol):
    connect_failures: int
    connects: int
    connected: bool


async def open_bus_retrying(
    interface: str,
    channel: str,
    bitrate: int | None,
    on_message: Callable[[Any], None],
    stats: _ConnectStats,
    log: logging.Logger,
    *,
    backoff_max_s: float,
    fd: bool = False,
) -> tuple[Any, Any]:
    """Open the bus, retrying with backoff (warning on the 1st, 10th and every 100th failure), and start
    a Notifier delivering frames to ``on_message`` on the running loop. Returns ``(bus, notifier)``."""
    import can

    delays = backoff_delays(0.2, backoff_max_s)
    while True:
        try:
            kw: dict[str, Any] = {"bitrate": bitrate} if bitrate else {}
            if fd:
                kw["fd"] = True
            bus = can.Bus(interface=interface, channel=channel, **kw)
        except Exception as exc:  # python-can raises many types (CanError, OSError, ValueError)
            stats.connect_failures += 1
            if stats.connect_failures in (1, 10) or stats.connect_failures % 100 == 0:
                log.warning("can open failed interface=%s channel=%s error=%r", interface, channel, str(exc))
            await asyncio.sleep(next(delays))
            continue
        notifier = can.Notifier(bus, [on_message], timeout=0.1, loop=asyncio.get_running_loop())
        stats.connects += 1
        stats.connected = True
        return bus, notifier


def close_bus(notifier: Any, bus: Any) -> None:
    """Stop the Notifier (if any), then shut the bus down (if any)."""
    if notifier is not None:
        notifier.stop(timeout=1.0)
    if bus is not None:
        bus.shutdown()
