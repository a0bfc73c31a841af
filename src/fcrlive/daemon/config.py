"""Daemon configuration: a TOML file with ``FCRLIVE_...`` environment overrides (pydantic-settings).

``load_config(path)`` reads the file, applies environment overrides (``FCRLIVE_MQTT__HOST=broker``;
nested sections joined by ``__``; the environment wins over the file) and validates everything,
including the Modbus register map the file points at. Any problem becomes ONE
:class:`fcrlive.errors.ConfigError` line naming the file and the key path, e.g.::

    fcrlive.toml: source.modbus.poll_hz: must be between 10 and 50 (got 80)

Unknown keys are errors everywhere (a typo must not silently fall back to a default). Relative paths
in the file are relative to the file's directory.
"""

from __future__ import annotations

import contextvars
import os
import tomllib
from pathlib import Path
from typing import Annotated, Any, Literal

import annotated_types
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    SecretStr,
    ValidationError,
    model_validator,
)
from pydantic_settings import BaseSettings, PydanticBaseSettingsSource, SettingsConfigDict

from fcrlive.daemon.registers import TYPE_WORDS, RegisterMap, RegisterPoint, find_overlap
from fcrlive.errors import ConfigError
from fcrlive.excitation.config import ExcitationSettings as ExcitationConfig

ENV_PREFIX = "FCRLIVE_"
ENV_DELIMITER = "__"

_BASE_DIR: contextvars.ContextVar[Path | None] = contextvars.ContextVar("fcrlive_config_dir", default=None)
_FILE_DATA: contextvars.ContextVar[dict[str, Any] | None] = contextvars.ContextVar(
    "fcrlive_config_data", default=None)


def _resolve(p: Path) -> Path:
    base = _BASE_DIR.get()
    p = p.expanduser()
    return p if p.is_absolute() or base is None else (base / p)


ConfigPath = Annotated[Path, AfterValidator(_resolve)]
"""A path; relative ones are taken relative to the config file's directory."""

Name = Annotated[str, Field(pattern=r"^[A-Za-z][A-Za-z0-9_]{0,62}$")]
"""A signal name: also an SQLite column and part of MQTT payloads."""


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_default=True)


class UnitConfig(_Section):
    """The generating unit: ``name`` is used in MQTT topics and file names."""

    name: str = Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$")
    rated_mw: float = Field(gt=0, le=5000, description="rated active power [MW]")
    f0: float = Field(50.0, ge=45, le=65, description="nominal frequency [Hz]")
    kd: float = Field(0.0, ge=0, le=10, description="load damping of the swing equation [pu]")
    plant: ConfigPath | None = Field(None, description="optional plant description file")


class PointModel(_Section):
    """One register-map point (same keys as ``sim_device/registers.toml``)."""

    name: Name
    table: Literal["input", "holding"]
    address: int = Field(ge=0, le=65535)
    type: Literal["int16", "uint16", "int32", "uint32", "float32", "float64"]
    scale: float = 1.0
    offset: float = 0.0
    unit: str = ""
    writable: bool = False
    description: str = ""

    @model_validator(mode="after")
    def _check(self) -> PointModel:
        if self.address + TYPE_WORDS[self.type] > 65536:
            raise ValueError(f"{self.type} at address {self.address} runs past register 65535")
        if self.writable and self.table != "holding":
            raise ValueError("only holding registers can be writable")
        if self.scale == 0:
            raise ValueError("scale must not be 0")
        return self


def _check_points(points: list[PointModel]) -> None:
    seen: set[str] = set()
    for p in points:
        if p.name in seen:
            raise ValueError(f"point name {p.name!r} used twice")
        seen.add(p.name)
    pair = find_overlap([RegisterPoint(**p.model_dump()) for p in points])
    if pair:
        a, b = pair
        raise ValueError(
            f"points {a.name!r} ({a.table} {a.address}-{a.end - 1}) and {b.name!r} "
            f"({b.table} {b.address}-{b.end - 1}) overlap"
        )


