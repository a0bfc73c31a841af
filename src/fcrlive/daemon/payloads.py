"""MQTT payloads (pydantic models), the topic tree, and the generator of docs/mqtt.md.

Every topic lives under ``<base_topic>/<unit>/`` (``fcrlive/G1/...``). Times are UNIX seconds (UTC)
as floats plus an ISO 8601 copy for humans. ``python -m fcrlive.daemon.payloads docs/mqtt.md``
rewrites the documentation from the models below, so the JSON Schemas in the docs never drift.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from fcrlive.analysis.report import Bounds, IdentifyReport, PeakCI, ValueCI


def iso(t: float) -> str:
    """UNIX time [s] → ISO 8601 UTC with milliseconds."""
    return datetime.fromtimestamp(t, UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


class _Payload(BaseModel):
    # JSON has no NaN: pydantic writes NaN/inf as null (ser_json_inf_nan="null", said explicitly)
    model_config = ConfigDict(extra="forbid", ser_json_inf_nan="null")


class Window(_Payload):
    """The analysed stretch of data."""

    start: float = Field(description="window start [UNIX s]")
    end: float = Field(description="window end [UNIX s]")
    start_iso: str
    end_iso: str

    @classmethod
    def of(cls, t1: float, t2: float) -> Window:
        return cls(start=t1, end=t2, start_iso=iso(t1), end_iso=iso(t2))


class DataQuality(_Payload):
    """How good the window's data was."""

    ok_fraction: float = Field(ge=0, le=1, description="fraction of expected samples with quality ok")
    samples: int = Field(ge=0, description="rows stored in the window")
    expected: int = Field(ge=0, description="samples expected at the configured rate")
    counts: dict[str, int] = Field(description="samples per quality flag (ok, stale, missing, ...)")
    gaps: int = Field(ge=0, description="number of stretches without good samples")
    gap_s: float = Field(ge=0, description="total length of those stretches [s]")


QualityLevel = Literal["ok", "uncertain", "rejected"]


class QuantityQuality(_Payload):
    """The quality rule's verdict on one published number (docs/daemon.md, "Result quality")."""

    level: QualityLevel = Field(description='"ok", "uncertain" (interval wide) or "rejected"')
    reasons: list[str] = Field(default_factory=list, description="why not ok, one line each")


class ResultQuality(_Payload):
    """The quality rule's verdict on one identification run: the worst of its numbers' levels."""

    level: QualityLevel = Field(description='"ok", "uncertain" or "rejected" (the headline topics keep '
                                            'their previous values)')
    reasons: list[str] = Field(default_factory=list,
                               description='why not ok, "<key>: ..." per number; the error of a failed run')
    quantities: dict[str, QuantityQuality] = Field(
        default_factory=dict, description="the verdict per judged number (droop, max_abs_s, max_abs_g1)")
    not_identifiable: dict[str, str] = Field(
        default_factory=dict,
        description="quantities the identification says this window cannot give (max_abs_s, max_abs_g1, gp, "
                    "tso, ...) -> why; not judged, and their topics keep the last published values")


class ResultQualityPayload(ResultQuality):
    """``result_quality``: the quality verdict of the latest identification run (retained)."""

    t: float = Field(description="when the run finished [UNIX s]")
    window_end: float = Field(description="end of the data window [UNIX s]")


class ResultPayload(_Payload):
    """``result/latest``: the whole outcome of one identification run (retained)."""

    unit: str
    t: float = Field(description="when the run finished [UNIX s]")
    t_iso: str
    window: Window
    method: str
    ok: bool = Field(description="false when the run was skipped or failed (see error)")
    error: str | None = None
    duration_s: float = Field(description="wall time of the identification [s]")
    quality: DataQuality
    result: IdentifyReport | None = Field(
        description="the identification report (docs/identify.md), null when the run was skipped or failed")
    result_quality: ResultQuality | None = Field(
        None, description="the quality rule's verdict; rejected also for a skipped or failed run")


SKIPPED_TOO_LITTLE_DATA = "too little good data"
"""How ``ResultPayload.error`` starts when a window was skipped for missing samples (not a failed fit)."""


