"""The whole-log identification pipeline: pick the method, identify, assess, report.

:func:`identify_signals` is pure (no I/O) and is what the daemon and the Monte Carlo call;
:func:`identify_files` reads TSO CSV logs and calls it. Method choice (``method="auto"``):

- every file is a sine-test log (period in the headers) → ``sine``;
- an excitation was applied (ApplFreqSig differs from GridFreq) → ``zcu`` when ContOutSig and GuideVane
  are logged, else ``zur``;
- no excitation → ``zu`` whatever else is logged: without r the inputs of Z_cu and Z_ur are not
  excited independently (paper Sections 6.1-6.3).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from fcrlive.analysis import experiments as ex
from fcrlive.analysis.assess import PEAK_MIN_PERIOD_S, Assessment, assess
from fcrlive.analysis.report import IdentifyReport, build_report
from fcrlive.constants import F0_HZ
from fcrlive.errors import DataError, UserError
from fcrlive.tso.signals import PlantSignals

METHODS = ("auto", "zu", "zur", "zcu", "sine")


@dataclass(frozen=True, eq=False)
class Identification:
    """Everything behind a report (for plots and further analysis)."""

    report: IdentifyReport
    assessment: Assessment
    experiment: object


def choose_method(signals: Sequence[PlantSignals]) -> tuple[str, str]:
    """(method, reason) for ``method="auto"`` (module docstring)."""
    if all(s.period_s is not None for s in signals):
        return "sine", "sine-test logs (period in the headers): industry sine-test evaluation"
    if any(s.period_s is not None for s in signals):
        raise UserError("mix of sine-test and operation logs: identify them separately")
    if all(s.has_excitation for s in signals):
        if all(s.c is not None and s.a is not None for s in signals):
            return "zcu", "excitation applied and ContOutSig/GuideVane logged: Z_cu with Z_ca (paper 4.2.2)"
        return "zur", "excitation applied, no ContOutSig/GuideVane: Z_ur (paper 4.2.1)"
    return "zu", (
        "no excitation (ApplFreqSig absent or equal to GridFreq): Z_u, G_1 only (paper 4.2.1 eq. 16, 6.3)"
    )


def merge_signals(signals: Sequence[PlantSignals]) -> PlantSignals:
    """Several logs of one unit as one multi-experiment PlantSignals (each file a segment)."""
    if len(signals) == 1:
        return signals[0]
    ts = {round(s.Ts, 9) for s in signals}
    if len(ts) > 1:
        raise DataError(f"logs with different sample intervals {sorted(ts)} s cannot be combined")
    cat = lambda k: np.concatenate([np.asarray(getattr(s, k)) for s in signals])  # noqa: E731
    segs, n = [], 0
    for s in signals:
        segs += [(a + n, b + n) for a, b in s.segments]
        n += len(s)
    has_c = all(s.c is not None for s in signals)
    has_a = all(s.a is not None for s in signals)
    t = np.concatenate([s.t + (i * 1e6) for i, s in enumerate(signals)])
    return replace(
        signals[0],
        t=t,
        u=cat("u"),
        y=cat("y"),
        r=cat("r"),
        epsilon=cat("epsilon"),
        c=cat("c") if has_c else None,
        a=cat("a") if has_a else None,
        filled=cat("filled"),
        segments=tuple(segs),
        has_excitation=all(s.has_excitation for s in signals),
        sources=tuple(x for s in signals for x in s.sources),
        notes=tuple(x for s in signals for x in s.notes),
    )


def identify_signals(
    signals: PlantSignals | Sequence[PlantSignals],
    *,
    rated_mw: float | None = None,
    f0: float = F0_HZ,
    kd: float = 0.0,
    plant=None,
    method: str = "auto",
    ts_id: float = ex.DEFAULT_TS_ID,
    t_fme_s: float | None = None,
    peak_min_period_s: float = PEAK_MIN_PERIOD_S,
) -> IdentifyReport:
    """Identify and assess; returns the report (see :func:`identify_full` for the objects behind it)."""
    return identify_full(
        signals, rated_mw=rated_mw, f0=f0, kd=kd, plant=plant, method=method, ts_id=ts_id, t_fme_s=t_fme_s,
        peak_min_period_s=peak_min_period_s,
    ).report


SLOW_LOG_S = 0.03
"""Logs sampled more slowly than this [s] get the warning on biased peaks for Z_cu/Z_ur (see below)."""


def identify_full(
    signals: PlantSignals | Sequence[PlantSignals],
    *,
    rated_mw: float | None = None,
    f0: float = F0_HZ,
    kd: float = 0.0,
    plant=None,
    method: str = "auto",
    ts_id: float = ex.DEFAULT_TS_ID,
    t_fme_s: float | None = None,
    peak_min_period_s: float = PEAK_MIN_PERIOD_S,
) -> Identification:
    """The pipeline (module docstring). ``plant``: an fcrlive Plant; its controller is used for Z_cu and
    its droop for the sine-test normalisation. ``peak_min_period_s``: shortest period of the band in which
    max|G_1| and max|S| are searched (analysis.assess.peak_band). Raises DataError/UserError with
    one-line messages."""
    sigs = [signals] if isinstance(signals, PlantSignals) else list(signals)
    if not sigs:
        raise UserError("no data")
    if method not in METHODS:
        raise UserError(f"unknown method {method!r}; use one of {', '.join(METHODS)}")
    rated = float(rated_mw if rated_mw is not None else sigs[0].rated_mw)
    auto_method, auto_reason = choose_method(sigs)
    if method == "auto":
        method, reason = auto_method, auto_reason
    else:
        reason = f"requested (auto would pick {auto_method})"
    extra: list[str] = []
    controller = None
    if method == "sine":
        if any(s.period_s is None for s in sigs):
            raise UserError("--method sine needs sine-test logs (period in the headers)")
        droop = plant.unit.governor.droop if plant is not None else None
        exp = ex.sine(sigs, droop=droop, t_fme_s=t_fme_s)
        a = assess(exp, t_fme_s=None)
        n = sum(len(s) for s in sigs)
        dur = sum(float(s.t[-1] - s.t[0]) for s in sigs)
        rep = build_report(
            a,
            method_reason=reason,
            samples=n,
            duration_s=dur,
            rated_mw=rated,
            f0=f0,
            sources=[x for s in sigs for x in s.sources],
            notes=[f"droop used: {exp.droop_source}"],
        )
        return Identification(rep, a, exp)
    sig = merge_signals(sigs)
    if method in ("zur", "zcu") and not sig.has_excitation:
        raise DataError(
            f"--method {method} needs an excitation (ApplFreqSig differing from GridFreq); "
            "this log has none: use zu"
        )
    if method == "zcu":
        if plant is not None:
            controller = ex.controller_from_plant(plant)
        exp = ex.zcu(sig, controller=controller, ts_id=ts_id)
        controller = exp.controller
    elif method == "zur":
        exp = ex.zur(sig, ts_id=ts_id)
    else:
        exp = ex.zu(sig, ts_id=ts_id)
    a = assess(exp, kd=kd, t_fme_s=t_fme_s, peak_min_period_s=peak_min_period_s)
    # With a plant description, "slow" means slower than its own controller; otherwise than a 50 Hz one.
    slow_log_s = 1.5 * plant.unit.governor.Tc if plant is not None else SLOW_LOG_S
    if method in ("zcu", "zur") and sig.Ts > slow_log_s:
        # The process noise on the governor's speed signal reaches c and ε unfiltered; logged below the
        # controller rate it aliases into the band as input noise (errors in variables), and the
        # controller's difference equation no longer holds per log sample. Measured on paper-plant1
        # (12 dB, 30 min, 10 Hz logs, seeds 0/1): droop +0.74/−0.94 pp with the identified controller,
        # −0.33/−0.00 pp with the plant description; max|S| −10 … +20 %, max|G_1| −30 … −57 %. Tried and
        # not enough: instrumental variables and windowed sums for the controller, the gate position
        # instead of c as input (max|S| still +13..+18 %); docs/identify.md.
        extra.append(
            f"log sampled every {sig.Ts * 1e3:.0f} ms, slower than a governor's controller rate: "
            "the droop, max|S|, max|G_1| and G_p from this method are biased, by up to about 1 percentage "
            "point of droop on the paper's plant (log at the controller rate, e.g. 20 ms, or give the "
            "plant description)"
        )
    if kd == 0.0:
        extra.append("Kd = 0 assumed: the droop shown is 1/(1/G_1(0)), i.e. including the speed damping")
    rep = build_report(
        a,
        method_reason=reason,
        samples=exp.n_samples,
        duration_s=exp.duration_s,
        rated_mw=rated,
        f0=f0,
        sources=list(sig.sources),
        ts_id=exp.Ts,
        controller=controller,
        extra_warnings=extra,
        notes=list(exp.notes),
    )
    return Identification(rep, a, exp)


def identify_files(
    paths: Sequence[str | Path], *, rated_mw: float, f0: float = F0_HZ, **kw
) -> Identification:
    """Read TSO logs and run :func:`identify_full`. DataError names the file at fault."""
    from fcrlive.tso.csvlog import read_log
    from fcrlive.tso.signals import plant_signals

    sigs = [plant_signals(read_log(p), rated_mw, f0=f0) for p in paths]
    return identify_full(sigs, rated_mw=rated_mw, f0=f0, **kw)
