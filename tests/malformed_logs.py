"""The malformed-log corpus of issue 14, generated (no committed blobs).

Each :class:`Case` is a set of ``fcrlive identify`` arguments built around a file that an adversarial (or
just unlucky) user might feed in, and what must happen: ``"refuse"`` (exit 2, one line on stderr naming the
file or the option) or ``"ok"`` (exit 0). Used by tests/test_reader_hardening.py and
tests/test_identify_hardening.py, and as a script that runs every case through the real CLI in a
subprocess and counts tracebacks, hangs and broken logs accepted with numbers::

    .venv/bin/python tests/malformed_logs.py [DIR]
"""

from __future__ import annotations

import gzip
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np

START = datetime(2026, 11, 1)


@dataclass(frozen=True)
class Case:
    name: str
    args: list[str]
    """Arguments after ``fcrlive identify``."""
    expect: str
    """"refuse" (exit 2, one line naming ``names``) or "ok" (exit 0)."""
    names: str = ""
    """Text the one-line error must contain (the file or the option)."""
    hint: str = ""
    """Text the error must also contain (what to do), if any."""
    group: str = "crash"
    """"crash" (traceback/hang before), "broken" (accepted with numbers before), "message"."""
    extra: dict = field(default_factory=dict)


def _sim_log(seconds: float, *, sample_s: float, excitation: bool = False, seed: int = 4):
    from fcrlive.plant.params import preset
    from fcrlive.sim import SimConfig, simulate
    from fcrlive.tso.signals import log_from_sim

    res = simulate(preset("paper-plant1"), SimConfig(duration_s=seconds, snr_db=12.0, excitation=excitation,
                                                     seed=seed))
    return log_from_sim(res, start=START, sample_s=sample_s)


def valid_log_bytes(seconds: float = 900.0, sample_s: float = 0.1) -> bytes:
    """A valid TSO log (simulated paper-plant1, no excitation): what the mutations start from."""
    from fcrlive.tso.csvlog import write_log

    with tempfile.TemporaryDirectory() as d:
        p = write_log(Path(d) / "v.csv", _sim_log(seconds, sample_s=sample_s))
        return p.read_bytes()


def _edit_column(data: bytes, column: str, fn) -> bytes:
    """Apply ``fn(list_of_value_strings) -> list`` to one column of a CRLF log."""
    lines = data.decode("ascii").split("\r\n")
    header = lines[0].split(",")
    j = header.index(column)
    rows = [ln.split(",") for ln in lines[1:] if ln]
    vals = fn([r[j] for r in rows])
    for r, v in zip(rows, vals):
        r[j] = v
    return ("\r\n".join([lines[0], *(",".join(r) for r in rows)]) + "\r\n").encode("utf-8")


