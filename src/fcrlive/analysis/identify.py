"""The whole-log identification pipeline: pick the method, identify, assess, report.

:func:`identify_signals` is pure (no I/O) and is what the daemon and the Monte Carlo call;
:func:`identify_files` reads TSO CSV logs and calls it. Method choice (``method="auto"``):

- every file is a sine-test log (period in the headers) → ``sine``;
- an excitation was applied (r = (GridFreq − ApplFreqSig)/f0 clearly above the columns' resolution,
  :func:`excitation_detected`) and the log is at the controller rate → ``zcu`` when ContOutSig and
  GuideVane are logged, else ``zur``. Without a plant description the controller rate is unknown: Z_cu's
  controller fit (:mod:`fcrlive.analysis.controller`) is exact only at it and says so; with H known, a
  controller that does not fit sends the log to ``lowband`` instead. With H known Z_cu takes G_J from
  the data sheet (:func:`fcrlive.analysis.experiments.zcu_swing`);
- otherwise, with H known (plant description or ``h``) → ``lowband`` (:mod:`fcrlive.analysis.lowband`:
  G_p from u − (2Hs + Kd) y on ε, robust to power-meter noise and to logs slower than the controller);
- otherwise ``zu``: without r the inputs of Z_cu and Z_ur are not excited independently (paper
  Sections 6.1-6.3).

With ``lowband`` the peaks max|G_1| and max|S| and the G_p/TSO points are reported only where the u-ε
coherence at their frequency is at least :data:`fcrlive.analysis.lowband.PEAK_MIN_COHERENCE`; otherwise
they are null with the reason (``IdentifyReport.not_identifiable``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from fcrlive.analysis import experiments as ex
from fcrlive.analysis import lowband as lb
from fcrlive.analysis import quality
from fcrlive.analysis.assess import OMEGA_MIN, PEAK_MIN_PERIOD_S, Assessment, assess, peak_band
from fcrlive.analysis.controller import ControllerFitError
from fcrlive.analysis.report import IdentifyReport, build_report
from fcrlive.blas import single_threaded
from fcrlive.constants import F0_HZ
from fcrlive.errors import DataError, UserError
from fcrlive.signals import PlantSignals, PowerChain, excitation_detected

METHODS = ("auto", "zu", "zur", "zcu", "sine", "lowband")

@dataclass(frozen=True, eq=False)
class Identification:
    """Everything behind a report (for plots and further analysis)."""

    report: IdentifyReport
    assessment: Assessment
    experiment: object


def choose_method(
    signals: Sequence[PlantSignals], *, h_known: bool = False, controller_ts: float | None = None
) -> tuple[str, str]:
    """(method, reason) for ``method="auto"`` (module docstring). ``h_known``: H is known (plant
    description or ``h``); ``controller_ts``: the governor's sample time [s] when known."""
    if all(s.period_s is not None for s in signals):
        return "sine", "sine-test logs (period in the headers): industry sine-test evaluation"
    if any(s.period_s is not None for s in signals):
        raise UserError("mix of sine-test and operation logs: identify them separately")
    excited = all(excitation_detected(s) for s in signals)
    ts = max(float(s.Ts) for s in signals)
    governor_cols = all(s.c is not None and s.a is not None for s in signals)
    # Without the controller's rate, an excited log with the governor's columns goes to Z_cu: its controller
    # fit is exact only at the controller rate and says so (analysis.controller); identify_full falls back
    # to lowband when it does not fit. Only a known controller rate marks a log slow beforehand.
    slow = ts > 1.5 * controller_ts if controller_ts else (ts > SLOW_LOG_S and not governor_cols)
    if h_known and (not excited or slow):
        why = "no excitation" if not excited else (
            f"log at {1.0 / ts:.3g} Hz, slower than the controller"
            + (f" ({1.0 / controller_ts:.3g} Hz)" if controller_ts else "")
        )
        return "lowband", (
            f"{why}, H known: G_p from the swing equation (lowband; robust to power-meter noise and to "
            "logs slower than the controller)"
        )
    if excited:
        if all(s.c is not None and s.a is not None for s in signals):
            return "zcu", "excitation applied and ContOutSig/GuideVane logged: Z_cu with Z_ca (paper 4.2.2)"
        return "zur", "excitation applied, no ContOutSig/GuideVane: Z_ur (paper 4.2.1)"
    return "zu", (
        "no excitation (ApplFreqSig absent or equal to GridFreq within the columns' resolution): Z_u, G_1 "
        "only (paper 4.2.1 eq. 16, 6.3); give H (--h or --plant) for G_p and the droop from lowband"
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
    ts_id: float | None = None,
    t_fme_s: float | None = None,
    peak_min_period_s: float = PEAK_MIN_PERIOD_S,
    h: float | None = None,
    power_chain: PowerChain | None = None,
) -> IdentifyReport:
    """Identify and assess; returns the report (see :func:`identify_full` for the objects behind it)."""
    return identify_full(
        signals, rated_mw=rated_mw, f0=f0, kd=kd, plant=plant, method=method, ts_id=ts_id, t_fme_s=t_fme_s,
        peak_min_period_s=peak_min_period_s, h=h, power_chain=power_chain,
    ).report


