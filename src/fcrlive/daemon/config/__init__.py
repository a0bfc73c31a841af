"""Daemon configuration: a TOML file with ``FCRLIVE_...`` environment overrides, validated into
:class:`FcrliveConfig`.

The public surface is re-exported here: :func:`load_config` (:mod:`.loading`: file +
environment, one-line errors), :func:`load_register_map` (:mod:`fcrlive.modbus.mapfile`) and the
models (:mod:`.models`: one section per TOML table). :mod:`.docs` writes docs/config.md
(``python -m fcrlive.daemon.config docs/config.md``) and the ``check-config`` summary.
"""

from fcrlive.daemon.config.loading import load_config
from fcrlive.daemon.config.models import (
    WRITTEN_SIGNAL,
    CanConfig,
    ExcitationConfig,
    FcrliveConfig,
    IdentificationConfig,
    MetricsConfig,
    ModbusConfig,
    MqttConfig,
    PointModel,
    RegisterMapModel,
    ResultQualityConfig,
    SourceConfig,
    StoreConfig,
    TlsConfig,
    UnitConfig,
)
from fcrlive.modbus.mapfile import load_register_map

__all__ = [
    "WRITTEN_SIGNAL", "CanConfig", "ExcitationConfig", "FcrliveConfig", "IdentificationConfig",
    "MetricsConfig", "ModbusConfig", "MqttConfig", "PointModel", "RegisterMapModel", "ResultQualityConfig",
    "SourceConfig", "StoreConfig", "TlsConfig", "UnitConfig", "load_config", "load_register_map",
]
