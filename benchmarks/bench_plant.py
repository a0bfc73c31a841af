"""Analytic plant model: cost of analytic(), freqresp on a 1000-point grid, peak(); accuracy of G_1(z)."""

from __future__ import annotations

import argparse
import time

import numpy as np


def _best(fn, repeat: int = 20) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="bench_plant", description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=20, help="best of this many calls per figure (20)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    import control  # noqa: F401

    print(f"import control: {time.perf_counter() - t0:.2f} s")
    from fcrlive.plant.params import preset
    from fcrlive.plant.transfer import analytic, freqresp, peak

    plant = preset("paper-plant1")
    tfs = analytic(plant)
    w = np.geomspace(1e-4, 100, 1000)
    n = args.repeat
    print(f"analytic(): {1e3 * _best(lambda: analytic(plant), n):.1f} ms")
    print(f"freqresp G_1(s), 1000 points: {1e3 * _best(lambda: freqresp(tfs.G_1, w), n):.2f} ms")
    t_z = _best(lambda: freqresp(tfs.discrete.G_1, w), n)
    print(f"freqresp G_1(z) (state space), 1000 points: {1e3 * t_z:.2f} ms")
    print(
        f"peak(G_1): {1e3 * _best(lambda: peak(tfs.G_1), max(1, n // 4)):.1f} ms; peak(G_1(z)): "
        f"{1e3 * _best(lambda: peak(tfs.discrete.G_1), max(1, n // 4)):.1f} ms"
    )
    for hold in ("zoh", "foh"):
        t = analytic(plant, u_hold=hold)
        wl = np.geomspace(1e-4, 0.5, 200)
        err = np.max(np.abs(freqresp(t.discrete.G_1, wl) / freqresp(t.G_1, wl) - 1))
        print(f"u_hold={hold}: max |G_1(z)/G_1(jω) − 1| up to 0.5 rad/s = {100 * err:.2f} %")


if __name__ == "__main__":
    main()
