"""Which test a TSO file holds, from its name (TR v1.1 Appendix 2 Table 21 test IDs, ``Operation``,
sine files with the period in the name or the headers). Pure: a parsed name in, a :class:`TestFile` out.

The test type field carries the test ID (Test Program §11.1): ``1.1`` … ``1.4`` FCR-N steps, ``2.x`` /
``3.x`` FCR-D up / down ramps (fast or static: told apart later from the applied frequency), ``4.x``
sines (``4.1-40``, ``4.1_40``, ``4.1Sine40``, or ``Sine40`` as fcrlive's simulator writes it, the period
also from the headers), ``5.x``/``6.x``/``7.x`` linearity steps, ``Operation`` normal operation.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from fcrlive.errors import DataError
from fcrlive.tso.names import TsoFileName

GROUP_KIND = {
    "1": "fcrn-steps",
    "2": "fcrd-ramps",
    "3": "fcrd-ramps",
    "4": "sine",
    "5": "linearity",
    "6": "linearity",
    "7": "linearity",
}
GROUP_SERVICE = {"1": "Fcrn", "2": "FcrdUp", "3": "FcrdDo", "5": "Fcrn", "6": "FcrdUp", "7": "FcrdDo"}
SINE_ID = {"Fcrn": "4.1", "FcrdUp": "4.2", "FcrdDo": "4.3"}

_ID = re.compile(r"^(?P<group>[1-7])\.(?P<n>\d+)(?:[-_.]?(?:sine)?_?(?P<period>\d+(?:\.\d+)?))?$", re.I)
_SINE = re.compile(r"^sine_?(?P<period>\d+(?:\.\d+)?)$", re.I)


@dataclass(frozen=True)
class TestFile:
    """What a file name says about the test in it."""

    __test__ = False

    service: str
    test_id: str
    """``1.1`` …, ``4.1`` for sines, ``Operation``."""
    kind: str
    """fcrn-steps, fcrd-ramps (fast or static: decided from the data), sine, linearity, operation."""
    period_s: float | None = None
    """Sine period [s] from the name (the headers may give it too)."""


def classify(name: TsoFileName, header_period_s: float | None = None, where: str | None = None) -> TestFile:
    """The test of a parsed TSO file name; DataError naming the file when the test type is not one of
    the TR's or disagrees with the service or the headers."""
    tt = name.test_type
    where = where or name.name
    if tt.lower() == "operation":
        return TestFile(name.service, "Operation", "operation")
    m = _SINE.match(tt)
    if m:
        period = _period(float(m.group("period")), header_period_s, where)
        return TestFile(name.service, SINE_ID[name.service], "sine", period)
    m = _ID.match(tt)
    if not m:
        raise DataError(
            f"test type {tt!r} is not a test ID of TR Appendix 2 Table 21 (1.1, 2.3, 4.1-40 ...), "
            "'Operation' or 'Sine<period>'",
            where=where,
        )
    group, test_id = m.group("group"), f"{m.group('group')}.{m.group('n')}"
    kind = GROUP_KIND[group]
    if group == "4":
        expected = {v: k for k, v in SINE_ID.items()}.get(test_id)
        if expected is not None and expected != name.service:
            raise DataError(
                f"test {test_id} is a sine test of {expected}, the name says {name.service}", where
            )
        p = m.group("period")
        period = _period(float(p) if p else None, header_period_s, where)
        if period is None:
            raise DataError(f"sine test {test_id}: no period in the test type or the headers", where=where)
        return TestFile(name.service, test_id, "sine", period)
    if m.group("period"):
        raise DataError(f"test type {tt!r}: only sine tests (4.x) carry a period", where=where)
    if GROUP_SERVICE[group] != name.service:
        raise DataError(
            f"test {test_id} is a {GROUP_SERVICE[group]} test (TR App. 2 Table 21), "
            f"the name says {name.service}",
            where=where,
        )
    return TestFile(name.service, test_id, kind)


def _period(from_name: float | None, from_headers: float | None, where: str) -> float | None:
    if from_name is not None and from_headers is not None and abs(from_name - from_headers) > 1e-9:
        raise DataError(f"sine period {from_name:g} s in the name, {from_headers:g} s in the headers", where)
    return from_name if from_name is not None else from_headers
