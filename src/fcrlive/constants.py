"""Constants shared across fcrlive: the TSO sine-test periods, the paper's Table 1, the 95 % quantile."""

from __future__ import annotations

F0_HZ = 50.0
"""Nominal frequency of the Nordic synchronous area [Hz]."""

TSO_PERIODS_S: tuple[float, ...] = (10.0, 15.0, 25.0, 40.0, 50.0, 60.0, 70.0, 90.0, 150.0, 300.0)
"""Sine-test periods of the Nordic TR v1.1 Table 6 [s]."""

TSO_STATIONARY_PERIODS: dict[float, int] = {
    p: (5 if p <= 90 else 3 if p <= 150 else 2) for p in TSO_PERIODS_S
}
"""Stationary periods used per sine test (TR Table 6): 5 up to 90 s, 3 at 150 s, 2 at 300 s."""

PAPER_PERIODS_S: tuple[float, ...] = (300.0, 150.0, 100.0, 80.0, 70.0, 60.0, 50.0, 40.0, 25.0, 15.0, 10.0)
"""Sine periods of the paper's Table 1 (an older TSO draft) [s]: the 11 datasets of Section 7.5."""

PAPER_EXCITATION_STD_PU = 0.1 / (50.0 * 3.0)
"""The paper's white-noise excitation r[n]: standard deviation 0.1/(50·3) pu (Section 7.1)."""

Z95 = 1.959963984540054
"""Two-sided 95 % quantile of the standard normal distribution: every 95 % interval is value ± Z95·sd."""
