"""Plausibility of a log before identification (fcrlive.tso.plausibility) and the screening of absurd
results at the `fcrlive identify` layer."""

from __future__ import annotations

from datetime import datetime
from types import SimpleNamespace

import numpy as np
import pytest

from fcrlive.analysis.report import PeakCI, ValueCI
from fcrlive.commands._identify_guard import identification_error, screen_result
from fcrlive.errors import DataError, UserError
from fcrlive.tso.csvlog import TsoLog
from fcrlive.tso.plausibility import check_log, spikes

START = datetime(2026, 11, 1)


def _log(n=3000, dt=0.1, seed=0, **cols):
    rng = np.random.default_rng(seed)
    base = {
        "InsAcPow": 225.0 + rng.normal(scale=2.0, size=n),
        "GridFreq": 50.0 + 0.03 * rng.normal(size=n),
    }
    base.update(cols)
    return TsoLog.from_arrays(np.arange(n) * dt, base, START)


def test_valid_signals_of_many_kinds_have_no_outliers():
    rng = np.random.default_rng(1)
    n = 5000
    t = np.arange(n) * 0.1
    prbs = 50.0 + 0.1 * np.sign(rng.normal(size=n))  # one-sample pulses of an excitation
    quantised = 225.0 + 0.1 * np.round(np.cumsum(rng.normal(scale=0.02, size=n)) / 0.1)
    step = 225.0 + 20.0 * (t > 200) + rng.normal(scale=0.1, size=n)
    sine = 50.0 + 0.1 * np.sin(2 * np.pi * t / 10.0)
    for x in (prbs, quantised, step, sine, 50.0 + 0.03 * rng.normal(size=n)):
        assert spikes(x).size == 0
    check_log(_log(n, ApplFreqSig=prbs), rated_mw=300.0)


@pytest.mark.parametrize("where", [0, 1234, 2999])
def test_a_single_corrupt_sample_is_found_with_its_row(where):
    log = _log()
    log.columns["GridFreq"][where] += 0.6  # 20 standard deviations, inside 45-55 Hz
    assert spikes(log.columns["GridFreq"]).tolist() == [where]
    log = _log()
    log.columns["GridFreq"][where] += 0.6
    object.__setattr__(log, "rows", np.arange(len(log)) + 2)
    with pytest.raises(DataError, match=f"row {where + 2}"):
        check_log(log, rated_mw=300.0)


@pytest.mark.parametrize(
    ("edit", "text"),
    [
        (lambda c: c.__setitem__("GridFreq", c["GridFreq"] * 1000), "GridFreq looks like mHz"),
        (lambda c: c.__setitem__("GridFreq", c["GridFreq"] / 50), "per unit"),
        (lambda c: c.__setitem__("InsAcPow", c["InsAcPow"] * 1000), "InsAcPow looks like kW, or --rated-mw"),
        (lambda c: c.__setitem__("InsAcPow", c["InsAcPow"] * 3), "--rated-mw"),
    ],
)
def test_units_are_checked_with_a_hint(edit, text):
    log = _log()
    edit(log.columns)
    with pytest.raises(DataError, match=text.replace("|", r"\|")):
        check_log(log, rated_mw=300.0)


def test_many_missing_samples_are_refused_not_interpolated():
    rng = np.random.default_rng(3)
    keep = np.sort(rng.choice(3000, 2700, replace=False))
    log = TsoLog.from_arrays(keep * 0.1, {k: v[keep] for k, v in _log().columns.items()}, START)
    with pytest.raises(DataError, match="are missing in"):
        check_log(log, rated_mw=300.0)
    few = np.delete(np.arange(3000), [100, 900])
    ok = TsoLog.from_arrays(few * 0.1, {k: v[few] for k, v in _log().columns.items()}, START)
    check_log(ok, rated_mw=300.0)


def _res(droop, ci, peak=(1.0, 0.9, 1.1)):
    rep = SimpleNamespace(
        droop=ValueCI(value=droop, ci95=list(ci)),
        g1_static=ValueCI(value=1 / droop, ci95=[1 / ci[1], 1 / ci[0]] if ci[0] > 0 else [None, None]),
        max_abs_g1=PeakCI(value=peak[0], ci95=[peak[1], peak[2]], omega=0.1),
        max_abs_s=PeakCI(value=1.2, ci95=[1.1, 1.3], omega=0.3),
        not_identifiable={},
        warnings=[],
    )
    rep.model_copy = lambda update: SimpleNamespace(**{**vars(rep), **update})
    from dataclasses import dataclass

    @dataclass(frozen=True)
    class R:
        report: object

    return R(rep)


def test_absurd_droop_is_not_a_number():
    with pytest.raises(DataError, match=r"not identifiable: the droop came out 1\.047e\+04 %"):
        screen_result(_res(104.71, (0.0, 6.7e6)), ["x.csv"])
    with pytest.raises(DataError, match=r"outside the 0\.5-30 %"):
        screen_result(_res(0.00008, (0.00007, 0.00009)), ["x.csv"])
    # a plausible droop passes unchanged: the width rule (an interval wider than the value) is applied by
    # the identification itself for every caller (analysis.quality; tests/test_identify_quality.py)
    res = _res(0.106, (0.0, 0.648), peak=(0.8, 0.1, 2.0))
    assert screen_result(res, ["x.csv"]) is res
    fine = _res(0.08, (0.079, 0.081))
    assert screen_result(fine, ["x.csv"]) is fine


def test_identification_errors_name_the_files_and_say_what_to_do():
    msg = "zu: 55 s of usable data, at least 300 s are needed"
    e = identification_error(UserError(msg), ["a.csv", "b.csv"])
    assert str(e).startswith("a.csv, b.csv: zu: 55 s") and "longer log" in str(e)
    e = identification_error(UserError("could not identify a PI controller with droop"), ["a.csv"])
    assert "--plant" in str(e)
