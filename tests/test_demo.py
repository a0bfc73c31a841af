"""``fcrlive demo`` as a user runs it after the README set-up: no Mosquitto on PATH (embedded broker)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path


def _path_without_mosquitto() -> str:
    dirs = os.environ.get("PATH", "").split(os.pathsep)
    keep = [d for d in dirs if d and not (Path(d) / "mosquitto").exists()]
    return os.pathsep.join([str(Path(sys.executable).parent), *keep])


def test_demo_runs_without_mosquitto_and_prints_a_summary(tmp_path):
    env = {**os.environ, "PATH": _path_without_mosquitto(), "OPENBLAS_NUM_THREADS": "1"}
    assert shutil.which("mosquitto", path=env["PATH"]) is None
    cmd = [sys.executable, "-m", "fcrlive.cli", "demo", "--speed", "30", "--identifications", "1",
           "--window-min", "15", "--minutes", "3"]
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=240, cwd=tmp_path)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    out = p.stdout
    assert "amqtt broker" in out
    assert "#1 15.0 sim-min window" in out
    assert "into the SIMULATED governor only" in out
    assert "demo summary: 1 identification(s), 1 with a result" in out
    assert "droop     truth 8 %" in out
    assert "Traceback" not in p.stderr


def test_demo_bad_option_is_one_line():
    p = subprocess.run([sys.executable, "-m", "fcrlive.cli", "demo", "--poll-hz", "80"], capture_output=True,
                       text=True, timeout=60)
    assert p.returncode == 2
    assert p.stderr.strip().splitlines() == [
        "fcrlive demo: error: --poll-hz must be between 10 and 50, not 80"]