SLOW_LOG_S = 0.03
"""Logs sampled more slowly than this [s] get the warning on biased peaks for Z_cu/Z_ur (see below)."""


@single_threaded
def identify_full(
    signals: PlantSignals | Sequence[PlantSignals],
    *,
    rated_mw: float | None = None,
    f0: float = F0_HZ,
    kd: float = 0.0,
    plant=None,
    method: str = "auto",
    ts_id: float | None = None,
    t_fme_s: float | None = None,
    peak_min_period_s: float = PEAK_MIN_PERIOD_S,
    h: float | None = None,
    power_chain: PowerChain | None = None,
) -> Identification:
    """The pipeline (module docstring). ``plant``: an fcrlive Plant; its controller is used for Z_cu and
    its droop for the sine-test normalisation. ``peak_min_period_s``: shortest period of the band in which
    max|G_1| and max|S| are searched (analysis.assess.peak_band). Raises DataError/UserError with
    one-line messages. ``power_chain``: how the logged power lags the other columns (a transducer's lag
    and dead time, :class:`fcrlive.signals.PowerChain`); Z_cu with H takes it off u before it forms
    w = y + G_J u, and with None (not given) profiles the log for one and widens its intervals by the
    effect of one it finds (:func:`fcrlive.analysis.experiments.power_chain_profile`). The other
    methods do not use it: they fit u as an input, where the restored power's raised meter noise is
    errors in variables, and their droop rests on periods of minutes, where a sub-second chain does not
    show.

    Every report passes :func:`fcrlive.analysis.quality.withhold`: a quantity whose 95 % interval is
    missing, of zero width or wider than its value, and every quantity of a Z_ur search that did not
    converge, is null with the reason (``not_identifiable``), for the CLI, the daemon and prequal alike."""
    res = _identify(
        signals, rated_mw=rated_mw, f0=f0, kd=kd, plant=plant, method=method, ts_id=ts_id, t_fme_s=t_fme_s,
        peak_min_period_s=peak_min_period_s, h=h, power_chain=power_chain,
    )
    ni, note = _not_identifiable(res, kd=kd, t_fme_s=t_fme_s, peak_min_period_s=peak_min_period_s)
    rep = res.report
    if rep.method == "zu":
        # the errors-in-variables bound of Z_u's max|G_1| (quality.zu_eiv), before the width rule
        rep, ni_eiv, note = quality.zu_eiv(rep, res.experiment.coherence,
                                           low_edge_omega=OMEGA_MIN / PEAK_EDGE_FRACTION)
        ni.update(ni_eiv)
    if note:
        rep = rep.model_copy(update={"notes": [*rep.notes, note]})
    rep = quality.withhold(rep, ni)
    H = _inertia(h, plant)
    if power_chain is not None and power_chain.active and not (rep.method == "zcu" and H is not None):
        rep = rep.model_copy(update={"notes": [
            *rep.notes, f"{power_chain.describe()} given but not used: only Z_cu with H uses it (method "
            f"{rep.method})"]})
    if (rep.method == "zcu" and H is not None and rep.droop is not None and rep.droop.value is None
            and not rep.method_reason.startswith("requested")):
        rep = _droop_from_lowband(rep, signals, H=H, f0=f0, kd=kd, t_fme_s=t_fme_s,
                                  peak_min_period_s=peak_min_period_s)
    return replace(res, report=rep)


