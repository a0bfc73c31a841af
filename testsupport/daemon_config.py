"""The daemon's TOML configuration as the end-to-end tests and the acquisition benchmarks write it: one
simulated governor over Modbus on loopback, a store, identification, MQTT (or none), metrics off and,
optionally, the white-noise excitation."""

from __future__ import annotations

from pathlib import Path

WHITE_EXCITATION = """
[excitation]
enabled = true
period_s = {period_s!r}
[excitation.limits]
amplitude_hz = 0.1
holdoff_s = 1.0
[excitation.generator]
kind = "white"
seed = 7
"""


def _value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (str, Path)):
        return f'"{v}"'
    return repr(v)


def _table(name: str, keys: dict[str, object]) -> str:
    return f"[{name}]\n" + "".join(f"{k} = {_value(v)}\n" for k, v in keys.items() if v is not None) + "\n"


def daemon_toml(*, unit: str, port: int, regmap: Path | str, store: Path | str,
                identification: dict[str, object], plant: Path | str | None = None,
                poll_hz: float | None = None, mqtt: dict[str, object] | None = None,
                excitation_period_s: float | None = None, unit_extra: str = "", extra: str = "") -> str:
    """Configuration text: ``identification`` keys go to ``[identification]`` as given (None: left out);
    ``mqtt`` None disables MQTT; ``excitation_period_s`` turns the white-noise excitation on (writing
    through the guard's 0.1 Hz limit); ``unit_extra`` and ``extra`` are raw TOML appended to ``[unit]`` and
    to the end."""
    text = (_table("unit", {"name": unit, "rated_mw": 300.0, "f0": 50.0, "kd": 0.1, "plant": plant})[:-1]
            + unit_extra + "\n"
            + _table("source.modbus", {"host": "127.0.0.1", "port": port, "register_map": regmap,
                                       "poll_hz": poll_hz})
            + _table("store", {"path": store})
            + _table("identification", identification)
            + _table("mqtt", {"host": "127.0.0.1", **mqtt} if mqtt is not None else {"enabled": False})
            + _table("metrics", {"enabled": False}))
    if excitation_period_s is not None:
        text += WHITE_EXCITATION.format(period_s=excitation_period_s)
    return text + extra