def is_data_skip(msg: dict) -> bool:
    """True for a ``result/latest`` message (as JSON) of a window skipped for too little good data."""
    return not msg["ok"] and (msg.get("error") or "").startswith(SKIPPED_TOO_LITTLE_DATA)


class ExcitationEventPayload(_Payload):
    """``excitation``: every change of the excitation's state, with the safety guard's reasons (retained)."""

    t_wall: float = Field(description="when the state changed [UNIX s]")
    state: str = Field(description='"active", "inhibited", "ramping", "stopped", "link_down" or "fault"')
    reasons: list[str] = Field(description="the guard's reasons, e.g. frequency_out_of_band, holdoff")
    detail: str = ""


class ScalarPayload(_Payload):
    """``droop``, ``max_abs_s``, ``max_abs_g1``: one estimated number with its 95 % interval (retained)."""

    t: float = Field(description="when the estimate was made [UNIX s]")
    window_end: float = Field(description="end of the data window it is based on [UNIX s]")
    value: float | None
    ci95: Bounds = Field(description="95 % interval [lower, upper] (same unit; not symmetric in general, "
                                     "e.g. the droop's); an end is null where unknown")
    omega: float | None = Field(None, description="for peaks: ω of the maximum [rad/s]")
    unit: str = ""
    reason: str | None = Field(None, description="why value is null (not identifiable from this window)")
    quality: QuantityQuality | None = Field(None, description="the quality rule's verdict on this number")
    method: str | None = Field(None, description="the method that gave this number when it is not the "
                                                 "identification's own (e.g. lowband for a Z_cu droop)")


class TsoVerdictPayload(_Payload):
    """``tso/<product>`` (fcrn, fcrd, fcrd_up, fcrd_down): Nordic TR v1.1 checks on the identified model."""

    t: float
    window_end: float
    product: Literal["fcrn", "fcrd", "fcrd_up", "fcrd_down"]
    verdict: Literal["pass", "fail", "undecided", "unknown"] = Field(
        description="the report's `decision`: pass/fail only when the 95 % interval of every margin is "
                    "clear of its limit, undecided otherwise (docs/tso-checks.md); unknown: G_p not "
                    "identifiable")
    details: dict[str, Any] = Field(default_factory=dict,
                                    description="the report's `tso.<product>` without `pass` (margins "
                                                "with their 95 % bounds, reasons, ...), or `{reason}` when "
                                                "unknown")


class GpPayload(_Payload):
    """``gp``: the identified closed-loop power response G_p(jω) at the TSO periods (retained)."""

    t: float
    window_end: float
    periods_s: list[float]
    gain: list[float | None] = Field(description="|G_p| [pu/pu]")
    phase_deg: list[float | None] = Field(description="arg G_p [deg]")


class SignalStats(_Payload):
    """Statistics of one signal over the statistics interval (good samples only)."""

    mean: float | None
    std: float | None
    min: float | None
    max: float | None


class LiveStatsPayload(_Payload):
    """``live``: low-rate statistics of the raw signals, every ``stats_interval_s`` (not retained)."""

    t: float
    interval_s: float = Field(description="length of the interval the statistics cover [s]")
    samples: int
    rate_hz: float = Field(description="samples per second actually stored")
    quality: dict[str, int] = Field(description="samples per quality flag in the interval")
    missed_ticks: int
    signals: dict[str, SignalStats]


@dataclass(frozen=True)
class Topic:
    """One entry of the topic tree (``suffix`` is relative to ``<base>/<unit>/``)."""

    suffix: str
    model: type[BaseModel] | None
    retained: bool
    qos: int
    doc: str


