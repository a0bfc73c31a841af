"""`fcrlive prequal DIR`: the table, the JSON document the issue specifies, the document option, bad input
(one line naming the file, exit status 2)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from test_prequal_eval_support import Lag, activation_knots, fast_ramps, fcrn_steps, sample, write

from fcrlive.cli import main

UNIT_TOML = """
preset = "paper-plant1"
[unit]
name = "test unit"
rated_mw = 300.0
[unit.prequal]
resource = "TESTU1"
area = "NO5"
p_min_mw = 60.0
p_max_mw = 300.0
power_accuracy_pct = 0.5
frequency_accuracy_mhz = 10.0
[unit.prequal.governor]
type = "digital PI"
settings = { Kp = 1.0, Ti = 9.1 }
[[unit.prequal.points]]
load = "high"
droop_level = "high"
power_mw = 250.0
droop = 0.08
[[unit.prequal.points]]
load = "high"
droop_level = "low"
power_mw = 250.0
droop = 0.04
dp_ss_theo_mw = { Fcrn = 15.0, FcrdUp = 40.0, FcrdDo = 60.0 }
"""


def _app(folder: Path) -> Path:
    """An application with an FCR-N step test (1.1: ΔP_ss,theo 7.5 MW from the droop) and an FCR-D up
    fast ramp test (2.2: 40 MW from the table), both exact lags; unit.toml in the folder."""
    folder.mkdir(exist_ok=True)
    (folder / "unit.toml").write_text(UNIT_TOML)
    tk, fk = fcrn_steps()
    t, f = sample(tk, fk)
    p = 200.0 + 7.5 * Lag(tk, (50.0 - np.asarray(fk)) / 0.1, 5.0)(t)
    write(folder, "Fcrn", "1.1", t, {"InsAcPow": p, "ApplFreqSig": f, "GridFreq": 50.0 + 0.0 * t})
    tk, fk = fast_ramps("FcrdUp")
    ta, a = activation_knots(tk, fk, 49.9, 49.5)
    t, f = sample(tk, fk)
    p = 200.0 + 40.0 * Lag(ta, a, 1.0)(t)
    write(folder, "FcrdUp", "2.2", t, {"InsAcPow": p, "ApplFreqSig": f})
    (folder / "README.txt").write_text("not a test file")
    return folder


def test_json_document_shape(tmp_path, capsys):
    app = _app(tmp_path / "app")
    assert main(["prequal", str(app), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["document"] == "nordic-2025" and doc["deactivation_limit_s"] == 2.5
    assert set(doc) >= {"document", "tests", "capacity", "verdict", "unit"}
    by_id = {t["test_id"]: t for t in doc["tests"]}
    steps, ramps = by_id["1.1"], by_id["2.2"]
    for t in (steps, ramps):
        assert set(t) >= {"file", "service", "test_id", "kind", "requirements", "figures"}
        for r in t["requirements"].values():
            assert set(r) >= {"value", "limit", "pass"}
    assert steps["service"] == "Fcrn" and steps["kind"] == "fcrn-steps"
    assert steps["figures"]["dp_ss_mw"] == pytest.approx(7.5, abs=1e-4)
    assert steps["requirements"]["1-up"]["limit"] == [-0.05, 0.2]
    assert steps["requirements"]["1-up"]["pass"] is True
    assert ramps["kind"] == "fcrd-ramps" and ramps["operating_point"] == "high load, low droop"
    for key in ("dp_ss_mw", "dp_7p5s_mw", "e_7p5s_mws", "deactivation_mws"):
        assert isinstance(ramps["figures"][key], float)
    assert ramps["figures"]["dp_ss_theo_mw"] == 40.0  # the table value of the point of test 2.2
    assert ramps["requirements"]["2"]["limit"] == pytest.approx(0.86 * 40.0)
    assert ramps["requirements"]["4"]["document"] == "nordic-2025"
    cap = doc["capacity"]["FcrdUp"]
    assert set(cap) >= {"k_red_ss", "k_red_dyn", "capacity_mw"}
    # C = min(K_red,ss, K_red,dyn)·|ΔP_ss,theo| at the largest point (40 MW from the table, 30 MW by droop)
    assert cap["capacity_mw"] == pytest.approx(min(cap["k_red_ss"], cap["k_red_dyn"]) * 40.0)
    for s in ("Fcrn", "FcrdUp", "FcrdDo"):
        v = doc["verdict"][s]
        assert v["status"] in ("pass", "fail", "incomplete") and isinstance(v["missing"], list)
    assert doc["verdict"]["FcrdDo"]["status"] == "incomplete"
    assert any("3.1" in m for m in doc["verdict"]["FcrdDo"]["missing"])
    assert doc["unit"]["resource"] == "TESTU1" and doc["unit"]["H_s"] == 3.5


def test_table_and_document_option(tmp_path, capsys):
    app = _app(tmp_path / "app")
    assert main(["prequal", str(app), "--document", "statnett-2024"]) == 0
    out = capsys.readouterr().out
    assert "document: statnett-2024" in out
    line = next(x for x in out.splitlines() if x.startswith("FcrdUp 2.2") and "Deactivation" in x)
    assert "<= 68 MWs" in line  # 1.7 s · 40 MW
    assert "Fcrn: " in out and "missing: step sequence 1.2" in out


def test_bad_file_one_line_exit_2(tmp_path, capsys):
    app = _app(tmp_path / "app")
    bad = app / "notes.csv"
    bad.write_text("a,b\r\n1,2\r\n")
    assert main(["prequal", str(app)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "notes.csv" in err and "not a TSO file name" in err


def test_bad_test_type_and_bad_unit(tmp_path, capsys):
    app = _app(tmp_path / "app")
    src = next(app.glob("*_2.2_*.csv"))
    src.rename(app / src.name.replace("_2.2_", "_9.9_"))
    assert main(["prequal", str(app)]) == 2
    err = capsys.readouterr().err
    assert "_9.9_" in err and "test type '9.9'" in err and len(err.strip().splitlines()) == 1
    app2 = _app(tmp_path / "app2")
    (app2 / "unit.toml").write_text(UNIT_TOML.replace('area = "NO5"', 'area = "NO5"\nrated = 3'))
    assert main(["prequal", str(app2)]) == 2
    err = capsys.readouterr().err
    assert "unit.toml" in err and "unknown key 'unit.prequal.rated'" in err


def test_service_and_test_id_must_agree(tmp_path, capsys):
    app = _app(tmp_path / "app")
    src = next(app.glob("*_2.2_*.csv"))
    src.rename(app / src.name.replace("_FcrdUp_2.2_", "_FcrdDo_2.2_"))
    assert main(["prequal", str(app)]) == 2
    assert "test 2.2 is a FcrdUp test" in capsys.readouterr().err


def test_report_option(tmp_path, capsys):
    app = _app(tmp_path / "app")
    out = tmp_path / "report.html"
    rc = main(["prequal", str(app), "--report", str(out)])
    if importlib.util.find_spec("fcrlive.prequal.report") is None:
        assert rc == 2 and "not available" in capsys.readouterr().err
    else:
        assert rc == 0 and out.is_file() and "<html" in out.read_text(encoding="utf-8").lower()


def test_pdf_option(tmp_path, capsys, monkeypatch):
    """--pdf prints the report with headless Chromium next to the HTML; without --report, or without a
    Chromium, one line and exit status 2 (the HTML is written all the same)."""
    pytest.importorskip("fcrlive.prequal.report")
    from fcrlive.prequal.report import find_chromium

    app = _app(tmp_path / "app")
    html, pdf = tmp_path / "report.html", tmp_path / "report.pdf"
    assert main(["prequal", str(app), "--pdf", str(pdf)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--pdf" in err[0] and "--report" in err[0] and not pdf.exists()

    with monkeypatch.context() as m:
        m.setenv("FCRLIVE_CHROMIUM", str(tmp_path / "no-such-browser"))
        assert main(["prequal", str(app), "--report", str(html), "--pdf", str(pdf)]) == 2
        err = [x for x in capsys.readouterr().err.splitlines() if "error" in x]  # (and the progress bar)
        assert len(err) == 1 and err[0].startswith("fcrlive prequal: error: no Chromium found")
        assert html.is_file() and not pdf.exists()

    if find_chromium() is None:
        pytest.skip("no Chromium on this machine (./dev installs Debian's chromium when run as root)")
    html.unlink()
    assert main(["prequal", str(app), "--report", str(html), "--pdf", str(pdf)]) == 0
    data = pdf.read_bytes()
    assert html.is_file() and data.startswith(b"%PDF-")
    assert b"/Title (FCR prequalification: TESTU1)" in data


def test_no_unit_description_uses_regstr_or_is_undecided(tmp_path, capsys):
    app = _app(tmp_path / "app")
    (app / "unit.toml").unlink()
    assert main(["prequal", str(app), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["unit"] is None
    steps = next(t for t in doc["tests"] if t["test_id"] == "1.1")
    assert steps["requirements"]["1-up"]["pass"] is None
    assert doc["verdict"]["Fcrn"]["status"] == "incomplete"
