"""Run benchmarks: ``python -m benchmarks [NAME ...]`` runs benchmarks/bench_NAME.py (all when none given);
``python -m benchmarks NAME [options]`` runs one benchmark with its options (``NAME --help`` lists them).

Each module defines ``main(argv: list[str] | None = None) -> None`` that parses ``argv`` (the process's
arguments when None) and prints its figures.
BLAS is pinned to one thread: multithreaded OpenBLAS on 2 cores is slower and noisier (libraries.md).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import importlib  # noqa: E402
import pkgutil  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import benchmarks  # noqa: E402

USAGE = """usage: python -m benchmarks [NAME ...]        run these benchmarks (all when none given)
       python -m benchmarks NAME [options]    run one benchmark with its options
       python -m benchmarks NAME --help       that benchmark's options

benchmarks: {names}"""


def main(argv: list[str]) -> int:
    names = sorted(i.name[len("bench_"):] for i in pkgutil.iter_modules(benchmarks.__path__)
                   if i.name.startswith("bench_"))
    first_opt = next((i for i, a in enumerate(argv) if a.startswith("-")), len(argv))
    wanted, options = argv[:first_opt] or names, argv[first_opt:]
    if not argv[:first_opt] and options:
        if options in (["-h"], ["--help"]):
            print(USAGE.format(names=", ".join(names)))
            return 0
        print(f"options go after one benchmark name\n{USAGE.format(names=', '.join(names))}", file=sys.stderr)
        return 2
    unknown = [w for w in wanted if w not in names]
    if unknown:
        print(f"unknown benchmark(s) {', '.join(unknown)}; known: {', '.join(names)}", file=sys.stderr)
        return 2
    if options and len(wanted) > 1:
        print(f"options ({' '.join(options)}) go to one benchmark at a time, got {', '.join(wanted)}",
              file=sys.stderr)
        return 2
    for name in wanted:
        module = importlib.import_module(f"benchmarks.bench_{name}")
        if "-h" in options or "--help" in options:
            module.main(options)  # its parser prints the help and exits
            continue
        print(f"=== benchmark {name}" + (f" {' '.join(options)}" if options else ""), flush=True)
        t0 = time.perf_counter()
        module.main(options)
        print(f"=== {name} done in {time.perf_counter() - t0:.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
