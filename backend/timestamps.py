"""One rule set for every timestamp the service and the command line accept.

- An **instant** is ISO 8601 with a UTC offset (``2024-03-15T12:00:00-06:00``,
  ``…Z``); the standard library's ``datetime.fromisoformat`` parses it. A naive
  time (no offset) is refused: its meaning would depend on the reader.
- A **day or instant** (query ranges, ``simulate --start``) may also be a bare
  date ``YYYY-MM-DD``: midnight in the site's zone (where midnight falls in a DST
  gap, the first valid instant after it — pandas' ``shift_forward``).
- Years :data:`FIRST_YEAR`–:data:`LAST_YEAR` are accepted anywhere (inside
  pandas' nanosecond range, wide enough for any history and any forecast).
  Readings from loggers must also be from :data:`READINGS_FROM_S` on.
- Ranges are ``[start, end)``: ``end`` exclusive and after ``start``.

Ingestion parses thousands of stamps a request; :func:`parse_instants` has a
vectorised fast path for the one form loggers send (``YYYY-MM-DDTHH:MM:SS±HH:MM``
or ``Z``) — it triples CSV ingest throughput (``benchmarks/bench_service.py``) —
and falls back to :func:`parse_instant` row by row for every other form.
"""

from __future__ import annotations

import datetime as dt
import math
import re
from collections.abc import Sequence
from typing import Any
from zoneinfo import ZoneInfo

import numpy as np
import pandas as pd

FIRST_YEAR, LAST_YEAR = 1900, 2199
#: Readings stamped before 1990-01-01T00:00:00Z are refused (no logger of ours is older).
READINGS_FROM_S = 631_152_000
_BARE_DATE = re.compile(r"^\d{4}-\d{2}-\d{2}$")


class TimestampError(ValueError):
    """A timestamp that breaks the rules; the message names the field and the problem."""


def parse_instant(text: str, field: str) -> dt.datetime:
    """An ISO 8601 instant with offset → aware ``datetime`` in UTC."""
    text = text.strip()
    try:
        value = dt.datetime.fromisoformat(text)
    except ValueError:
        raise TimestampError(f"{field}: {text[:40]!r} is not an ISO 8601 date-time") from None
    if value.tzinfo is None or value.utcoffset() is None:
        raise TimestampError(f"{field}: {text[:40]!r} has no UTC offset; add one "
                             "(e.g. Z, +00:00 or -06:00)")
    return _in_years(value.astimezone(dt.UTC) if _year_ok(value) else value, text, field)


def parse_day_or_instant(text: str, zone: ZoneInfo | str, field: str) -> dt.datetime:
    """A bare date (midnight in ``zone``) or an instant with offset → aware ``datetime``."""
    text = text.strip()
    if _BARE_DATE.match(text):
        try:
            day = pd.Timestamp(dt.date.fromisoformat(text))
        except ValueError:
            raise TimestampError(f"{field}: {text!r} is not a valid date") from None
        value = day.tz_localize(str(zone), ambiguous=True, nonexistent="shift_forward")
        return _in_years(value.to_pydatetime(), text, field)
    try:
        return parse_instant(text, field)
    except TimestampError as exc:
        if "no UTC offset" in str(exc):
            raise TimestampError(f"{field}: {text!r} has no UTC offset; add one or give a "
                                 "bare date (YYYY-MM-DD)") from None
        raise TimestampError(f"{field}: {text[:40]!r} is not a date (YYYY-MM-DD) or an ISO "
                             "8601 date-time with offset") from None


def parse_range(start: str, end: str, zone: ZoneInfo | str,
                names: tuple[str, str] = ("start", "end")) -> tuple[dt.datetime, dt.datetime]:
    """``[start, end)`` (see :func:`parse_day_or_instant`); ``end`` must be after ``start``."""
    t0 = parse_day_or_instant(start, zone, names[0])
    t1 = parse_day_or_instant(end, zone, names[1])
    if not t1 > t0:
        raise TimestampError(f"{names[1]} ({end}) must be after {names[0]} ({start}); "
                             f"{names[1]} is exclusive")
    return t0, t1


def _year_ok(value: dt.datetime) -> bool:
    return FIRST_YEAR <= value.year <= LAST_YEAR


def _in_years(value: dt.datetime, text: str, field: str) -> dt.datetime:
    if not _year_ok(value):
        raise TimestampError(f"{field}: {text[:40]!r} is outside the years "
                             f"{FIRST_YEAR}–{LAST_YEAR}")
    return value


# ------------------------------------------------------------------ ingestion, vectorised


