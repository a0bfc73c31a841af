"""Errors that are the user's to fix (bad files, bad options, bad config).

The CLI prints them as one line on stderr and exits with status 2: no traceback for user mistakes.
Numerical code raises its own specific subclasses so callers can tell problems apart.
"""

from __future__ import annotations


class UserError(Exception):
    """Something the user can fix: printed as one line, exit status 2.

    ``where`` names the file (and row) or config key the problem is in.
    """

    exit_status = 2

    def __init__(self, message: str, where: str | None = None):
        super().__init__(message)
        self.message = message
        self.where = where

    def __str__(self) -> str:
        return f"{self.where}: {self.message}" if self.where else self.message


class DataError(UserError):
    """A data file or signal that cannot be used (missing column, NaN, time going backwards, too short)."""


class ConfigError(UserError):
    """A configuration file or plant description that is invalid."""


class ConfigProblems(ConfigError):
    """Several problems with one configuration: ``str()`` is one line per problem (the CLI prefixes each
    line with the command), so a user fixes them all in one go instead of one per run."""

    def __init__(self, problems: list[ConfigError]):
        if not problems:
            raise ValueError("ConfigProblems needs at least one problem")
        super().__init__(problems[0].message, where=problems[0].where)
        self.problems = tuple(problems)

    def __str__(self) -> str:
        return "\n".join(str(p) for p in self.problems)