class RegisterMapModel(_Section):
    """A register map file (``sim_device/registers.toml`` format)."""

    unit_id: int = Field(1, ge=0, le=255)
    word_order: Literal["big", "little"] = "big"
    byte_order: Literal["big", "little"] = "big"
    points: list[PointModel] = Field(min_length=1)

    @model_validator(mode="after")
    def _check(self) -> RegisterMapModel:
        _check_points(self.points)
        return self

    def to_map(self, unit_id: int | None = None) -> RegisterMap:
        """The plain frozen map used by the source."""
        return RegisterMap(
            points=tuple(RegisterPoint(**p.model_dump()) for p in self.points),
            unit_id=self.unit_id if unit_id is None else unit_id,
            word_order=self.word_order,
            byte_order=self.byte_order,
        )


class ModbusConfig(_Section):
    """Modbus TCP source: a register map file or inline points, polled at ``poll_hz``."""

    host: str = "127.0.0.1"
    port: int = Field(502, ge=1, le=65535)
    unit_id: int | None = Field(None, ge=0, le=255, description="overrides the map's unit_id")
    register_map: ConfigPath | None = Field(None, description="register map TOML file")
    word_order: Literal["big", "little"] = "big"
    byte_order: Literal["big", "little"] = "big"
    points: list[PointModel] | None = Field(None, description="inline points instead of register_map")
    timeout_s: float = Field(0.2, gt=0, le=5, description="response timeout per request [s]")
    retries: int = Field(0, ge=0, le=1)
    poll_hz: float = Field(20.0, ge=10, le=50, description="polling rate [Hz]")
    watchdog_failures: int = Field(
        10, ge=1, le=1000, description="consecutive failed polls before the client is recreated")
    backoff_max_s: float = Field(5.0, ge=0.5, le=10, description="cap of the reconnect backoff [s]")

    _map: RegisterMap | None = PrivateAttr(None)

    @model_validator(mode="after")
    def _check(self) -> ModbusConfig:
        if (self.register_map is None) == (self.points is None):
            raise ValueError("give exactly one of register_map (a file) or points (inline)")
        if self.points is not None:
            _check_points(self.points)
            self._map = RegisterMapModel(
                unit_id=self.unit_id if self.unit_id is not None else 1, word_order=self.word_order,
                byte_order=self.byte_order, points=self.points).to_map()
        else:
            self._map = load_register_map(self.register_map, self.unit_id)
        return self

    def load_map(self) -> RegisterMap:
        """The validated register map (loaded when the config was)."""
        assert self._map is not None
        return self._map


class CanConfig(_Section):
    """CAN source (python-can bus + cantools DBC); latest decoded values sampled at ``poll_hz``."""

    interface: str = "socketcan"
    channel: str = "can0"
    dbc: ConfigPath
    bitrate: int | None = Field(None, ge=10_000, le=1_000_000)
    poll_hz: float = Field(20.0, ge=10, le=50, description="sampling rate [Hz]")
    stale_after_s: float = Field(0.5, gt=0, le=10, description="a signal older than this is stale [s]")


class SourceConfig(_Section):
    """Where samples come from; the sub-section named by ``kind`` is required."""

    kind: Literal["modbus", "can"] = "modbus"
    modbus: ModbusConfig | None = None
    can: CanConfig | None = None

    @model_validator(mode="after")
    def _check(self) -> SourceConfig:
        if getattr(self, self.kind) is None:
            raise ValueError(f"kind = {self.kind!r} needs a [source.{self.kind}] section")
        return self


class StoreConfig(_Section):
    """SQLite window store."""

    path: ConfigPath = Path("/var/lib/fcrlive/fcrlive.sqlite")
    retention_hours: float = Field(72.0, gt=0, le=24 * 366, description="samples older are deleted [h]")
    commit_interval_s: float = Field(1.0, gt=0, le=1, description="longest time between commits [s]")


class ResultQualityConfig(_Section):
    """The quality rule on identification results (docs/daemon.md, "Result quality")."""

    droop_min_pct: float = Field(1.0, ge=0, le=100, description="lowest plausible droop [%]; below: rejected")
    droop_max_pct: float = Field(20.0, gt=0, le=100,
                                 description="highest plausible droop [%]; above: rejected")
    uncertain_ci_rel_width: float = Field(
        0.25, gt=0, description="95 % interval width relative to the value above which a number is uncertain")
    reject_ci_rel_width: float = Field(
        1.0, gt=0, description="95 % interval width relative to the value above which a number is rejected")

    @model_validator(mode="after")
    def _check(self) -> ResultQualityConfig:
        if self.droop_min_pct >= self.droop_max_pct:
            raise ValueError("droop_min_pct must be below droop_max_pct")
        if self.uncertain_ci_rel_width > self.reject_ci_rel_width:
            raise ValueError("uncertain_ci_rel_width must not exceed reject_ci_rel_width")
        return self


