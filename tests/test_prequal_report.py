"""The prequalification report (fcrlive.prequal.report): what the HTML holds, the daemon-store history,
and the report opened in a real headless Chromium (started here): the DOM it builds (tables and figures
of every test), a screenshot kept as an artefact, and the PDF it prints.

The application is the paper's plant simulated (``fcrlive simulate --tso-test``: FCR-N steps, FCR-D up
ramps and three FCR-N sine periods) and evaluated (``fcrlive.prequal.load.evaluate_dir``)."""

from __future__ import annotations

import html.parser
import re
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from tests_daemon_support import report as daemon_report

from fcrlive.cli import main
from fcrlive.errors import DataError
from fcrlive.prequal import report
from fcrlive.prequal.model import (
    DOCUMENTS,
    Capacity,
    FrequencyPoint,
    PrequalResult,
    RequirementResult,
    TestEvaluation,
    Verdict,
)

# ---------------------------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def application(tmp_path_factory):
    from fcrlive.prequal.load import evaluate_dir

    d = tmp_path_factory.mktemp("application")
    rc = main(
        [
            "simulate",
            "--tso-test",
            "fcrn-steps",
            "--tso-test",
            "fcrd-up-ramps",
            "--tso-test",
            "sines-fcrn",
            "--sine-periods",
            "10,40,150",
            "--out-dir",
            str(d),
        ]
    )
    assert rc == 0
    return evaluate_dir(d, None, "nordic-2025")


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """A daemon store with four identification results (written by the daemon's own writer)."""
    from fcrlive.daemon.store import ResultRow, SampleWriter

    path = tmp_path_factory.mktemp("store") / "fcrlive.sqlite"
    t0 = 1_790_000_000.0
    with SampleWriter(path, ["power", "grid_freq"]) as w:
        for k, (droop, level) in enumerate(
            ((0.080, "ok"), (0.0795, "ok"), (0.12, "rejected"), (0.0802, "ok"))
        ):
            # what the daemon stores: the typed report's JSON form
            result = daemon_report(
                droop=droop, droop_ci95=(droop - 0.002, droop + 0.002), max_abs_s=1.29 + 0.01 * k
            )
            fcrn = result.tso["fcrn"]
            result.tso["fcrd"] = fcrn.model_copy(update={"passed": k != 2})
            result = result.to_json_dict()
            t2 = t0 + 1800.0 * (k + 1)
            w.add_result(
                ResultRow(
                    t=t2 + 1.0,
                    t1=t2 - 1800.0,
                    t2=t2,
                    method="zcu",
                    ok_fraction=1.0,
                    quality={},
                    result=result,
                    duration_s=0.8,
                    result_quality={"level": level, "reasons": []},
                )
            )
        # and one run the daemon skipped
        w.add_result(
            ResultRow(
                t=t0 + 9001.0,
                t1=t0 + 7200.0,
                t2=t0 + 9000.0,
                method="zcu",
                ok_fraction=0.3,
                quality={},
                result=None,
                duration_s=0.0,
                error="too little good data: 30 % ok",
            )
        )
        # and one stored under another schema: listed as unreadable, not guessed at
        w.add_result(
            ResultRow(
                t=t0 + 9601.0,
                t1=t0 + 7800.0,
                t2=t0 + 9600.0,
                method="zcu",
                ok_fraction=1.0,
                quality={},
                result={"droop": {"value": 0.08, "std": 0.001}},
                duration_s=0.8,
            )
        )
        assert w.flush()
    return path


@pytest.fixture(scope="module")
def written(application, store, tmp_path_factory):
    out = tmp_path_factory.mktemp("report") / "report.html"
    report.write_report(application, out, store=store)
    return out


# ---------------------------------------------------------------------------------------------- the HTML


