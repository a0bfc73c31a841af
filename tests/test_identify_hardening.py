"""Issue 14: `fcrlive identify` on the malformed-log corpus (tests/malformed_logs.py): exit 2 with one line
that names the file (or the option) and says what to do; never a traceback, a hang or numbers from a broken
log."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from malformed_logs import Outcome, make_corpus

from fcrlive.cli import main


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return {c.name: c for c in make_corpus(tmp_path_factory.mktemp("corpus"))}


def _run(case, capsys) -> Outcome:
    rc = main(["identify", *case.args])
    cap = capsys.readouterr()
    return Outcome(case, rc, cap.err, cap.out)


CASES = [
    "valid log", "utf16_bom", "utf16_nobom", "cr_only", "random_bytes", "header_then_garbage",
    "gzip_named_csv", "field_1mb", "dev_zero", "fifo", "kd_nan_json", "plot_unwritable",
    # broken logs that gave numbers with exit 0
    "freq_spike_1e30", "freq_spike_in_band", "power_spike_in_range", "freq_mhz", "power_kw", "arabic_digits",
    "underscore_number", "drop_10pct_rows",
    # identification-stage messages without the file
    "short_60s", "constant_power", "constant_1e300", "pi_controller_1hz",
]


def test_the_corpus_is_all_here(corpus):
    assert set(CASES) == set(corpus)


@pytest.mark.timeout(120)
@pytest.mark.parametrize("name", CASES)
def test_corpus_case(corpus, name, capsys):
    o = _run(corpus[name], capsys)
    assert o.verdict == "ok", (o.rc, o.stderr[-2000:])


def test_json_has_no_nan_even_where_a_value_is_unknown(corpus, capsys):
    case = corpus["valid log"]
    rc = main(["identify", *case.args, "--json", "--kd", "0.0"])
    out = capsys.readouterr().out
    assert rc == 0
    json.loads(out, parse_constant=lambda c: pytest.fail(f"JSON holds {c}"))


@pytest.mark.parametrize(
    ("opt", "value"), [("--rated-mw", "inf"), ("--f0", "nan"), ("--ts-id", "0"), ("--kd", "inf")]
)
def test_non_finite_options_are_one_line(corpus, opt, value, capsys):
    case = corpus["valid log"]
    args = [a for a in case.args]
    if opt == "--rated-mw":
        args[args.index("--rated-mw") + 1] = value
    else:
        args += [opt, value]
    rc = main(["identify", *args])
    err = capsys.readouterr().err
    assert rc == 2 and len(err.strip().splitlines()) == 1 and opt in err


def test_a_log_split_at_a_gap_says_so(corpus, tmp_path, capsys):
    lines = Path(corpus["valid log"].args[0]).read_bytes().split(b"\r\n")
    del lines[4001:4051]  # 5 s missing: 0.6 % of the samples, split (not filled)
    path = tmp_path / "gap.csv"
    path.write_bytes(b"\r\n".join(lines))
    rc = main(["identify", str(path), "--rated-mw", "300", "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert rc == 0
    assert any("gap.csv: gap of 5.100 s (50 samples missing)" in n and "log split here" in n
               for n in doc["notes"])
    assert any("gap.csv: 2 gap-free segments" in n for n in doc["notes"])
