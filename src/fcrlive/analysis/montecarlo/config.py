"""Monte Carlo study: what to run (:class:`StudyConfig`), the seeds, the analytic truth, the sine
datasets' layout and the process noise per SNR (package docstring)."""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from fcrlive.constants import PAPER_PERIODS_S
from fcrlive.errors import UserError

METHODS = ("zcu", "zur", "zu", "sine")

METHOD_LABELS = {"zcu": "Z_cu", "zur": "Z_ur", "zu": "Z_u", "sine": "sine test"}

KIND_OF = {"zcu": "excited", "zur": "excited", "zu": "plain", "sine": "sine"}
"""Which simulated datasets a method uses (zcu and zur share theirs)."""

SCALARS = ("g1_static", "max_g1", "max_s")



GRID = np.geomspace(1e-3, 2.0, 80)
"""Frequencies [rad/s] of the stored responses for the mean-response figure (Figs. 4-6)."""



def period_tag(T: float) -> str:
    return f"T{T:g}"



@dataclass(frozen=True)
class StudyConfig:
    """What to run (package docstring)."""

    runs: int = 100
    snr_db: tuple[float, ...] = (12.0, 6.0, 0.0)
    minutes: tuple[float, ...] = (10.0, 30.0)
    methods: tuple[str, ...] = METHODS
    seed: int = 0
    excitation_seed: int = 12345
    model: str = "nonlinear"
    chunk: int = 25
    """Runs per task, simulated in one batch (the batch's cost is nearly independent of its size up to
    about 50 runs); bounds a worker's memory: about 8 B · samples · 5 signals · chunk (25 runs of 30 min:
    90 MB of signals, about 250 MB peak)."""
    sine_amplitude_hz: float = 0.1
    periods_s: tuple[float, ...] = PAPER_PERIODS_S
    ts_id: float = 0.5

    def __post_init__(self):
        bad = [m for m in self.methods if m not in METHODS]
        if bad:
            raise UserError(f"unknown method(s) {', '.join(bad)}; use {', '.join(METHODS)}")
        if self.runs < 1:
            raise UserError(f"--runs must be at least 1, got {self.runs}")
        if self.chunk < 1:
            raise UserError(f"chunk must be at least 1, got {self.chunk}")
        if not self.snr_db or not self.minutes or not self.methods:
            raise UserError("need at least one SNR, one length and one method")
        if any(not m > 0 for m in self.minutes):
            raise UserError("dataset lengths must be positive")
        if self.model not in ("nonlinear", "linear"):
            raise UserError(f"model must be 'nonlinear' or 'linear', got {self.model!r}")

    def key(self, plant) -> str:
        """Identity of the study's tasks (everything but ``runs``, which may grow on resume)."""
        d = asdict(self)
        d.pop("runs")
        d["plant"] = repr(plant)
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]



def run_seed(seed: int, run: int) -> int:
    """Seed of the load and process noise of run ``run`` (the same in every cell)."""
    return int(np.random.SeedSequence([int(seed), int(run)]).generate_state(1, np.uint32)[0])



def sine_seed(seed: int, run: int, period_index: int) -> int:
    """Seed of the sine-test dataset of run ``run`` at the ``period_index``-th period."""
    ss = np.random.SeedSequence([int(seed), int(run), 1 + int(period_index)])
    return int(ss.generate_state(1, np.uint32)[0])



@dataclass(frozen=True, eq=False)
class Truth:
    """The analytic values the estimates are compared with (continuous-time, fcrlive.plant.transfer)."""

    g1_static: float
    max_g1: float
    max_s: float
    periods_s: tuple[float, ...]
    gp: np.ndarray
    """G_p(jΩ) at the periods (complex)."""
    greq: np.ndarray
    """G_req(jΩ) at the periods (what the sine test measures, eq. 13)."""
    grid: np.ndarray
    responses: dict[str, np.ndarray]
    """G_1, S, G_p on ``grid``."""

    def scalar(self, name: str) -> float:
        return float(getattr(self, name))

    def to_json(self) -> dict:
        return {
            "g1_static": self.g1_static,
            "max_g1": self.max_g1,
            "max_s": self.max_s,
            "periods_s": list(self.periods_s),
            "abs_gp": [float(abs(g)) for g in self.gp],
            "abs_greq": [float(abs(g)) for g in self.greq],
        }



def truth(plant, periods_s: Sequence[float] = PAPER_PERIODS_S, grid: np.ndarray = GRID) -> Truth:
    from fcrlive.plant.transfer import analytic, freqresp, peak, static_gain

    tfs = analytic(plant)
    w = 2 * np.pi / np.asarray(periods_s, float)
    return Truth(
        g1_static=float(static_gain(tfs.G_1)),
        max_g1=float(peak(tfs.G_1).value),
        max_s=float(peak(tfs.S).value),
        periods_s=tuple(float(p) for p in periods_s),
        gp=np.asarray(freqresp(tfs.G_p, w), complex),
        greq=np.asarray(freqresp(tfs.G_req, w), complex),
        grid=np.asarray(grid, float),
        responses={k: np.asarray(freqresp(getattr(tfs, k), grid), complex) for k in ("G_1", "S", "G_p")},
    )



def sine_layout(plant, period_s: float, length_s: float) -> tuple[int, int, int]:
    """(samples, settling periods k, evaluated periods n) of a sine dataset (package docstring)."""
    from fcrlive.sim import settle_time

    Tc = plant.unit.governor.Tc
    total = math.floor(length_s / period_s + 1e-9)
    if total < 2:
        raise UserError(f"a {length_s:g} s sine dataset holds fewer than two {period_s:g} s periods")
    need = min(settle_time(plant, period_s), length_s / 3.0)
    k = min(max(1, math.ceil(need / period_s - 1e-9)), total - 1)
    return round(length_s / Tc), k, total - k



def process_noise_levels(plant, cfg: StudyConfig) -> dict[float, float]:
    """Process noise std per SNR, sized from the excited closed loop (package docstring)."""
    from fcrlive.constants import PAPER_EXCITATION_STD_PU
    from fcrlive.sim.linear import load_noise_std, process_noise_std

    sl = load_noise_std(plant)
    r_std = PAPER_EXCITATION_STD_PU
    return {float(s): process_noise_std(plant, float(s), sl, r_std=r_std) for s in cfg.snr_db}
