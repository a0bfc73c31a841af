"""The zoo benchmark's scoring (benchmarks/bench_zoo.py): what counts as "not identifiable", errors,
coverage; and one cell end to end through the real identification."""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
_env = dict(os.environ)
from benchmarks import bench_zoo as bz  # noqa: E402 (pins BLAS threads for its own runs: undone here)

os.environ.clear()
os.environ.update(_env)


def _row(entries, key="droop"):
    return {"plant": "p", "logger": "l", "minutes": 15.0, "excitation": False, "seed": 0, "method": "zu",
            "q": {key: entries}}


@pytest.mark.parametrize("value, ci", [
    (None, [0.01, 0.02]),
    (math.nan, [0.01, 0.02]),
    (0.05, None),
    (0.05, [None, 0.06]),
    (0.05, [0.04, math.inf]),
    (0.05, []),
])
def test_missing_or_nonfinite_is_not_identifiable(value, ci):
    e = bz._entry(value, ci, 0.05)
    assert e["identifiable"] is False
    s = bz.summarise([_row([e])], "droop")
    assert s["not_identifiable"] == 1.0 and s["n_ok"] == 0 and s["coverage"] is None


def test_errors_and_coverage():
    rows = [_row([bz._entry(0.052, [0.050, 0.054], 0.05)]),   # +0.2 pp, covered
            _row([bz._entry(0.046, [0.045, 0.047], 0.05)]),   # −0.4 pp, not covered
            _row([bz._entry(None, None, 0.05)])]              # not identifiable
    s = bz.summarise(rows, "droop")
    assert s["n"] == 3 and s["n_ok"] == 2
    assert s["median_abs"] == pytest.approx(0.3)
    assert s["median"] == pytest.approx(-0.1)
    assert s["coverage"] == pytest.approx(0.5)
    assert s["not_identifiable"] == pytest.approx(1 / 3)
    peaks = [_row([bz._entry(1.1, [1.0, 1.2], 1.0)], "max_s")]
    assert bz.summarise(peaks, "max_s")["median"] == pytest.approx(10.0)  # % of the truth


def test_a_failed_record_counts_for_every_quantity():
    row = {"plant": "p", "logger": "l", "minutes": 15.0, "excitation": False, "seed": 0, "status": "error",
           "reason": "x", "method": None, "q": None}
    for key in bz.QUANTITIES:
        assert bz.summarise([row], key)["not_identifiable"] == 1.0
    assert "1 identification(s) raised" in bz.table([row])


def test_one_cell_end_to_end():
    task = bz.Task("E-stiff5pct-classic-demand-25Hz", 5.0, False, 0, ("hist-1s", "ctl-0.1pct"))
    rows = bz.run_task(task)
    assert [r["logger"] for r in rows] == ["hist-1s", "ctl-0.1pct"]
    for r in rows:
        assert r["status"] in ("ok", "error")
        if r["status"] == "ok":
            assert len(r["q"]["gp"]) == 10 and r["q"]["droop"][0]["truth"] == pytest.approx(0.06)
    text = bz.table(rows)
    assert "### droop [pp]" in text and "E-stiff5pct-classic-demand-25Hz" in text