def _inertia(h: float | None, plant) -> float | None:
    """H [s] on the machine base: ``h`` when given, else the plant description's, else None (unknown)."""
    return h if h is not None else (plant.unit.swing.H if plant is not None else None)


def _droop_from_lowband(rep: IdentifyReport, signals, *, H: float, f0: float, kd: float, t_fme_s,
                        peak_min_period_s: float) -> IdentifyReport:
    """A Z_cu report whose droop is not identifiable, with the droop and G_1(0) of lowband on the same log
    where lowband gives them (marked ``method="lowband"``, Z_cu's reason in a note); else unchanged.

    Why: the Kd = 0 units at 0.1 % meter noise withhold Z_cu's droop (experiments.METER_MATERIAL_PCT), and a
    plant owner then had to run the log again with ``--method lowband``. lowband's droop rests on the low
    band, where the meter noise is small against the load's swings, and holds on these logs: on the zoo's
    excited logs at the controller rate (7 plants × ctl-0.1pct/ctl-ideal × 15/30/60 min × 10 seeds) it was
    covered 412/415 (5 withheld), B and G 60/60, median abs error 0.008 pp (docs/zoo.md)."""
    sigs = [signals] if isinstance(signals, PlantSignals) else list(signals)
    try:
        # Z_cu ran: the log is at the controller rate, the excitation in ε the governor's own
        low = quality.withhold(_identify_lowband(
            merge_signals(sigs), H=H, kd=kd, rated=rep.rated_mw, f0=f0, reason=rep.method_reason,
            t_fme_s=t_fme_s, peak_min_period_s=peak_min_period_s, excitation_in_input=True).report)
    except (DataError, UserError):
        return rep
    if low.droop is None or low.droop.value is None:
        return rep
    why = rep.droop.reason or rep.not_identifiable.get("droop", "")
    why = why.removeprefix(quality.NOT_IDENTIFIABLE + ": ")
    why = why.split("; --method lowband")[0]
    ni = {k: v for k, v in rep.not_identifiable.items() if k not in ("droop", "g1_static")}
    dropped = {rep.not_identifiable.get("droop"), rep.not_identifiable.get("g1_static"), rep.droop.reason}
    g1s = low.g1_static if low.g1_static is not None and low.g1_static.value is not None else None
    note = (f"droop{' and G_1(0)' if g1s is not None else ''} from lowband on the same log (the low band, "
            f"with the given H): Z_cu could not give it ({why})")
    return rep.model_copy(update={
        "droop": low.droop.model_copy(update={"method": "lowband"}),
        "g1_static": None if g1s is None else g1s.model_copy(update={"method": "lowband"}),
        "not_identifiable": ni,
        "warnings": [w for w in rep.warnings if w not in dropped],
        "notes": [*rep.notes, note],
    })


def _not_identifiable(res: Identification, *, kd: float = 0.0, t_fme_s: float | None = None,
                      peak_min_period_s: float = PEAK_MIN_PERIOD_S) -> tuple[dict[str, str], str | None]:
    """Quantities the method itself says it cannot give (beyond the width rule), and a note: of a Z_ur
    search that stopped short of the minimum, those one exact Newton step moves by more than half a
    standard error (quality.search_short; all of Z_ur when the step could not be made); the droop of the
    sine tests (the setting, not a measurement)."""
    rep, exp = res.report, res.experiment
    if rep.method == "zur":
        fit = exp.models["epsilon<-(u,r)"].report
        noise = quality.zur_process_noise(rep.max_abs_s.omega if rep.max_abs_s else None,
                                          (exp.coherence or {}).get("u-residual"),
                                          max_g1_omega=rep.max_abs_g1.omega if rep.max_abs_g1 else None)
        if exp.unpolished:
            # stopped after its first search (ex.zur's pre-check): the gate above withholds every quantity
            return noise, None
        if fit.converged or exp.newton is None:
            return {**noise, **quality.zur_not_converged(fit.converged, fit.stop_reason)}, None
        a2 = assess(replace(exp, responses=exp.newton), kd=kd, t_fme_s=t_fme_s,
                    peak_min_period_s=peak_min_period_s, products=())
        stepped = build_report(a2, method_reason="", samples=exp.n_samples, duration_s=exp.duration_s,
                               rated_mw=rep.rated_mw, f0=rep.f0_hz)
        short, note = quality.search_short(rep, stepped, fit.stop_reason)
        return {**noise, **short}, note
    if rep.method == "sine" and rep.droop is not None and rep.droop.value is not None:
        return {"droop": quality.SINE_DROOP.format(droop=100.0 * rep.droop.value)}, None
    return {}, None


