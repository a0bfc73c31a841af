"""``fcrlive model``: through cli.main and once as the installed console script."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from fcrlive.cli import main
from fcrlive.constants import TSO_PERIODS_S

ROOT = Path(__file__).resolve().parents[1]


def _json(capsys, argv) -> dict:
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_model_json_paper_plant1(capsys):
    out = _json(capsys, ["model", "--preset", "paper-plant1", "--json"])
    assert out["g1_static"] == pytest.approx(0.0794, rel=1e-3)
    assert out["max_abs_g1"]["value"] == pytest.approx(1.011, abs=1e-3)
    assert out["max_abs_g1"]["omega_rad_s"] == pytest.approx(0.142, rel=0.01)
    assert out["max_abs_s"]["value"] == pytest.approx(1.287, abs=1e-3)
    assert out["droop"] == 0.08
    assert out["effective_droop"] == pytest.approx(0.08)
    assert [r["period_s"] for r in out["responses"]] == list(TSO_PERIODS_S)
    by_t = {r["period_s"]: r for r in out["responses"]}
    r25 = by_t[25.0]
    assert r25["g1"]["abs"] == pytest.approx(0.7275, rel=1e-3)
    assert r25["s"]["phase_deg"] == pytest.approx(38.8, abs=0.1)
    assert r25["gp"]["phase_deg"] == pytest.approx(-42.0, abs=0.1)
    for key in ("g1", "s", "gp", "f", "greq"):
        c = r25[key]
        assert math.hypot(c["re"], c["im"]) == pytest.approx(c["abs"], rel=1e-12)
        assert math.degrees(math.atan2(c["im"], c["re"])) == pytest.approx(c["phase_deg"], abs=1e-9)
    # F is G_p normalised to unit static gain: ρ·|G_p| with a unit-gain turbine
    assert by_t[300.0]["f"]["abs"] == pytest.approx(0.08 * by_t[300.0]["gp"]["abs"], rel=1e-9)
    assert out["parameters"]["unit"]["governor"]["droop_placement"] == "integral"


def test_model_table(capsys):
    assert main(["model"]) == 0
    text = capsys.readouterr().out
    assert "max|S|" in text and "1.2871" in text
    assert "0.0794" in text
    assert "rad/s" in text
    assert len([line for line in text.splitlines() if line.strip().startswith(("10 ", "300 "))]) == 2


def test_model_plant_file_overrides_preset(capsys, tmp_path):
    f = tmp_path / "c.toml"
    f.write_text('[unit.governor]\ndroop_placement = "classic"\n[unit.turbine]\nPm0 = 0.8\n')
    out = _json(capsys, ["model", "--plant", str(f), "--json"])
    assert out["droop_placement"] == "classic"
    assert out["max_abs_g1"]["value"] == pytest.approx(1.090, abs=1.5e-3)
    assert out["max_abs_s"]["value"] == pytest.approx(1.295, abs=1.5e-3)


def test_model_unknown_preset_exit_2(capsys):
    assert main(["model", "--preset", "nope"]) == 2
    err = capsys.readouterr().err
    assert "unknown preset 'nope'" in err and err.count("\n") == 1


def test_model_bad_file_exit_2(capsys, tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text("[unit.governor]\nKp = 'one'\n")
    assert main(["model", "--plant", str(f)]) == 2
    err = capsys.readouterr().err
    assert str(f) in err and "unit.governor.Kp" in err and err.count("\n") == 1


def test_console_script_json():
    exe = Path(sys.executable).with_name("fcrlive")
    proc = subprocess.run(
        [str(exe), "model", "--preset", "paper-plant1", "--json"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["g1_static"] == pytest.approx(0.0794, rel=1e-3)
    assert out["max_abs_s"]["value"] == pytest.approx(1.287, abs=1e-3)
