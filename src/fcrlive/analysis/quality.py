"""Which numbers of an identification may be shown: a value with a usable 95 % interval, or null with the
reason (issue 12, "an honest result per quantity").

One place for the rules, applied by :func:`fcrlive.analysis.identify.identify_full` to every report, so
``fcrlive identify``, the daemon (its result-quality rule and MQTT topics) and ``fcrlive prequal`` give
the same verdicts. A withheld quantity is null (``value`` and ``ci95`` None) with its ``reason``, the
same reason is in ``IdentifyReport.not_identifiable`` under the quantity's key (the mechanism lowband's
coherence gate already uses, :func:`fcrlive.analysis.report.build_report`), and a warning says it once.

The rules, per scalar quantity (droop, G_1(0), max|G_1|, max|S|; :data:`QUANTITIES`):

- :func:`withhold_wide`: its 95 % interval is missing or not finite (a model without a covariance: the
  uncertainty is unknown, never zero), of zero width, inverted, does not contain the value, or is wider
  than |value|. An interval wider than its value says the log cannot tell the value from zero or from
  twice itself: no number one can use.
- :func:`zur_not_converged`: the Z_ur prediction-error search stopped without converging and no exact
  Newton step could be made from its end point (:data:`ZUR_NOT_CONVERGED`): every quantity of Z_ur (all
  come from that one fit) is withheld, with the search's own stop reason.
- the droop of a sine-test evaluation is the plant description's setting, not a measurement
  (:data:`SINE_DROOP`).
- per TSO period: G_p (and F) at a period whose |G_p| interval fails the width rule is null with the
  reason (key ``gp_<T>s``, :func:`gp_key`), and the TSO verdicts, which span the whole band, become
  ``undecided`` with the reason (:func:`withhold`).
- Z_ur: :func:`search_short` (a search that stopped short: only what one exact Newton step moves by more
  than half a standard error) and :func:`zur_process_noise` (Remark 7: the peaks, G_p and TSO withheld
  where the process noise makes a share of u; :func:`zur_fails_clearly`, the same gate on a first
  search's residual, lets the pipeline skip polishing a fit it would withhold whole); Z_u: :func:`zu_eiv`
  (max|G_1|'s interval widened by the errors-in-variables bias bound).

Pure: no I/O. Units as in the report (droop a fraction, shown in % in the reasons).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from fcrlive.analysis.report import IdentifyReport, PeakCI, PeriodValue, ValueCI
from fcrlive.constants import Z95

NOT_IDENTIFIABLE = "not identifiable from this log"
"""How every reason of the width rule begins (lowband's coherence gate says the same)."""

WIDE_HINT = "too little movement of frequency and power in the log for it"
"""Why an interval is wide, in words a plant owner can act on."""

QUANTITIES: tuple[tuple[str, str, float, str], ...] = (
    ("droop", "the droop", 100.0, " %"),
    ("g1_static", "G_1(0)", 1.0, ""),
    ("max_abs_g1", "max|G_1|", 1.0, ""),
    ("max_abs_s", "max|S|", 1.0, ""),
)
"""(report key, label, display scale, unit) of the scalar quantities the rules judge."""

WARN_MAX_S = "local stability (eq. 9): max|S| = "
WARN_GP0 = "identified G_p(0) = "
WARN_G1_0 = "identified G_1(1) = "
QUOTING_WARNINGS: tuple[tuple[str, tuple[str, ...]], ...] = (
    (WARN_MAX_S, ("max_abs_s",)),
    (WARN_GP0, ("droop", "g1_static", "gp")),
    (WARN_G1_0, ("droop", "g1_static")),
)
"""Assessment warnings (analysis.assess) that quote an identified number, by their start, and the report
keys they quote: :func:`withhold` drops such a warning once one of those is withheld. A withheld max|S|
went on as "local stability (eq. 9): max|S| = 12.688 ≥ M_s = 1.5" beside "not identifiable: max|S| 12.7
with a 95 % interval [0, 71.3]" (Z_ur at 6 dB): an alarm raised by the number the report refuses to give."""

ZUR_NOT_CONVERGED = "Z_ur search did not converge: {stop}; no quantity of Z_ur is identifiable from this log"
"""Reason of every Z_ur quantity when its Box-Jenkins search did not converge (``{stop}``: the search's
stop reason, e.g. "maximum number of iterations (78) reached")."""

SINE_DROOP = (
    "not measured by the sine tests: {droop:.3g} % is the droop setting of the plant description, used "
    "only to normalise F"
)
"""Reason of the droop of a sine-test evaluation: it is the setting, not an estimate (no interval)."""

ZUR_QUANTITIES = ("droop", "g1_static", "max_abs_g1", "max_abs_s", "gp", "tso")
"""Everything Z_ur reports (G_1, S and G_p = (1 − S)/G_1 all come from its one fit)."""


def _g(x: float) -> str:
    return f"{x:.3g}"


def withhold_wide(
    value: float | None,
    ci95: tuple[float | None, float | None],
    *,
    label: str = "the value",
    scale: float = 1.0,
    unit: str = "",
) -> str | None:
    """The reason to withhold one quantity (module docstring), or None when it may be shown.

    ``value`` and ``ci95`` in the report's units; ``scale`` and ``unit`` only format the reason (100 and
    " %" for the droop). A null value (None) is not judged: it is already withheld or not given."""
    if value is None:
        return None
    if not math.isfinite(value):
        return f"{NOT_IDENTIFIABLE}: {label} came out {value}, not a number"
    v = scale * value
    lo, hi = ci95
    if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
        return (f"{NOT_IDENTIFIABLE}: {label} {_g(v)}{unit} has no 95 % interval (the model gives no "
                "covariance: its uncertainty is unknown)")
    lo_s, hi_s = scale * lo, scale * hi
    span = f"[{_g(lo_s)}, {_g(hi_s)}]{unit}"
    if hi < lo:
        return f"{NOT_IDENTIFIABLE}: the 95 % interval {span} of {label} is inverted"
    if hi == lo:
        return (f"{NOT_IDENTIFIABLE}: the 95 % interval {span} of {label} has zero width (no uncertainty "
                "estimate, not an exact value)")
    tol = 1e-9 * abs(value)
    if not lo - tol <= value <= hi + tol:
        return f"{NOT_IDENTIFIABLE}: {label} {_g(v)}{unit} lies outside its own 95 % interval {span}"
    if hi - lo > abs(value):
        return (f"{NOT_IDENTIFIABLE}: {label} {_g(v)}{unit} with a 95 % interval {span} wider than the "
                f"value ({WIDE_HINT})")
    return None


def zur_not_converged(converged: bool, stop_reason: str) -> dict[str, str]:
    """``not_identifiable`` entries for a Z_ur fit: every Z_ur quantity when its search did not converge
    (:data:`ZUR_NOT_CONVERGED`), else none."""
    if converged:
        return {}
    why = ZUR_NOT_CONVERGED.format(stop=stop_reason or "no stop reason given")
    return dict.fromkeys(ZUR_QUANTITIES, why)


SEARCH_SHORT_SE = 0.5
"""A quantity of a Z_ur fit whose search stopped short is withheld when one exact Newton step from the
fit's end point moves it by more than this many of its standard errors (:func:`search_short`)."""

SEARCH_SHORT = (
    "Z_ur search stopped short of the minimum ({stop}): one exact Newton step from its end point moves "
    "{label} from {before} to {after}, {moved:.1f} standard errors (more than {limit:g}); "
    f"{NOT_IDENTIFIABLE} until the search reaches the minimum"
)
"""Reason of a Z_ur quantity the Newton step moved too far (:func:`search_short`)."""

SEARCH_SHORT_NOTE = (
    "Z_ur search stopped short of the minimum ({stop}); one exact Newton step from its end point moved "
    "each quantity shown by less than {limit:g} standard errors"
)


def _moved_se(value: float, after: float, ci95: tuple[float | None, float | None]) -> float:
    """|after − value| in standard errors of ``value``, the half-width of its 95 % interval on the side
    the step moved to (the droop's interval is not symmetric, a peak's may be cut at 0); inf when that
    half-width is unknown or zero (the width rule withholds such a value anyway)."""
    lo, hi = ci95
    end = hi if after >= value else lo
    if end is None or not math.isfinite(end) or not math.isfinite(after):
        return math.inf
    se = abs(end - value) / Z95
    return abs(after - value) / se if se > 0 else math.inf


def search_short(
    report: IdentifyReport, stepped: IdentifyReport, stop_reason: str, *, limit: float = SEARCH_SHORT_SE
) -> tuple[dict[str, str], str | None]:
    """``not_identifiable`` entries of a Z_ur fit whose search stopped short of the minimum, given the
    report of the same fit after one exact Newton step (``stepped``, :func:`fcrlive.ident.pem.newton_step`).

    Only what the step moves by more than ``limit`` standard errors is withheld (:data:`SEARCH_SHORT`):
    the rest sits at the minimum to within a fraction of its own uncertainty, which the interval already
    states. G_p at the TSO periods is judged per period (|G_p| against its interval, key
    :func:`gp_key`); :func:`withhold` then makes the TSO verdicts undecided. Returns the entries and a
    note for the report when something stays shown (None when all is withheld or nothing was judged)."""
    stop = stop_reason or "no stop reason given"
    out: dict[str, str] = {}
    for key, label, scale, unit in QUANTITIES:
        a, b = getattr(report, key), getattr(stepped, key)
        if a is None or a.value is None:
            continue
        after = b.value if b is not None and b.value is not None else math.nan
        k = _moved_se(a.value, after, a.ci95)
        if not k <= limit:
            out[key] = SEARCH_SHORT.format(stop=stop, label=label, before=f"{_g(scale * a.value)}{unit}",
                                           after=f"{_g(scale * after)}{unit}", moved=k, limit=limit)
    if report.gp:
        after = {p.period_s: p.abs for p in (stepped.gp or [])}
        for p in report.gp:
            if p.abs is None:
                continue
            a = after.get(p.period_s)
            a = math.nan if a is None else a
            k = _moved_se(p.abs, a, p.abs_ci95)
            if not k <= limit:
                out[gp_key(p.period_s)] = SEARCH_SHORT.format(
                    stop=stop, label=f"|G_p| at T = {p.period_s:g} s", before=_g(p.abs), after=_g(a), moved=k,
                    limit=limit)
    shown = [k for k, *_ in QUANTITIES if getattr(report, k) is not None
             and getattr(report, k).value is not None and k not in out]
    if not (shown or any(gp_key(p.period_s) not in out for p in report.gp or [])):
        return out, None
    note = SEARCH_SHORT_NOTE.format(stop=stop, limit=limit)
    return out, note


ZUR_NOISE_BAND = (0.05, 0.5)
"""ω band [rad/s] (periods 13-126 s) of the noise share judged for the whole Z_ur fit
(:func:`zur_process_noise`): the Welch estimate has no resolution nearer ω = 0, and the bias of the whole
fit follows the share of the noise in u over the band the model is fitted on."""

ZUR_MAX_NOISE_COHERENCE = 0.25
"""Largest coherence of u and Z_ur's residual near max|S| for S (and G_p, the TSO checks) to be shown
(:func:`zur_process_noise`)."""

ZUR_PROCESS_NOISE = (
    f"{NOT_IDENTIFIABLE}: process noise reaches the electric power and biases Z_ur's "
    "{what} (paper Remark 7): it makes {coh:.2f} of u at ω = {lo:.3g}-{omega:.3g} rad/s (mean coherence "
    "of u and the residual, needs ≤ {thr:g}); log ContOutSig and GuideVane for Z_cu or excite more"
)


def _mean_coherence(coherence, lo: float, hi: float) -> float:
    """The mean of ``coherence`` (ω → coherence) over [lo, hi] rad/s, on 32 points."""
    return float(np.mean(coherence(np.linspace(lo, hi, 32))))


def zur_process_noise(max_s_omega: float | None, coherence, *, max_g1_omega: float | None = None,
                      threshold: float = ZUR_MAX_NOISE_COHERENCE) -> dict[str, str]:
    """``not_identifiable`` entries for Z_ur's S, G_p and TSO checks when the process noise's share of u is
    not negligible where max|S| lies, for max|G_1| likewise where it lies (``max_g1_omega``), and for every
    quantity of Z_ur when it is not negligible over :data:`ZUR_NOISE_BAND` (the band the fit rests on: a
    biased fit, whatever a single peak's neighbourhood shows; on a 12-dB record of seeds 10-19 max|G_1|
    passed its own gate at −7 % with ±4.6 %). The
    paper's Remark 7: the noise reaches u through the loop without a delay, so the direct fit is biased,
    "limited if the contribution of the process noise in u is negligible"; the fit's interval does not
    contain that bias. The share is the coherence of u and the fit's residual, the mean from half the
    found peak frequency to it (the bias moves the peak up to twice its true frequency; a mean, not the
    one bin the peak sits on).

    ``coherence``: ω → that coherence (:attr:`fcrlive.analysis.experiments.ExperimentResult.coherence`,
    "u-residual"). Measured on paper-plant1, 30-min logs, seeds 0-9 (docs/identify.md): 0.02-0.13 at
    30 dB in every band of 0.1-0.7 rad/s (max|S| −0.8 … +2.3 %), 0.32-0.62 at 12 dB (max|S| +5 … +26 %,
    intervals ±7-9 %, 2 of 10 covering; max|G_1| −12 … +6 %, 5 of 8 covering; the droop −1 … 0 % of its
    value, ≤ 0.08 percentage points, covering on 5 of 10, one record in a wrong basin at +26 %). The r-ε
    coherence tried first overlapped (0.43-0.69 vs 0.35-0.60)."""
    if coherence is None:
        return {}
    out: dict[str, str] = {}
    lo_band, hi_band = ZUR_NOISE_BAND
    for lo, hi, what, keys in (
        (lo_band, hi_band, "fit (G_1, S and G_p)", ZUR_QUANTITIES),
        *(((0.5 * max_g1_omega, max_g1_omega, "G_1", ("max_abs_g1",)),) if max_g1_omega else ()),
        *(((0.5 * max_s_omega, max_s_omega, "S", ("max_abs_s", "gp", "tso")),) if max_s_omega else ()),
    ):
        if not hi > 0:
            continue
        coh = _mean_coherence(coherence, lo, hi)
        if coh > threshold:
            why = ZUR_PROCESS_NOISE.format(what=what, coh=coh, lo=lo, omega=hi, thr=threshold)
            for k in keys:
                out.setdefault(k, why)
    return out


ZUR_CLEAR_MARGIN = 0.15
"""How far above :data:`ZUR_MAX_NOISE_COHERENCE` the whole-fit coherence of Z_ur's FIRST search (one
start, no restarts) must lie for the pipeline not to polish the fit (:func:`zur_fails_clearly`): the
restarts, the Newton step and the polished fit's numbers would all be withheld by the Remark 7 gate anyway.
Measured (u-residual coherence over :data:`ZUR_NOISE_BAND`, first search vs every start, 107 excited
30-min records): paper-plant1 at 6/12/20/30 dB, seeds 0-9, 10 Hz and 50 Hz logs (50 Hz at 30 dB: seeds
0-2), seeds 100-105 at 12 dB on 10 Hz, and the zoo plants A-G (ctl-0.1pct logger, seeds 0-3). Every start
ended at most 0.085 below the first search (paper, 6 dB, 50 Hz, seed 5: 0.883 → 0.798; relatively at most
11 %: zoo E, seed 1, 0.411 → 0.364) and at most 0.082 above it. The 31 records beyond 0.25 + 0.15 = 0.40
after the first search (paper at 6 and 12 dB on 50 Hz logs, zoo B, E, F, G) were all above 0.36 after every
start, every quantity withheld; the four whose verdict the polish moved across the gate itself (0.232 →
0.257, 0.262 → 0.246, ...) lay below 0.28 and are polished as before. CPU of a withheld identification:
about 0.3 s instead of 1.0 s; the paper's plant at 12 dB on 10 Hz logs (0.13-0.27, shown) is unchanged."""

ZUR_UNPOLISHED_NOTE = (
    "Z_ur search not polished (one start, no restarts nor Newton step): the data fail the Remark 7 gate "
    "by more than {margin:g} (coherence of u and the first search's residual {coh:.2f} at ω = "
    "{lo:g}-{hi:g} rad/s, needs ≤ {thr:g}), so no quantity of Z_ur would be shown however far it is polished"
)
"""Note of a Z_ur fit stopped after its first search by :func:`zur_fails_clearly`."""


def zur_fails_clearly(coherence, *, threshold: float = ZUR_MAX_NOISE_COHERENCE,
                      margin: float = ZUR_CLEAR_MARGIN) -> str | None:
    """The note (:data:`ZUR_UNPOLISHED_NOTE`) when the whole-fit gate of :func:`zur_process_noise` fails by
    more than ``margin`` on ``coherence`` (ω → coherence of u and a first, unpolished fit's residual), so
    that polishing the fit cannot change the verdict (every quantity of Z_ur withheld;
    :data:`ZUR_CLEAR_MARGIN` for how much polishing moved it); else None. The margin is wide so that no
    verdict hangs on the rounding of a coherence near the gate."""
    if coherence is None:
        return None
    lo, hi = ZUR_NOISE_BAND
    coh = _mean_coherence(coherence, lo, hi)
    if not coh > threshold + margin:
        return None
    return ZUR_UNPOLISHED_NOTE.format(margin=margin, coh=coh, lo=lo, hi=hi, thr=threshold)


ZCU_MIN_U_SNR_DB = 20.0
"""Least SNR of u over its meter-noise floor [dB], in the bands of the peaks (:data:`ZCU_U_SNR_BAND`), for
Z_cu without H to show its peaks, G_p and the TSO checks (:func:`zcu_meter_noise`)."""
ZCU_U_SNR_BAND = (0.06, 0.4)
"""ω band [rad/s] where the loop's peaks lie, judged by :func:`zcu_meter_noise` (lowband's bands in it)."""

ZCU_METER_NOISE = (
    f"{NOT_IDENTIFIABLE}: " + "u's SNR over its noise floor is {snr:.0f} dB at ω = {lo:g}-{hi:g} rad/s "
    "(floor {floor:.2g} % of rated; needs ≥ {thr:g} dB): without H, Z_cu fits the swing path G_J from u, "
    "which the meter noise biases (errors in variables); give H (--h or --plant) for Z_cu with the data "
    "sheet's swing path"
)


def zcu_meter_noise(bands, floor_pct: float, *, threshold: float = ZCU_MIN_U_SNR_DB) -> dict[str, str]:
    """``not_identifiable`` entries for the peaks, G_p and the TSO checks of Z_cu WITHOUT H when u's band
    SNR over its meter-noise floor (``bands``: :class:`fcrlive.analysis.lowband.BandInfo` of
    :func:`fcrlive.analysis.lowband.diagnostics`) is below ``threshold`` in a band overlapping
    :data:`ZCU_U_SNR_BAND`.

    Why: without H, Z_cu fits G_J = y/u from the measured u; white meter noise on u makes that an
    errors-in-variables fit, biased by about 1/(1 + 10^(−SNR/10)) and more through the loop, and its
    intervals do not hold the bias. Measured on the zoo (30-min excited logs at the controller rate, seeds
    0-2, no H): with 0.1 % meter noise (SNR 3-20 dB at 0.06-0.4 rad/s) max|S| −28 … +143 % and max|G_1|
    −85 … −21 %, nearly all outside their intervals; on ideal logs (24-54 dB) the plants without derivative
    action and with Kd > 0 (A, E) within 3 %, covered. The droop (G_1 at ω → 0, where u's SNR is 35-40 dB
    even at 0.1 %) was within 1.8 % of its value and covered, so it stays. On the ideal logs it also
    withholds the Kd = 0 unit B (max|S| −25 … −28 % before). Not this gate's: process noise above the
    paper's 12 dB (paper-plant1 at 6 dB: max|S| +7 … +12 %, 2 of 8 covered) and F (+16 … +21 %), which the
    loop model's delay check withholds where they lean on the delay (experiments._loop_delay_check); still
    shown and missed on ideal logs: D max|S| −5 … −6 %, G max|G_1| −4 … −6 % (with H: right or withheld,
    docs/zoo.md)."""
    lo, hi = ZCU_U_SNR_BAND
    inside = [b for b in bands if b.hi > lo and b.lo < hi and np.isfinite(b.snr_u_db)]
    worst = min(inside, key=lambda b: b.snr_u_db, default=None)
    if worst is None or worst.snr_u_db >= threshold:
        return {}
    why = ZCU_METER_NOISE.format(snr=worst.snr_u_db, lo=worst.lo, hi=worst.hi, floor=floor_pct, thr=threshold)
    return {k: why for k in ("max_abs_g1", "max_abs_s", "gp", "tso")}


ZU_EIV_NOTE = (
    "max|G_1| interval widened by ±{b:.3g} ({pct:.0f} %), the errors-in-variables bias bound of Z_u at "
    "ω = {omega:.3g} rad/s: u-ε coherence {g_ue:.2f}, u-residual coherence {g_ur:.2f} (the process noise "
    "reaches u through the loop)"
)

ZU_EIV = (
    f"{NOT_IDENTIFIABLE}: " + "max|G_1| {value} with the errors-in-variables bias bound ±{b:.3g} of Z_u "
    "(u-ε coherence {g_ue:.2f}, u-residual coherence {g_ur:.2f} at ω = {omega:.3g} rad/s: the process noise "
    "reaches u through the loop) has a 95 % interval [{lo}, {hi}] wider than the value; an excitation "
    "(Z_ur, Z_cu) removes that bias"
)

ZU_LOW_EDGE = (
    f"{NOT_IDENTIFIABLE}: " + "the Z_u fit has no resonance (max|G_1| at the low end of the band, "
    "ω = {omega:.3g} rad/s: the static gain, not a peak)"
)


def zu_eiv(report: IdentifyReport, coherence: Mapping | None, *, low_edge_omega: float
           ) -> tuple[IdentifyReport, dict[str, str], str | None]:
    """Z_u's max|G_1| with the errors-in-variables bias bound in its interval, or withheld.

    Without an excitation u is driven by the process noise through the loop, so the noise in ε is
    correlated with u and the fit of G_1 = ε/u is biased; the fit's covariance does not contain that.
    With γ²_uε the coherence of u and ε and γ²_uê that of u and the fit's residual at the peak's ω (the
    share of the noise that the feedback put into u), the relative bias is at most
    √((1 − γ²_uε)/γ²_uε · γ²_uê) (the residual's cross-spectrum with u over u's spectrum, against
    |G_1|). The interval is widened by that bound × |max|G_1|| on both sides, then the width rule applies
    (:data:`ZU_EIV` when it is too wide). A maximum at the band's low end (``low_edge_omega``) is the
    static gain of a fit without a resonance (:data:`ZU_LOW_EDGE`). ``coherence``: "u-epsilon" and
    "u-residual", ω → γ² (:attr:`fcrlive.analysis.experiments.ExperimentResult.coherence`).

    Returns the report (max|G_1|'s interval widened), ``not_identifiable`` entries and a note."""
    pk = report.max_abs_g1
    if pk is None or pk.value is None or pk.omega is None or not coherence:
        return report, {}, None
    if pk.omega <= low_edge_omega:
        return report, {"max_abs_g1": ZU_LOW_EDGE.format(omega=pk.omega)}, None
    w = np.array([pk.omega])
    g_ue = float(coherence["u-epsilon"](w)[0])
    g_ur = float(coherence["u-residual"](w)[0])
    rel = math.sqrt(max(1.0 - g_ue, 0.0) / g_ue * g_ur) if g_ue > 0 else math.inf
    b = rel * abs(pk.value)
    lo, hi = pk.ci95
    if lo is None or hi is None:
        return report, {}, None  # the width rule withholds it
    lo2, hi2 = max(lo - b, 0.0), hi + b
    fmt = dict(b=b, g_ue=g_ue, g_ur=g_ur, omega=pk.omega)
    if not hi2 - lo2 <= abs(pk.value):
        why = ZU_EIV.format(value=_g(pk.value), lo=_g(lo2), hi=_g(hi2), **fmt)
        return report, {"max_abs_g1": why}, None
    widened = report.model_copy(update={"max_abs_g1": pk.model_copy(update={"ci95": (lo2, hi2)})})
    return widened, {}, ZU_EIV_NOTE.format(pct=100.0 * rel, **fmt)


def _null(key: str, reason: str) -> ValueCI:
    if key.startswith("max_abs"):
        return PeakCI(value=None, ci95=(None, None), omega=None, reason=reason)
    return ValueCI(value=None, ci95=(None, None), reason=reason)


def gp_key(period_s: float) -> str:
    """``not_identifiable`` key of G_p (and F) at one TSO period, e.g. "gp_10s"."""
    return f"gp_{period_s:g}s"


TSO_UNDECIDED = (
    "undecided: G_p at T = {periods} s, within the band the check spans, is not identifiable from this log"
)
"""Reason added to a TSO verdict made undecided by a withheld G_p point (:func:`withhold`)."""


def _null_point(p: PeriodValue, reason: str) -> PeriodValue:
    return PeriodValue(period_s=p.period_s, re=None, im=None, abs=None, phase_deg=None, abs_ci95=(None, None),
                       reason=reason)


def _period_update(report: IdentifyReport, given: Mapping[str, str], ni: dict[str, str],
                   warn) -> dict:
    """G_p and F per TSO period: a point in ``given`` (key :func:`gp_key`) or whose |G_p| interval fails
    the width rule is null with the reason, F at that period too; the TSO verdicts (each spans the whole
    10-300 s band) become undecided, saying which periods."""
    if not report.gp:
        return {}
    nulled: dict[float, str] = {}
    for p in report.gp:
        key = gp_key(p.period_s)
        if p.abs is None:
            continue
        label = f"|{report.gp_kind}| at T = {p.period_s:g} s"
        why = given.get(key) or withhold_wide(p.abs, p.abs_ci95, label=label)
        if why is not None:
            nulled[p.period_s] = why
            ni[key] = why
            warn(why)
    if not nulled:
        return {}
    upd: dict = {"gp": [_null_point(p, nulled[p.period_s]) if p.period_s in nulled else p for p in report.gp]}
    if report.f:
        upd["f"] = [_null_point(p, nulled[p.period_s]) if p.period_s in nulled else p for p in report.f]
    if report.tso:
        why = TSO_UNDECIDED.format(periods=", ".join(f"{t:g}" for t in nulled))
        upd["tso"] = {
            k: v.model_copy(update={"decision": "undecided",
                                    "reasons": [*v.reasons, why] if why not in v.reasons else v.reasons})
            for k, v in report.tso.items()
        }
    return upd


def withhold(report: IdentifyReport, not_identifiable: Mapping[str, str] | None = None) -> IdentifyReport:
    """The report with every rule applied (module docstring): the quantities in ``not_identifiable``
    (key -> reason, e.g. :func:`zur_not_converged`; they override the report's) and those the width rule
    rejects null with their reason, listed in the report's ``not_identifiable``, each reason once in the
    warnings. ``gp`` in ``not_identifiable`` nulls G_p, F and the TSO checks, ``tso`` the TSO checks,
    ``max_abs_s`` also the local checks (eq. 9-10, margins: the same S and loop). Otherwise G_p is judged
    per TSO period (:func:`_period_update`: key :func:`gp_key` given, or the width rule on |G_p|): a null
    point nulls F at that period and makes every TSO verdict undecided. The report itself when nothing is
    withheld."""
    given = dict(not_identifiable or {})
    ni = {**report.not_identifiable, **given}
    update: dict = {}
    warnings = list(report.warnings)

    def warn(why: str) -> None:
        if why not in warnings:
            warnings.append(why)

    for key, label, scale, unit in QUANTITIES:
        v = getattr(report, key)
        if key in given:
            update[key] = _null(key, given[key])
            warn(given[key])
            continue
        if v is None or v.value is None:
            continue
        why = withhold_wide(v.value, v.ci95, label=label, scale=scale, unit=unit)
        if why is not None:
            update[key] = _null(key, why)
            ni[key] = why
            warn(why)
    if "gp" in given:  # the TSO checks are made from G_p
        update.update(gp=None, f=None, tso=None)
    else:
        update.update(_period_update(report, given, ni, warn))
    if "tso" in given:
        update["tso"] = None
    if "max_abs_s" in given:  # eq. 9-10 and the loop margins come from the same S and L
        update["local"] = None
    if not update:
        return report
    withheld = set(ni) | ({"gp"} if "gp" in update and update["gp"] is None else set())
    warnings = [w for w in warnings
                if not any(w.startswith(start) and withheld.intersection(keys)
                           for start, keys in QUOTING_WARNINGS)]
    update.update(not_identifiable=ni, warnings=warnings)
    return report.model_copy(update=update)