def parse_instants(values: Sequence[Any]) -> tuple[np.ndarray, list[tuple[int, str, str]]]:
    """Many instants → (UTC Unix seconds int64, errors ``[(row, message, code)]``).

    Fractions of a second are dropped (readings are stored in whole seconds). A
    rejected row's seconds are :data:`READINGS_FROM_S`, so it draws no second
    error from later range checks.
    """
    n = len(values)
    ts = np.zeros(n, np.int64)
    ok = np.zeros(n, bool)
    if n >= 32:  # numpy pays off past a few rows
        try:
            arr = np.asarray(values)
        except ValueError:  # ragged input (a list as one value): per row below
            arr = np.zeros(0, "U25")
        if arr.dtype.kind == "U" and arr.ndim == 1:
            ts, ok = _fast_instants(arr)
    errors: list[tuple[int, str, str]] = []
    for r in np.flatnonzero(~ok).tolist():
        value = values[r]
        ts[r] = READINGS_FROM_S
        if not isinstance(value, str):
            what = "missing" if value is None else f"a {type(value).__name__}"
            errors.append((r, f"timestamp is {what}; send ISO 8601 with an offset",
                           "missing" if value is None else "type_error"))
            continue
        try:
            parsed = parse_instant(value, "ts")
        except TimestampError as exc:
            code = "timezone_naive" if "no UTC offset" in str(exc) else "value_error"
            errors.append((r, str(exc).removeprefix("ts: "), code))
            continue
        ts[r] = math.floor(parsed.timestamp())
    return ts, errors


def _days_from_civil(y: np.ndarray, m: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's algorithm)."""
    y = y - (m <= 2)
    era = y // 400
    yoe = y - era * 400
    doy = (153 * (m + np.where(m > 2, -3, 9)) + 2) // 5 + d - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146097 + doe - 719468


_DIGITS = np.array([0, 1, 2, 3, 5, 6, 8, 9, 11, 12, 14, 15, 17, 18])
_MONTH_DAYS = np.array([0, 31, 29, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31])


def _fast_instants(strings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised ``YYYY-MM-DDTHH:MM:SS±HH:MM`` / ``…Z`` → (ts_s, ok); the rest is not ok."""
    n = strings.shape[0]
    width = strings.dtype.itemsize // 4
    if width < 20:
        return np.zeros(n, np.int64), np.zeros(n, bool)
    raw = strings.view(np.uint32).reshape(n, width)
    c = raw[:, :25].astype(np.int32)
    if c.shape[1] < 25:
        c = np.pad(c, ((0, 0), (0, 25 - c.shape[1])))
    length = np.count_nonzero(raw, axis=1)
    dig = c - 48
    ok = np.all((dig[:, _DIGITS] >= 0) & (dig[:, _DIGITS] <= 9), axis=1)
    ok &= (c[:, 4] == 45) & (c[:, 7] == 45) & (c[:, 13] == 58) & (c[:, 16] == 58)
    ok &= (c[:, 10] == 84) | (c[:, 10] == 32) | (c[:, 10] == 116)
    zulu = (length == 20) & ((c[:, 19] == 90) | (c[:, 19] == 122))
    odig = dig[:, [20, 21, 23, 24]]
    offset = (
        (length == 25)
        & ((c[:, 19] == 43) | (c[:, 19] == 45))
        & (c[:, 22] == 58)
        & np.all((odig >= 0) & (odig <= 9), axis=1)
    )
    ok &= zulu | offset
    year = dig[:, 0] * 1000 + dig[:, 1] * 100 + dig[:, 2] * 10 + dig[:, 3]
    month = dig[:, 5] * 10 + dig[:, 6]
    day = dig[:, 8] * 10 + dig[:, 9]
    hour = dig[:, 11] * 10 + dig[:, 12]
    minute = dig[:, 14] * 10 + dig[:, 15]
    second = dig[:, 17] * 10 + dig[:, 18]
    leap = (year % 4 == 0) & ((year % 100 != 0) | (year % 400 == 0))
    mdays = _MONTH_DAYS[np.clip(month, 0, 12)] - ((month == 2) & ~leap)
    ok &= (month >= 1) & (month <= 12) & (day >= 1) & (day <= mdays)
    ok &= (hour <= 23) & (minute <= 59) & (second <= 59)
    ok &= (year >= FIRST_YEAR) & (year <= LAST_YEAR)
    off_h = odig[:, 0] * 10 + odig[:, 1]
    off_m = odig[:, 2] * 10 + odig[:, 3]
    ok &= ~offset | ((off_h <= 23) & (off_m <= 59))
    sign = np.where(c[:, 19] == 45, -1, 1)
    off_s = np.where(offset, sign * (off_h * 3600 + off_m * 60), 0)
    days = _days_from_civil(year.astype(np.int64), month, day)
    ts = days * 86400 + hour * 3600 + minute * 60 + second - off_s
    return ts.astype(np.int64), ok
