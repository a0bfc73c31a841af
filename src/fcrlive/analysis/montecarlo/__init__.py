"""Monte Carlo study of the identification methods: the paper's Section 7 (Figs. 4-11, eqs. 35-36).

Cells: SNR × dataset length × method. Methods:

- ``zcu``, ``zur`` (paper 4.2.2, 4.2.1) on the SAME closed-loop datasets WITH the excitation r[n]
  (white, std 0.1/(50·3) pu, generated once from ``excitation_seed``);
- ``zu`` (4.2.1 eq. 16) on closed-loop datasets WITHOUT excitation (same seeds otherwise);
- ``sine``: the industry test (4.1), one open-loop sine test per period of :data:`PAPER_PERIODS_S`, each
  dataset as long as the cell's length (10 min → 110 min of tests, 30 min → 330 min, as in the paper).

Randomness (paper 7.1): r is generated once; the stochastic load and the process noise are regenerated
per run from the run's seed (:func:`run_seed`), the same seeds in every cell (common random numbers:
differences between cells are not blurred by different realisations). Every sine dataset has its own
seed (:func:`sine_seed`).

Process noise: its std is sized ONCE per SNR from the excited closed loop (``fcrlive.sim`` docstring:
SNR = var u from load and r over var u from the process noise) and the same std is used for the
unexcited Z_u datasets and for the sine tests (there added to the applied frequency the governor sees):
the noise is a property of the plant, not of the experiment.

Sine test datasets of length L at period T: the test signal starts at t = 0 from steady state; the first
k whole periods settle (k·T covers ``settle_time`` — 5 slowest open-loop time constants — but at most
L/3, at least one period), the remaining whole periods are evaluated (:func:`sine_layout`) by
:func:`fcrlive.analysis.sine_fit.evaluate_sine_test` (least-squares sine + offset + trend).

Figures of merit (per cell, over the successful runs):

- NRMSE (eq. 35) of G_1(1), max|G_1|, max|S|: ``sqrt(mean((a0 − a_i)²))``, absolute and divided by the
  truth a0; the bias ``mean(a_i) − a0``; the coverage of the reported 95 % intervals (fraction of runs
  whose interval contains a0). G_1(1) is the droop seen from the grid (ρ_eff = G_1(1) with K_d = 0), and
  the droop interval is the monotone image of the G_1(1) interval, so its coverage is the same.
- NRMSE(Ω) (eq. 36) of G_p at the Table 1 periods: ``sqrt(mean(|G_p − G_i|²/|G_p|²))`` on the COMPLEX
  responses; for the sine test G_i is the estimate of G_req compared with G_p as the paper does, and
  also with G_req (``nrmse_vs_greq``); the relative bias of |G_i| and the coverage of the 95 % interval
  of |G_i|.

Peaks are taken as :mod:`fcrlive.analysis.assess` does (grid from 1e-3 rad/s to the Nyquist frequency of
the identification rate, refined around the maximum); G_1(1) from the response at ω = 1e-7 rad/s.

Modules: :mod:`.config` (what to run, seeds, truth), :mod:`.metrics` (the estimates of a run, the
figures of merit of a cell), :mod:`.runner` (tasks, workers, resume, :func:`run_study`), :mod:`.tables`
(CSV, Markdown) and :mod:`.figures` (PNG).

Execution: tasks are (SNR, length, data kind, chunk of runs); a worker simulates its chunk in one
:func:`fcrlive.sim.simulate_batch` and identifies each run. Every finished task is written atomically to
``<out>/chunks/`` so an interrupted study resumes where it stopped; a failing identification is recorded
with its reason, never raised. BLAS is pinned to one thread per worker.
"""

from fcrlive.analysis.montecarlo.config import (
    METHODS,
    StudyConfig,
    Truth,
    process_noise_levels,
    run_seed,
    sine_layout,
    sine_seed,
    truth,
)
from fcrlive.analysis.montecarlo.metrics import coverage, nrmse, nrmse_omega, summarise_cell
from fcrlive.analysis.montecarlo.runner import (
    StudyResult,
    _identify_closed_loop,  # noqa: F401 (run_task's default identification; tests wrap it)
    plan,
    run_study,
    run_task,
)
from fcrlive.analysis.montecarlo.tables import markdown_table

__all__ = [
    "METHODS",
    "StudyConfig",
    "StudyResult",
    "Truth",
    "coverage",
    "markdown_table",
    "nrmse",
    "nrmse_omega",
    "plan",
    "process_noise_levels",
    "run_seed",
    "run_study",
    "run_task",
    "sine_layout",
    "sine_seed",
    "summarise_cell",
    "truth",
]
