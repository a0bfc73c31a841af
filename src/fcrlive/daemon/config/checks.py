"""What ``fcrlive run`` would refuse at start, checked on a validated configuration without touching the
network: ``fcrlive check-config`` and ``fcrlive run`` both go through :func:`check` (via
:func:`~.loading.load_config`), so a configuration that check-config passes does not fail at start.

Run-time only (they need the peers): the port of the metrics endpoint being free, the device answering,
and the device's ``rated_power`` register against ``[unit] rated_mw`` (``check-config --connect`` and
the daemon check that one, :mod:`fcrlive.daemon.reach`).

Each problem is ``(key path, message)``; warnings do not stop anything but are printed by check-config
and logged by run.
"""

from __future__ import annotations

import importlib
import ipaddress
import os
from dataclasses import dataclass
from pathlib import Path

from fcrlive.errors import ConfigError

BUILTIN_PLUGIN = "fcrlive.daemon.identify_plugin:identify_window"
"""The default identification plug-in."""
PLUGIN_NAMESPACE = "fcrlive_plugins"
"""Other plug-ins must live in this package (``fcrlive_plugins.<site>:function``): a configuration (or an
environment variable) cannot name an arbitrary callable such as ``os:system`` to run with the daemon's
rights."""
DEFAULT_STATE_DIR = Path("/var/lib/fcrlive")
"""systemd's ``StateDirectory=fcrlive`` (``$STATE_DIRECTORY`` when systemd sets it)."""


@dataclass(frozen=True)
class Problem:
    """One finding: ``key`` is the configuration key path (``store.path``)."""

    key: str
    message: str
    warning: bool = False


def state_dir() -> Path:
    """The daemon's state directory: systemd's ``$STATE_DIRECTORY`` (its first entry), else
    :data:`DEFAULT_STATE_DIR`. The only place where fcrlive creates missing directories."""
    env = os.environ.get("STATE_DIRECTORY", "")
    first = env.split(":")[0]
    return Path(first) if first else DEFAULT_STATE_DIR


def _within(p: Path, root: Path) -> bool:
    try:
        p.relative_to(root)
    except ValueError:
        return False
    return True


def store_problems(path: Path) -> list[Problem]:
    """The store path: a file (or none yet) in an existing directory, or one under the state directory
    (created 0700 at start); never a directory, never a missing directory elsewhere (``mkdir -p`` as
    root of a mistyped path)."""
    key = "store.path"
    path = Path(os.path.abspath(path))
    if path.is_dir():
        return [Problem(key, f"{path} is a directory; give the store's file name, e.g. "
                             f"{path / 'fcrlive.sqlite'}")]
    if path.exists() and not path.is_file():
        return [Problem(key, f"{path} is not a regular file")]
    parent = path.parent
    if parent.exists():
        if not parent.is_dir():
            return [Problem(key, f"{parent} is not a directory")]
        return []
    root = state_dir()
    if _within(parent, root) and root.parent.is_dir():
        return []  # created at start, 0700, under the state directory only
    return [Problem(key, f"directory {parent} does not exist; create it (fcrlive creates missing "
                         f"directories only under its state directory {root})")]


def plugin_problems(function: str) -> list[Problem]:
    """The identification plug-in: the built-in one, or a function in a module of
    :data:`PLUGIN_NAMESPACE`; importable and callable."""
    key = "identification.function"
    mod, _, name = function.partition(":") if ":" in function else function.rpartition(".")
    builtin_mod, _, builtin_name = BUILTIN_PLUGIN.partition(":")
    if (mod, name) != (builtin_mod, builtin_name) and not mod.startswith(PLUGIN_NAMESPACE + "."):
        return [Problem(key, f"{function!r} is not allowed: use the built-in {BUILTIN_PLUGIN!r} or a "
                             f"function in a module under {PLUGIN_NAMESPACE}. (e.g. "
                             f"'{PLUGIN_NAMESPACE}.site:identify_window')")]
    try:
        module = importlib.import_module(mod)
    except Exception as exc:  # a plug-in's own import error, whatever it is, is the user's to fix
        return [Problem(key, f"cannot import {mod!r} ({type(exc).__name__}: {exc})")]
    fn = getattr(module, name, None)
    if not callable(fn):
        return [Problem(key, f"module {mod!r} has no function {name!r}")]
    return []


