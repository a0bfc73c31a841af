"""TSO data file names (Nordic FCR Test Program §11.1).

``[Resource]_[Service]_[TestType]_[Area]_[Timezone]_[Interval]_[SamplingRate].csv``, e.g.
``FCPG1_Fcrn_Operation_NO5_UTC_20261101T0000-20261101T0100_100ms.csv``. Service is one of Fcrn, FcrdUp,
FcrdDo; TestType ``Operation`` for normal operation, and for a sine test the period is written with the
test type (``Sine40``). Interval is ``YYYYMMDDThhmm-YYYYMMDDThhmm``; SamplingRate is the nominal time
between samples in s, or in ms below 1 s (``50ms``, ``1s``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from fcrlive.errors import DataError

SERVICES: tuple[str, ...] = ("Fcrn", "FcrdUp", "FcrdDo")
"""The services a TSO file name may carry."""

_SAFE = re.compile(r"^[A-Za-z0-9.\-]+$")
_SAFE_UNDERSCORE = re.compile(r"^[A-Za-z0-9.\-_]+$")
_INTERVAL = re.compile(r"^(\d{8}T\d{4})-(\d{8}T\d{4})$")
_RATE = re.compile(r"^(\d+(?:\.\d+)?)(ms|s)$", re.IGNORECASE)
_SINE = re.compile(r"^sine_?(\d+(?:\.\d+)?)$", re.IGNORECASE)


@dataclass(frozen=True)
class TsoFileName:
    """The fields of a TSO data file name."""

    resource: str
    service: str
    test_type: str
    area: str
    timezone: str
    start: datetime
    """Start of the interval (minute resolution), wall-clock time in ``timezone``."""
    end: datetime
    sample_s: float
    """Nominal time between samples [s]."""

    @property
    def period_s(self) -> float | None:
        """Sine-test period [s] when the test type is ``Sine<period>``, else None."""
        m = _SINE.match(self.test_type)
        return float(m.group(1)) if m else None

    @property
    def name(self) -> str:
        return tso_filename(
            self.resource,
            self.service,
            self.test_type,
            self.area,
            self.timezone,
            self.start,
            self.end,
            self.sample_s,
        )


def format_sampling_rate(sample_s: float) -> str:
    """``0.1`` -> ``100ms``, ``1.0`` -> ``1s``, ``2.5`` -> ``2.5s`` (TSO SamplingRate field)."""
    if not sample_s > 0:
        raise ValueError(f"sample interval must be positive, got {sample_s!r}")
    if sample_s < 1.0:
        ms = sample_s * 1000.0
        if abs(ms - round(ms)) > 1e-6:
            raise ValueError(f"sample interval {sample_s} s is not a whole number of milliseconds")
        return f"{round(ms)}ms"
    return f"{sample_s:g}s"


def _fmt_period(period_s: float) -> str:
    return f"{period_s:g}"


def sine_test_type(period_s: float) -> str:
    """TestType of a sine-test file: ``Sine40`` for a 40 s period (the period goes with the test type)."""
    return f"Sine{_fmt_period(period_s)}"


def tso_filename(
    resource: str,
    service: str,
    test_type: str,
    area: str,
    tz: str,
    start: datetime,
    end: datetime,
    sample_s: float,
) -> str:
    """Build a TSO file name; strict: raises ValueError on fields that would make it unparsable.

    ``start``/``end`` are wall-clock times in ``tz``, written to the minute (seconds are dropped).
    Underscores are allowed in ``resource`` and ``test_type`` only (the parser finds the service).
    """
    if service not in SERVICES:
        raise ValueError(f"service must be one of {', '.join(SERVICES)}, got {service!r}")
    for label, value in (("resource", resource), ("test type", test_type)):
        if not _SAFE_UNDERSCORE.match(value) or value.startswith("_") or value.endswith("_"):
            raise ValueError(f"{label} {value!r} must be letters, digits, '.', '-', '_'")
    if any(s in resource.split("_") for s in SERVICES):
        raise ValueError(f"resource {resource!r} must not contain a service name as a '_' field")
    for label, value in (("area", area), ("time zone", tz)):
        if not _SAFE.match(value):
            raise ValueError(f"{label} {value!r} must be letters, digits, '.', '-' (no '_')")
    if end < start:
        raise ValueError(f"interval end {end} is before its start {start}")
    interval = f"{start:%Y%m%dT%H%M}-{end:%Y%m%dT%H%M}"
    return f"{resource}_{service}_{test_type}_{area}_{tz}_{interval}_{format_sampling_rate(sample_s)}.csv"


def parse_tso_filename(name: str | Path) -> TsoFileName:
    """Parse a TSO file name (a path is fine: only its last part is used).

    Lenient on case of the service and the ``.csv`` suffix; raises DataError(where=name) naming the
    field that does not fit.
    """
    base = Path(name).name
    stem = base[:-4] if base.lower().endswith(".csv") else base
    parts = stem.split("_")
    if len(parts) < 7:
        raise DataError(
            "not a TSO file name: expected Resource_Service_TestType_Area_Timezone_Interval_SamplingRate.csv",
            where=base,
        )
    services = {s.lower(): s for s in SERVICES}
    idx = next((i for i, p in enumerate(parts[:-5]) if p.lower() in services and i > 0), None)
    if idx is None:
        raise DataError(f"no service field ({', '.join(SERVICES)}) in the file name", where=base)
    resource = "_".join(parts[:idx])
    test_type = "_".join(parts[idx + 1 : -4])
    if not test_type:
        raise DataError("no test type field in the file name", where=base)
    area, tz, interval, rate = parts[-4:]
    m = _INTERVAL.match(interval)
    if not m:
        raise DataError(f"interval {interval!r} is not YYYYMMDDThhmm-YYYYMMDDThhmm", where=base)
    try:
        start = datetime.strptime(m.group(1), "%Y%m%dT%H%M")
        end = datetime.strptime(m.group(2), "%Y%m%dT%H%M")
    except ValueError:
        raise DataError(f"interval {interval!r} is not a valid date and time", where=base) from None
    r = _RATE.match(rate)
    if not r:
        raise DataError(f"sampling rate {rate!r} is not like '100ms' or '1s'", where=base)
    value = float(r.group(1))
    sample_s = value / 1000.0 if r.group(2).lower() == "ms" else value
    if sample_s <= 0:
        raise DataError(f"sampling rate {rate!r} must be positive", where=base)
    return TsoFileName(
        resource=resource,
        service=services[parts[idx].lower()],
        test_type=test_type,
        area=area,
        timezone=tz,
        start=start,
        end=end,
        sample_s=sample_s,
    )