class IdentificationConfig(_Section):
    """Periodic re-identification in a worker process."""

    enabled: bool = True
    every_min: float = Field(5.0, gt=0, le=1440, description="period of identification runs [min]")
    window_min: float = Field(30.0, ge=0.1, le=1440, description="length of the analysed window [min]")
    method: str = "auto"
    function: str = Field(
        "fcrlive.daemon.identify_plugin:identify_window",
        pattern=r"^[A-Za-z_][\w.]*(:[A-Za-z_]\w*)?$",
        description="dotted path module:function of the identification plug-in",
    )
    min_ok_fraction: float = Field(0.8, ge=0, le=1, description="skip windows with fewer good samples")
    timeout_s: float = Field(600.0, gt=0, description="abandon an identification after this [s]")
    result_quality: ResultQualityConfig = ResultQualityConfig()


class TlsConfig(_Section):
    """TLS to the broker: CA bundle, optional client certificate and key."""

    ca: ConfigPath | None = None
    cert: ConfigPath | None = None
    key: ConfigPath | None = None
    insecure: bool = Field(False, description="skip host name verification (testing only)")

    @model_validator(mode="after")
    def _check(self) -> TlsConfig:
        if (self.cert is None) != (self.key is None):
            raise ValueError("cert and key go together")
        return self


class MqttConfig(_Section):
    """MQTT publisher; ``password_file`` is how systemd's LoadCredential hands the secret over."""

    enabled: bool = True
    host: str = "localhost"
    port: int = Field(1883, ge=1, le=65535)
    username: str | None = None
    password: SecretStr | None = None
    password_file: ConfigPath | None = None
    tls: TlsConfig | None = None
    base_topic: str = Field("fcrlive", pattern=r"^[^#+\s]+[^#+\s/]$|^[^#+\s/]$")
    client_id: str | None = None
    keepalive_s: int = Field(30, ge=5, le=3600)
    homeassistant_discovery: bool = False
    discovery_prefix: str = "homeassistant"
    stats_interval_s: float = Field(10.0, ge=1, le=3600, description="live statistics period [s]")
    queue_max: int = Field(1000, ge=10, le=100_000, description="messages kept while the broker is away")
    backoff_max_s: float = Field(30.0, ge=1, le=300)

    @model_validator(mode="after")
    def _check(self) -> MqttConfig:
        if self.password is not None and self.password_file is not None:
            raise ValueError("give password or password_file, not both")
        return self

    def secret(self) -> str | None:
        """The password, read from ``password_file`` when given (read at connect time)."""
        if self.password_file is not None:
            try:
                return self.password_file.read_text().strip()
            except OSError as exc:
                raise ConfigError(f"cannot read: {exc.strerror}", where=str(self.password_file)) from exc
        return self.password.get_secret_value() if self.password else None


class MetricsConfig(_Section):
    """Prometheus endpoint (keep it on localhost)."""

    enabled: bool = True
    host: str = "127.0.0.1"
    port: int = Field(9108, ge=0, le=65535)


WRITTEN_SIGNAL = "excitation_written"
"""Store column (and plug-in signal) of the excitation r actually written [Hz] (with [excitation] on)."""


class _FileSource(PydanticBaseSettingsSource):
    """The parsed TOML file (set by :func:`load_config`), lowest priority after the environment."""

    def get_field_value(self, field, field_name):  # pragma: no cover - __call__ is used instead
        return None, field_name, False

    def __call__(self) -> dict[str, Any]:
        return _FILE_DATA.get() or {}