def make_corpus(folder: Path) -> list[Case]:
    """Write the corpus files into ``folder`` and return the cases."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(14)
    good = valid_log_bytes()
    text = good.decode("ascii")
    cases: list[Case] = []

    def put(name: str, data: bytes) -> str:
        p = folder / name
        p.write_bytes(data)
        return str(p)

    def refuse(name, data_or_path, hint="", group="crash", args=(), names=None):
        path = data_or_path if isinstance(data_or_path, str) else put(f"{name}.csv", data_or_path)
        cases.append(Case(name, [path, "--rated-mw", "300", *args], "refuse", names or path, hint, group))

    ok_path = put("good.csv", good)
    cases.append(Case("valid log", [ok_path, "--rated-mw", "300"], "ok", group="control"))
    # --- tracebacks and hangs before
    refuse("utf16_bom", text.encode("utf-16"), hint="UTF-16")
    refuse("utf16_nobom", text.encode("utf-16-le"), hint="UTF-16")
    refuse("cr_only", text.replace("\r\n", "\r").encode("ascii"), hint="line end")
    refuse("random_bytes", rng.integers(0, 256, 200_000, dtype=np.uint8).tobytes())
    head = text.split("\r\n", 1)[0] + "\r\n"
    refuse("header_then_garbage", head.encode() + rng.integers(0, 256, 100_000, dtype=np.uint8).tobytes())
    refuse("gzip_named_csv", gzip.compress(good), hint="compressed")
    lines = text.split("\r\n")
    lines[50] = lines[50].split(",", 1)[0] + "," + "1" * 1_000_000 + "," + lines[50].split(",", 2)[2]
    refuse("field_1mb", "\r\n".join(lines).encode("ascii"))
    refuse("dev_zero", "/dev/zero", hint="regular file")
    fifo = folder / "fifo.csv"
    if not fifo.exists():
        os.mkfifo(fifo)
    refuse("fifo", str(fifo), hint="regular file")
    refuse("kd_nan_json", ok_path, args=("--kd", "nan", "--json"), names="--kd")
    blocker = folder / "not_a_dir"
    blocker.write_text("x")
    refuse("plot_unwritable", ok_path, args=("--plot", str(blocker / "plots")), names="--plot")
    # --- broken logs accepted with numbers before
    def spike(v):
        v[4000] = "1e30"
        return v

    refuse("freq_spike_1e30", _edit_column(good, "GridFreq", spike), hint="row", group="broken")
    def inband(v):
        v[3000] = f"{float(v[3000]) + 0.5:.6f}"
        return v

    refuse("freq_spike_in_band", _edit_column(good, "GridFreq", inband), hint="row 3002", group="broken")

    def power_spike(v):
        v[5000] = f"{float(v[5000]) - 150:.6f}"
        return v

    refuse("power_spike_in_range", _edit_column(good, "InsAcPow", power_spike), hint="row 5002",
           group="broken")
    refuse("freq_mhz", _edit_column(good, "GridFreq", lambda v: [f"{1e3 * float(x):.3f}" for x in v]),
           hint="mHz", group="broken")
    refuse("power_kw", _edit_column(good, "InsAcPow", lambda v: [f"{1e3 * float(x):.3f}" for x in v]),
           hint="kW", group="broken")
    arabic = str.maketrans("0123456789", "٠١٢٣٤٥٦٧٨٩")

    def arab(v):
        v[100] = v[100].translate(arabic)
        return v

    refuse("arabic_digits", _edit_column(good, "InsAcPow", arab), hint="row 102", group="broken")

    def under(v):
        v[100] = v[100][:1] + "_" + v[100][1:]
        return v

    refuse("underscore_number", _edit_column(good, "InsAcPow", under), hint="row 102", group="broken")
    body = text.split("\r\n")
    keep = [body[0]] + [ln for ln in body[1:-1] if rng.random() >= 0.1]
    refuse("drop_10pct_rows", ("\r\n".join(keep) + "\r\n").encode(), hint="gap", group="broken")
    # --- messages from the identification stage (exit 2 before, but without the file's name)
    short = "\r\n".join(body[:601]) + "\r\n"  # 60 s
    refuse("short_60s", short.encode(), group="message")
    refuse("constant_power", _edit_column(good, "InsAcPow", lambda v: ["225.0"] * len(v)), group="message",
           hint="constant")
    refuse("constant_1e300", _edit_column(good, "InsAcPow", lambda v: ["1e300"] * len(v)), group="message")
    from fcrlive.tso.csvlog import write_log

    slow = write_log(folder / "exc_1hz.csv", _sim_log(900.0, sample_s=1.0, excitation=True, seed=5))
    refuse("pi_controller_1hz", str(slow), group="message", args=("--method", "zcu"))
    return cases


# --- running the corpus through the CLI -------------------------------------------------------------


@dataclass(frozen=True)
class Outcome:
    case: Case
    rc: int | None
    """None: killed after the time limit (a hang)."""
    stderr: str
    stdout: str

    @property
    def verdict(self) -> str:
        if self.rc is None:
            return "HANG"
        if "Traceback" in self.stderr:
            return "TRACEBACK"
        if self.case.expect == "ok":
            return "ok" if self.rc == 0 else "REFUSED-VALID"
        if self.rc == 0:
            return "ACCEPTED-BROKEN"
        lines = self.stderr.strip().splitlines()
        if self.rc != 2 or len(lines) != 1:
            return f"BAD-EXIT({self.rc}, {len(lines)} lines)"
        if self.case.names not in lines[0]:
            return "NO-NAME"
        if self.case.hint and self.case.hint.lower() not in lines[0].lower():
            return "NO-HINT"
        return "ok"


def run_case(case: Case, timeout: float = 120.0) -> Outcome:
    cmd = [sys.executable, "-m", "fcrlive.cli", "identify", *case.args]
    env = {**os.environ, "MPLBACKEND": "Agg"}
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env,
                           stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired as exc:
        return Outcome(case, None, str(exc.stderr or ""), str(exc.stdout or ""))
    return Outcome(case, p.returncode, p.stderr, p.stdout)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(argv[0]) if argv else Path(tmp)
        cases = make_corpus(folder)
        counts: dict[str, int] = {}
        for case in cases:
            o = run_case(case, timeout=60.0)
            counts[o.verdict.split("(")[0]] = counts.get(o.verdict.split("(")[0], 0) + 1
            last = (o.stderr.strip().splitlines() or [""])[-1][:150]
            print(f"{case.name:<22} {o.verdict:<16} rc={o.rc}  {last}", flush=True)
        print("counts:", ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
