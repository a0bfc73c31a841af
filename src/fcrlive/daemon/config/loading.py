"""Loading the daemon configuration: a TOML file with ``FCRLIVE_...`` environment overrides
(pydantic-settings), and one-line errors.

``load_config(path)`` reads the file, applies environment overrides (``FCRLIVE_MQTT__HOST=broker``;
nested sections joined by ``__``; the environment wins over the file) and validates everything,
including the Modbus register map the file points at, then what the daemon would refuse at start
(:mod:`.checks`). Every problem becomes ONE line naming the file (or the environment variable) and the
key path, e.g.::

    fcrlive.toml: source.modbus.poll_hz: must be between 10 and 50 (got 80)

and all of them are reported together (:class:`fcrlive.errors.ConfigProblems`).
"""

from __future__ import annotations

import os
import tomllib
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from fcrlive.configerrors import decode_config_text, explain_all
from fcrlive.daemon.config.models import (
    ENV_DELIMITER,
    ENV_PREFIX,
    FcrliveConfig,
    file_context,
)
from fcrlive.errors import ConfigError, ConfigProblems


def _read_toml(path: Path) -> dict[str, Any]:
    if path.exists() and not path.is_file():  # a FIFO would block, a directory is a mistake
        raise ConfigError("not a regular file", where=str(path))
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise ConfigError("no such file", where=str(path)) from None
    except OSError as exc:
        raise ConfigError(f"cannot read: {exc.strerror}", where=str(path)) from None
    try:
        return tomllib.loads(decode_config_text(data, str(path)))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"invalid TOML: {exc}", where=str(path)) from None


def _env_name(loc: str) -> str:
    return ENV_PREFIX + loc.replace(".", ENV_DELIMITER).upper()


def _env_var(key: str) -> str | None:
    """The environment variable that set ``key`` (or its section, as JSON), if any (case-insensitive,
    as pydantic-settings reads them)."""
    names = {k.upper(): k for k in os.environ}
    parts = key.split(".")
    for n in range(len(parts), 0, -1):
        name = names.get(_env_name(".".join(parts[:n])))
        if name is not None:
            return name
    return None


def _problem(where: str, key: str, msg: str) -> ConfigError:
    env = _env_var(key) if key else None
    if env is not None:
        where = f"{env} (environment)"
    return ConfigError(msg, where=f"{where}: {key}" if key else where)


def _raise(problems: list[ConfigError]) -> None:
    raise (problems[0] if len(problems) == 1 else ConfigProblems(problems))


def load_config(path: str | Path | None = None, *, startup_checks: bool = True,
                **overrides: Any) -> FcrliveConfig:
    """Load ``path`` (TOML) with ``FCRLIVE_...`` environment overrides; ConfigError on any problem
    (:class:`~fcrlive.errors.ConfigProblems`, one line each, when there are several).

    ``startup_checks``: also what ``fcrlive run`` would refuse at start (:mod:`.checks`: the store path,
    the plug-in, the excitation's registers, files the daemon reads later); their warnings are in
    :attr:`FcrliveConfig.warnings`. ``overrides`` (keyword sections, e.g. ``store={"path": ...}``) win
    over the file and the environment, for tests and tools.
    """
    where = str(path) if path is not None else "environment"
    data = _read_toml(Path(path)) if path is not None else {}
    base = Path(path).resolve().parent if path is not None else Path.cwd()
    try:
        with file_context(base, data):
            cfg = FcrliveConfig(**overrides)
    except ValidationError as exc:
        _raise([_problem(where, key, msg) for key, msg in explain_all(exc, FcrliveConfig)])
    if startup_checks:
        from fcrlive.daemon.config.checks import check

        found = check(cfg)
        errors = [_problem(where, p.key, p.message) for p in found if not p.warning]
        if errors:
            _raise(errors)
        cfg._warnings = tuple(str(_problem(where, p.key, p.message)) for p in found if p.warning)
    return cfg