class _Dom(html.parser.HTMLParser):
    """Counts elements and collects the ones the checks need (articles with what they contain)."""

    def __init__(self):
        super().__init__()
        self.count: dict[str, int] = {}
        self.ids: list[str] = []
        self.articles: list[dict[str, int]] = []
        self.svg_labels: list[str] = []
        self.external: list[str] = []
        self._in_article = 0

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.count[tag] = self.count.get(tag, 0) + 1
        if "id" in a and tag in ("section", "article"):
            self.ids.append(a["id"])
        if tag == "article":
            self.articles.append({})
            self._in_article += 1
        elif self._in_article and self.articles:
            self.articles[-1][tag] = self.articles[-1].get(tag, 0) + 1
        if tag == "svg" and "aria-label" in a:
            self.svg_labels.append(a["aria-label"])
        for key in ("src", "href"):
            v = a.get(key) or ""
            if v and not v.startswith("#"):
                self.external.append(v)
        if tag in ("script", "link", "img", "iframe"):
            self.external.append(tag)

    def handle_endtag(self, tag):
        if tag == "article":
            self._in_article -= 1


def parse(text: str) -> _Dom:
    d = _Dom()
    d.feed(text)
    return d


def test_report_holds_every_test_and_the_sections(application, written):
    text = written.read_text(encoding="utf-8")
    dom = parse(text)
    assert dom.external == []  # self-contained: no scripts, images, style sheets or links out
    for section in ("summary", "unit", "coverage", "time", "freq", "measurement", "history", "document"):
        assert section in dom.ids, section
    assert len(dom.articles) == len(application.tests)
    for ev, art in zip(_ordered(application), dom.articles):
        assert art.get("table", 0) >= 1, ev.file  # its requirements (and figures) tables
        if ev.series is not None:
            assert art.get("svg", 0) >= 1, ev.file
    # the frequency domain: a Nyquist plot with both circles and the Req. 9 plot for the sine set
    assert any("Nyquist" in s for s in dom.svg_labels) and any("Req. 9" in s for s in dom.svg_labels)
    assert "0.95·0.43 (accepted margin)" in text and "0.43 (Req. 8)" in text
    # the zoom where Req. 2-4 are read, for the fast ramp test
    assert any("where Req. 2, 3 and 4 are read" in s for s in dom.svg_labels)
    # verdicts and capacity per service, the document
    cap = application.capacity["Fcrn"]
    assert f"{report._num(cap.capacity_mw)} MW" in text
    assert DOCUMENTS["nordic-2025"].title in text
    assert "print" in text and "@page" in text  # print rules


def _ordered(result):
    time_tests = [ev for ev in result.tests if ev.kind not in ("sine", "sine-set", "operation")]
    freq = [ev for ev in result.tests if ev.kind in ("sine-set", "operation")]
    sines = [ev for ev in result.tests if ev.kind == "sine"]
    return [*time_tests, *freq, *sines]


def test_history_from_the_daemon_store(written):
    text = written.read_text(encoding="utf-8")
    sec = text[text.index('id="history"') : text.index('id="document"')]
    assert "6 identification runs" in sec and "4 with a droop estimate" in sec
    assert "stored result not readable" in sec
    assert "8.00 [7.80, 8.20]" in sec and "12.00 [11.80, 12.20]" in sec  # droop in % with its 95 % interval
    assert "fcrd: fail" in sec and "fcrd: pass" in sec
    assert "rejected" in sec and "too little good data" in sec
    assert "<svg" in sec  # the droop-over-time figure


def test_bad_store_is_a_data_error(application, tmp_path):
    bad = tmp_path / "not-a-store.sqlite"
    bad.write_text("this is not SQLite")
    with pytest.raises(DataError, match="cannot read the store") as e:
        report.write_report(application, tmp_path / "r.html", store=bad)
    assert e.value.where == str(bad)
    with pytest.raises(DataError, match="no such store"):
        report.write_report(application, tmp_path / "r.html", store=tmp_path / "missing.sqlite")


