"""One rule set for every timestamp the service and the command line accept.

- An **instant** is ISO 8601 with a UTC offset (``2024-03-15T12:00:00-06:00``,
  ``…Z``; RFC 3339's lower-case ``t`` and ``z`` too), as the standard library's
  ``datetime.fromisoformat`` or pandas' ISO 8601 parser reads it (pandas also takes
  fields without their leading zero, ``2026-1-5T12:00Z``: ingestion parses big batches
  with pandas, so every path takes what it takes). A naive time (no offset) is refused:
  its meaning would depend on the reader.
- A **day or instant** (query ranges, ``simulate --start``) may also be a bare
  date ``YYYY-MM-DD``: midnight in the site's zone (where midnight falls in a DST
  gap, the first valid instant after it — pandas' ``shift_forward``).
- Years :data:`FIRST_YEAR`–:data:`LAST_YEAR` are accepted anywhere (inside
  pandas' nanosecond range, wide enough for any history and any forecast).
  Readings from loggers must also be from :data:`READINGS_FROM_S` on.
- Ranges are ``[start, end)``: ``end`` exclusive and after ``start``.

Ingestion parses thousands of stamps a request: :func:`parse_instants` lets pandas
parse a batch whose stamps share one offset (what a logger sends) and decides every
other row by :func:`parse_instant`, so both follow the one rule above.
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
#: A date-time of a year of five digits or more (or signed), which Python cannot hold.
_LONG_YEAR = re.compile(r"^(\d{5,}|[+-]\d{4,})-\d{2}-\d{2}([T ]|$)", re.I)


class TimestampError(ValueError):
    """A timestamp that breaks the rules; the message names the field and the problem."""


def parse_instant(text: str, field: str) -> dt.datetime:
    """An ISO 8601 instant with offset → aware ``datetime`` in UTC."""
    text = text.strip()
    try:
        value = _from_iso(text.upper())  # RFC 3339 allows 't' and 'z'
    except ValueError:
        if _LONG_YEAR.match(text):  # 10000-01-01T00:00Z: ISO 8601 (expanded), no datetime's
            raise TimestampError(f"{field}: {text[:40]!r} is outside the years "
                                 f"{FIRST_YEAR}–{LAST_YEAR}") from None
        raise TimestampError(f"{field}: {text[:40]!r} is not an ISO 8601 date-time") from None
    if value.tzinfo is None or value.utcoffset() is None:
        raise TimestampError(f"{field}: {text[:40]!r} has no UTC offset; add one "
                             "(e.g. Z, +00:00 or -06:00)")
    return _in_years(value.astimezone(dt.UTC) if _year_ok(value) else value, text, field)


def _from_iso(text: str) -> dt.datetime:
    """``datetime.fromisoformat``, else pandas' ISO 8601 parser (the bulk path's)."""
    try:
        return dt.datetime.fromisoformat(text)
    except ValueError:
        try:
            stamp = pd.to_datetime(text, format="ISO8601")
        except (ValueError, TypeError, OverflowError):
            raise ValueError(text) from None
        if not isinstance(stamp, pd.Timestamp) or pd.isna(stamp):
            raise ValueError(text) from None
        return stamp.to_pydatetime()


def parse_day_or_instant(text: str, zone: ZoneInfo | str, field: str) -> dt.datetime:
    """A bare date (midnight in ``zone``; a date the zone skipped whole is refused saying so,
    where it had read "end must be after start") or an instant with offset → aware
    ``datetime``."""
    text = text.strip()
    if _BARE_DATE.match(text):
        try:
            day = pd.Timestamp(dt.date.fromisoformat(text))
        except ValueError:
            raise TimestampError(f"{field}: {text!r} is not a valid date") from None
        value = day.tz_localize(str(zone), ambiguous=True, nonexistent="shift_forward")
        if value.date() != day.date():  # a whole day skipped: Samoa's 30 December 2011
            raise TimestampError(
                f"{field}: {text} is no day in {zone}: its clocks skipped it, from "
                f"{(day - pd.Timedelta(days=1)).date()} straight to {value.date()} (a date "
                f"line crossing); give {(day - pd.Timedelta(days=1)).date()} or "
                f"{value.date()}")
        return _in_years(value.to_pydatetime(), text, field)
    try:
        return parse_instant(text, field)
    except TimestampError as exc:
        if "outside the years" in str(exc):  # a date-time, but of a year not accepted
            raise
        if "no UTC offset" in str(exc):
            raise TimestampError(f"{field}: {text!r} has no UTC offset; add one or give a "
                                 "bare date (YYYY-MM-DD)") from None
        # a '+' left unencoded in a query string arrives as a space (a tester's finding)
        hint = "; a '+' in a URL's query reads as a space: send it as %2B" \
            if re.search(r"\d \d{2}(:?\d{2})?$", text) else ""
        raise TimestampError(f"{field}: {text[:40]!r} is not a date (YYYY-MM-DD) or an ISO "
                             f"8601 date-time with offset{hint}") from None


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


# ------------------------------------------------------------------ ingestion, in bulk

#: Below this many stamps the standard library row by row is quicker than pandas.
_PANDAS_FROM_ROWS = 32
_FIRST_S = int(dt.datetime(FIRST_YEAR, 1, 1, tzinfo=dt.UTC).timestamp())
#: The first second after :data:`LAST_YEAR` (no instant the service accepts is from it on).
LAST_S = int(dt.datetime(LAST_YEAR + 1, 1, 1, tzinfo=dt.UTC).timestamp())


def parse_instants(values: Sequence[Any]) -> tuple[np.ndarray, list[tuple[int, str, str]]]:
    """Many instants → (UTC Unix seconds int64, errors ``[(row, message, code)]``).

    pandas parses the column at once (``pd.to_datetime(format="ISO8601", utc=False)``)
    when every stamp carries the same offset — what a logger sends; any other row
    (naive, unparseable, another offset, outside the years) goes through
    :func:`parse_instant` (``datetime.fromisoformat``), which decides and words its
    error. Fractions of a second are dropped (readings are stored in whole seconds). A
    rejected row's seconds are :data:`READINGS_FROM_S`, so it draws no second error
    from later range checks.
    """
    n = len(values)
    ts = np.zeros(n, np.int64)
    ok = np.zeros(n, bool)
    if n >= _PANDAS_FROM_ROWS:
        ts, ok = _same_offset_instants(values)
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


def _same_offset_instants(values: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
    """(UTC seconds, ok) by pandas when the parsed stamps share one offset; nothing is ok
    when pandas meets naive stamps or several offsets (the caller decides row by row)."""
    n = len(values)
    none = np.zeros(n, np.int64), np.zeros(n, bool)
    try:
        parsed = pd.DatetimeIndex(pd.to_datetime(values, format="ISO8601", utc=False,
                                                 errors="coerce", cache=False))
    except (ValueError, TypeError, OverflowError):  # mixed offsets, naive beside aware
        return none
    if parsed.tz is None:  # naive stamps only (or none parsed)
        return none
    ok = ~np.asarray(parsed.isna())
    ts = np.where(ok, parsed.as_unit("us").asi8, 0) // 1_000_000  # floor: fractions dropped
    ok &= (ts >= _FIRST_S) & (ts < LAST_S)
    return ts.astype(np.int64), ok