TOPICS: tuple[Topic, ...] = (
    Topic("status", None, True, 1,
          'plain text "online" (birth, on connect) / "offline" (will, and on clean shutdown)'),
    Topic("result/latest", ResultPayload, True, 1, "the latest identification run, complete"),
    Topic("droop", ScalarPayload, True, 1, "estimated droop ρ [%] (key `droop` of the result)"),
    Topic("max_abs_s", ScalarPayload, True, 1, "peak sensitivity max|S| (key `max_abs_s`)"),
    Topic("max_abs_g1", ScalarPayload, True, 1, "peak disturbance response max|G_1| (key `max_abs_g1`)"),
    Topic("tso/fcrn", TsoVerdictPayload, True, 1, "FCR-N verdict (key `tso.fcrn`)"),
    Topic("tso/fcrd", TsoVerdictPayload, True, 1, "FCR-D verdict, both directions (key `tso.fcrd`)"),
    Topic("tso/fcrd_up", TsoVerdictPayload, True, 1, "FCR-D upwards verdict (key `tso.fcrd_up`)"),
    Topic("tso/fcrd_down", TsoVerdictPayload, True, 1, "FCR-D downwards verdict (key `tso.fcrd_down`)"),
    Topic("gp", GpPayload, True, 1, "G_p(jω) at the TSO periods (key `gp`)"),
    Topic("quality", DataQuality, True, 1, "data quality of the latest analysed window"),
    Topic("result_quality", ResultQualityPayload, True, 1,
          "quality verdict of the latest run: ok / uncertain / rejected and why"),
    Topic("live", LiveStatsPayload, False, 0, "signal statistics every stats_interval_s"),
    Topic("excitation", ExcitationEventPayload, True, 1,
          "excitation state changes (active / inhibited and why), when writing is enabled"),
)


TSO_PRODUCTS = ("fcrn", "fcrd", "fcrd_up", "fcrd_down")


HEADLINE_SCALARS = ("droop", "max_abs_s", "max_abs_g1")


def _scalar(x: ValueCI | PeakCI, t: float, t2: float, unit: str, scale: float = 1.0,
            not_identifiable_reason: str | None = None) -> ScalarPayload:
    """One headline number of the report as published (``scale`` 100: the droop fraction in %)."""
    lo, hi = (None if c is None else c * scale for c in x.ci95)
    if x.value is None:  # not identifiable: no number, no interval, no ω (even if the report kept one)
        return ScalarPayload(t=t, window_end=t2, value=None, ci95=(None, None), unit=unit,
                             reason=x.reason or not_identifiable_reason)
    return ScalarPayload(t=t, window_end=t2, value=x.value * scale,
                         ci95=(lo, hi), omega=x.omega if isinstance(x, PeakCI) else None, unit=unit,
                         method=x.method)


def not_identifiable(r: IdentifyReport) -> dict[str, str]:
    """Quantity -> why the identification could not give it from this window: the report's
    ``not_identifiable`` and the reason of any headline quantity that is null with one."""
    out = dict(r.not_identifiable)
    for key in HEADLINE_SCALARS:
        x = getattr(r, key)
        if x is not None and x.value is None and x.reason:
            out.setdefault(key, x.reason)
    return out


def headline_scalars(r: IdentifyReport, t: float = 0.0, t2: float = 0.0) -> dict[str, ScalarPayload]:
    """``droop`` [%], ``max_abs_s`` and ``max_abs_g1`` of a report as they are published. The peaks the
    method could not give (null in the report) and those the identification says this window cannot give
    (null with a reason, :func:`not_identifiable`) are left out: never a number on their topics. The droop
    is always there (null with its reason when not identifiable; the quality rule rejects such a run)."""
    ni = not_identifiable(r)
    out: dict[str, ScalarPayload] = {}
    if r.droop is not None:
        out["droop"] = _scalar(r.droop, t, t2, "%", 100.0, ni.get("droop"))
    for key, x in (("max_abs_s", r.max_abs_s), ("max_abs_g1", r.max_abs_g1)):
        if x is not None and key not in ni:
            out[key] = _scalar(x, t, t2, "")
    return out


def _tso_verdicts(r: IdentifyReport, t: float, t2: float) -> dict[str, TsoVerdictPayload]:
    """``tso/<product>`` of a report; ``tso`` null (G_p not identifiable) → ``unknown`` for FCR-N/D."""
    if r.tso is None:
        why = r.not_identifiable.get("tso") or r.not_identifiable.get("gp") or next(
            (w for w in r.warnings if "G_p" in w or "excitation" in w),
            "G_p not identifiable from this window")
        return {f"tso/{k}": TsoVerdictPayload(t=t, window_end=t2, product=k, verdict="unknown",
                                              details={"reason": why}) for k in ("fcrn", "fcrd")}
    return {f"tso/{k}": TsoVerdictPayload(t=t, window_end=t2, product=k,
                                          verdict=v.verdict,
                                          details=v.model_dump(mode="json", exclude={"passed"}))
            for k, v in r.tso.items() if k in TSO_PRODUCTS}


