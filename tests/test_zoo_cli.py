"""``fcrlive simulate`` with the validation zoo's options (docs/zoo.md)."""

from __future__ import annotations

import numpy as np
import pytest

from fcrlive import cli
from fcrlive.tso.csvlog import read_log


def test_list_zoo(capsys):
    assert cli.main(["simulate", "--list-zoo"]) == 0
    out = capsys.readouterr().out
    assert "B-int-beuler-10Hz" in out and "hist-1s" in out


def test_zoo_plant_through_a_historian_logger(capsys, tmp_path):
    path = tmp_path / "h.csv"
    argv = ["simulate", "--zoo-plant", "B-int-beuler-10Hz", "--logger", "hist-1s", "--minutes", "3",
            "--out", str(path)]
    assert cli.main(argv) == 0
    err = capsys.readouterr().err
    assert "droop 4.444 %" in err and "1 s block averages" in err
    log = read_log(path)
    assert log.sample_s == pytest.approx(1.0) and len(log) == 180
    assert set(log.columns) == {"GridFreq", "ApplFreqSig", "InsAcPow"}
    text = path.read_text().splitlines()[1].split(",")
    assert len(text[1].split(".")[1]) == 3 and len(text[2].split(".")[1]) == 6  # GridFreq, ApplFreqSig


def test_logger_options_without_a_named_logger(capsys, tmp_path):
    path = tmp_path / "c.csv"
    argv = ["simulate", "--zoo-plant", "C-pid-tustin-50Hz", "--log-every", "5", "--freq-resolution-mhz", "10",
            "--columns", "governor", "--minutes", "1", "--excitation", "--out", str(path)]
    assert cli.main(argv) == 0
    log = read_log(path)
    assert log.sample_s == pytest.approx(0.1)
    f = log.columns["GridFreq"]
    np.testing.assert_allclose(f * 100, np.round(f * 100), atol=1e-6)  # 10 mHz steps
    assert {"ContOutSig", "GuideVane"} <= set(log.columns)


@pytest.mark.parametrize("argv, text", [
    (["--zoo-plant", "nope"], "--zoo-plant: unknown zoo plant"),
    (["--logger", "nope"], "unknown zoo logger"),
    (["--logger", "hist-1s", "--sample-ms", "40"], "--sample-ms"),
    (["--block-average", "1", "--jitter-ms", "2"], "jitter"),
    (["--meter-noise-pct", "-1"], "meter_noise_pct"),
])
def test_bad_zoo_options_are_one_line_exit_2(argv, text, capsys, tmp_path):
    assert cli.main(["simulate", *argv, "--minutes", "1", "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert text in err and "\n" not in err


@pytest.mark.parametrize(
    "opt", [["--zoo-plant", "ref-paper-50Hz"], ["--logger", "hist-1s"], ["--jitter-ms", "1"]]
)
def test_tso_test_refuses_zoo_options(opt, capsys, tmp_path):
    # the prequalification programme simulates --preset/--plant; a zoo option would be silently ignored
    assert cli.main(["simulate", "--tso-test", "operation", "--out-dir", str(tmp_path / "d"), *opt]) == 2
    err = capsys.readouterr().err.strip()
    assert opt[0] in err and "--tso-test" in err and "\n" not in err
    assert not (tmp_path / "d").exists()
