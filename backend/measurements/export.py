"""Measurements as InfluxDB line protocol (``GET …/measurements?format=influx``).

One line per reading (or per bucket, when the answer is downsampled)::

    heliotwin,array=tracker,site=tehuantepec,source=measured voltage_v=26.1,current_a=27.3,\
    power_w=712.53 1710525600000000000

(one line, broken here to fit)

- measurement ``heliotwin``; tags ``array``, ``site``, ``source`` (sorted by key,
  as InfluxDB prefers);
- fields with their unit in the name: ``voltage_v``, ``current_a``, ``power_w``
  (floats), and for buckets also ``…_min``, ``…_max`` and ``n`` (an integer,
  ``60i``: readings in the bucket);
- the timestamp in nanoseconds since the Unix epoch (UTC), the protocol's default
  precision, so no ``precision`` parameter is needed when writing it to InfluxDB.

Escaping follows the line-protocol reference ("Special characters"): in the
measurement a comma or a space is backslash-escaped; in tag keys, tag values
and field keys a comma, an equals sign or a space, and a backslash itself.
A newline cannot be escaped in any of them and is refused. A value that is not
finite (InfluxDB has no NaN) is left out of its line; a line without fields is
left out.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

MEASUREMENT = "heliotwin"
#: fields written as integers (``…i``); all others are floats
INTEGER_FIELDS = frozenset({"n"})
_MEASUREMENT_SPECIAL = re.compile(r"([, \\])")
_KEY_SPECIAL = re.compile(r"([,= \\])")


def _checked(text: str) -> str:
    if "\n" in text or "\r" in text or not text:
        raise ValueError(f"{text!r} cannot be written as line protocol (empty or a newline)")
    return text


def escape_measurement(text: str) -> str:
    """A measurement name, escaped (commas, spaces, backslashes)."""
    return _MEASUREMENT_SPECIAL.sub(r"\\\1", _checked(text))


def escape_key(text: str) -> str:
    """A tag key, tag value or field key, escaped (commas, equals signs, spaces, backslashes)."""
    return _KEY_SPECIAL.sub(r"\\\1", _checked(text))


def _ts_ns(ts: Sequence[str]) -> list[int]:
    """ISO 8601 UTC stamps (``…Z``, as the measurement queries give them) → ns since epoch."""
    seconds = np.array([t.removesuffix("Z") for t in ts], "datetime64[s]").astype(np.int64)
    return (seconds * 1_000_000_000).tolist()


def _field(key: str, value: Any, integer: bool) -> str | None:
    if value is None:
        return None
    if integer:
        return f"{key}={int(value)}i"
    x = float(value)
    return f"{key}={x!r}" if math.isfinite(x) else None


def influx_lines(site_id: str, array: str, source: str, cols: dict[str, list[Any]],
                 chunk_rows: int = 20_000) -> Iterator[str]:
    """The line-protocol text of a measurements answer's columns, in pieces of
    ``chunk_rows`` lines; ``cols`` has ``ts`` (ISO UTC) and one list per field."""
    prefix = (f"{escape_measurement(MEASUREMENT)},array={escape_key(array)},"
              f"site={escape_key(site_id)},source={escape_key(source)} ")
    ts_ns = _ts_ns(cols["ts"])
    fields = [(escape_key(k), v, k in INTEGER_FIELDS) for k, v in cols.items() if k != "ts"]
    for start in range(0, len(ts_ns), chunk_rows):
        out = []
        for i in range(start, min(len(ts_ns), start + chunk_rows)):
            parts = [p for key, col, integer in fields
                     if (p := _field(key, col[i], integer)) is not None]
            if parts:
                out.append(f"{prefix}{','.join(parts)} {ts_ns[i]}\n")
        yield "".join(out)
