"""Reading the daemon's results over MQTT as a dashboard would (end-to-end tests, benchmarks)."""

from __future__ import annotations

import asyncio
import json

import aiomqtt

from fcrlive.daemon.payloads import is_data_skip


async def first_identification(host: str, port: int, unit: str, timeout_s: float,
                               base_topic: str = "fcrlive") -> dict:
    """The first ``<base_topic>/<unit>/result/latest`` message (JSON) of a run that was not skipped for too
    little data. ``base_topic`` is the daemon's ``[mqtt] base_topic`` (default "fcrlive", the config's
    default). Raises TimeoutError after ``timeout_s``."""
    async with aiomqtt.Client(host, port) as client:
        await client.subscribe(f"{base_topic}/{unit}/result/latest", qos=1)
        async with asyncio.timeout(timeout_s):
            async for m in client.messages:
                msg = json.loads(m.payload)
                if not is_data_skip(msg):
                    return msg
    raise aiomqtt.MqttError("the broker closed the subscription")
