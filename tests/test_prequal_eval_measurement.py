"""Measurement-chain checks from the data (TR Section 4): sampling per test type, resolution of power and
frequency, the stated accuracy class against Table 15."""

from __future__ import annotations

import numpy as np
import pytest
from test_prequal_eval_support import Lag, activation_knots, fast_ramps, sample, write

from fcrlive.plant.description import unit_description_from_dict
from fcrlive.prequal.evaluate import evaluate_logs
from fcrlive.prequal.measurement import power_accuracy_limit_pct, resolution
from fcrlive.tso.csvlog import read_log


def _ramp_file(folder, dt, quantum_mw=None):
    tk, fk = fast_ramps("FcrdUp")
    ta, a = activation_knots(tk, fk, 49.9, 49.5)
    t, f = sample(tk, fk, dt)
    p = 200.0 + 20.0 * Lag(ta, a, 1.0)(t)
    rng = np.random.default_rng(0)
    grid = np.round(50.0 + 0.01 * rng.standard_normal(t.size), 3)  # a 1 mHz frequency meter
    if quantum_mw is not None:
        p = np.round((p + 0.05 * rng.standard_normal(t.size)) / quantum_mw) * quantum_mw
    reg = np.full(t.size, 20.0 / 0.4)
    return write(
        folder,
        "FcrdUp",
        "2.1",
        t,
        {"InsAcPow": p, "ApplFreqSig": f, "GridFreq": grid, "RegStr_FcrdUp": reg},
        dt=dt,
    )


def test_fcrd_test_logged_at_5_hz_fails_sampling(tmp_path):
    path = _ramp_file(tmp_path, 0.2)
    res = evaluate_logs([read_log(path, required=("InsAcPow",))])
    ev = res.tests[0]
    s = ev.checks["sampling"]
    assert s.value == pytest.approx(0.2) and s.limit == 0.1 and s.passed is False
    assert any("TR 4.3 sampling" in x for x in res.verdict["FcrdUp"].failed)
    f = ev.checks["frequency_resolution"]
    assert f.value == pytest.approx(0.001, abs=1e-9) and f.passed is True


def test_power_resolution_from_the_data(tmp_path):
    path = _ramp_file(tmp_path, 0.1, quantum_mw=0.1)
    ev = evaluate_logs([read_log(path, required=("InsAcPow",))]).tests[0]
    r = ev.checks["power_resolution"]
    assert r.value == pytest.approx(0.1, abs=1e-9) and r.limit == 0.01 and r.passed is False
    assert ev.checks["sampling"].passed is True


def test_resolution_needs_distinct_values():
    assert resolution(np.repeat([1.0, 2.0, 3.0], 100)) == (None, 3)
    q, n = resolution(np.arange(100) * 0.005)
    assert q == pytest.approx(0.005) and n == 100


@pytest.mark.parametrize(
    "rated, stated, ok", [(300.0, 0.5, True), (300.0, 1.0, False), (5.0, 1.0, True), (1.0, 4.0, True)]
)
def test_stated_accuracy_against_table15(rated, stated, ok):
    d = {
        "unit": {
            "rated_mw": rated,
            "prequal": {
                "resource": "U",
                "area": "NO5",
                "power_accuracy_pct": stated,
                "frequency_accuracy_mhz": 10.0,
            },
        }
    }
    unit = unit_description_from_dict(d).prequal
    res = evaluate_logs([], unit)
    r = res.checks["power_accuracy"]
    assert r.limit == power_accuracy_limit_pct(rated) and r.passed is ok
    assert res.checks["frequency_accuracy"].passed is True