def result_topics(res: ResultPayload) -> dict[str, BaseModel]:
    """Split a result into its topics: ``result/latest``, ``quality``, ``result_quality`` (when judged)
    and, from the report: ``droop``, ``max_abs_s``, ``max_abs_g1`` (those the method gives),
    ``tso/<product>`` (``unknown`` for FCR-N and FCR-D when G_p was not identifiable) and ``gp``.

    A failed run or one whose ``result_quality`` is ``rejected`` publishes none of the headline topics
    (droop ... gp): a dashboard keeps showing the last acceptable values, each with its ``window_end``,
    and reads why from ``result_quality``. Each published number carries its own verdict in ``quality``."""
    out: dict[str, BaseModel] = {"result/latest": res, "quality": res.quality}
    t, t2 = res.t, res.window.end
    rq = res.result_quality
    if rq is not None:
        out["result_quality"] = ResultQualityPayload(t=t, window_end=t2, **rq.model_dump())
    r = res.result
    if not res.ok or r is None or (rq is not None and rq.level == "rejected"):
        return out
    for key, p in headline_scalars(r, t, t2).items():
        out[key] = p if rq is None or key not in rq.quantities else \
            p.model_copy(update={"quality": rq.quantities[key]})
    out.update(_tso_verdicts(r, t, t2))
    if r.gp:
        out["gp"] = GpPayload(t=t, window_end=t2, periods_s=[p.period_s for p in r.gp],
                              gain=[p.abs for p in r.gp], phase_deg=[p.phase_deg for p in r.gp])
    return out


def to_bytes(payload: BaseModel | str) -> bytes:
    """Wire form: compact JSON for models, UTF-8 for plain strings."""
    return payload.encode() if isinstance(payload, str) else payload.model_dump_json().encode()


def json_schemas() -> dict[str, dict]:
    """JSON Schema of each model-carrying topic, keyed by topic suffix."""
    return {t.suffix: t.model.model_json_schema() for t in TOPICS if t.model is not None}