def window_problems(cfg) -> list[Problem]:
    """A window the built-in identification could never use: shorter (in the device's time) than the
    gap-free data the closed-loop methods need."""
    ic = cfg.identification
    if not ic.enabled or ic.function.replace(".identify_window", ":identify_window") != BUILTIN_PLUGIN:
        return []
    from fcrlive.analysis.experiments import MIN_DURATION_S

    device_s = ic.window_min * 60.0 * ic.device_speed
    if device_s >= MIN_DURATION_S:
        return []
    speed = f" × device_speed {ic.device_speed:g}" if ic.device_speed != 1 else ""
    return [Problem("identification.window_min",
                    f"{ic.window_min:g} min{speed} = {device_s:.0f} s of data is shorter than the "
                    f"{MIN_DURATION_S:.0f} s the identification needs: it could never identify "
                    f"(use window_min ≥ {MIN_DURATION_S / 60.0 / ic.device_speed:g})")]


def excitation_problems(cfg) -> list[Problem]:
    """With writing enabled: the points it writes exist, are writable holding registers, and so on
    (the writer's own check, :meth:`ExcitationPoints.check`)."""
    if not cfg.excitation.enabled or cfg.source.kind != "modbus":
        return []
    try:
        cfg.excitation.points.to_points().check(cfg.source.modbus.load_map())
    except ConfigError as exc:
        return [Problem("excitation.points", exc.message.removeprefix("excitation: "))]
    return []


def _readable_file(key: str, p: Path | None, what: str) -> list[Problem]:
    if p is None:
        return []
    if not p.exists():
        return [Problem(key, f"{what} {p} does not exist")]
    if not p.is_file():
        return [Problem(key, f"{what} {p} is not a regular file")]
    if not os.access(p, os.R_OK):
        return [Problem(key, f"{what} {p} is not readable by this user")]
    return []


def mqtt_problems(cfg) -> list[Problem]:
    """The secret and the TLS files must be there at start: the publisher reads them when it connects,
    and a daemon that samples for hours without ever connecting says nothing useful."""
    q = cfg.mqtt
    if not q.enabled:
        return []
    out = _readable_file("mqtt.password_file", q.password_file, "password file")
    if q.tls is not None:
        files = [("mqtt.tls.ca", q.tls.ca, "CA bundle"), ("mqtt.tls.cert", q.tls.cert, "client certificate"),
                 ("mqtt.tls.key", q.tls.key, "client key")]
        tls = [p for key, path, what in files for p in _readable_file(key, path, what)]
        if not tls:
            import ssl

            from fcrlive.daemon.mqtt import tls_context

            try:
                tls_context(q.tls)
            except (ssl.SSLError, OSError, ValueError) as exc:
                tls = [Problem("mqtt.tls", f"cannot use the certificates ({exc})")]
        out += tls
    return out


def plant_problems(cfg) -> list[Problem]:
    """``[unit] plant``: the identification reads it in the worker; a broken file would fail every run."""
    if cfg.unit.plant is None:
        return []
    from fcrlive.plant.description import load_plant

    try:
        load_plant(cfg.unit.plant)
    except ConfigError as exc:
        return [Problem("unit.plant", str(exc))]
    return []


def metrics_problems(cfg) -> list[Problem]:
    """Warn when the Prometheus endpoint listens beyond localhost (docs/daemon.md: keep it local)."""
    m = cfg.metrics
    if not m.enabled or m.host == "localhost":
        return []
    try:
        loopback = ipaddress.ip_address(m.host).is_loopback
    except ValueError:
        loopback = False
    if loopback:
        return []
    return [Problem("metrics.host", f"{m.host!r} serves /metrics beyond this machine (unauthenticated, "
                                    "unencrypted); keep it on 127.0.0.1 or put a proxy in front",
                    warning=True)]


def check(cfg) -> list[Problem]:
    """Every problem :func:`~.loading.load_config` reports after the models validated (module docstring)."""
    return [*store_problems(cfg.store.path), *plugin_problems(cfg.identification.function),
            *window_problems(cfg), *excitation_problems(cfg), *mqtt_problems(cfg), *plant_problems(cfg),
            *metrics_problems(cfg)]