def _identify(
    signals: PlantSignals | Sequence[PlantSignals],
    *,
    rated_mw: float | None,
    f0: float,
    kd: float,
    plant,
    method: str,
    ts_id: float | None,
    t_fme_s: float | None,
    peak_min_period_s: float,
    h: float | None,
    power_chain: PowerChain | None = None,
) -> Identification:
    """:func:`identify_full` before the quality rules."""
    sigs = [signals] if isinstance(signals, PlantSignals) else list(signals)
    if not sigs:
        raise UserError("no data")
    if method not in METHODS:
        raise UserError(f"unknown method {method!r}; use one of {', '.join(METHODS)}")
    rated = float(rated_mw if rated_mw is not None else sigs[0].rated_mw)
    H = _inertia(h, plant)
    tc = plant.unit.governor.Tc if plant is not None else None
    auto_method, auto_reason = choose_method(sigs, h_known=H is not None, controller_ts=tc)
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
    ts_default = ex.DEFAULT_TS_ID if ts_id is None else ts_id
    if method == "lowband":
        # the excitation in ε is the governor's own only on a log at its controller rate (lowband.lowband)
        at_rate = plant is not None and sig.Ts <= 1.5 * plant.unit.governor.Tc
        return _identify_lowband(sig, H=H, kd=kd, rated=rated, f0=f0, reason=reason, t_fme_s=t_fme_s,
                                 peak_min_period_s=peak_min_period_s, excitation_in_input=at_rate)
    if method in ("zur", "zcu") and not sig.has_excitation:
        raise DataError(
            f"--method {method} needs an excitation (ApplFreqSig differing from GridFreq); "
            "this log has none: use zu"
        )
    if method == "zcu":
        if plant is not None:
            controller = ex.controller_from_plant(plant)
        try:
            # With H (and Kd) from the data sheet G_J is known and only G_jp is fitted (ex.zcu_swing): the
            # fitted swing path of plain Z_cu was 35-100 % off on half the zoo and 68-74 % off at 0.1 %
            # meter noise, and its peaks with it, with intervals that excluded the truth.
            if H is not None:
                exp = ex.zcu_swing(sig, H=float(H), kd=kd, controller=controller,
                                   ts_id=ex.ZCU_TS_ID if ts_id is None else ts_id, power_chain=power_chain)
            else:
                exp = ex.zcu(sig, controller=controller, ts_id=ts_default, kd=kd)
        except ControllerFitError as exc:
            # Every quantity of Z_cu hangs on c/ε: with a controller that does not fit, none is identifiable
            # by Z_cu. With H known, auto answers from the low band instead (it needs no controller).
            if reason.startswith("requested") or H is None:
                raise
            why = f"Z_cu not possible: {exc.message}"
            return _identify_lowband(sig, H=H, kd=kd, rated=rated, f0=f0, reason=f"{why}; lowband instead",
                                     t_fme_s=t_fme_s, peak_min_period_s=peak_min_period_s)
        controller = exp.controller
        if exp.resid_failed and H is not None and not reason.startswith("requested"):
            # The data reject the Z_cu model (its residual still carries the excitation in the band): its
            # intervals are parameter uncertainty of a wrong model. Seen on a log at half the controller
            # rate with no plant description (zoo E, half-0.5pct): droop 4.44 [4.31, 4.56] % against 6 %.
            why = "; ".join(w for w in exp.warnings if w.startswith("residual test"))
            return _identify_lowband(sig, H=H, kd=kd, rated=rated, f0=f0,
                                     reason=f"Z_cu rejected by the data ({why}); lowband instead",
                                     t_fme_s=t_fme_s, peak_min_period_s=peak_min_period_s)
    elif method == "zur":
        exp = ex.zur(sig, ts_id=ts_default, stop_if_withheld=True)
    else:
        exp = ex.zu(sig, ts_id=ts_default)
    a = assess(exp, kd=kd, t_fme_s=t_fme_s, peak_min_period_s=peak_min_period_s)
    # With a plant description, "slow" means slower than its own controller; otherwise than a 50 Hz one.
    slow_log_s = 1.5 * plant.unit.governor.Tc if plant is not None else SLOW_LOG_S
    # Without one, a controller Z_cu fitted from this log says more than any default: its difference
    # equation held per log sample within what the columns' rounding explains (analysis.controller refuses
    # a fit 1.6-6 × above that, as on logs at half the controller rate), so the log is at the controller's
    # rate. The warning fired on every Z_cu of the zoo's 10 Hz governor (B) logged at 10 Hz.
    at_controller_rate = method == "zcu" and plant is None and exp.controller is not None
    if method in ("zcu", "zur") and sig.Ts > slow_log_s and not at_controller_rate:
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
    ni: dict[str, str] = {}
    if method == "zcu" and H is None:
        diag = lb.diagnostics(sig)
        ni = quality.zcu_meter_noise(diag.bands, diag.u_noise_pct_rated)
    rep = build_report(
        a,
        method_reason=reason,
        samples=exp.n_samples,
        duration_s=exp.duration_s,
        rated_mw=rated,
        f0=f0,
        sources=list(sig.sources),
        ts_id=exp.Ts,
        sample_interval_s=sig.Ts,
        segments=len(sig.segments),
        controller=controller,
        extra_warnings=extra,
        notes=list(exp.notes),
        not_identifiable=ni,
    )
    return Identification(rep, a, exp)


