"""Retry pacing: bounded exponential backoff with jitter, for every link that reconnects by itself.

The Modbus and CAN sources, the MQTT publisher and the excitation writer all reconnect in their own
loops (pymodbus never retries a failed first ``connect()``, aiomqtt has no reconnect); they take their
delays from :func:`backoff_delays` so that a dead device or broker is retried quickly at first and then
at most every ``maximum`` seconds, and several clients restarting together do not retry in lock step.
"""

from __future__ import annotations

import random
from collections.abc import Iterator


def backoff_delays(minimum: float, maximum: float, rng: random.Random | None = None) -> Iterator[float]:
    """Infinite bounded exponential backoff with ±20 % jitter: min, 2·min, … capped at ``maximum`` [s]."""
    rng = rng or random.Random()
    d = minimum
    while True:
        yield min(maximum, d) * rng.uniform(0.8, 1.2)
        d = min(maximum, d * 2)
