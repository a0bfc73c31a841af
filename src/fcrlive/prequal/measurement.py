"""Measurement-chain checks from the data themselves (TR v1.1 Section 4). Pure.

- Sampling (4.3): tests at ≥ 5 Hz for FCR-N and ≥ 10 Hz for FCR-D, normal operation ≥ 1 Hz. The TR
  also accepts logging thresholds (0.01 MW, 5 mHz) instead; a log written that way is not uniform and is
  reported against the rate with a note.
- Resolution (4.2, Table 16): 0.01 MW for power, 5 mHz for frequency. Estimated as the smallest step
  between the distinct values of the signal: an upper bound of the quantum, decided only with enough
  distinct values (a generated profile or a constant signal tells nothing).
- Accuracy (4.1, Table 15) cannot be seen in the data: the stated class of the unit description is
  checked against the table.
"""

from __future__ import annotations

import numpy as np

from fcrlive.prequal.common import Context, compare, undecided
from fcrlive.prequal.model import RequirementResult

SAMPLE_MAX_S = {"Fcrn": 0.2, "FcrdUp": 0.1, "FcrdDo": 0.1}
"""Longest sample interval of a test log [s] (TR 4.3)."""
OPERATION_SAMPLE_MAX_S = 1.0
POWER_RESOLUTION_MW = 0.01
FREQUENCY_RESOLUTION_HZ = 0.005
MIN_DISTINCT = 30
"""Distinct values needed before a resolution estimate is trusted."""


def resolution(x: np.ndarray) -> tuple[float | None, int]:
    """(smallest step between distinct values, number of distinct values); None for fewer than
    :data:`MIN_DISTINCT` distinct values."""
    x = np.asarray(x, float)
    u = np.unique(x[np.isfinite(x)])
    if u.size < MIN_DISTINCT:
        return None, int(u.size)
    return float(np.min(np.diff(u))), int(u.size)


def chain_checks(
    sample_s: float, power: np.ndarray | None, freq: np.ndarray | None, kind: str, ctx: Context
) -> dict[str, RequirementResult]:
    """Sampling and resolution checks of one log (``freq``: the measured grid frequency)."""
    out: dict[str, RequirementResult] = {}
    limit = OPERATION_SAMPLE_MAX_S if kind == "operation" else SAMPLE_MAX_S[ctx.service]
    what = (
        "normal operation"
        if kind == "operation"
        else ("FCR-N tests" if ctx.service == "Fcrn" else "FCR-D tests")
    )
    out["sampling"] = compare(
        "4.3",
        "Sampling interval",
        sample_s,
        limit,
        "s",
        ctx,
        op="<=",
        note=f"median interval; at least {1 / limit:g} Hz for {what} (or logging thresholds 0.01 MW / 5 mHz)",
    )
    for key, x, lim, unit, name in (
        ("power_resolution", power, POWER_RESOLUTION_MW, "MW", "power"),
        ("frequency_resolution", freq, FREQUENCY_RESOLUTION_HZ, "Hz", "grid frequency"),
    ):
        title = f"Resolution of the {name}"
        if x is None:
            out[key] = undecided("4.2", title, unit, ctx, f"no {name} column", limit=lim, op="<=")
            continue
        q, n = resolution(x)
        if q is None:
            out[key] = undecided(
                "4.2", title, unit, ctx, f"only {n} distinct values: the resolution cannot be told", lim, "<="
            )
        else:
            out[key] = compare(
                "4.2",
                title,
                q,
                lim,
                unit,
                ctx,
                op="<=",
                note=f"smallest step between {n} distinct values (an upper bound of the quantum)"
                + ("; 0.025 % is the TR's alternative for power" if key == "power_resolution" else ""),
            )
    return out


def power_accuracy_limit_pct(rated_mw: float) -> float:
    """TR Table 15: ±5 % below 1.5 MW, ±1 % below 10 MW, ±0.5 % from 10 MW."""
    return 5.0 if rated_mw < 1.5 else (1.0 if rated_mw < 10.0 else 0.5)


def accuracy_checks(
    rated_mw: float | None, power_pct: float | None, freq_mhz: float | None, ctx: Context
) -> dict[str, RequirementResult]:
    """The stated accuracy class against TR Table 15."""
    out: dict[str, RequirementResult] = {}
    if rated_mw is not None:
        lim = power_accuracy_limit_pct(rated_mw)
        if power_pct is None:
            out["power_accuracy"] = undecided(
                "4.1",
                "Power accuracy (stated)",
                "%",
                ctx,
                "not stated ([unit.prequal] power_accuracy_pct)",
                lim,
                "<=",
            )
        else:
            out["power_accuracy"] = compare(
                "4.1",
                "Power accuracy (stated)",
                power_pct,
                lim,
                "%",
                ctx,
                op="<=",
                note=f"TR Table 15 for {rated_mw:g} MW",
            )
    if freq_mhz is None:
        out["frequency_accuracy"] = undecided(
            "4.1",
            "Frequency accuracy (stated)",
            "mHz",
            ctx,
            "not stated ([unit.prequal] frequency_accuracy_mhz)",
            10.0,
            "<=",
        )
    else:
        out["frequency_accuracy"] = compare(
            "4.1", "Frequency accuracy (stated)", freq_mhz, 10.0, "mHz", ctx, op="<="
        )
    return out
