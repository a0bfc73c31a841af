"""The plain-text table of ``fcrlive prequal``: one line per requirement (test, requirement, value,
limit, pass), then capacity and verdict per service."""

from __future__ import annotations

from fcrlive.prequal.model import PrequalResult, RequirementResult


def _num(x: float | None, unit: str = "") -> str:
    if x is None:
        return "-"
    s = f"{x:.4g}"
    return f"{s} {unit}".strip()


def _limit(r: RequirementResult) -> str:
    if r.limit is None:
        return "-"
    if isinstance(r.limit, tuple):
        return f"[{r.limit[0]:g}, {r.limit[1]:g}]"
    return f"{r.comparison} {_num(r.limit, r.unit)}"


def _status(r: RequirementResult) -> str:
    if r.passed is False and r.k_red is not None and r.k_red > 0:
        return f"fail (K={r.k_red:.3f})"
    return r.status


def text_table(result: PrequalResult) -> str:
    rows: list[tuple[str, ...]] = [("test", "req", "what", "value", "limit", "result")]
    for e in result.tests:
        label = f"{e.service} {e.test_id}"
        if e.kind == "sine":
            label += f" T={e.figures.get('period_s', 0):g}s"
        elif e.kind != "operation":
            label += f" {e.kind}"
        for r in e.requirements.values():
            rows.append((label, r.number, r.title, _num(r.value, r.unit), _limit(r), _status(r)))
        for r in e.checks.values():
            if r.passed is False:
                rows.append((label, r.number, r.title, _num(r.value, r.unit), _limit(r), r.status))
    for r in result.checks.values():
        rows.append(("unit", r.number, r.title, _num(r.value, r.unit), _limit(r), r.status))
    width = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    width[2] = min(width[2], 52)
    out = [f"document: {result.document.key} ({result.document.title})"]
    for row in rows:
        cells = [c if i != 2 else (c if len(c) <= 52 else c[:51] + "…") for i, c in enumerate(row)]
        out.append("  ".join(c.ljust(width[i]) for i, c in enumerate(cells)).rstrip())
    out.append("")
    for s, c in result.capacity.items():
        out.append(
            f"{s}: K_red,ss = {_num(c.k_red_ss)}, K_red,dyn = {_num(c.k_red_dyn)}, "
            f"capacity = {_num(c.capacity_mw, 'MW')} (|ΔP_ss,theo| = {_num(c.dp_ss_theo_mw, 'MW')})"
        )
    for s, v in result.verdict.items():
        out.append(f"{s}: {v.status.upper()}")
        out.extend(f"  failed: {x}" for x in v.failed)
        out.extend(f"  missing: {x}" for x in v.missing)
    return "\n".join(out)
