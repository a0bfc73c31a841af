"""``fcrlive demo`` as a user runs it after the README set-up: no Mosquitto on PATH (embedded broker)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest


def _path_without_mosquitto() -> str:
    dirs = os.environ.get("PATH", "").split(os.pathsep)
    keep = [d for d in dirs if d and not (Path(d) / "mosquitto").exists()]
    return os.pathsep.join([str(Path(sys.executable).parent), *keep])


def test_demo_runs_without_mosquitto_and_prints_a_summary(tmp_path):
    env = {**os.environ, "PATH": _path_without_mosquitto(), "OPENBLAS_NUM_THREADS": "1"}
    assert shutil.which("mosquitto", path=env["PATH"]) is None
    cmd = [sys.executable, "-m", "fcrlive.cli", "demo", "--speed", "30", "--identifications", "1",
           "--window-min", "15", "--minutes", "3", "--summary-json", str(tmp_path / "summary.json")]
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=240, cwd=tmp_path)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    out = p.stdout
    assert "amqtt broker" in out
    assert "#1 15.0 sim-min window" in out
    assert "into the SIMULATED governor only" in out
    assert "demo summary: 1 identification(s), 1 with a result" in out
    assert "droop     truth 8 %" in out
    assert "Traceback" not in p.stderr
    doc = json.loads((tmp_path / "summary.json").read_text())
    truth = doc["truth"]
    assert truth["controller_rate_hz"] == 50.0  # the paper's governor, no 10 Hz variant
    assert truth["droop"] == pytest.approx(8.0) and truth["max_abs_s"] == pytest.approx(1.287, abs=1e-3)
    [w] = doc["windows"]
    assert set(w) == {"method", "verdict", "lost_samples", "droop", "max_abs_s", "max_abs_g1", "tso",
                      "reasons"}
    # every null number says why (the demo's store, which held the whole report, is gone afterwards)
    assert set(w["reasons"]) == {k for k in ("droop", "max_abs_s", "max_abs_g1", "tso") if w[k] is None}
    assert all(isinstance(v, str) and v for v in w["reasons"].values())
    assert w["method"] == "zcu" and w["lost_samples"] == 0  # buffered: every controller sample
    for key in ("droop", "max_abs_s", "max_abs_g1"):  # null only when the quality rule withholds it
        assert (w[key] is None) == (w["verdict"] == "rejected")
        if w[key] is not None:
            lo, hi = w[key]["ci95"]
            assert lo <= w[key]["value"] <= hi


def test_demo_bad_option_is_one_line():
    p = subprocess.run([sys.executable, "-m", "fcrlive.cli", "demo", "--speed", "80"], capture_output=True,
                       text=True, timeout=60)
    assert p.returncode == 2
    assert p.stderr.strip().splitlines() == [
        "fcrlive demo: error: --speed must be in (0, 40], not 80"]


def test_summary_json_says_why_each_null_number_is_null():
    # A real Z_u report (no excitation: no S, no G_p, no TSO checks) and a skipped window, through the same
    # typed result payload the demo reads from the broker.
    from fcrlive.analysis.identify import identify_signals
    from fcrlive.commands.demo import summary_json
    from fcrlive.daemon.payloads import DataQuality, ResultPayload, Window
    from fcrlive.daemon.result_quality import judge
    from fcrlive.plant.params import preset
    from fcrlive.sim import SimConfig, simulate
    from fcrlive.tso.signals import log_from_sim, plant_signals

    res = simulate(preset("paper-plant1"), SimConfig(duration_s=600.0, snr_db=12.0, excitation=False, seed=4))
    rep = identify_signals(plant_signals(log_from_sim(res), rated_mw=300.0), rated_mw=300.0, f0=50.0, kd=0.1)
    assert rep.method == "zu"

    def payload(result, error=None):
        return ResultPayload(
            unit="G1", t=1e4, t_iso="x", window=Window.of(1e4 - 600, 1e4), method="auto", ok=error is None,
            error=error, duration_s=1.0, result=result,
            result_quality=None if result is None else judge(result),
            quality=DataQuality(ok_fraction=1.0, samples=1, expected=1, counts={"ok": 1}, gaps=0, gap_s=0.0))

    truth = {"g1_static": 1.0 / (12.5 + 0.1), "max_S": 1.3, "max_G1": 1.0, "dt": 0.02}
    skipped = "too little good data: 40 % of the window's samples are ok (needs 90 %)"
    skip = payload(None, skipped)
    doc = summary_json([m.model_dump(mode="json", by_alias=True) for m in (payload(rep), skip)], truth, 0.1)
    zu, skip = doc["windows"]
    assert zu["droop"] is not None and zu["max_abs_s"] is None and zu["tso"] is None
    assert set(zu["reasons"]) == {k for k in ("droop", "max_abs_s", "max_abs_g1", "tso") if zu[k] is None}
    assert "Z_u" in zu["reasons"]["max_abs_s"] and "TSO checks" in zu["reasons"]["tso"]
    assert skip["reasons"] == {k: skipped for k in ("droop", "max_abs_s", "max_abs_g1", "tso")}
