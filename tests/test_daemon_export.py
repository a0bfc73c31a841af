"""fcrlive export: a stored stretch → TSO CSV (CRLF, DateTime stamps) that the TSO reader reads back."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fcrlive.cli import main
from fcrlive.daemon.sample import Quality, Sample
from fcrlive.daemon.store import write_samples
from fcrlive.tso.csvlog import read_log

T0 = 1_793_491_200.0  # 2026-11-01T00:00:00Z
SIGNALS = ("power", "grid_freq", "controller_output", "guide_vane", "excitation_applied")


def _stretch(n, t0, bad=(), exc=0.0, seed=0):
    rng = np.random.default_rng(seed)
    for i in range(n):
        t = t0 + i * 0.04 + rng.uniform(0, 0.004)  # 25 Hz ticks, arrival jitter up to 4 ms
        f = 50.0 + 0.05 * math.sin(2 * math.pi * i * 0.04 / 40)
        v = {"power": 80.0 + 40 * (50 - f), "grid_freq": f, "controller_output": 55.0, "guide_vane": 54.0,
             "excitation_applied": exc}
        q = Quality.OK
        if i in bad:
            q, v = Quality.COMM_ERROR, dict.fromkeys(v, math.nan)
        yield Sample(t, math.nan, i, v, q)


def test_export_roundtrip(tmp_path, capsys):
    db = tmp_path / "s.sqlite"
    write_samples(db, SIGNALS, _stretch(750, T0, bad=range(100, 102)))  # 30 s, 2 comm errors
    out = tmp_path / "G1.csv"
    rc = main(["export", "--db", str(db), "--from", "2026-11-01T00:00:00Z", "--to", str(T0 + 60),
               "--out", str(out)])
    assert rc == 0
    assert "748 samples" in capsys.readouterr().out
    raw = out.read_bytes()
    assert raw.startswith(b"DateTime,InsAcPow,GridFreq,ContOutSig,GuideVane\r\n")
    assert raw.split(b"\r\n")[1].startswith(b"20261101T000000.")
    log = read_log(out)
    assert len(log) == 750  # the 2-sample gap is filled (and flagged) by the reader
    assert int(np.count_nonzero(log.filled)) == 2
    assert log.sample_s == pytest.approx(0.04, abs=1e-3)
    assert log.columns["GridFreq"][0] == pytest.approx(50.0, abs=1e-6)
    assert "ApplFreqSig" not in log.columns


def test_export_with_excitation_and_config(tmp_path):
    db = tmp_path / "s.sqlite"
    write_samples(db, SIGNALS, _stretch(600, T0, exc=0.01))
    cfg = tmp_path / "f.toml"
    cfg.write_text(f"""
[unit]
name = "G1"
rated_mw = 100
[source.modbus]
points = [{{name = "power", table = "input", address = 0, type = "float32"}}]
[store]
path = "{db.name}"
""")
    out = tmp_path / "x.csv"
    assert main(["export", "--config", str(cfg), "--from", str(T0), "--to", str(T0 + 30),
                 "--out", str(out), "--timestamps", "arrival"]) == 0
    log = read_log(out)
    assert np.allclose(log.columns["GridFreq"] - log.columns["ApplFreqSig"], 0.01, atol=1e-6)


def test_export_errors_are_one_line(tmp_path, capsys):
    db = tmp_path / "s.sqlite"
    write_samples(db, SIGNALS, _stretch(10, T0))
    assert main(["export", "--db", str(db), "--from", "yesterday", "--to", "1", "--out", "x.csv"]) == 2
    assert "--from: cannot read time 'yesterday'" in capsys.readouterr().err
    assert main(["export", "--db", str(db), "--from", str(T0 + 100), "--to", str(T0 + 200),
                 "--out", str(tmp_path / "y.csv")]) == 2
    assert "only 0 good sample(s)" in capsys.readouterr().err
