"""TSO log reader: rows per second and peak memory of ``read_log`` (issue 14 targets: 24 h at 10 Hz within
15 s and 300 MiB; a 30-minute 50 Hz log in under 0.1 s).

The logs are written to a temporary directory by ``write_log`` (the columns ``fcrlive simulate`` writes
with an excitation: InsAcPow, GridFreq, ApplFreqSig, ContOutSig, GuideVane, 6 decimals). Time is the
median of ``--repeat`` reads (wall clock, and CPU time, which a shared machine disturbs less); peak
memory is measured twice: tracemalloc's peak of the Python and numpy allocations during one read, and
the peak resident set (ru_maxrss) of a fresh process that only imports
fcrlive and reads the log, next to that of one that only imports.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from datetime import datetime
from pathlib import Path

import numpy as np

LOGS = {"30min-50Hz": (1800.0, 0.02), "2h-10Hz": (7200.0, 0.1), "24h-10Hz": (86400.0, 0.1)}


def make_log(path: Path, seconds: float, sample_s: float, seed: int = 0) -> Path:
    from fcrlive.tso.csvlog import TsoLog, write_log

    rng = np.random.default_rng(seed)
    n = round(seconds / sample_s)
    t = np.arange(n) * sample_s
    f = 50.0 + 0.02 * np.cumsum(rng.normal(scale=0.01, size=n)) / np.sqrt(n)
    cols = {
        "InsAcPow": 225.0 + rng.normal(scale=2.0, size=n),
        "GridFreq": f,
        "ApplFreqSig": f + 0.01 * rng.normal(size=n),
        "ContOutSig": 75.0 + rng.normal(size=n),
        "GuideVane": 70.0 + rng.normal(size=n),
    }
    return write_log(path, TsoLog.from_arrays(t, cols, datetime(2026, 11, 1)))


_CHILD = """
import resource, sys, time
from fcrlive.tso.csvlog import read_log
t0 = time.perf_counter()
if sys.argv[1] != "-":
    read_log(sys.argv[1])
print(time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def _child(path: str) -> tuple[float, float]:
    """(seconds, peak RSS [MiB]) of a fresh process reading ``path`` ("-": import only)."""
    out = subprocess.run([sys.executable, "-c", _CHILD, path], capture_output=True, text=True, check=True)
    secs, kib = out.stdout.split()
    return float(secs), int(kib) / 1024.0


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="bench reader", description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--repeat", type=int, default=3, help="reads per log for the median time (default 3)")
    ap.add_argument("--logs", nargs="+", choices=list(LOGS), default=list(LOGS), help="which logs")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    from fcrlive.tso.csvlog import read_log

    _, base_rss = _child("-")
    print(f"fresh process importing fcrlive.tso.csvlog: peak RSS {base_rss:.0f} MiB")
    print(f"{'log':<12}{'rows':>10}{'MiB':>8}{'read [s]':>10}{'CPU [s]':>9}{'rows/s':>12}{'tracemalloc':>13}"
          f"{'RSS child':>11}{'child [s]':>11}")
    with tempfile.TemporaryDirectory() as d:
        for name in args.logs:
            seconds, ts = LOGS[name]
            path = make_log(Path(d) / f"{name}.csv", seconds, ts)
            size = path.stat().st_size / 1024**2
            times, cpu = [], []
            for _ in range(args.repeat):
                t0, c0 = time.perf_counter(), time.process_time()
                log = read_log(path)
                times.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
            rows = len(log)
            del log
            tracemalloc.start()
            read_log(path)
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
            child_s, rss = _child(str(path))
            med = statistics.median(times)
            print(f"{name:<12}{rows:>10}{size:>8.1f}{med:>10.3f}{statistics.median(cpu):>9.3f}"
                  f"{rows / med:>12.3g}{peak / 1024**2:>10.0f} MiB"
                  f"{rss:>7.0f} MiB{child_s:>11.2f}", flush=True)
            path.unlink()
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"this process (writing the logs too): peak RSS {own:.0f} MiB")


if __name__ == "__main__":
    main()