class FcrliveConfig(BaseSettings):
    """The whole daemon configuration (one TOML file, environment overrides ``FCRLIVE_...``)."""

    model_config = SettingsConfigDict(
        env_prefix=ENV_PREFIX, env_nested_delimiter=ENV_DELIMITER, extra="forbid", validate_default=True,
    )

    unit: UnitConfig
    source: SourceConfig
    store: StoreConfig = StoreConfig()
    identification: IdentificationConfig = IdentificationConfig()
    mqtt: MqttConfig = MqttConfig()
    metrics: MetricsConfig = MetricsConfig()
    excitation: ExcitationConfig = ExcitationConfig()

    @classmethod
    def settings_customise_sources(cls, settings_cls, init_settings, env_settings, dotenv_settings,
                                   file_secret_settings):
        return init_settings, env_settings, _FileSource(settings_cls)

    @model_validator(mode="after")
    def _check_excitation(self) -> FcrliveConfig:
        if self.excitation.enabled and self.source.kind != "modbus":
            raise ValueError("excitation: writing needs source.kind = 'modbus'")
        return self

    @property
    def signals(self) -> tuple[str, ...]:
        """Names of the sampled signals (register points or DBC signals; plus ``excitation_written``
        when the excitation is enabled)."""
        if self.source.kind == "modbus":  # measurements: the input registers (see ModbusParams)
            names = tuple(p.name for p in self.source.modbus.load_map().points if p.table == "input")
            return (*names, WRITTEN_SIGNAL) if self.excitation.enabled else names
        from fcrlive.daemon.can_source import dbc_signal_names

        return dbc_signal_names(self.source.can.dbc)


# ---------------------------------------------------------------------------------------------------
# Loading and one-line errors

def _read_toml(path: Path) -> dict[str, Any]:
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError("no such file", where=str(path)) from None
    except OSError as exc:
        raise ConfigError(f"cannot read: {exc.strerror}", where=str(path)) from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"invalid TOML: {exc}", where=str(path)) from None


