"""``fcrlive simulate``: option errors are one line with exit status 2; written logs read back."""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive import cli
from fcrlive.constants import PAPER_EXCITATION_STD_PU
from fcrlive.plant.params import preset
from fcrlive.tso.csvlog import read_log
from fcrlive.tso.signals import plant_signals


@pytest.mark.parametrize(
    ("argv", "text"),
    [
        (["simulate"], "nothing to do"),
        (["simulate", "--out", "x.csv", "--sample-ms", "30"], "--sample-ms: --sample-ms 30 is not a whole"),
        (["simulate", "--out", "x.csv", "--minutes", "0"], "--minutes must be positive"),
        (["simulate", "--out", "x.csv", "--preset", "nope"], "unknown preset 'nope'"),
        (["simulate", "--out", "x.csv", "--start", "tomorrow"], "--start 'tomorrow'"),
    ],
)
def test_option_errors_are_one_line_exit_2(argv, text, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("fcrlive simulate: error: ")
    assert text in err
    assert not (tmp_path / "x.csv").exists()


def test_missing_plant_file_is_one_line_exit_2(capsys, tmp_path):
    assert cli.main(["simulate", "--plant", str(tmp_path / "none.toml"), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "none.toml" in err


def test_simulate_writes_a_readable_tso_log_into_a_directory(capsys, tmp_path):
    out = tmp_path / "logs"
    argv = ["simulate", "--minutes", "1", "--excitation", "--sample-ms", "100", "--seed", "3"]
    assert cli.main([*argv, "--out", f"{out}/"]) == 0
    files = list(out.iterdir())
    assert [f.name for f in files] == ["FCPSIM1_Fcrn_Operation_NO5_UTC_20261101T0000-20261101T0001_100ms.csv"]
    log = read_log(files[0])
    assert len(log) == 600 and log.sample_s == pytest.approx(0.1) and log.period_s is None
    assert list(log.columns) == ["InsAcPow", "GridFreq", "ApplFreqSig", "ContOutSig", "GuideVane"]
    s = plant_signals(log, preset("paper-plant1").unit.rated_mw)
    assert s.has_excitation
    # the paper's excitation: white, std 0.1/(50·3) pu
    assert np.std(s.r) == pytest.approx(PAPER_EXCITATION_STD_PU, rel=0.15)
    assert 0.5 < np.mean(s.c) < 1.0 and 0.5 < np.mean(s.a) < 1.0
    stdout = capsys.readouterr().out.strip().splitlines()
    assert len(stdout) == 1
    assert stdout[0].startswith(f"{files[0]}: 600 samples, 59.9 s, power std ")
    assert "mHz" in stdout[0]


def test_simulate_to_a_file_without_excitation(capsys, tmp_path):
    path = tmp_path / "op.csv"
    assert cli.main(["simulate", "--minutes", "0.5", "--out", str(path)]) == 0
    log = read_log(path)
    assert len(log) == 1500 and "ApplFreqSig" not in log.columns
    assert not plant_signals(log, 300.0).has_excitation
    assert path.read_bytes().count(b"\r\n") == 1501


def test_sine_tests_one_file_per_period(capsys, tmp_path, monkeypatch):
    import fcrlive.constants

    monkeypatch.setattr(fcrlive.constants, "TSO_PERIODS_S", (10.0, 40.0))  # all ten take seconds
    assert cli.main(["simulate", "--sample-ms", "100", "--sine-tests", str(tmp_path / "sine")]) == 0
    files = sorted((tmp_path / "sine").iterdir(), key=lambda p: p.stat().st_mtime_ns)
    assert len(files) == 2
    captured = capsys.readouterr()
    assert "sine test 1/2: period 10 s" in captured.err and "sine test 2/2" in captured.err
    assert len(captured.out.strip().splitlines()) == 2
    for f, period in zip(files, (10.0, 40.0)):
        assert f"_Sine{period:g}_" in f.name
        assert f.read_bytes().startswith(f"DateTime{period:g},InsAcPow{period:g},".encode())
        log = read_log(f)
        assert log.period_s == period and log.name is not None and log.name.period_s == period
        assert log.notes == ()
        s = plant_signals(log, 300.0)
        # the applied ±100 mHz sine is the governor's control error: amplitude 0.1/50 pu
        assert np.max(np.abs(s.epsilon)) == pytest.approx(0.1 / 50.0, rel=1e-3)
        assert s.has_excitation
