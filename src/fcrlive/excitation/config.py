"""The ``[excitation]`` configuration section: writing is OFF unless ``enabled = true``.

The daemon's configuration embeds :class:`ExcitationSettings` as its ``excitation`` section::

    [excitation]
    enabled = true               # the only switch that opens a write path to the governor: the TOML
                                 # boolean only ("yes", 1 are errors); the environment may only disable
    period_s = 0.1               # write period = sample time of r[n] [s]
    [excitation.limits]          # fcrlive.excitation.guard.GuardLimits, validated against the safe maxima;
    amplitude_hz = 0.1           # required with enabled = true (at least amplitude_hz)
    holdoff_s = 30.0
    [excitation.generator]
    kind = "white"               # white (paper), prbs, multisine, sine
    seed = 7                     # omit: a random seed, recorded in the description
    params = { sigma_factor = 3.0 }
    [excitation.points]          # register-map point names (defaults: the simulated governor's)
    offset = "excitation_offset"

Every limit is checked by :class:`GuardLimits` (one error naming the field and the safe maximum, e.g.
``limits: excitation guard: amplitude_hz = 0.2 is above its safe maximum 0.1 (the FCR-N band / TSO
sine-test amplitude)``), also while ``enabled = false``, so a bad file is refused before anyone turns
writing on.
"""

from __future__ import annotations

import dataclasses
import inspect
import secrets
import time
import typing
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, create_model, field_validator, model_validator

from fcrlive.constants import F0_HZ
from fcrlive.errors import ConfigError
from fcrlive.excitation.generators import _KINDS, ExcitationGenerator, make_generator
from fcrlive.excitation.guard import GuardLimits, SafetyGuard
from fcrlive.excitation.writer import ExcitationPoints

_BASE_ARGS = {"self", "amplitude_hz", "sample_time_s", "seed", "f0_hz"}


def generator_params(kind: str) -> tuple[str, ...]:
    """The kind-specific constructor parameters a ``[excitation.generator] params`` table may set."""
    sig = inspect.signature(_KINDS[kind].__init__)
    return tuple(n for n in sig.parameters if n not in _BASE_ARGS)


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_default=True)


class GeneratorSettings(_Section):
    """r[n]: the generator (``fcrlive.excitation.generators``)."""

    kind: Literal["white", "prbs", "multisine", "sine"] = Field(
        "white", description="white noise (the paper's), prbs, multisine (TSO periods) or sine")
    amplitude_hz: float | None = Field(
        None, gt=0, le=0.1, description="bound on |r| [Hz]; default: limits.amplitude_hz")
    seed: int | None = Field(None, ge=0, le=2**63 - 1, description="omit for a random seed (recorded)")
    params: dict[str, Any] = Field(default_factory=dict, description="kind-specific parameters")

    @model_validator(mode="after")
    def _check(self) -> GeneratorSettings:
        allowed = generator_params(self.kind)
        unknown = sorted(set(self.params) - set(allowed))
        if unknown:
            raise ValueError(f"unknown {self.kind} parameter(s) {', '.join(unknown)}; "
                             f"known: {', '.join(allowed) or 'none'}")
        return self


class _PointSettingsBase(_Section):
    def to_points(self) -> ExcitationPoints:
        return ExcitationPoints(**self.model_dump())


# The same fields and defaults as the writer's ExcitationPoints (one source of truth), validated like
# every other section (unknown keys refused).
_POINT_TYPES = typing.get_type_hints(ExcitationPoints)
PointSettings = create_model(
    "PointSettings",
    __base__=_PointSettingsBase,
    __doc__="Register-map point names (see ``fcrlive.excitation.writer.ExcitationPoints``).",
    **{f.name: (_POINT_TYPES[f.name], f.default) for f in dataclasses.fields(ExcitationPoints)},
)


class FromEnvironment(str):
    """A value of ``[excitation] enabled`` that came from the environment (the daemon's configuration
    loader marks it so): the environment may turn writing off, never on (docs/excitation-safety.md)."""


FALSE_WORDS = frozenset({"false", "0", "no", "off", "n", "f", ""})
"""Environment values that disable writing (``FCRLIVE_EXCITATION__ENABLED=false``)."""


def strict_enabled(v: Any) -> bool:
    """``enabled`` as the one switch that opens a write path: the TOML boolean only.

    pydantic's lax booleans would take ``"yes"``, ``"on"``, ``"1"`` or ``1`` for true; a typo or a
    stray string must not start writing to a governor. A value from the environment
    (:class:`FromEnvironment`) may only disable.
    """
    if isinstance(v, FromEnvironment):
        if v.strip().lower() in FALSE_WORDS:
            return False
        raise ValueError(f"the environment may only disable writing (got {str(v)!r}); writing is enabled "
                         "only by `enabled = true` in the configuration file")
    if type(v) is bool:
        return v
    raise ValueError(f"must be the TOML boolean true or false, not {v!r}: only `enabled = true` (no "
                     "quotes, no number) enables writing to the governor")