def render_docs() -> str:
    """docs/mqtt.md, generated from :data:`TOPICS` and the models."""
    lines = [
        "# fcrlive MQTT interface",
        "",
        "<!-- Generated by `python -m fcrlive.daemon.payloads docs/mqtt.md`; edit payloads.py, not this"
        " file. -->",
        "",
        "All topics live under `<base_topic>/<unit>/` (config `[mqtt] base_topic`, default `fcrlive`, and",
        "`[unit] name`), e.g. `fcrlive/G1/droop`. Payloads are compact JSON (UTF-8) except `status`.",
        "Times are UNIX seconds (UTC, float); `*_iso` fields repeat them in ISO 8601. JSON has no NaN:",
        "unavailable numbers are `null`.",
        "",
        "Retained topics always hold the latest value, so a dashboard that subscribes later gets the",
        "state at once. While the broker is unreachable the daemon keeps the newest message per",
        "retained topic (and a bounded queue of the others) and delivers them when it reconnects.",
        "",
        "## Topic tree",
        "",
        "| topic | retained | QoS | payload | content |",
        "|---|---|---|---|---|",
    ]
    for t in TOPICS:
        lines.append(f"| `<base>/<unit>/{t.suffix}` | {'yes' if t.retained else 'no'} | {t.qos} | "
                     f"{t.model.__name__ if t.model else 'text'} | {t.doc} |")
    lines += [
        "",
        "`status` is the availability topic: the client connects with a retained last will",
        '"offline" and publishes a retained "online" right after connecting; a clean shutdown',
        'publishes "offline" itself.',
        "",
        "## Mapping from the identification result",
        "",
        "The identification plug-in returns the identification report of `fcrlive identify --json`",
        "(`IdentifyReport`, docs/identify.md; the default plug-in is",
        "`fcrlive.daemon.identify_plugin:identify_window`), published whole in `result/latest.result`.",
        "These keys of it also get their own topics:",
        "",
        "| key | topic |",
        "|---|---|",
        "| `droop` `{value, ci95}` (a fraction) | `droop`, in % (value and interval × 100) |",
        "| `max_abs_s`, `max_abs_g1` `{value, omega, ci95}` (null: not given by the method) | same name |",
        "| a quantity null with a `reason` or in `not_identifiable` (e.g. a peak from normal operation where"
        " the coherence is too low) | not published on its topic (never a number): the topic keeps its last"
        " value, the reason is in `result_quality.not_identifiable` |",
        "| `tso.fcrn`, `tso.fcrd` (`{decision, pass, ...}`) | `tso/<product>`: verdict from `decision`"
        " (pass / fail / undecided), the rest in `details` |",
        "| `tso` = `null` (G_p not identifiable: no excitation, or `not_identifiable.tso`) | `tso/fcrn`,"
        " `tso/fcrd` with verdict `unknown` and the reason in `details.reason` |",
        "| `gp` (list of `{period_s, abs, phase_deg, abs_ci95, ...}`) | `gp` |",
        "",
        "Every published interval is the report's 95 % interval `[lower, upper]` as it is: the droop's is",
        "not symmetric about its value, so no standard deviation is derived from it.",
        "",
        "## Result quality",
        "",
        "Every run is judged by the daemon's quality rule (docs/daemon.md, thresholds in",
        "`[identification.result_quality]`): `ok`, `uncertain` (a 95 % interval wider than",
        "`uncertain_ci_rel_width` × |value|) or `rejected` (droop not identifiable or outside the plausible",
        "range, an interval that is not finite, empty or does not contain its value, or wider than",
        "`reject_ci_rel_width` × |value|; also every skipped or failed run). The verdict is in",
        "`result/latest.result_quality` and on the retained `result_quality` topic, with one reason per",
        "line. A **rejected** run is published only there (and on `quality`): the headline topics `droop`,",
        "`max_abs_s`, `max_abs_g1`, `tso/*` and `gp` keep the last accepted values (their `window_end` says",
        "from when). An `uncertain` run updates them, and each number carries its own verdict in `quality`",
        "(`{level, reasons}`), so a dashboard can grey it out. A TSO verdict `undecided` (the 95 % interval",
        "of a margin reaches over its limit: `pass` is the point verdict) is a result, not a reason to",
        "reject the run: it is published on `tso/<product>` like pass and fail.",
        "",
        "## Home Assistant discovery",
        "",
        "With `[mqtt] homeassistant_discovery = true` the daemon publishes retained sensor configs to",
        "`<discovery_prefix>/sensor/fcrlive_<unit>_<key>/config` (droop, max_abs_s, max_abs_g1, data",
        "quality, result quality, live power and frequency, FCR-N, FCR-D, FCR-D up and FCR-D down",
        "verdicts), with `availability_topic` = the status topic, and announces them again whenever",
        "`<discovery_prefix>/status` says `online` (Home Assistant restarted). The live power sensor has",
        "`unit_of_measurement` MW, `device_class` power, the live frequency Hz and frequency, both",
        "`state_class` measurement (so Home Assistant keeps long-term statistics of them).",
        "",
        "The retained `excitation` state is published again on every reconnect: a broker restarted",
        "without persistence has lost it, and whether fcrlive writes to the governor must stay visible.",
        "",
        "## JSON Schemas",
        "",
    ]
    seen: set[str] = set()
    for t in TOPICS:
        if t.model is None or t.model.__name__ in seen:
            continue
        seen.add(t.model.__name__)
        used = ", ".join(f"`{x.suffix}`" for x in TOPICS if x.model is t.model)
        lines += [f"### {t.model.__name__} ({used})", "", "```json",
                  json.dumps(t.model.model_json_schema(), indent=2), "```", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Write docs/mqtt.md (path from argv, default docs/mqtt.md)."""
    argv = sys.argv[1:] if argv is None else argv
    path = argv[0] if argv else "docs/mqtt.md"
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(render_docs())
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