def _synthetic(note: str) -> PrequalResult:
    periods = (10.0, 25.0, 60.0, 150.0)
    # a first-order lag with a delay: F = e^{-jωτ}/(1 + jωT)
    pts = tuple(
        FrequencyPoint(
            T, complex(np.exp(-1j * 2 * np.pi / T * 1.0) / (1 + 1j * 2 * np.pi / T * 20.0)), 0.01, 0.2
        )
        for T in periods
    )
    r8 = RequirementResult("8", "Frequency-domain stability", 0.9, 0.4085, "", True, ">=", note=note)
    r9 = RequirementResult("9", "Frequency-domain performance", 1.2, 1.0, "", False, "<", k_red=0.93)
    r1 = RequirementResult(
        "1-up",
        "Steady-state response upwards",
        None,
        (-0.05, 0.2),
        "",
        None,
        "within",
        note="no steady state",
    )
    sine_set = TestEvaluation(
        file="a.csv, b.csv",
        service="Fcrn",
        test_id="4.1",
        kind="sine-set",
        requirements={"8": r8, "9": r9},
        figures={"k_red_dyn": 0.93},
        points=pts,
    )
    steps = TestEvaluation(
        file="FCPG1_Fcrn_1.1_<x>.csv",
        service="Fcrn",
        test_id="1.1",
        kind="fcrn-steps",
        requirements={"1-up": r1},
        figures={"dp_ss_mw": 7.4},
    )
    cap = Capacity("Fcrn", None, 0.93, 6.975, 7.5, 0.9)
    return PrequalResult(
        document=DOCUMENTS["statnett-2024"],
        unit=None,
        tests=(steps, sine_set),
        capacity={"Fcrn": cap},
        verdict={"Fcrn": Verdict("Fcrn", "incomplete", ("step sequence 1.2",), ("Req. 9 (a.csv, b.csv)",))},
    )


def test_report_of_a_synthetic_result_escapes_and_marks_status():
    """No unit, no series: the report still renders, says what is unknown, escapes text, and shows
    pass / FAIL / undecided as words (readable in black and white)."""
    text = report.render_html(_synthetic("<script>alert(1)</script> & more"))
    dom = parse(text)
    assert dom.external == [] and "<script>alert" not in text and "&lt;script&gt;" in text
    assert "FCPG1_Fcrn_1.1_&lt;x&gt;.csv" in text
    assert ">pass<" in text and ">FAIL<" in text and ">undecided<" in text and "INCOMPLETE" in text
    assert "No unit description" in text and "No daemon store was given" in text
    assert "statnett-2024" in text and "1.7 s" in text  # the document and its Req. 4 limit
    assert any("Nyquist" in s for s in dom.svg_labels)
    assert "with K_red,dyn = 0.930" in text  # Req. 9 failed: the reduced curve is drawn too


# ---------------------------------------------------------------------------------------------- Chromium


def _chromium() -> str:
    exe = report.find_chromium()
    if exe is None:
        pytest.skip("no Chromium on this machine (./dev installs Debian's chromium when run as root)")
    return exe


def _run_chromium(
    exe: str, tmp_path: Path, *args: str, timeout: float = 120.0
) -> subprocess.CompletedProcess:
    prof = tmp_path / "chromium-profile"
    cmd = report.chromium_command(exe, *args, profile_dir=str(prof))
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)
    assert proc.returncode == 0, (cmd, proc.stderr[-2000:])
    return proc


