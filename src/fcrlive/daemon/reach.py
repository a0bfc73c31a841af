"""Reachability of the daemon's peers (Modbus device, MQTT broker): one attempt, one line of reason; and
the device's ``rated_power`` register against ``[unit] rated_mw`` (:func:`rating_problem`).

Used by ``fcrlive check-config FILE --connect`` (exit 2 on failure) and at daemon start-up, where an
unreachable device is reported once ("cannot reach 10.0.0.1:502 (connection refused); retrying") and
the daemon keeps retrying with backoff: a device that is down at start must not stop the service.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import math
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


RATED_POINT = "rated_power"
"""The register-map point with the unit's rated power [MW], when the device exposes one."""
RATED_TOLERANCE = 0.01
"""``[unit] rated_mw`` may differ from the device's ``rated_power`` by this fraction (float32, rounding)."""


def rating_problem(rated_mw: float, device_mw: float | None) -> str | None:
    """One line when ``[unit] rated_mw`` disagrees with the device's rated power (None: agrees, or the
    device gave no usable value). Every power in pu is divided by it: a 3× wrong rating makes a 7.9 %
    droop read 2.6 %."""
    if device_mw is None or not math.isfinite(device_mw) or device_mw <= 0:
        return None
    if abs(rated_mw - device_mw) <= RATED_TOLERANCE * device_mw:
        return None
    return (f"{rated_mw:g} MW, but the device's {RATED_POINT} register says {device_mw:g} MW; every droop "
            f"would be off by a factor {device_mw / rated_mw:.3g}: fix [unit] rated_mw (or the register map)")


async def read_rated_power(src) -> float | None:
    """The device's rated power [MW] from a connected ModbusSource, None when its map has no
    :data:`RATED_POINT`; ConnectionError when the read fails."""
    from fcrlive.modbus.registers import plan_reads

    point = next((p for p in src.map.points if p.name == RATED_POINT), None)
    if point is None:
        return None
    values, why = await src._read_once(plan_reads([point]))
    if values is None:
        raise ConnectionError(why)
    return float(values[RATED_POINT])


async def _probe_modbus(mcfg, timeout: float, rated_mw: float | None) -> tuple[str | None, str | None]:
    reason = await probe_tcp(mcfg.host, mcfg.port, timeout)
    if reason is not None:
        return reason, None
    from fcrlive.daemon.modbus_source import ModbusSource
    from fcrlive.modbus.client import ModbusParams

    src = ModbusSource(ModbusParams.from_config(mcfg))
    async with src:
        try:
            await src.wait_connected(timeout)
        except TimeoutError:
            return "TCP works but the Modbus client could not connect", None
        values, why = await src._read_once(src.read_blocks[:1])
        if values is None:
            return f"connected, but reading the input registers failed ({why})", None
        if rated_mw is None:
            return None, None
        try:
            device_mw = await read_rated_power(src)
        except ConnectionError as exc:
            return f"connected, but reading {RATED_POINT} failed ({exc})", None
    return None, rating_problem(rated_mw, device_mw)


async def probe_modbus(mcfg, timeout: float = 3.0) -> str | None:
    """TCP connect, then one read of the first input block with the configured unit id; None if OK."""
    return (await _probe_modbus(mcfg, timeout, None))[0]


async def check_peers(cfg, timeout: float = 3.0) -> list[str]:
    """One-line problems with the configured peers (empty when all answer)."""
    problems = []
    if cfg.source.kind == "modbus":
        m = cfg.source.modbus
        why, rating = await _probe_modbus(m, timeout, cfg.unit.rated_mw)
        if why:
            problems.append(f"cannot reach the Modbus device {m.host}:{m.port} ({why})")
        if rating:
            problems.append(f"unit.rated_mw: {rating}")
    if cfg.mqtt.enabled:
        why = await probe_tcp(cfg.mqtt.host, cfg.mqtt.port, timeout)
        if why:
            problems.append(f"cannot reach the MQTT broker {cfg.mqtt.host}:{cfg.mqtt.port} ({why})")
    return problems