PEAK_EDGE_FRACTION = 0.9
"""A lowband maximum at or above this fraction of the peak band's upper end counts as the band's edge."""
PEAK_MIN_RISE = 2.0
"""A lowband maximum of |G_1| or |S| must be at least this multiple of the value at the band's low end to
count as a resonance. Physics, not tuning: G_1(0) is the droop (0.02-0.1 pu) and a governed unit's
max|G_1| is 0.5-1.1 (the zoo's truths: 12-36× G_1(0)); S rises from near 0."""
_PEAK_RESPONSE = {"max_abs_g1": "G_1", "max_abs_s": "S"}


def _identify_lowband(sig: PlantSignals, *, H, kd, rated, f0, reason, t_fme_s, peak_min_period_s,
                      excitation_in_input: bool = False) -> Identification:
    """The lowband experiment, assessed, with the peaks and G_p points gated by the coherence.
    ``excitation_in_input``: the log is known to be at the controller rate (lowband.lowband)."""
    if H is None:
        raise UserError("--method lowband needs the inertia constant H (--h or --plant)")
    exp = lb.lowband(sig, H=float(H), kd=kd, excitation_in_input=excitation_in_input)
    a = assess(exp, kd=kd, t_fme_s=t_fme_s, peak_min_period_s=peak_min_period_s)
    diag = lb.diagnostics(sig)
    ni: dict[str, str] = {}
    thr = lb.PEAK_MIN_COHERENCE
    band_lo, band_hi = peak_band(exp.Ts, peak_min_period_s)
    for key, pk in (("max_abs_g1", a.max_g1), ("max_abs_s", a.max_s)):
        if pk is None:
            continue
        if pk.omega <= band_lo / PEAK_EDGE_FRACTION:
            # G_1 and S of a governed unit rise from ω = 0 to a resonance; a maximum at the band's low end
            # is a fit without one (zoo: max|G_1| 93 % low, the static gain, with a narrow interval)
            ni[key] = (
                f"not identifiable from this log: the low-band fit has no resonance (its maximum is at the "
                f"low end of the band, ω = {pk.omega:.3g} rad/s)"
            )
            continue
        if pk.omega >= PEAK_EDGE_FRACTION * band_hi:
            # The fit at 5 s reaches ω ≤ band_hi only; a maximum at that edge is the edge, not a peak (on the
            # zoo: true peaks at 0.28-0.6 rad/s came out 17-96 % low here, with intervals that missed them).
            ni[key] = (
                f"not identifiable from this log: the maximum lies at the upper edge of the band the lowband "
                f"fit reaches (ω = {pk.omega:.3g} of ≤ {band_hi:.3g} rad/s); the true peak may be above it"
            )
            continue
        # the fit must carry the curve on both sides of the maximum: one whose maximum sits below the top
        # of the band it reaches, or where the coherence just passes below a band it has lost, has not
        # seen the peak (paper plant, 20 min, 12 dB: max|S| 1.09 [0.89, 1.28] at 0.185 rad/s, band up to
        # 0.25 rad/s, coherence 0.64 there and 0.09 at the true peak, 0.29 rad/s: excluded the truth 1.29)
        if lb.PEAK_BRACKET * pk.omega > band_hi:
            ni[key] = (
                f"not identifiable from this log: the maximum at ω = {pk.omega:.3g} rad/s is not followed by "
                f"{lb.PEAK_BRACKET:g}× its frequency inside the band the lowband fit reaches "
                f"(≤ {band_hi:.3g} rad/s); the true peak may be above it"
            )
            continue
        low = float(np.abs(exp.responses([band_lo])[_PEAK_RESPONSE[key]].value[0]))
        if not pk.value >= PEAK_MIN_RISE * low:
            # a maximum in the middle of the band that hardly rises above the low end is a flat curve, not a
            # resonance (zoo B at 2 Hz, 60 min, seed 14: max|G_1| 0.0424 [0.036, 0.048] at 0.158 rad/s, its
            # G_1(0.001) 0.0423; truth 0.677 at 0.30 rad/s, above the band the fit reaches)
            ni[key] = (
                f"not identifiable from this log: the low-band fit has no resonance (its maximum "
                f"{pk.value:.3g} at ω = {pk.omega:.3g} rad/s is less than {PEAK_MIN_RISE:g}× its value "
                f"{low:.3g} at ω = {band_lo:.3g} rad/s)"
            )
            continue
        for w in (pk.omega, lb.PEAK_BRACKET * pk.omega):
            coh, snr = diag.at(w)
            if not coh >= thr:
                ni[key] = (
                    f"not identifiable from this log: u-ε coherence {coh:.2f} at ω = {w:.3g} rad/s "
                    f"(needs ≥ {thr:g} at the maximum, ω = {pk.omega:.3g} rad/s, and up to "
                    f"{lb.PEAK_BRACKET:g}× it; u's SNR over its noise floor {snr:.0f} dB)"
                )
                break
    # G_p and the TSO checks need the band of 10-300 s periods; the fit at 5 s reaches 0.5 rad/s only
    w_lo, w_hi = 2 * np.pi / 300.0, 2 * np.pi / 10.0
    bad = [w for w in np.geomspace(w_lo, min(w_hi, 0.8 * np.pi / exp.Ts), 12) if not diag.at(w)[0] >= thr]
    if bad or w_hi > 0.8 * np.pi / exp.Ts:
        why = (
            f"not identifiable from this log: u-ε coherence {diag.at(bad[0])[0]:.2f} at ω = {bad[0]:.3g} "
            f"rad/s (needs ≥ {thr:g})" if bad else
            f"the lowband fit at Ts = {exp.Ts:g} s does not reach the 10 s period of the TSO band"
        )
        ni["gp"] = why
        ni["tso"] = why
    dq = {
        "u_noise_floor_pct_rated": float(diag.u_noise_pct_rated),
        "bands": [
            {"omega_lo": b.lo, "omega_hi": b.hi, "snr_u_db": b.snr_u_db, "coherence": b.coherence}
            for b in diag.bands
        ],
    }
    bands = ", ".join(f"{b.lo:g}-{b.hi:g}: {b.snr_u_db:.0f} dB, {b.coherence:.2f}" for b in diag.bands)
    notes = [*exp.notes, f"u noise floor ≈ {diag.u_noise_pct_rated:.3g} % of rated; per band (rad/s: "
             f"SNR_u dB, coherence): {bands}"]
    rep = build_report(
        a, method_reason=reason, samples=exp.n_samples, duration_s=exp.duration_s, rated_mw=rated, f0=f0,
        sources=list(sig.sources), ts_id=exp.Ts, sample_interval_s=sig.Ts, segments=len(sig.segments),
        notes=notes, not_identifiable=ni, data_quality=dq,
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