class ExcitationSettings(_Section):
    """Safe excitation (docs/excitation-safety.md, docs/excitation-writer.md)."""

    enabled: bool = Field(False, description="write r[n] to the governor: only the TOML boolean `true` "
                          "enables (not \"yes\", 1, ...; the environment may only disable)")
    period_s: float = Field(0.1, ge=0.02, le=1.0, description="write period = sample time of r[n] [s]")
    limits: dict[str, float] = Field(
        default_factory=dict, description="GuardLimits fields (docs/excitation-safety.md); required with "
        "enabled = true, at least amplitude_hz; each checked against its hard safe range, also when disabled")
    generator: GeneratorSettings = GeneratorSettings()
    points: PointSettings = PointSettings()
    verify_applied_ticks: int = Field(
        5, ge=0, le=100, description="fresh reads in a row with a different applied value → fault; 0 off")
    exit_verify_s: float = Field(1.0, ge=0, le=10, description="wait this long for applied = 0 on exit [s]")

    @field_validator("enabled", mode="before")
    @classmethod
    def _enabled(cls, v: Any) -> bool:
        return strict_enabled(v)

    @field_validator("limits")
    @classmethod
    def _limits(cls, v: dict[str, float]) -> dict[str, float]:
        try:
            GuardLimits.from_mapping(dict(v))
        except ConfigError as exc:
            raise ValueError(str(exc)) from None
        except TypeError as exc:
            raise ValueError(f"excitation guard: {exc}") from None
        return v

    @model_validator(mode="after")
    def _check(self) -> ExcitationSettings:
        if self.enabled and "amplitude_hz" not in self.limits:
            raise ValueError("enabled = true needs an explicit [excitation.limits] table with at least "
                             "amplitude_hz (the largest |r| to write, ≤ 0.1 Hz): a write path runs on "
                             "limits someone chose, not on defaults")
        lim = self.guard_limits()
        amp = self.generator.amplitude_hz
        if amp is not None and amp > lim.amplitude_hz:
            raise ValueError(f"generator.amplitude_hz = {amp!r} exceeds limits.amplitude_hz = "
                             f"{lim.amplitude_hz!r}")
        if self.period_s >= lim.stale_after_s:
            raise ValueError(f"period_s = {self.period_s!r} must be below limits.stale_after_s = "
                             f"{lim.stale_after_s!r} (every tick would be a step gap)")
        try:
            self.make_generator(seed=0)  # the kind-specific parameters are checked by the constructor
        except ConfigError as exc:
            raise ValueError(str(exc)) from None
        return self

    def guard_limits(self) -> GuardLimits:
        return GuardLimits.from_mapping(dict(self.limits))

    def make_guard(self, f0: float = F0_HZ) -> SafetyGuard:
        return SafetyGuard(self.guard_limits(), f0=f0)

    def make_generator(self, seed: int | None = None, f0: float = F0_HZ) -> ExcitationGenerator:
        """The configured generator; ``seed`` overrides the configured one (None: configured or random)."""
        g = self.generator
        if seed is None:
            seed = g.seed if g.seed is not None else secrets.randbits(63)
        amp = g.amplitude_hz if g.amplitude_hz is not None else self.guard_limits().amplitude_hz
        return make_generator({"kind": g.kind, "seed": seed, "amplitude_hz": amp,
                               "sample_time_s": self.period_s, "params": dict(g.params), "f0_hz": f0})

    def make_writer(self, params):
        """An ExcitationWriter on ``params`` (a :class:`fcrlive.modbus.client.ModbusParams`)."""
        from fcrlive.excitation.writer import ExcitationWriter

        return ExcitationWriter(params, max_abs_hz=self.guard_limits().amplitude_hz,
                                write_period_s=self.period_s, points=self.points.to_points())

    def make_task(self, params, *, f0: float = F0_HZ, seed: int | None = None, clock=time.monotonic,
                  on_written=None, on_event=None):
        """The whole chain (writer, guard, generator) as an ExcitationTask. ConfigError when disabled."""
        from fcrlive.excitation.task import ExcitationTask

        if not self.enabled:
            raise ConfigError("excitation is disabled ([excitation] enabled = false): nothing may be written")
        return ExcitationTask(
            self.make_writer(params), self.make_guard(f0), self.make_generator(seed, f0),
            period_s=self.period_s, clock=clock, on_written=on_written, on_event=on_event,
            verify_applied_ticks=self.verify_applied_ticks, exit_verify_s=self.exit_verify_s)
