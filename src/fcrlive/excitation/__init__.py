"""Excitation r[n] for closed-loop identification.

This package namespace exports the pure parts only (generators and the safety guard: no I/O), so that
importing it never pulls in a Modbus stack. The writing path lives in its own modules:
:mod:`fcrlive.excitation.writer` (ExcitationWriter: zero first, one FC16, read-back),
:mod:`fcrlive.excitation.task` (ExcitationTask: generator → guard → writer, zero on every way out) and
:mod:`fcrlive.excitation.config` (ExcitationSettings: off unless enabled). Every value written to a
governor must come from :meth:`SafetyGuard.step` (docs/excitation-safety.md, docs/excitation-writer.md).

Layering: the generators and the guard are part of the pure core (with ``ident``: no asyncio, no I/O); the
writer and the task sit above :mod:`fcrlive.modbus` and receive what they need (``ModbusParams`` with the
register map, a writer) instead of importing the daemon; the command-line driver
(``python -m fcrlive.excitation``) is :mod:`fcrlive.commands._excitation`. pyproject.toml's import contracts
enforce this.
"""

from fcrlive.excitation.generators import (
    ExcitationDescription,
    ExcitationGenerator,
    MultisineGenerator,
    PrbsGenerator,
    SineGenerator,
    WhiteNoiseGenerator,
    crest_factor,
    hz_to_pu,
    make_generator,
    pu_to_hz,
    replay,
)
from fcrlive.excitation.guard import (
    HARD_REASONS,
    SOFT_REASONS,
    GuardCounters,
    GuardDecision,
    GuardLimits,
    SafetyGuard,
)

__all__ = [
    "HARD_REASONS",
    "SOFT_REASONS",
    "ExcitationDescription",
    "ExcitationGenerator",
    "GuardCounters",
    "GuardDecision",
    "GuardLimits",
    "MultisineGenerator",
    "PrbsGenerator",
    "SafetyGuard",
    "SineGenerator",
    "WhiteNoiseGenerator",
    "crest_factor",
    "hz_to_pu",
    "make_generator",
    "pu_to_hz",
    "replay",
]
