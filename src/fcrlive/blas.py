"""One BLAS thread for fcrlive's numerics, whatever the machine's start-up setting.

Why: a number fcrlive publishes must not depend on how many BLAS threads the process was started with
(OPENBLAS_NUM_THREADS, the core count). It did: with two threads the simulator's discretised matrices
(``sim.model.build``, computed once and cached) differed in the 16th digit, and on the zoo's Kd = 0
unit B, whose G_jp search ends pressed against the stability guard, that moved max|S| by up to 3.7 %
and interval ends by up to 20 % between OPENBLAS_NUM_THREADS=1 and 2 (56 of 2730 numbers of the 30-min
excited zoo; docs/zoo.md). The matrices here are small (a few to a few tens of columns), so a second
thread buys nothing: `./dev bench identify` has always run on one.

The entry points of the core (identification, simulation, the cached model builders) and the command
line run under :func:`one_thread`; the daemon's identification workers are started with one thread.
What is left is the BLAS kernel itself (OPENBLAS_CORETYPE), which ``../shared/tools/blas-determinism``
checks. Pure: no I/O; it changes the thread count of the loaded BLAS libraries for the duration of a
call and restores it.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterator
from typing import ParamSpec, TypeVar

_P = ParamSpec("_P")
_R = TypeVar("_R")

_controller = None


def _get_controller():
    """threadpoolctl's controller over the BLAS libraries numpy and SciPy load (created once: a limit
    through it costs ~10 µs, a fresh ``threadpool_limits`` ~0.7 ms of library scanning)."""
    global _controller
    if _controller is None:
        import numpy  # noqa: F401  (its OpenBLAS must be loaded before the scan)
        import scipy.linalg  # noqa: F401  (SciPy's own OpenBLAS likewise)
        from threadpoolctl import ThreadpoolController

        _controller = ThreadpoolController()
    return _controller


@contextlib.contextmanager
def one_thread() -> Iterator[None]:
    """Run the block with every loaded BLAS library on one thread; the previous counts come back after."""
    try:
        ctl = _get_controller()
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency
        yield
        return
    with ctl.limit(limits=1, user_api="blas"):
        yield


def single_threaded(func: Callable[_P, _R]) -> Callable[_P, _R]:
    """Decorator: ``func`` runs under :func:`one_thread`."""

    @functools.wraps(func)
    def wrapper(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        with one_thread():
            return func(*args, **kwargs)

    return wrapper
