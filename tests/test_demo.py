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
    assert set(w) == {"method", "verdict", "lost_samples", "droop", "max_abs_s", "max_abs_g1", "tso"}
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
