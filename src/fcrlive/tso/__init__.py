"""TSO data files: the Nordic FCR CSV log format, file names, and the mapping between a log and the
paper's signals.

See docs/tso-csv.md. Reading/writing: :mod:`fcrlive.tso.csvlog`; names: :mod:`fcrlive.tso.names`;
log -> :class:`fcrlive.signals.PlantSignals` and simulation -> log: :mod:`fcrlive.tso.signals`.
"""

from fcrlive.tso.csvlog import Gap, TsoLog, read_log, write_log
from fcrlive.tso.names import TsoFileName, parse_tso_filename, sine_test_type, tso_filename
from fcrlive.tso.signals import log_from_sim, log_from_sine, plant_signals

__all__ = [
    "Gap",
    "TsoFileName",
    "TsoLog",
    "log_from_sim",
    "log_from_sine",
    "parse_tso_filename",
    "plant_signals",
    "read_log",
    "sine_test_type",
    "tso_filename",
    "write_log",
]