def _loc_str(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


def _field_info(model: type[BaseModel], loc: tuple):
    """The FieldInfo at ``loc`` (skipping list indices), or None."""
    info = None
    cur: Any = model
    for part in loc:
        if isinstance(part, int):
            continue
        if not (isinstance(cur, type) and issubclass(cur, BaseModel)) or part not in cur.model_fields:
            return None
        info = cur.model_fields[part]
        cur = _inner_model(info.annotation)
    return info


def _inner_model(annotation: Any) -> Any:
    """The BaseModel inside ``X``, ``X | None`` or ``list[X]``, else the annotation itself."""
    args = getattr(annotation, "__args__", ())
    for a in (annotation, *args):
        if isinstance(a, type) and issubclass(a, BaseModel):
            return a
        for b in getattr(a, "__args__", ()):
            if isinstance(b, type) and issubclass(b, BaseModel):
                return b
    return annotation


def _bounds_message(info, got: Any) -> str | None:
    lo = hi = None
    lo_incl = hi_incl = True
    for m in info.metadata if info else ():
        if isinstance(m, annotated_types.Ge):
            lo = m.ge
        elif isinstance(m, annotated_types.Gt):
            lo, lo_incl = m.gt, False
        elif isinstance(m, annotated_types.Le):
            hi = m.le
        elif isinstance(m, annotated_types.Lt):
            hi, hi_incl = m.lt, False
    if lo is None and hi is None:
        return None
    if lo is not None and hi is not None and lo_incl and hi_incl:
        return f"must be between {lo:g} and {hi:g} (got {got})"
    parts = []
    if lo is not None:
        parts.append(f"{'≥' if lo_incl else '>'} {lo:g}")
    if hi is not None:
        parts.append(f"{'≤' if hi_incl else '<'} {hi:g}")
    return f"must be {' and '.join(parts)} (got {got})"


def explain(exc: ValidationError, model: type[BaseModel]) -> tuple[str, str]:
    """``(key path, message)`` for the first error of ``exc``: short, in the user's words."""
    err = exc.errors(include_url=False)[0]
    loc = tuple(err["loc"])
    kind = err["type"]
    got = err.get("input")
    got_s = repr(got) if isinstance(got, str) else str(got)
    if kind == "extra_forbidden":
        return _loc_str(loc), "unknown key"
    if kind == "missing":
        return _loc_str(loc), "required key missing"
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        msg = _bounds_message(_field_info(model, loc), got)  # env values arrive as strings: no quotes
        if msg:
            return _loc_str(loc), msg
    msg = err["msg"]
    for prefix in ("Value error, ", "Assertion failed, "):
        msg = msg.removeprefix(prefix)
    msg = msg.replace("Input should be", "must be").replace("Input should", "must")
    msg = msg[:1].lower() + msg[1:]
    if kind != "value_error" and not isinstance(got, dict | list):
        msg += f" (got {got_s})"
    return _loc_str(loc), msg


def _env_name(loc: str) -> str:
    return ENV_PREFIX + loc.replace(".", ENV_DELIMITER).upper()


def load_register_map(path: Path, unit_id: int | None = None) -> RegisterMap:
    """Read and validate a register map file; errors name the file and the key in it."""
    data = _read_toml(path)
    try:
        model = RegisterMapModel.model_validate(data)
    except ValidationError as exc:
        key, msg = explain(exc, RegisterMapModel)
        raise ConfigError(msg, where=f"{path}: {key}" if key else str(path)) from None
    return model.to_map(unit_id)


def load_config(path: str | Path | None = None, **overrides: Any) -> FcrliveConfig:
    """Load ``path`` (TOML) with ``FCRLIVE_...`` environment overrides; ConfigError on any problem.

    ``overrides`` (keyword sections, e.g. ``store={"path": ...}``) win over both, for tests and tools.
    """
    where = str(path) if path is not None else "environment"
    data = _read_toml(Path(path)) if path is not None else {}
    base = Path(path).resolve().parent if path is not None else Path.cwd()
    t_base = _BASE_DIR.set(base)
    t_data = _FILE_DATA.set(data)
    try:
        return FcrliveConfig(**overrides)
    except ValidationError as exc:
        key, msg = explain(exc, FcrliveConfig)
        if key and _env_name(key) in os.environ:
            where = f"{_env_name(key)} (environment)"
        raise ConfigError(msg, where=f"{where}: {key}" if key else where) from None
    finally:
        _BASE_DIR.reset(t_base)
        _FILE_DATA.reset(t_data)


def summary(cfg: FcrliveConfig) -> str:
    """A few human-readable lines describing ``cfg`` (for ``fcrlive check-config``)."""
    lines = [f"unit {cfg.unit.name}: {cfg.unit.rated_mw:g} MW, f0 {cfg.unit.f0:g} Hz"]
    if cfg.source.kind == "modbus":
        m = cfg.source.modbus
        rmap = m.load_map()
        from fcrlive.daemon.registers import plan_reads

        sampled = [p for p in rmap.points if p.table == "input"]
        blocks = plan_reads(sampled)
        lines.append(
            f"source modbus {m.host}:{m.port} unit {rmap.unit_id}, {len(sampled)} input points sampled "
            f"({', '.join(p.name for p in sampled)}) in {len(blocks)} read block(s) at {m.poll_hz:g} Hz, "
            f"{len(rmap.points) - len(sampled)} holding points, timeout {m.timeout_s:g} s, "
            f"words {rmap.word_order}/bytes {rmap.byte_order}"
        )
    else:
        c = cfg.source.can
        lines.append(f"source can {c.interface}:{c.channel} dbc {c.dbc}, {c.poll_hz:g} Hz "
                     f"({', '.join(cfg.signals)})")
    s = cfg.store
    lines.append(f"store {s.path}, retention {s.retention_hours:g} h, commit every {s.commit_interval_s:g} s")
    i = cfg.identification
    lines.append(f"identification {'on' if i.enabled else 'off'}: every {i.every_min:g} min, window "
                 f"{i.window_min:g} min, method {i.method}, {i.function}")
    rq = i.result_quality
    lines.append(f"result quality: droop {rq.droop_min_pct:g}-{rq.droop_max_pct:g} %, 95 % interval up to "
                 f"{rq.uncertain_ci_rel_width:g}x the value ok, up to {rq.reject_ci_rel_width:g}x uncertain, "
                 "wider rejected")
    q = cfg.mqtt
    if q.enabled:
        auth = "password file" if q.password_file else "password" if q.password else "anonymous"
        lines.append(f"mqtt {q.host}:{q.port} {'TLS' if q.tls else 'plain'}, {auth}, topics "
                     f"{q.base_topic}/{cfg.unit.name}/..., HA discovery "
                     f"{'on' if q.homeassistant_discovery else 'off'}")
    else:
        lines.append("mqtt off")
    met = cfg.metrics
    lines.append(f"metrics http://{met.host}:{met.port}/metrics" if met.enabled else "metrics off")
    lines.append(f"excitation {'on' if cfg.excitation.enabled else 'off'}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------------
# Documentation (docs/config.md is generated from the models: python -m fcrlive.daemon.config FILE)

_SECTIONS: tuple[tuple[str, type[BaseModel]], ...] = (
    ("unit", UnitConfig), ("source", SourceConfig), ("source.modbus", ModbusConfig),
    ("source.modbus.points[]", PointModel), ("source.can", CanConfig), ("store", StoreConfig),
    ("identification", IdentificationConfig), ("identification.result_quality", ResultQualityConfig),
    ("mqtt", MqttConfig), ("mqtt.tls", TlsConfig),
    ("metrics", MetricsConfig), ("excitation", ExcitationConfig),
)


def _type_name(annotation: Any) -> str:
    s = str(annotation)
    if "Path" in s:
        return "path" + (" \\| None" if "None" in s or "Optional" in s else "")
    if isinstance(annotation, type):
        return annotation.__name__
    for junk in ("typing.", "pydantic.types.", "fcrlive.daemon.config.", "__main__."):
        s = s.replace(junk, "")
    return s.replace("|", "\\|")


def _constraint(info) -> str:
    parts = []
    for m in info.metadata:
        for attr, sym in (("ge", "≥"), ("gt", ">"), ("le", "≤"), ("lt", "<")):
            if hasattr(m, attr):
                parts.append(f"{sym} {getattr(m, attr):g}")
        if hasattr(m, "pattern") and m.pattern:
            parts.append(f"`{m.pattern}`")
    return ", ".join(parts)


def render_config_docs() -> str:
    """docs/config.md from the models (defaults, constraints, descriptions)."""
    from pydantic_core import PydanticUndefined

    lines = [
        "# fcrlive daemon configuration", "",
        "<!-- Generated by `python -m fcrlive.daemon.config docs/config.md`; edit config.py. -->", "",
        "One TOML file (`fcrlive run --config fcrlive.toml`, validate with `fcrlive check-config FILE`);",
        "an annotated example is `deploy/fcrlive.toml`. Every key can be overridden from the environment",
        "as `FCRLIVE_<SECTION>__<KEY>` (nested sections joined by `__`, e.g. `FCRLIVE_MQTT__HOST`,",
        "`FCRLIVE_SOURCE__MODBUS__POLL_HZ`); the environment wins over the file. Unknown keys are errors.",
        "Relative paths are relative to the config file's directory.", "",
        "Errors are one line naming the file and the key, e.g.", "",
        "    fcrlive.toml: source.modbus.poll_hz: must be between 10 and 50 (got 80)", "",
        "A register map file (`register_map`) has the format of `sim_device/registers.toml`: top-level",
        "`unit_id`, `word_order`, `byte_order` and `[[points]]` with the keys of `source.modbus.points[]`",
        "below. Overlapping registers within a table are refused, naming both points.", "",
    ]
    for name, model in _SECTIONS:
        doc = (model.__doc__ or "").strip().splitlines()[0]
        lines += [f"## [{name}]", "", doc, "", "| key | type | default | allowed | meaning |",
                  "|---|---|---|---|---|"]
        for key, info in model.model_fields.items():
            if isinstance(info.default, BaseModel) or key in ("modbus", "can", "tls"):
                continue
            default = "required" if info.default is PydanticUndefined else f"`{info.default!r}`"
            lines.append(f"| `{key}` | {_type_name(info.annotation)} | {default} | {_constraint(info)} | "
                         f"{info.description or ''} |")
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    import sys

    out = sys.argv[1] if len(sys.argv) > 1 else "docs/config.md"
    Path(out).write_text(render_config_docs(), encoding="utf-8")
    print(f"wrote {out}")
