"""The store's file on disk: private (0600) whatever the umask, and never in a directory made up on the fly.

Outside systemd (``UMask=0077`` in the unit) a umask of 022 made SQLite create the store, its ``-wal`` and
``-shm`` 0644: the samples and results readable by every local user. SQLite creates ``-wal`` and ``-shm``
with the mode of the database file, so creating the database file itself 0600 (``os.open`` + ``fchmod``,
which the umask does not touch) is enough; a store created 0644 by an older version is tightened.

A missing parent directory is created (0700) only under the state directory
(:func:`fcrlive.daemon.config.checks.state_dir`); anywhere else it is an error: a mistyped path run as root
must not become ``mkdir -p /nonexistent-dir/x``.

No descriptor of an EXISTING store file (or its ``-wal``/``-shm``) is ever opened here: the daemon calls
:func:`prepare` on every writing :func:`~fcrlive.daemon.store.connect`, the operation log's included, while
its sample writer's connection is open, and closing ANY descriptor of a file drops every POSIX lock the
process holds on it (SQLite's own included; sqlite.org/howtocorrupt.html §2.2). Without its shared lock on
the ``-shm`` the daemon looks gone to the next connection of another process (the test's or an operator's
reader), which re-initialises the wal-index: ``ftruncate(-shm, 3)`` under the daemon's mapping, whose next
commit then dies of SIGBUS (or, between the truncation and the rebuild, works from a stale wal-index). So
an existing file is checked and tightened by path (``stat``/``chmod``, no descriptor); only a file created
here, which nobody can have locked yet, is opened.
"""

from __future__ import annotations

import logging
import os
import stat
from pathlib import Path

from fcrlive.errors import ConfigError

log = logging.getLogger("fcrlive.store")

MODE = 0o600
SIDE_FILES = ("-wal", "-shm", "-journal")


def prepare(path: str | Path) -> Path:
    """Make ``path`` ready for SQLite: the directory exists (created 0700 under the state directory
    only), the file exists with mode 0600, as do any ``-wal``/``-shm`` left by an earlier run.
    ConfigError (key ``store.path``) when it cannot be."""
    from fcrlive.daemon.config.checks import state_dir, store_problems

    p = Path(os.path.abspath(path))
    problems = store_problems(p)
    if problems:
        raise ConfigError(problems[0].message, where=problems[0].key)
    if not p.parent.exists():  # under the state directory (store_problems allowed it)
        root = state_dir()
        missing = [d for d in (p.parent, *p.parent.parents) if not d.exists()]
        for d in reversed(missing):
            if not d.is_relative_to(root):
                raise ConfigError(f"will not create {d} outside the state directory {root}",
                                  where="store.path")
            try:
                d.mkdir(mode=0o700)
            except FileExistsError:
                pass
            except OSError as exc:
                raise ConfigError(f"cannot create {d} ({exc.strerror})", where="store.path") from None
            log.info("store: created directory %s (0700)", d)
    try:  # a new file only: O_EXCL (an existing one may be under this process's SQLite locks)
        fd = os.open(p, os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), MODE)
    except FileExistsError:
        if not os.access(p, os.R_OK | os.W_OK, effective_ids=os.access in os.supports_effective_ids):
            why = "Permission denied" if p.exists() else "a dangling symbolic link"
            raise ConfigError(f"cannot open the store {p} ({why})", where="store.path") from None
    except OSError as exc:
        raise ConfigError(f"cannot open the store {p} ({exc.strerror})", where="store.path") from None
    else:
        try:
            os.fchmod(fd, MODE)  # the umask does not touch fchmod
        finally:
            os.close(fd)
    for side in (p, *(p.with_name(p.name + suffix) for suffix in SIDE_FILES)):
        _private(side)
    return p


def _private(p: Path) -> None:
    """Mode 0600 for ``p`` when it exists and is ours: by path, never through a descriptor (module
    docstring)."""
    try:
        st = os.stat(p)
    except OSError:
        return  # not there: SQLite creates it with the database file's mode
    mode = stat.S_IMODE(st.st_mode)
    if mode == MODE or st.st_uid != os.geteuid():
        return
    os.chmod(p, MODE)
    if st.st_size and mode & 0o077:
        log.warning("store: %s was readable by others (mode %o); now %o", p, mode, MODE)