def test_chromium_builds_the_dom(application, written, tmp_path):
    """The DOM headless Chromium builds from the file (--dump-dom): every test's article with its
    tables and figures, the sections, the SVG figures rendered as elements."""
    exe = _chromium()
    proc = _run_chromium(exe, tmp_path, "--dump-dom", written.resolve().as_uri())
    dom = parse(proc.stdout)
    src = parse(written.read_text(encoding="utf-8"))
    assert dom.count.get("article") == len(application.tests)
    assert dom.count.get("table") == src.count.get("table") and dom.count["table"] > len(application.tests)
    assert dom.count.get("figure") == src.count.get("figure") and dom.count.get("svg") == src.count.get("svg")
    assert dom.count["svg"] >= sum(ev.series is not None for ev in application.tests)
    for section in ("summary", "unit", "coverage", "time", "freq", "measurement", "history", "document"):
        assert section in dom.ids
    assert [len(a) > 0 for a in dom.articles] == [True] * len(application.tests)
    assert "FCR prequalification: FCPSIM1" in proc.stdout


def test_chromium_screenshot_is_kept(written, tmp_path):
    """A screenshot of the top of the report (kept under pytest's tmp directory as an artefact)."""
    exe = _chromium()
    shot = tmp_path / "prequal-report.png"
    _run_chromium(
        exe, tmp_path, f"--screenshot={shot}", "--window-size=1280,1800", written.resolve().as_uri()
    )
    import matplotlib.image

    img = matplotlib.image.imread(shot)
    assert img.shape[:2] == (1800, 1280)
    # not blank: the page has text, tables and coloured badges
    assert float(np.std(img[..., :3])) > 0.05
    red = (img[..., 0] > 0.6) & (img[..., 1] < 0.3) & (img[..., 2] < 0.3)  # the FAIL badges
    assert red.sum() > 50
    print(f"screenshot kept: {shot}")


def test_chromium_prints_the_pdf(written, tmp_path):
    _chromium()
    pdf = tmp_path / "report.pdf"
    t0 = time.monotonic()
    out = report.write_pdf(written, pdf)
    data = out.read_bytes()
    assert data.startswith(b"%PDF-")
    pages = len(re.findall(rb"/Type\s*/Page[^s]", data))
    assert pages >= 5, pages
    boxes = {
        tuple(round(float(x)) for x in m.split()) for m in re.findall(rb"/MediaBox\s*\[([^\]]*)\]", data)
    }
    assert boxes == {(0, 0, 595, 842)}  # A4 from the print CSS
    assert b"/Title (FCR prequalification: FCPSIM1)" in data
    assert data.count(b"/Link") > 0  # the table of contents and test links stay links
    print(f"PDF: {pages} pages, {len(data) / 1e6:.1f} MB in {time.monotonic() - t0:.1f} s")


def test_pdf_without_chromium_is_one_clear_error(written, tmp_path, monkeypatch):
    from fcrlive.errors import UserError

    monkeypatch.setenv("FCRLIVE_CHROMIUM", str(tmp_path / "no-such-browser"))
    with pytest.raises(UserError, match="no Chromium found"):
        report.write_pdf(written, tmp_path / "x.pdf")


def test_many_failures_of_one_requirement_are_one_line():
    """A linearity test fails step by step: the summary says how many steps and the worst one."""
    items = [
        "Req. 11 Linearity at 49.980 Hz (step 1): -0.1183 outside [-0.05, 0.1] (A_5.1.csv)",
        "Req. 11 Linearity at 49.960 Hz (step 2): -0.1522 outside [-0.05, 0.1] (A_5.1.csv)",
        "Req. 11 Linearity at 49.940 Hz (step 3): -0.174 outside [-0.05, 0.1] (A_5.1.csv)",
        "Req. 11 Linearity, all steps (the worst): -0.18 outside [-0.05, 0.1] (A_5.1.csv)",
        "Req. 1 Steady-state response upwards (eq. 1): -0.054 outside [-0.05, 0.2] (A_1.1.csv)",
        "K_red,ss = 0.839 below the minimum 0.9",
    ]
    assert report._group_failures(items) == [
        "Req. 11 Linearity: 3 not met; the worst -0.18 outside [-0.05, 0.1] (A_5.1.csv)",
        items[4],
        items[5],
    ]
