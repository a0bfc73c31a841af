"""The daemon tests' identification plug-in, where a site's plug-ins live: under ``fcrlive_plugins.`` (the
only package besides the built-in one that ``[identification] function`` may name)."""

from tests_daemon_support import fake_identify

__all__ = ["failing_identify", "fake_identify"]


def failing_identify(signals, rated_mw, f0, plant=None, method="auto", **params):
    """A plug-in that always fails (the daemon must count the run as rejected)."""
    from fcrlive.errors import DataError

    raise DataError("this plug-in fails deliberately")
