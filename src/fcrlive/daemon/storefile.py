"""The store's file on disk: private (0600) whatever the umask, and never in a directory made up on the fly.

Outside systemd (``UMask=0077`` in the unit) a umask of 022 made SQLite create the store, its ``-wal`` and
``-shm`` 0644: the samples and results readable by every local user. SQLite creates ``-wal`` and ``-shm``
with the mode of the database file, so creating the database file itself 0600 (``os.open`` + ``fchmod``,
which the umask does not touch) is enough; a store created 0644 by an older version is tightened.

A missing parent directory is created (0700) only under the state directory
(:func:`fcrlive.daemon.config.checks.state_dir`); anywhere else it is an error: a mistyped path run as root
must not become ``mkdir -p /nonexistent-dir/x``.
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
    try:
        fd = os.open(p, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), MODE)
    except OSError as exc:
        raise ConfigError(f"cannot open the store {p} ({exc.strerror})", where="store.path") from None
    try:
        _private(fd, p)
    finally:
        os.close(fd)
    for suffix in SIDE_FILES:
        side = p.with_name(p.name + suffix)
        try:
            fd = os.open(side, os.O_RDWR | getattr(os, "O_CLOEXEC", 0))
        except OSError:
            continue  # not there (or not ours): SQLite creates it with the database file's mode
        try:
            _private(fd, side)
        finally:
            os.close(fd)
    return p


def _private(fd: int, p: Path) -> None:
    st = os.fstat(fd)
    mode = stat.S_IMODE(st.st_mode)
    if mode == MODE or st.st_uid != os.geteuid():
        return
    os.fchmod(fd, MODE)
    if st.st_size and mode & 0o077:
        log.warning("store: %s was readable by others (mode %o); now %o", p, mode, MODE)
