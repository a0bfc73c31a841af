"""The JSON document of ``fcrlive prequal --json`` (docs/prequal.md): a pydantic boundary model built
from a :class:`~fcrlive.prequal.model.PrequalResult`. Non-finite numbers become null."""

from __future__ import annotations

import math
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from fcrlive.prequal.model import Capacity, PrequalResult, RequirementResult, TestEvaluation, Verdict

SCHEMA_VERSION = 1


def _num(x: Any) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


class _Out(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True)


class RequirementOut(_Out):
    number: str
    title: str
    value: float | None
    limit: float | list[float] | None
    passed: bool | None = Field(serialization_alias="pass")
    status: str
    comparison: str
    unit: str
    note: str
    interval: list[float | None] | None = None
    k_red: float | None = None
    document: str


class TestOut(_Out):
    file: str
    files: list[str]
    service: str
    test_id: str
    kind: str
    operating_point: str
    requirements: dict[str, RequirementOut]
    checks: dict[str, RequirementOut]
    figures: dict[str, float | None]
    F: list[dict[str, float | None]] = []
    notes: list[str]


class CapacityOut(_Out):
    k_red_ss: float | None
    k_red_dyn: float | None
    capacity_mw: float | None
    dp_ss_theo_mw: float | None
    k_min: float
    from_tests: list[str]
    note: str


class VerdictOut(_Out):
    status: str
    missing: list[str]
    failed: list[str]


class PrequalOut(_Out):
    schema_version: int = SCHEMA_VERSION
    document: str
    document_title: str
    deactivation_limit_s: float
    unit: dict[str, Any] | None
    tests: list[TestOut]
    capacity: dict[str, CapacityOut]
    verdict: dict[str, VerdictOut]
    checks: dict[str, RequirementOut]
    notes: list[str]


def _req(r: RequirementResult) -> RequirementOut:
    lim = r.limit
    return RequirementOut(
        number=r.number,
        title=r.title,
        value=_num(r.value),
        limit=[float(lim[0]), float(lim[1])] if isinstance(lim, tuple) else _num(lim),
        passed=r.passed,
        status=r.status,
        comparison=r.comparison,
        unit=r.unit,
        note=r.note,
        interval=[_num(r.value_interval[0]), _num(r.value_interval[1])] if r.value_interval else None,
        k_red=_num(r.k_red),
        document=r.document,
    )


def _test(e: TestEvaluation) -> TestOut:
    return TestOut(
        file=e.file,
        files=list(e.files),
        service=e.service,
        test_id=e.test_id,
        kind=e.kind,
        operating_point=e.operating_point,
        requirements={k: _req(r) for k, r in e.requirements.items()},
        checks={k: _req(r) for k, r in e.checks.items()},
        figures={k: _num(v) for k, v in e.figures.items()},
        F=[
            {"period_s": p.period_s, "re": _num(p.F.real), "im": _num(p.F.imag), "sd": _num(p.F_sd)}
            for p in e.points
        ],
        notes=list(e.notes),
    )


def _cap(c: Capacity) -> CapacityOut:
    return CapacityOut(
        k_red_ss=_num(c.k_red_ss),
        k_red_dyn=_num(c.k_red_dyn),
        capacity_mw=_num(c.capacity_mw),
        dp_ss_theo_mw=_num(c.dp_ss_theo_mw),
        k_min=c.k_min,
        from_tests=list(c.from_tests),
        note=c.note,
    )


def _verdict(v: Verdict) -> VerdictOut:
    return VerdictOut(status=v.status, missing=list(v.missing), failed=list(v.failed))


def _unit(result: PrequalResult) -> dict[str, Any] | None:
    u = result.unit
    if u is None:
        return None
    return {
        "name": result.unit_name,
        "resource": u.resource,
        "area": u.area,
        "rated_mw": u.rated_mw,
        "p_min_mw": u.p_min_mw,
        "p_max_mw": u.p_max_mw,
        "H_s": u.H,
        "Kd": u.Kd,
        "t_fme_s": u.t_fme_s,
        "fcrd": u.fcrd,
        "governor_type": u.governor_type,
        "governor_settings": {k: v for k, v in u.governor_settings},
        "dp_ss_method": u.dp_ss_method,
        "points": [
            {
                "name": p.name,
                "power_mw": p.power_mw,
                "droop": p.droop,
                "droop_fcrd": p.droop_fcrd,
                "dp_ss_theo_mw": dict(p.dp_ss_theo_mw),
                "test_ids": list(p.test_ids),
            }
            for p in u.points
        ],
    }


def to_model(result: PrequalResult) -> PrequalOut:
    return PrequalOut(
        document=result.document.key,
        document_title=result.document.title,
        deactivation_limit_s=result.document.deactivation_limit_s,
        unit=_unit(result),
        tests=[_test(e) for e in result.tests],
        capacity={k: _cap(c) for k, c in result.capacity.items()},
        verdict={k: _verdict(v) for k, v in result.verdict.items()},
        checks={k: _req(r) for k, r in result.checks.items()},
        notes=list(result.notes),
    )


def to_json_dict(result: PrequalResult) -> dict[str, Any]:
    """The document as plain JSON-ready data (``pass`` keys, null for unknown numbers)."""
    return to_model(result).model_dump(by_alias=True)
