"""Excitation r[n] for closed-loop identification: generators and the safety guard (pure: no I/O).

Every value written to a governor must come from :meth:`SafetyGuard.step` (docs/excitation-safety.md).
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
