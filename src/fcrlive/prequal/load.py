"""Reading an application directory (the I/O around the pure :mod:`fcrlive.prequal.evaluate`).

Every ``*.csv`` file of the directory is a TSO log that must carry a TSO file name; other files
(``unit.toml``, a README) are left alone. Errors are :class:`~fcrlive.errors.UserError` naming the file.
"""

from __future__ import annotations

from pathlib import Path

from fcrlive.errors import ConfigError, DataError
from fcrlive.plant.description import load_unit_description
from fcrlive.plant.prequal_unit import UnitDescription
from fcrlive.prequal.evaluate import Identifier, evaluate_logs
from fcrlive.prequal.model import PrequalResult
from fcrlive.tso.csvlog import TsoLog, read_log
from fcrlive.tso.names import parse_tso_filename

UNIT_FILE = "unit.toml"


def csv_files(folder: Path) -> list[Path]:
    """The ``*.csv`` files of ``folder`` (any case), sorted by name."""
    if not folder.is_dir():
        raise DataError("not a directory", where=str(folder))
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() == ".csv")


def read_logs(folder: Path) -> list[TsoLog]:
    """Every TSO log of ``folder``; DataError naming the first bad file."""
    files = csv_files(folder)
    if not files:
        raise DataError("no *.csv test files", where=str(folder))
    logs = []
    for p in files:
        parse_tso_filename(p)  # a name that is not a TSO name is refused before reading
        logs.append(read_log(p, required=("InsAcPow",)))
    return logs


def read_unit(folder: Path, unit: Path | None) -> UnitDescription | None:
    """The unit description: ``unit`` if given, else ``folder/unit.toml`` if present, else None."""
    path = unit if unit is not None else folder / UNIT_FILE
    if unit is None and not path.exists():
        return None
    desc = load_unit_description(path)
    if desc.prequal is None:
        raise ConfigError("no [unit.prequal] section (docs/plant-toml.md)", where=str(path))
    return desc


def evaluate_dir(
    folder: str | Path,
    unit: str | Path | None = None,
    document: str = "nordic-2025",
    *,
    identifier: Identifier | None = None,
    progress=None,
) -> PrequalResult:
    """Evaluate every test file of ``folder`` (see :func:`fcrlive.prequal.evaluate.evaluate_logs`);
    ``progress`` wraps the iteration over the logs."""
    folder = Path(folder)
    desc = read_unit(folder, Path(unit) if unit is not None else None)
    logs = read_logs(folder)
    return evaluate_logs(
        logs,
        desc.prequal if desc is not None else None,
        document,
        unit_name=desc.plant.unit.name if desc is not None else "",
        identifier=identifier,
        progress=progress,
    )
