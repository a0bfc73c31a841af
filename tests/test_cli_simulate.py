"""``fcrlive simulate``: option errors are one line with exit status 2; written logs read back."""

from __future__ import annotations

import pytest

from fcrlive import cli


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
