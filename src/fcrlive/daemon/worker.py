"""Identification in a worker process (one at a time), with the plug-in given by dotted path.

The event loop must never run numerics: an identification takes 0.05-10 s of CPU. It runs in a
``ProcessPoolExecutor(max_workers=1)`` whose initializer pins BLAS to one thread (multithreaded
OpenBLAS on 2 cores made a least-squares fit 35× slower, libraries.md) and pre-imports the plug-in.

Plug-in contract (``[identification] function = "module:function"``)::

    def identify_window(signals, rated_mw, f0, plant=None, method="auto", kd=0.0, **params) -> IdentifyReport

``signals`` is a dict of 1-D float64 numpy arrays of equal length: ``t`` [UNIX s], ``ok`` (1.0 for
quality-OK samples, else 0.0) and one array per stored signal in its unit (``power`` [MW],
``grid_freq`` [Hz], ``excitation_applied`` [Hz], ...; NaN where unavailable). ``plant`` is the path of
the plant description file or None, ``kd`` the load damping of ``[unit]``; a plug-in should accept
(and may ignore) further keyword parameters. The default plug-in is
:func:`fcrlive.daemon.identify_plugin.identify_window`. The result is an
:class:`fcrlive.analysis.report.IdentifyReport` (anything else is a TypeError in the worker). It crosses
the process boundary as the model's JSON (``model_dump_json``, validated back by
``model_validate_json``: a report that would not survive the store or MQTT fails here), and the
service gets the typed report: it judges it by the result-quality rule
(:mod:`fcrlive.daemon.result_quality`), stores it in SQLite and publishes it on MQTT.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import os
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from fcrlive.analysis.report import IdentifyReport

_BLAS_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def resolve(path: str) -> Callable:
    """``"pkg.mod:func"`` (or ``"pkg.mod.func"``) → the callable; ImportError/AttributeError if absent."""
    mod, _, name = path.partition(":") if ":" in path else path.rpartition(".")
    return getattr(importlib.import_module(mod), name)


def _init_worker(func_path: str | None) -> None:
    for v in _BLAS_VARS:
        os.environ[v] = "1"
    try:  # numpy may already be imported (fork): limit the running pools too
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency
        pass
    if func_path:  # pre-import; a failure is reported by the first call, not by a broken pool
        with contextlib.suppress(Exception):
            resolve(func_path)


def run_job(func: str | Callable, signals: dict[str, np.ndarray], rated_mw: float, f0: float,
            plant: str | None, method: str, params: dict | None = None) -> tuple[str, float]:
    """Executed in the worker: call the plug-in, return ``(the report's JSON, CPU wall time [s])``."""
    fn = resolve(func) if isinstance(func, str) else func
    t0 = time.perf_counter()
    rep = fn(signals, rated_mw, f0, plant=plant, method=method, **(params or {}))
    if not isinstance(rep, IdentifyReport):
        raise TypeError(f"identification returned {type(rep).__name__}, expected an IdentifyReport")
    return rep.model_dump_json(), time.perf_counter() - t0


class IdentificationWorker:
    """``async with IdentificationWorker(func) as w: result, dt = await w.run(signals, ...)``.

    ``func`` is a dotted path (resolved in the worker) or a picklable module-level callable.
    A call that exceeds ``timeout_s`` raises TimeoutError and the pool is replaced (the stuck
    process is terminated), so one bad window cannot block later ones.
    """

    def __init__(self, func: str | Callable, timeout_s: float = 600.0):
        self.func = func
        self.timeout_s = timeout_s
        self._pool: ProcessPoolExecutor | None = None

    def _new_pool(self) -> ProcessPoolExecutor:
        import multiprocessing as mp

        # spawn: a fork of a process with threads (store writer, metrics, CAN notifier) is unsafe
        return ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context("spawn"),
                                   initializer=_init_worker,
                                   initargs=(self.func if isinstance(self.func, str) else None,))

    async def __aenter__(self) -> IdentificationWorker:
        self._pool = self._new_pool()
        return self

    async def __aexit__(self, *exc) -> None:
        if self._pool is not None:
            procs = _processes(self._pool)
            self._pool.shutdown(wait=False, cancel_futures=True)
            _terminate(procs)
            self._pool = None

    async def run(self, signals: dict[str, np.ndarray], rated_mw: float, f0: float,
                  plant: str | None = None, method: str = "auto", **params) -> tuple[IdentifyReport, float]:
        """Run one identification; ``(report, duration [s])``. Exceptions of the plug-in propagate.
        ``params`` (e.g. ``kd``) are passed to the plug-in as keyword arguments."""
        loop = asyncio.get_running_loop()
        fut = loop.run_in_executor(self._pool, run_job, self.func, signals, rated_mw, f0, plant, method,
                                   params)
        try:
            text, dt = await asyncio.wait_for(fut, self.timeout_s)
        except TimeoutError:
            old, self._pool = self._pool, self._new_pool()
            procs = _processes(old)
            old.shutdown(wait=False, cancel_futures=True)
            _terminate(procs)
            raise
        return IdentifyReport.model_validate_json(text), dt


def _processes(pool: ProcessPoolExecutor) -> list:
    # ProcessPoolExecutor has no public kill; its process table is gone after shutdown()
    return list((getattr(pool, "_processes", None) or {}).values())


def _terminate(procs: list) -> None:
    """Terminate worker processes still running (a stuck identification must not block shutdown)."""
    for p in procs:
        if p.is_alive():
            p.terminate()


def window_signals(w) -> dict[str, np.ndarray]:
    """The plug-in's ``signals`` dict from a :class:`store.Window`."""
    out = {"t": np.asarray(w.t, dtype=np.float64), "ok": w.ok.astype(np.float64)}
    out.update({k: np.asarray(v, dtype=np.float64) for k, v in w.signals.items()})
    return out
