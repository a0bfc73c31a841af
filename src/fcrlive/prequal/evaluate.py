"""Evaluate an application: every TSO log, the sine sets, the capacity and the verdict per service.

Pure: :class:`~fcrlive.tso.csvlog.TsoLog` objects and the unit's :class:`PrequalUnit` in, one
:class:`~fcrlive.prequal.model.PrequalResult` out (reading the files: :mod:`fcrlive.prequal.load`).

Capacity (eqs. 3 and 5): one reduction factor per service for all operating points (the TR allows
that or one per point), the smallest found over its tests; C = min(K_red,ss, K_red,dyn)·|ΔP_ss,theo|
at the largest |ΔP_ss,theo| over the unit's points. K_red,dyn comes from Req. 2-3 (ramps) and Req. 9
(the sine set; normal operation when there is none).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from types import MappingProxyType

import numpy as np

from fcrlive.constants import TSO_PERIODS_S
from fcrlive.errors import DataError, UserError
from fcrlive.plant.prequal_unit import DEFAULT_TEST_POINTS, PrequalUnit, exempt_tests
from fcrlive.prequal import freqdomain, measurement, timedomain
from fcrlive.prequal.catalog import SINE_ID, TestFile, classify
from fcrlive.prequal.common import BAND_HZ, K_RED_DYN_MIN_STATIC, K_RED_MIN, Context
from fcrlive.prequal.model import (
    SERVICES,
    Capacity,
    DocumentSpec,
    PrequalResult,
    RequirementResult,
    TestEvaluation,
    Verdict,
    document_spec,
)
from fcrlive.tso.csvlog import TsoLog
from fcrlive.tso.names import parse_tso_filename

POINT_IDS = {
    "Fcrn": ("1.1", "1.2", "1.3", "1.4"),
    "FcrdUp": ("2.1", "2.2", "2.3", "2.4"),
    "FcrdDo": ("3.1", "3.2", "3.3", "3.4"),
}
LINEARITY_IDS = {"Fcrn": ("5.1", "5.2"), "FcrdUp": ("6.1", "6.2"), "FcrdDo": ("7.1", "7.2")}
_ORDER = {s: i for i, s in enumerate(SERVICES)}

Identifier = Callable[[TsoLog, Context], object]
"""Runs the identification of a normal-operation log (default: :func:`default_identifier`, fcrlive's
auto pipeline with the unit's H and Kd)."""


def _point_name(test_id: str, unit: PrequalUnit | None) -> str:
    if unit is not None:
        pt = unit.point_for_test(test_id)
        if pt is not None:
            return pt.name
    c = DEFAULT_TEST_POINTS.get(test_id)
    return f"{c[0]} load, {c[1]} droop" if c else ""


def _dp_theo(log: TsoLog, service: str, test_id: str, unit: PrequalUnit | None) -> tuple[float | None, str]:
    if unit is not None:
        d = unit.dp_ss_theo(service, test_id)
        if d is not None:
            src = "unit description" if unit.point_for_test(test_id) else "unit description (largest point)"
            return float(d), src
    col = log.columns.get(f"RegStr_{service}")
    if col is not None and col.dtype.kind == "f":
        v = col[np.isfinite(col)]
        if v.size and np.all(v > 0) and np.ptp(v) <= 1e-9 * max(1.0, float(np.max(v))):
            return float(v[0]) * BAND_HZ[service], f"RegStr_{service} × {BAND_HZ[service]:g} Hz"
    return None, ""


def _context(log: TsoLog, tf: TestFile, file: str, unit: PrequalUnit | None, doc: DocumentSpec) -> Context:
    dp, src = _dp_theo(log, tf.service, tf.test_id, unit)
    dpn = None
    if tf.service != "Fcrn":
        dpn, _ = _dp_theo(log, "Fcrn", tf.test_id, unit)
    return Context(
        document=doc,
        service=tf.service,
        test_id=tf.test_id,
        file=file,
        dp_theo=dp,
        dp_theo_source=src,
        dp_theo_fcrn=dpn,
        operating_point=_point_name(tf.test_id, unit),
        mode_shifting=bool(unit and unit.mode_shifting),
        fcrd_static=bool(unit and unit.fcrd == "static"),
        rated_mw=unit.rated_mw if unit else None,
        t_fme_s=unit.t_fme_s if unit else None,
        fcrn_exemption=bool(unit and unit.fcrn_exemption),
        H=unit.H if unit else None,
        Kd=unit.Kd if unit else None,
        f0_hz=unit.f0_hz if unit else 50.0,
    )


def default_identifier(log: TsoLog, ctx: Context):
    """fcrlive's identification of a normal-operation log with the unit's H and Kd (method ``auto``: with H
    known a log without excitation goes to ``lowband``, G_p fitted directly with the power-meter noise as
    output noise and coherence-gated; without H, Z_u)."""
    from fcrlive.analysis.identify import identify_full
    from fcrlive.tso.signals import plant_signals

    sig = plant_signals(log, ctx.rated_mw, f0=ctx.f0_hz)
    return identify_full(sig, rated_mw=ctx.rated_mw, f0=ctx.f0_hz, kd=ctx.Kd or 0.0, h=ctx.H, method="auto")


def evaluate_log(
    log: TsoLog, unit: PrequalUnit | None, document: DocumentSpec, *, identifier: Identifier | None = None
) -> TestEvaluation:
    """One log: its test from the name, its requirements and its measurement-chain checks."""
    file = log.path.name if log.path is not None else (log.name.name if log.name is not None else "<memory>")
    name = log.name if log.name is not None else parse_tso_filename(file)
    tf = classify(name, log.period_s, where=file)
    ctx = _context(log, tf, file, unit, document)
    t = log.t_s
    if "InsAcPow" not in log.columns:
        raise DataError("no InsAcPow column (active power)", where=file)
    p = np.asarray(log.columns["InsAcPow"], float)
    notes: list[str] = []
    grid = log.columns.get("GridFreq")
    grid = np.asarray(grid, float) if grid is not None and grid.dtype.kind == "f" else None
    if ctx.dp_theo_source and ctx.dp_theo_source != "unit description":
        notes.append(f"|ΔP_ss,theo| = {ctx.dp_theo:.4g} MW from {ctx.dp_theo_source}")
    try:
        if tf.kind == "operation":
            if grid is None:
                raise DataError("no GridFreq column (grid frequency)")
            ident, ident_error = None, None
            if ctx.rated_mw is not None:
                try:
                    ident = (identifier or default_identifier)(log, ctx)
                except UserError as exc:  # e.g. too short for the method: Req. 8/9 undecided, not the run
                    ident_error = exc.message
            ev = freqdomain.evaluate_operation(t, grid, p, ctx, ident, sample_s=log.sample_s,
                                               identification_error=ident_error)
        else:
            f = log.columns.get("ApplFreqSig")
            if f is None or f.dtype.kind != "f":
                if grid is None:
                    raise DataError("no ApplFreqSig (applied frequency) nor GridFreq column")
                f = grid
                notes.append("no ApplFreqSig column: the profile is read from GridFreq")
            f = np.asarray(f, float)
            if tf.kind == "fcrn-steps":
                ev = timedomain.evaluate_fcrn_steps(t, f, p, ctx)
            elif tf.kind == "fcrd-ramps":
                kind = timedomain.fcrd_kind(t, f, tf.service)
                if kind == "fcrd-static":
                    ev = timedomain.evaluate_fcrd_static(t, f, p, ctx)
                else:
                    mode = log.columns.get(f"ContMode_{tf.service}")
                    ev = timedomain.evaluate_fcrd_ramps(t, f, p, ctx, mode=mode)
                if unit is not None and (kind == "fcrd-static") != (unit.fcrd == "static"):
                    notes.append(
                        f"the unit description says {unit.fcrd} FCR-D, the profile is the {kind} test"
                    )
            elif tf.kind == "linearity":
                ev = timedomain.evaluate_linearity(t, f, p, ctx)
            elif tf.kind == "sine":
                ev = freqdomain.evaluate_sine(t, f, p, tf.period_s, ctx)
            else:  # pragma: no cover - classify() returns only the kinds above
                raise DataError(f"unknown test kind {tf.kind!r}")
    except DataError as exc:
        raise DataError(exc.message, where=exc.where or file) from None
    checks = measurement.chain_checks(log.sample_s, p, grid, ev.kind, ctx)
    return dataclasses.replace(ev, checks=MappingProxyType(checks), notes=tuple(notes) + ev.notes)


def _sort_key(ev: TestEvaluation):
    return (
        _ORDER.get(ev.service, 9),
        ev.test_id,
        ev.kind == "sine-set",
        ev.figures.get("period_s", 0.0),
        ev.file,
    )


def evaluate_logs(
    logs: Sequence[TsoLog],
    unit: PrequalUnit | None = None,
    document: str | DocumentSpec = "nordic-2025",
    *,
    unit_name: str = "",
    identifier: Identifier | None = None,
    progress: Callable[[Sequence[TsoLog]], Sequence[TsoLog]] | None = None,
) -> PrequalResult:
    """The whole application (module docstring). ``progress`` wraps the iteration over the logs (e.g. a
    progress bar); the evaluation itself prints nothing."""
    doc = document if isinstance(document, DocumentSpec) else document_spec(document)
    tests = [evaluate_log(lg, unit, doc, identifier=identifier) for lg in (progress or list)(logs)]
    seen: dict[str, str] = {}
    for ev in tests:
        key = f"{ev.service} {ev.test_id} {ev.kind} {ev.figures.get('period_s', '')}"
        if key in seen:
            raise DataError(
                f"the same test as {seen[key]} (service {ev.service}, test {ev.test_id})", where=ev.file
            )
        seen[key] = ev.file
    # the sine sets
    for service in SERVICES:
        sines = [ev for ev in tests if ev.kind == "sine" and ev.service == service]
        if sines:
            ctx = Context(
                document=doc,
                service=service,
                test_id=SINE_ID[service],
                file="",
                dp_theo=None,
                operating_point=_point_name(SINE_ID[service], unit),
                fcrn_exemption=bool(unit and unit.fcrn_exemption),
            )
            tests.append(freqdomain.evaluate_sine_set(sines, ctx))
    tests.sort(key=_sort_key)
    services = (
        unit.services
        if unit is not None
        else tuple(s for s in SERVICES if any(e.service == s for e in tests))
    )
    capacity = {s: _capacity(s, tests, unit) for s in services}
    verdict = {s: _verdict(s, tests, unit, capacity[s]) for s in services}
    checks = {}
    if unit is not None:
        ctx = Context(document=doc, service="Fcrn", test_id="", file="", dp_theo=None)
        checks = measurement.accuracy_checks(
            unit.rated_mw, unit.power_accuracy_pct, unit.frequency_accuracy_mhz, ctx
        )
    notes = [f"evaluated against {doc.title} ({doc.key})"]
    ex = exemption_note(unit)
    if ex is not None:
        notes.append(ex)
    return PrequalResult(
        document=doc,
        unit=unit,
        tests=tuple(tests),
        capacity=MappingProxyType(capacity),
        verdict=MappingProxyType(verdict),
        notes=tuple(notes),
        unit_name=unit_name,
        checks=MappingProxyType(checks),
    )


# --------------------------------------------------------------------------------------------------


def required_periods(service: str, mode_shifting: bool) -> tuple[float, ...]:
    """Sine periods TR Table 6 asks for: all ten for FCR-N; 10-70 s for FCR-D, 90-300 s too with mode
    shifting."""
    if service == "Fcrn" or mode_shifting:
        return TSO_PERIODS_S
    return tuple(p for p in TSO_PERIODS_S if p <= 70.0)


def _is_static(service: str, tests: Sequence[TestEvaluation], unit: PrequalUnit | None) -> bool:
    if unit is not None:
        return unit.fcrd == "static"
    return any(e.kind == "fcrd-static" and e.service == service for e in tests)


def _frequency_source(service: str, tests: Sequence[TestEvaluation]) -> TestEvaluation | None:
    """The evaluation that answers Req. 8/9 for a service: its sine set; for FCR-D the other direction's
    (TR Table 2 *: one FCR-D sine test is enough with the same parameters); else normal operation."""
    for svc in (
        service,
        *(("FcrdDo",) if service == "FcrdUp" else ("FcrdUp",) if service == "FcrdDo" else ()),
    ):
        for e in tests:
            if e.kind == "sine-set" and e.service == svc:
                return e
    for e in tests:
        if e.kind == "operation" and e.service == service:
            return e
    return None


def _capacity(service: str, tests: Sequence[TestEvaluation], unit: PrequalUnit | None) -> Capacity:
    own = [e for e in tests if e.service == service and e.kind in ("fcrn-steps", "fcrd-ramps", "fcrd-static")]
    k_ss = [e.figures["k_red_ss"] for e in own if "k_red_ss" in e.figures]
    k_dyn = [e.figures["k_red_dyn"] for e in own if "k_red_dyn" in e.figures]
    src = [e.file for e in own if "k_red_ss" in e.figures or "k_red_dyn" in e.figures]
    fd = _frequency_source(service, tests)
    if fd is not None and "k_red_dyn" in fd.figures and not _is_static(service, tests, unit):
        k_dyn.append(fd.figures["k_red_dyn"])
        src.extend(fd.files)
    kss = min(k_ss) if k_ss else None
    kdyn = min(k_dyn) if k_dyn else None
    dp = unit.dp_ss_theo(service) if unit is not None else None
    if dp is None:
        ds = [
            e.figures["dp_ss_theo_mw"] for e in tests if e.service == service and "dp_ss_theo_mw" in e.figures
        ]
        dp = max(ds) if ds else None
    known = [k for k in (kss, kdyn) if k is not None]
    cap = min(known) * dp if known and dp is not None else None
    note = ""
    if dp is not None:
        note = "at the largest |ΔP_ss,theo| of the tested points"
    if len(own) and not k_ss:
        note += "; K_red,ss not determined"
    return Capacity(
        service, kss, kdyn, cap, dp, K_RED_MIN[service], tuple(dict.fromkeys(src)), note.strip("; ")
    )


def _k_min_for(r: RequirementResult, ev: TestEvaluation) -> float:
    if ev.kind == "fcrd-static" and r.number in ("2", "3"):
        return K_RED_DYN_MIN_STATIC
    return K_RED_MIN.get(ev.service, 0.9)


def _verdict(
    service: str, tests: Sequence[TestEvaluation], unit: PrequalUnit | None, cap: Capacity
) -> Verdict:
    failed: list[str] = []
    missing: list[str] = []
    static = _is_static(service, tests, unit)
    own = [e for e in tests if e.service == service]
    fd = _frequency_source(service, tests)
    relevant = [e for e in own if e.kind not in ("sine-set", "operation")]
    if fd is not None and not static:
        relevant.append(fd)
    for e in relevant:
        keys = list(e.requirements)
        for key, r in e.requirements.items():
            if any(k.startswith(key + "-") for k in keys):
                continue  # a summary of the suffixed entries, counted through them

            if r.passed is False:
                if r.k_red is not None and r.k_red >= _k_min_for(r, e) - 1e-12:
                    continue  # met with a capacity reduction (Capacity)
                failed.append(f"Req. {r.number} {r.title}: {_fmt(r)} ({e.file})")
            elif r.passed is None:
                missing.append(f"Req. {r.number} undecided ({e.file}): {r.note}")
        for key, r in e.checks.items():
            if r.passed is False and key == "sampling":
                failed.append(f"TR 4.3 sampling interval {r.value:g} s > {r.limit:g} s ({e.file})")
    for k, name in ((cap.k_red_ss, "K_red,ss"), (cap.k_red_dyn, "K_red,dyn")):
        if k is not None and k < cap.k_min - 1e-12:
            failed.append(f"{name} = {k:.3f} below the minimum {cap.k_min:g}")
    # tests the programme needs
    ramp_kind = "fcrd-static" if static else "fcrd-ramps"
    kind = "fcrn-steps" if service == "Fcrn" else ramp_kind
    have = {e.test_id for e in own if e.kind == kind}
    exempt = _exempt(POINT_IDS[service], unit)
    for tid in POINT_IDS[service]:
        if tid not in have and tid not in exempt:
            what = (
                "step sequence" if service == "Fcrn" else ("static ramp test" if static else "fast ramp test")
            )
            missing.append(f"{what} {tid} ({_point_name(tid, unit)}){_EXEMPTION_HINT.get(tid[-1], '')}")
    if not static:
        if fd is None:
            missing.append(f"sine tests {SINE_ID[service]} (Req. 8, 9, 10)")
        elif fd.kind == "sine-set":
            periods = {pt.period_s for pt in fd.points}
            need = required_periods(service, bool(unit and unit.mode_shifting))
            lack = [p for p in need if all(abs(p - q) > 1e-9 for q in periods)]
            if lack:
                missing.append(f"sine test periods {', '.join(f'{p:g}' for p in lack)} s ({fd.service})")
    ops = [e for e in tests if e.kind == "operation"]
    if service == "Fcrn" and not ops:
        missing.append("1 hour of normal operation (Operation, ≥ 1 Hz, FCR-N at high load, low droop)")
    elif service == "Fcrn" and max(e.figures.get("duration_s", 0.0) for e in ops) < 3600.0 - 60.0:
        longest = max(e.figures.get("duration_s", 0.0) for e in ops)
        missing.append(f"1 hour of normal operation (the longest log covers {longest / 60:.0f} min)")
    non_continuous = unit is not None and not unit.continuous
    if static or non_continuous:
        lin = {e.test_id for e in own if e.kind == "linearity"}
        exempt = _exempt(LINEARITY_IDS[service], unit)
        missing.extend(
            f"linearity steps {tid}" for tid in LINEARITY_IDS[service] if tid not in lin and tid not in exempt
        )
    if not any(e.figures.get("endurance_variant") == 1.0 for e in tests):
        missing.append("endurance (15-min variant of a step or ramp test, Req. 12)")
    status = "fail" if failed else ("incomplete" if missing else "pass")
    return Verdict(service, status, tuple(missing), tuple(failed))


_EXEMPTION_HINT = {
    "2": "; TR 5.1: not needed at a single droop (unit.prequal.single_droop)",
    "3": "; TR 5.1: not needed at a single set point (unit.prequal.single_setpoint)",
    "4": "; TR 5.1: not needed at a single set point or droop (unit.prequal.single_setpoint/single_droop)",
}
"""Appended to a missing corner test (x.2-x.4) so that a unit at one set point or droop finds the key."""


def _exempt(test_ids: tuple[str, ...], unit: PrequalUnit | None) -> tuple[str, ...]:
    if unit is None:
        return ()
    return exempt_tests(test_ids, unit.single_setpoint, unit.single_droop)


def exemption_note(unit: PrequalUnit | None) -> str | None:
    """The TR 5.1 exemptions the unit claims, with the tests they omit, for the result's notes."""
    if unit is None or not (unit.single_setpoint or unit.single_droop):
        return None
    claims = (("a single power set point", unit.single_setpoint), ("a single droop", unit.single_droop))
    why = " and ".join(w for w, on in claims if on)
    ids = [t for fam in (*POINT_IDS.values(), *LINEARITY_IDS.values()) for t in _exempt(fam, unit)]
    return f"TR 5.1 exemption: FCR at {why}; tests {', '.join(ids)} are not needed"


def _fmt(r: RequirementResult) -> str:
    if r.value is None:
        return "no value"
    lim = r.limit
    if isinstance(lim, tuple):
        return f"{r.value:.4g} outside [{lim[0]:g}, {lim[1]:g}]"
    return f"{r.value:.4g} {'fails ' + r.comparison} {lim:.4g}"
