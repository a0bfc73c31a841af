"""Exceptions of the identification engine.

Data problems (NaN samples, a flat input, too few samples) are the user's to fix: they subclass
:class:`fcrlive.errors.DataError` (so the CLI prints them as one line) and ``ValueError`` (so numerical
callers can catch them as bad arguments). Model-structure problems subclass ``ValueError`` only.
Every message names the signal, the segment or the order concerned.
"""

from __future__ import annotations

from fcrlive.errors import DataError


class IdentError(Exception):
    """Base class of every error raised by :mod:`fcrlive.ident`."""


class NonFiniteDataError(DataError, IdentError, ValueError):
    """A signal holds NaN or inf samples where an estimator needs finite ones (split at gaps first)."""


class NotExcitingError(DataError, IdentError, ValueError):
    """An input is constant (or zero) over the data, so its transfer function cannot be estimated."""


class TooFewSamplesError(DataError, IdentError, ValueError):
    """Fewer usable samples than the model orders need (or a segment too short to filter/decimate)."""


class OrderError(IdentError, ValueError):
    """Model orders or delays that are invalid (negative, wrong count for the number of inputs)."""


class UnstableModelError(IdentError, ValueError):
    """An initial model with F, C or D roots on/outside the unit circle that cannot be stabilised."""
