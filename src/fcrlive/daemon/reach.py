"""Reachability of the daemon's peers (Modbus device, MQTT broker): one attempt, one line of reason.

Used by ``fcrlive check-config FILE --connect`` (exit 2 on failure) and at daemon start-up, where an
unreachable device is reported once ("cannot reach 10.0.0.1:502 (connection refused); retrying") and
the daemon keeps retrying with backoff: a device that is down at start must not stop the service.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import socket


def _reason(exc: BaseException) -> str:
    if isinstance(exc, TimeoutError):
        return "no answer (timeout)"
    if isinstance(exc, socket.gaierror):
        return f"cannot resolve host: {exc.strerror}"
    if isinstance(exc, ConnectionRefusedError):
        return "connection refused"
    if isinstance(exc, OSError):
        if exc.errno in (errno.EHOSTUNREACH, errno.ENETUNREACH):
            return "host unreachable" if exc.errno == errno.EHOSTUNREACH else "network unreachable"
        text = exc.strerror or str(exc)
        if "Multiple exceptions" in text and "refused" in text.lower():
            return "connection refused"
        return text.lower() if text else type(exc).__name__
    return f"{type(exc).__name__}: {exc}"


async def probe_tcp(host: str, port: int, timeout: float = 3.0) -> str | None:
    """Open and close one TCP connection; None when it worked, else the reason in a few words."""
    try:
        _, w = await asyncio.wait_for(asyncio.open_connection(host, port), timeout)
    except (OSError, TimeoutError) as exc:
        return _reason(exc)
    w.close()
    with contextlib.suppress(OSError):
        await w.wait_closed()
    return None


async def probe_modbus(mcfg, timeout: float = 3.0) -> str | None:
    """TCP connect, then one read of the first input block with the configured unit id; None if OK."""
    reason = await probe_tcp(mcfg.host, mcfg.port, timeout)
    if reason is not None:
        return reason
    from fcrlive.daemon.modbus_source import ModbusParams, ModbusSource

    src = ModbusSource(ModbusParams.from_config(mcfg))
    async with src:
        try:
            await src.wait_connected(timeout)
        except TimeoutError:
            return "TCP works but the Modbus client could not connect"
        values, why = await src._read_once(src.read_blocks[:1])
    if values is None:
        return f"connected, but reading the input registers failed ({why})"
    return None


async def check_peers(cfg, timeout: float = 3.0) -> list[str]:
    """One-line problems with the configured peers (empty when all answer)."""
    problems = []
    if cfg.source.kind == "modbus":
        m = cfg.source.modbus
        why = await probe_modbus(m, timeout)
        if why:
            problems.append(f"cannot reach the Modbus device {m.host}:{m.port} ({why})")
    if cfg.mqtt.enabled:
        why = await probe_tcp(cfg.mqtt.host, cfg.mqtt.port, timeout)
        if why:
            problems.append(f"cannot reach the MQTT broker {cfg.mqtt.host}:{cfg.mqtt.port} ({why})")
    return problems
