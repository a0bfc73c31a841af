"""The daemon configuration's models: one pydantic section per TOML table, and :class:`FcrliveConfig`.

Unknown keys are errors everywhere (a typo must not silently fall back to a default). Relative paths
(:data:`ConfigPath`) are relative to the config file's directory, which :func:`~.loading.load_config`
sets for the time of the validation, together with the parsed file (the lowest-priority source after
the environment).
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    SecretStr,
    model_validator,
)
from pydantic_settings import BaseSettings, PydanticBaseSettingsSource, SettingsConfigDict

from fcrlive.errors import ConfigError
from fcrlive.excitation.config import ExcitationSettings as ExcitationConfig
from fcrlive.excitation.config import FromEnvironment
from fcrlive.modbus.mapfile import PointModel, RegisterMapModel, load_register_map
from fcrlive.modbus.mapfile import check_points as _check_points
from fcrlive.modbus.registers import RegisterMap

ENV_PREFIX = "FCRLIVE_"
ENV_DELIMITER = "__"

_BASE_DIR: contextvars.ContextVar[Path | None] = contextvars.ContextVar("fcrlive_config_dir", default=None)
_FILE_DATA: contextvars.ContextVar[dict[str, Any] | None] = contextvars.ContextVar(
    "fcrlive_config_data", default=None)


@contextlib.contextmanager
def file_context(base_dir: Path, data: dict[str, Any]) -> Iterator[None]:
    """While validating a file: relative paths against ``base_dir``, ``data`` (the parsed file) as
    :class:`FcrliveConfig`'s lowest-priority source."""
    t_base, t_data = _BASE_DIR.set(base_dir), _FILE_DATA.set(data)
    try:
        yield
    finally:
        _BASE_DIR.reset(t_base)
        _FILE_DATA.reset(t_data)


def _resolve(p: Path) -> Path:
    base = _BASE_DIR.get()
    p = p.expanduser()
    return p if p.is_absolute() or base is None else (base / p)


ConfigPath = Annotated[Path, AfterValidator(_resolve)]
"""A path; relative ones are taken relative to the config file's directory."""


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_default=True)


class UnitConfig(_Section):
    """The generating unit: ``name`` is used in MQTT topics and file names."""

    name: str = Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$")
    rated_mw: float = Field(gt=0, le=5000, description="rated active power [MW]")
    f0: float = Field(50.0, ge=45, le=65, description="nominal frequency [Hz]")
    kd: float = Field(0.0, ge=0, le=10, description="load damping of the swing equation [pu]")
    plant: ConfigPath | None = Field(None, description="optional plant description file")
    power_lag_s: float | None = Field(
        None, ge=0, le=5, description="time constant of the power transducer's first-order lag [s] (its data "
        "sheet); Z_cu with H takes it off the power. Neither this nor power_delay_s set: Z_cu with H "
        "profiles each window for a chain and widens its intervals by one it finds")
    power_delay_s: float | None = Field(
        None, ge=0, le=5, description="dead time of the power measurement against the frequency [s] (0 when "
        "only power_lag_s is set)")


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
    acquisition: Literal["snapshot", "per_sample"] = Field(
        "snapshot", description="per_sample: every controller sample from the CAN FD frame GOV_Sample with "
        "its rolling counter (docs/buffered-acquisition.md); snapshot: the latest values at poll_hz")
    controller_tc_s: float = Field(0.02, gt=0, le=1, description="per_sample: the controller's sample time "
                                   "Tc [s] (device time = counter x Tc)")


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
    controller_rate_hours: float | None = Field(
        None, gt=0, le=24 * 366, description="buffered acquisition: controller-rate samples are kept this "
        "long [h] instead of retention_hours (default: two identification windows, at least 1 h)")
    oplog_enabled: bool = Field(True, description="the operation log of every TSO column (TR 6.2)")
    oplog_interval_s: float = Field(1.0, ge=0.1, le=10,
                                    description="operation log sample time [s] (TR: <= 1)")
    oplog_retention_days: float = Field(14.0, ge=1, le=366,
                                        description="operation log kept this long [days] (TR 6.2: >= 14)")


class ResultQualityConfig(_Section):
    """The quality rule on identification results (docs/daemon.md, "Result quality")."""

    droop_min_pct: float = Field(1.0, ge=0, le=100, description="lowest plausible droop [%]; below: rejected")
    droop_max_pct: float = Field(20.0, gt=0, le=100,
                                 description="highest plausible droop [%]; above: rejected")
    uncertain_ci_rel_width: float = Field(
        0.25, gt=0, description="95 % interval width relative to the value above which a number is uncertain")
    reject_ci_rel_width: float = Field(
        1.0, gt=0, description="95 % interval width relative to the value above which a number is rejected "
        "(the identification already withholds one wider than its value: above 1.0 no effect on its numbers)")

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
    device_speed: float = Field(
        1.0, ge=1, le=1000, description="device seconds per wall-clock second: 1 for a real governor; the "
        "simulated governor's --speed (only to judge window_min against what the identification needs)")
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


class _EnvSource(PydanticBaseSettingsSource):
    """The environment overrides, with ``excitation.enabled`` marked as coming from the environment
    (also when it arrives inside a JSON ``FCRLIVE_EXCITATION``): it may only disable writing."""

    def __init__(self, settings_cls, env: PydanticBaseSettingsSource):
        super().__init__(settings_cls)
        self._env = env

    def get_field_value(self, field, field_name):  # pragma: no cover - __call__ is used instead
        return None, field_name, False

    def __call__(self) -> dict[str, Any]:
        data = self._env()
        exc = data.get("excitation")
        if isinstance(exc, dict) and "enabled" in exc:
            v = exc["enabled"]
            exc = {**exc, "enabled": FromEnvironment(str(v).lower() if isinstance(v, bool) else str(v))}
            data = {**data, "excitation": exc}
        return data


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

    _warnings: tuple[str, ...] = PrivateAttr(())

    @property
    def warnings(self) -> tuple[str, ...]:
        """One line per warning of the start-up checks (``fcrlive check-config`` prints them, ``run`` logs
        them); set by :func:`~.loading.load_config`."""
        return self._warnings

    @classmethod
    def settings_customise_sources(cls, settings_cls, init_settings, env_settings, dotenv_settings,
                                   file_secret_settings):
        return init_settings, _EnvSource(settings_cls, env_settings), _FileSource(settings_cls)

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
            rmap = self.source.modbus.load_map()
            if rmap.acquisition == "buffered":  # r comes with every slot: nothing written is paired
                from fcrlive.daemon.buffered_source import buffered_signals

                return buffered_signals(rmap.buffer)
            names = tuple(p.name for p in rmap.points if p.table == "input")
            return (*names, WRITTEN_SIGNAL) if self.excitation.enabled else names
        from fcrlive.daemon.can_source import dbc_signal_names

        if self.source.can.acquisition == "per_sample":
            from fcrlive.daemon.can_sample_source import per_sample_signals

            return per_sample_signals(self.source.can.dbc)
        return dbc_signal_names(self.source.can.dbc)
