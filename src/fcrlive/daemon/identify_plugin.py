"""The daemon's default identification plug-in: a stored window → PlantSignals → identify → IdentifyReport.

``[identification] function = "fcrlive.daemon.identify_plugin:identify_window"`` (the default). Runs in
the worker process (:mod:`fcrlive.daemon.worker`), so it may take seconds of CPU.

From the window arrays (see the worker's plug-in contract) to the paper's signals, in pu:

- time axis: the device's own clock ``device_time`` [s] when the map has it and it is finite on the
  good samples (an accelerated simulator runs faster than the wall clock; a real governor's clock has no
  arrival jitter), else the arrival time ``t``;
- ``u = (power − mean power)/rated_mw``;
- ``y``, the frequency deviation the governor acts on [pu of f0], from the best signal available:
  ``control_error`` (the governor's own ε, so y = r − ε), else ``speed`` (pu, 1 = nominal), else
  ``grid_freq``; which one was used is written into the report's ``notes``;
- ``r`` [pu of f0]: ``excitation_written/f0`` (the value the daemon's excitation task wrote, stored with
  each sample) when present, else ``excitation_applied/f0`` (what the device reports applying), else
  zeros; ``epsilon = r − y``;
- ``c = controller_output/100``, ``a = guide_vane/100`` when present (% of full opening).

Only quality-OK samples with finite values are used. They are put on a uniform grid with the median
sample interval by linear interpolation between neighbouring good samples
(:func:`fcrlive.signals.resample_uniform`). Gaps follow the one gap rule of :mod:`fcrlive.signals`:
a gap of ``MAX_FILL`` (1) missing sample is interpolated over; at a longer one (bad samples, daemon
down) or where the time goes back (device restart: its clock jumps back) the data is split into separate
segments, and segments shorter than ``MIN_SEGMENT`` grid points are dropped, so no filter of the
identification runs across a gap.

Accuracy depends on the sample interval in the device's time: Z_u (no excitation) needs ~0.1-0.2 s. A
simulator accelerated 60× and polled at 50 Hz gives 1.2 s and unusable droop estimates (docs/daemon.md).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from fcrlive.analysis.report import IdentifyReport

MIN_SEGMENT = 50
"""Shortest segment kept [grid points]."""
MAX_FILL = 1
"""Gaps of at most this many missing samples are interpolated over; longer ones start a new segment."""


def _finite(signals: dict[str, np.ndarray], name: str, ok: np.ndarray) -> bool:
    v = signals.get(name)
    return v is not None and bool(np.all(np.isfinite(v[ok])))


def window_to_plant_signals(signals: dict[str, np.ndarray], rated_mw: float, f0: float = 50.0):
    """The :class:`fcrlive.signals.PlantSignals` of a window (module docstring); DataError when the
    window has no usable data."""
    from fcrlive.errors import DataError
    from fcrlive.signals import PlantSignals, find_gaps, is_excited, median_interval, resample_uniform

    sig = {k: np.asarray(v, dtype=np.float64) for k, v in signals.items()}
    if "power" not in sig:
        raise DataError("the register map has no 'power' point: cannot identify")
    notes: list[str] = []
    if "control_error" in sig:
        yname = "control_error"
    elif "speed" in sig:
        yname = "speed"
    elif "grid_freq" in sig:
        yname = "grid_freq"
    else:
        raise DataError("the register map has none of control_error, speed, grid_freq: cannot identify")
    rname = next((n for n in ("excitation_written", "excitation_applied") if n in sig), None)
    if rname == "excitation_written" and not np.any(np.isfinite(sig[rname]) & (sig["ok"] > 0)):
        rname = "excitation_applied" if "excitation_applied" in sig else None
    needed = ["power", yname] + [n for n in (rname, "controller_output", "guide_vane") if n and n in sig]
    ok = sig["ok"] > 0
    for n in needed:
        ok &= np.isfinite(sig[n])
    n_ok = int(np.count_nonzero(ok))
    if n_ok < MIN_SEGMENT:
        raise DataError(f"only {n_ok} good samples in the window")
    use_device = _finite(sig, "device_time", ok)
    tt = sig["device_time"] if use_device else sig["t"]
    notes.append("time axis: device_time (the device's clock)" if use_device else
                 "time axis: arrival time (no device_time)")
    idx = np.flatnonzero(ok)
    t = tt[idx]
    # a device restart sets its clock back: keep the order of arrival, split where time does not advance
    Ts = median_interval(t)
    if math.isnan(Ts):
        raise DataError("sample times do not advance")
    gaps = find_gaps(t, ts=Ts, max_fill=MAX_FILL)

    def col(name: str) -> np.ndarray:
        return sig[name][idx]

    raw = {"power": col("power"), "y": col(yname)}
    exc = col(rname) if rname else np.zeros(idx.size)
    raw["exc"] = exc
    for n in ("controller_output", "guide_vane"):
        if n in sig:
            raw[n] = col(n)
    grid = resample_uniform(t, raw, Ts, gaps.segments, MIN_SEGMENT)
    segments = grid.segments
    n_total = grid.t.size
    if not segments:
        raise DataError(f"no gap-free stretch of at least {MIN_SEGMENT} samples in the window")
    cat = grid.columns
    p_mw = cat["power"]
    p0 = float(np.mean(p_mw))
    u = (p_mw - p0) / rated_mw
    r = cat["exc"] / f0
    if yname == "control_error":
        y = r - cat["y"]
        notes.append("y = r − control_error (the governor's own control error)")
    elif yname == "speed":
        y = cat["y"] - 1.0
        notes.append("y = speed − 1 (no control_error point)")
    else:
        y = (cat["y"] - f0) / f0
        notes.append("y = (grid_freq − f0)/f0 (no control_error or speed point)")
    has_exc = is_excited(cat["exc"])
    if has_exc:
        notes.append(f"r from {rname}")
    if len(segments) > 1:
        notes.append(f"window split into {len(segments)} gap-free segments")
    return PlantSignals(
        t=grid.t, Ts=Ts, u=u, y=y, r=r, epsilon=r - y,
        c=cat["controller_output"] / 100.0 if "controller_output" in cat else None,
        a=cat["guide_vane"] / 100.0 if "guide_vane" in cat else None,
        rated_mw=float(rated_mw), f0=float(f0), p0_mw=p0, has_excitation=has_exc,
        filled=np.zeros(n_total, dtype=bool), segments=tuple(segments), sources=("fcrlive daemon window",),
        notes=tuple(notes),
    )


def identify_window(signals: dict[str, np.ndarray], rated_mw: float, f0: float = 50.0,
                    plant: str | None = None, method: str = "auto", kd: float = 0.0,
                    power_lag_s: float | None = None, power_delay_s: float | None = None,
                    **_params: Any) -> IdentifyReport:
    """The plug-in: identify the window and return the report, with how the window became signals at
    the head of its ``notes``.

    ``plant`` is the path of a plant description file (its controller is used by ``zcu``) or None.
    ``power_lag_s``, ``power_delay_s``: the power transducer's lag and dead time [s]
    (:class:`fcrlive.signals.PowerChain`; neither given: Z_cu with H checks the window for one). Extra
    keyword parameters from newer daemons are accepted and ignored.
    """
    from fcrlive.analysis.identify import identify_signals
    from fcrlive.signals import PowerChain

    ps = window_to_plant_signals(signals, rated_mw, f0)
    plant_obj = None
    if plant:
        from fcrlive.plant.description import load_plant

        plant_obj = load_plant(plant)
    rep = identify_signals(ps, rated_mw=rated_mw, f0=f0, kd=kd, plant=plant_obj, method=method,
                           power_chain=(None if power_lag_s is None and power_delay_s is None
                                        else PowerChain(power_lag_s or 0.0, power_delay_s or 0.0)))
    return rep.model_copy(update={"notes": [*ps.notes, *rep.notes]})
