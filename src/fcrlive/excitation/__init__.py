"""Excitation r[n] for closed-loop identification.

This package namespace exports the pure parts only (generators and the safety guard: no I/O), so that
importing it never pulls in a Modbus stack. The writing path lives in its own modules:
:mod:`fcrlive.excitation.writer` (ExcitationWriter: zero first, one FC16, read-back),
:mod:`fcrlive.excitation.task` (ExcitationTask: generator → guard → writer, zero on every way out) and
:mod:`fcrlive.excitation.config` (ExcitationSettings: off unless enabled). Every value written to a
governor must come from :meth:`SafetyGuard.step` (docs/excitation-safety.md, docs/excitation-writer.md).
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
