"""Bulk validation of field-logger readings, without a Python object per reading.

A batch (JSON ``{"readings": [...]}`` or CSV with a header row) is turned into
columns — ``orjson`` to parse, one list comprehension per field, NumPy to check
every row at once — and either becomes a :class:`Batch` of arrays or fails whole
with :class:`IngestError`, whose entries name the row, the field and what was
wrong. Timestamps follow :mod:`backend.timestamps` (vectorised for the form
loggers send) and are stored as whole UTC seconds (a fractional part is dropped).

Raw logger readings carry ADC counts instead of volts and amperes, as the
Arduino logger of seed 000 produces them; they are converted with the array's
stored calibration (:class:`Calibration`, seed 000 eqs. 16–19). A power-only
reading (``power_w`` alone) keeps NaN voltage and current; the optional sensor
fields are :data:`backend.measurements.fields.SENSOR_FIELDS`.
"""

from __future__ import annotations

import csv
import io
import json
import re
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import orjson

from backend.errors import load_json_pairs, repeated_keys
from backend.measurements.fields import SENSOR_FIELDS, SENSOR_NAMES, normalise_sensors
from backend.settings import Settings
from backend.timestamps import LAST_S, LAST_YEAR, READINGS_FROM_S, parse_instants

#: Problems listed per batch in all, and per field (a bounded answer that still shows
#: every kind of problem at once); the rest are counted in one closing entry.
MAX_ERRORS = 50
MAX_ERRORS_PER_FIELD = 10
#: A CSV header naming more columns than this is refused before anything else is looked at.
MAX_COLUMNS = 64
FIELDS = ("ts", "array", "voltage_v", "current_a", "power_w", "voltage_adc", "current_adc",
          *SENSOR_NAMES)
_FIELD_SET = frozenset(FIELDS)
#: Column order of an emonCMS-style row ``[unix_s, array, voltage_v, current_a, power_w]``.
EMONCMS_ROW = ("unix_s", "array", "voltage_v", "current_a", "power_w")
_READINGS_FROM_YEAR = time.gmtime(READINGS_FROM_S).tm_year
#: Python types a JSON number column may hold (``bool`` is not a number).
_JSON_NUMBERS = frozenset((float, int, type(None)))
_CSV_CELLS = frozenset((str, type(None)))
#: A UTF-8 byte order mark, taken off the front of a body or payload.
BOM = b"\xef\xbb\xbf"
#: A CSV number: plain decimal notation only (Python's float() would also take ``1_0``,
#: ``nan``, ``Infinity`` and non-ASCII digits).
_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_NOT_NUMERIC = re.compile(r"[^0-9eE+\-.\n]")


def _show(value: Any, limit: int = 40) -> str:
    """``repr(value)`` cut to ``limit`` characters: an error message never echoes a whole input."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass(frozen=True)
class Calibration:
    """Logger calibration of one array (seed 000, eqs. 16–19)."""

    adc_bits: int = 10
    adc_vref_v: float = 5.0
    current_zero_v: float = 2.5
    current_sensitivity_mv_per_a: float = 100.0
    divider_ratio: float = 10.0

    @property
    def adc_max_counts(self) -> int:
        """Full-scale count of the ADC (1023 for the Arduino's 10-bit converter)."""
        return (1 << self.adc_bits) - 1


def adc_to_volts_amps(
    voltage_counts: np.ndarray, current_counts: np.ndarray, cal: Calibration
) -> tuple[np.ndarray, np.ndarray]:
    """Convert ADC counts to panel voltage [V] and current [A] (seed 000, eqs. 16–19).

    ``v_pin = counts · adc_vref_v / (2**adc_bits − 1)`` on each analog pin. Current
    from the ACS712 output ``V = m·I + 2.5`` (eq. 16) rearranged as
    ``I = (V − current_zero_v) / m`` (eq. 17), ``m`` in V/A. Panel voltage from the
    divider ``V_out = V_in · R_x / (R1 + R2 + R3)`` (eqs. 18–19) inverted:
    ``V_in = V_out · divider_ratio``.
    """
    scale = cal.adc_vref_v / cal.adc_max_counts
    voltage_v = voltage_counts * scale * cal.divider_ratio
    current_a = (current_counts * scale - cal.current_zero_v) / (
        cal.current_sensitivity_mv_per_a / 1000.0
    )
    return voltage_v, current_a


class IngestArray(NamedTuple):
    """An array as the parser checks its readings against: its id, its ADC calibration and
    its rating (its modules' STC power [W]; None: not known, no bound from it)."""

    array_id: int
    calibration: Calibration
    stc_power_w: float | None = None


#: The most an array's power may be, in multiples of its STC rating: irradiance over a
#: clear sky's (cloud enhancement, up to ~1.5 × 1000 W m⁻² for minutes; Gueymard 2017) on
#: cold cells (+10 % at −10 °C) stays under it; a reading past it is a wrong unit or a
#: config with too few modules (a tester's 50 kW reading on a 820 W array counted +9 % of
#: the day's energy with no finding).
MAX_STC_MULTIPLE = 2.0
#: The most negative a power-only reading may be, as a share of the rating: an inverter's
#: or meter's night draw, not a reversed sensor (a tracker at −P all day read PR −1.006 and
#: "underperformance 200.6 %", while the same reading as voltage and current was refused).
MIN_STC_SHARE = -0.05


@dataclass(frozen=True)
class Limits:
    """Plausibility limits applied to every reading (from ``Settings``)."""

    max_rows: int = 100_000
    future_tolerance_s: int = 900
    max_voltage_v: float = 1500.0
    min_voltage_v: float = -1.0
    max_current_a: float = 100.0
    min_current_a: float = -1.0
    power_tolerance_w: float = 5.0

    @classmethod
    def from_settings(cls, settings: Settings) -> Limits:
        """The limits the service's settings set (HTTP and MQTT ingest alike)."""
        s = settings.ingest
        return cls(s.max_batch_rows, s.future_tolerance_s, s.max_voltage_v, s.min_voltage_v,
                   s.max_current_a, s.min_current_a, s.power_tolerance_w)


@dataclass
class Batch:
    """A validated batch: one entry per reading, arrays of equal length.

    ``voltage_v``/``current_a`` are NaN on power-only readings; ``sensors`` is
    ``(n, len(SENSOR_FIELDS))`` with NaN where a field was not sent, or None when
    no reading of the batch sent any.
    """

    array_ids: np.ndarray  # int64
    ts_s: np.ndarray  # int64, UTC Unix seconds
    voltage_v: np.ndarray
    current_a: np.ndarray
    power_w: np.ndarray
    sensors: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.ts_s.shape[0])

    @property
    def power_only(self) -> int:
        """Readings that carry power_w without voltage and current."""
        return int(np.count_nonzero(np.isnan(self.voltage_v)))


class IngestError(Exception):
    """A rejected batch: HTTP ``status`` and a list of ``{loc, msg, type, row, field}`` entries."""

    def __init__(self, status: int, errors: list[dict[str, Any]]) -> None:
        super().__init__(errors[0]["msg"] if errors else "invalid batch")
        self.status = status
        self.errors = errors



def body_error(status: int, field: str | None, kind: str, msg: str,
               **extra: Any) -> IngestError:
    """A rejection of the body as a whole (no row): its one entry names ``field`` if any."""
    loc = ["body"] if field is None else ["body", field]
    return IngestError(status, [{"loc": loc, "row": None, "field": field, "type": kind,
                                 "msg": msg, **extra}])


class _Errors:
    """Collects row/field problems: at most ``MAX_ERRORS_PER_FIELD`` of a field and
    ``MAX_ERRORS`` in all are listed, the others counted per field."""

    def __init__(self, csv_lines: bool) -> None:
        self.items: list[dict[str, Any]] = []
        self.csv_lines = csv_lines
        self.listed: Counter[str] = Counter()
        self.unlisted: Counter[str] = Counter()
        #: rows refused whole for their shape: what their fields lack is not said again
        self.shapeless: set[int] = set()

    def refuse_row(self, row: int, msg: str) -> None:
        """A row that is not a reading at all (a string where an object is due, an object
        where an emonCMS list is): said once; its fields are not checked."""
        self.add(row, None, msg, "type_error")
        self.shapeless.add(row)

    def _room(self, field: str) -> int:
        return max(0, min(MAX_ERRORS - len(self.items),
                          MAX_ERRORS_PER_FIELD - self.listed[field]))

    def add(self, row: int | None, field: str | None, msg: str, kind: str) -> None:
        if field is not None and row in self.shapeless:
            return
        key = field or "row"
        if self._room(key) == 0:
            self.unlisted[key] += 1
            return
        self.listed[key] += 1
        loc: list[Any] = ["body"] if row is None else ["body", "readings", row]
        if field:
            loc.append(field)
        item: dict[str, Any] = {"loc": loc, "msg": msg, "type": kind, "row": row, "field": field}
        if self.csv_lines and row is not None:
            item["line"] = row + 2  # 1-based, after the header line
        self.items.append(item)

    def add_rows(self, mask: np.ndarray, field: str, msg_of: Any, kind: str) -> None:
        """One problem for every row where ``mask`` is true (listed up to the caps)."""
        if not np.count_nonzero(mask):  # a fifth of mask.any()'s cost on a small batch
            return
        rows = np.flatnonzero(mask)
        if self.shapeless:
            rows = rows[~np.isin(rows, list(self.shapeless))]
        room = self._room(field)
        for r in rows[:room].tolist():
            self.add(int(r), field, msg_of(int(r)), kind)
        if rows.size > room:
            self.unlisted[field] += rows.size - room

    def raise_if_any(self, status: int = 422) -> None:
        if not self.items:
            return
        items = list(self.items)
        if self.unlisted:
            counts = ", ".join(f"{k}: {n}" for k, n in self.unlisted.most_common())
            items.append({"loc": ["body"], "row": None, "field": None, "type": "too_many_errors",
                          "msg": f"{sum(self.unlisted.values())} more problems not listed "
                                 f"({counts})"})
        raise IngestError(status, items)


# ---------------------------------------------------------------- timestamps


def parse_timestamps(values: Sequence[Any], errors: _Errors, field: str = "ts") -> np.ndarray:
    """Timestamps → UTC Unix seconds (int64) by :func:`backend.timestamps.parse_instants`;
    naive, non-string and unparseable stamps are reported per row.

    Anything but strings and ``None`` is reported here and never handed to NumPy (a
    list as one value once made the vectorised path drop the whole column)."""
    wrong: set[int] = set()
    if not _CSV_CELLS.issuperset(map(type, values)):
        wrong = {r for r, v in enumerate(values) if v is not None and type(v) is not str}
        for r in sorted(wrong):
            errors.add(r, field, f"timestamp is a {type(values[r]).__name__}; send ISO 8601 "
                                 "with an offset", "type_error")
        values = [None if r in wrong else v for r, v in enumerate(values)]
    ts, problems = parse_instants(values)
    for row, message, code in problems:
        if row not in wrong:
            errors.add(row, field, message, code)
    return ts


def _unix_seconds(values: list[Any], errors: _Errors) -> np.ndarray:
    """emonCMS timestamps (Unix seconds, JSON numbers) → int64 seconds, fractions dropped."""
    col, present, invalid = _floats(values, "ts", errors, text=False)
    errors.add_rows(~present, "ts", lambda r: "unix_s is missing", "missing")
    ts = np.full(len(values), READINGS_FROM_S, np.int64)
    ok = present & ~invalid & np.isfinite(col)
    # outside the years the service accepts (often milliseconds sent as seconds): one error
    # naming the value as sent, not a clipped echo from the later range checks
    far = ok & ((col < READINGS_FROM_S) | (col >= LAST_S))
    errors.add_rows(far, "ts", lambda r: (
        f"unix_s {_show(values[r])} is not in {_READINGS_FROM_YEAR}–{LAST_YEAR}"
        + (" (milliseconds sent as seconds?)" if col[r] >= LAST_S else "")), "value_error")
    ok &= ~far
    ts[ok] = np.floor(col[ok]).astype(np.int64)
    return ts


# ---------------------------------------------------------------- numbers


def _floats(values: list[Any], field: str, errors: _Errors, text: bool
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A float column, its 'present' mask and its 'already reported' mask.

    JSON columns (``text`` false) take JSON numbers only; CSV cells (``text``) take
    plain decimal notation only (:data:`_NUMBER`). Non-finite values are errors.
    """
    n = len(values)
    missing = values.count(None)
    if missing == n:
        return np.full(n, np.nan), np.zeros(n, bool), np.zeros(n, bool)
    col = None
    invalid = np.zeros(n, bool)
    allowed = _CSV_CELLS if text else _JSON_NUMBERS
    if allowed.issuperset(map(type, values)) and not (
            text and _NOT_NUMERIC.search("\n".join(v for v in values if v is not None))):
        try:
            col = np.array(values, dtype=np.float64)  # None → NaN
        except (ValueError, OverflowError):  # malformed (CSV "1e", "+-"): per value below
            col = None
    col_checked_per_value = col is None
    if col is None:
        col = np.full(n, np.nan)
        for r, x in enumerate(values):
            t = type(x)
            if x is None:
                continue
            if (t is str and text and _NUMBER.fullmatch(x)) or (
                    not text and (t is float or t is int)):
                try:
                    col[r] = float(x)
                except OverflowError:  # a JSON integer of 309+ digits (was a 500)
                    invalid[r] = True
                    errors.add(r, field, f"not a finite number: {_show(x)} is beyond a "
                                         "double's range", "finite_number")
                continue
            invalid[r] = True
            hint = " (send a JSON number)" if t is str and not text else ""
            errors.add(r, field, f"not a number: {_show(x)}{hint}", "type_error")
    if missing == 0:
        present = np.ones(n, bool)
    else:
        present = np.fromiter((x is not None for x in values), bool, n)
    bad = ~np.isfinite(col)  # absent and already reported rows are NaN: not counted again
    if missing or col_checked_per_value:
        bad &= present & ~invalid
    errors.add_rows(bad, field, lambda r: f"not a finite number: {_show(values[r])}",
                    "finite_number")
    return col, present, invalid


# ---------------------------------------------------------------- JSON documents


def _check_repeated_keys(body: bytes, doc: dict[str, Any], columns: dict[str, list[Any]] | None,
                         errors: _Errors) -> None:
    """Report keys given twice in one object (orjson, like most readers, keeps the last).

    Cheap proof first: each ``:`` of the body outside strings separates one key from its
    value, so when the colons of the body are exactly the parsed pairs plus the colons
    inside the ``ts`` and ``array`` strings, no key was repeated (a repeat, a nested
    value or a colon in another string only adds colons; a body with escapes, which
    could hide one, skips the proof). ``columns`` are the readings' columns when every
    reading is a flat object with the same known keys (else ``None``). Anything
    unproven is decided by a second, pair-keeping parse.
    """
    if columns is not None and len(doc) == 1 and b"\\" not in body:
        inside = 0
        for field in ("ts", "array"):
            col = columns[field]
            try:
                inside += "".join(col).count(":")
            except TypeError:  # not all strings (an error anyway)
                inside += "".join(x for x in col if type(x) is str).count(":")
        readings = doc["readings"]  # each with the first one's keys (the fast case)
        if body.count(b":") == 1 + len(readings[0]) * len(readings) + inside:
            return
    try:
        again = load_json_pairs(body)
    except (ValueError, RecursionError):  # 4300-digit integers, deep nesting: other errors
        return
    for path, key in repeated_keys(again):
        if path[:1] == ("readings",) and len(path) == 2 and isinstance(path[1], int):
            errors.add(path[1], key[:40], f"key {_show(key)} given twice in this reading",
                       "duplicate_key")
        else:
            where = "the body object" if not path else f"body at {list(path)}"
            errors.add(None, key[:40], f"key {_show(key)} given twice in {where}",
                       "duplicate_key")


def _columns(readings: list[Any], errors: _Errors) -> tuple[dict[str, list[Any]], bool]:
    """Every field as a column, and whether every reading was a flat object with the
    known keys of the first one (the fast case). Unknown keys are reported."""
    first = readings[0]
    n = len(readings)
    if type(first) is dict and _FIELD_SET.issuperset(first):
        try:
            # every reading has these keys (else KeyError) and no others (sum of sizes)
            if sum(map(len, readings)) == len(first) * n:
                none = [None] * n
                cols = {k: [r[k] for r in readings] for k in first}
                return {f: cols.get(f, none) for f in FIELDS}, True
        except (KeyError, TypeError):
            pass
    out: dict[str, list[Any]] = {f: [None] * n for f in FIELDS}
    for r, item in enumerate(readings):
        if type(item) is not dict:
            errors.refuse_row(r, f"a reading must be an object, got {type(item).__name__}")
            continue
        for k, v in item.items():
            if k in _FIELD_SET:
                out[k][r] = v
            else:
                errors.add(r, k[:40], f"unknown field {_show(k)}; a reading has "
                                      f"{', '.join(FIELDS)}", "extra_forbidden")
    return out, False


def _emoncms_columns(rows: list[Any], errors: _Errors) -> dict[str, list[Any]]:
    """Columns of emonCMS-style rows ``[unix_s, array, voltage_v, current_a, power_w]``
    (``power_w`` may be left off); ``ts`` holds the Unix seconds."""
    n = len(rows)
    names = ("ts", "array", "voltage_v", "current_a", "power_w")
    if set(map(type, rows)) == {list} and set(map(len, rows)) == {5}:
        cols = [list(c) for c in zip(*rows, strict=True)]
    else:
        cols = [[None] * n for _ in names]
        for r, row in enumerate(rows):
            if type(row) is not list or len(row) not in (4, 5):
                what = f"{len(row)} values" if type(row) is list else type(row).__name__
                msg = (f"a row must be [{', '.join(EMONCMS_ROW)}] (power_w may be left off), "
                       f"got {what}")
                if type(row) is not list:
                    errors.refuse_row(r, msg)
                    continue
                errors.add(r, None, msg, "type_error")
            for j, x in enumerate(row[:len(names)]):  # what a short row holds is not "missing"
                cols[j][r] = x
    out = dict(zip(names, cols, strict=True))
    return {f: out.get(f, [None] * n) for f in FIELDS}


# ---------------------------------------------------------------- batches


def build_batch(
    columns: dict[str, list[Any]],
    n: int,
    arrays: dict[str, IngestArray],
    limits: Limits,
    errors: _Errors,
    now_s: float | None = None,
    text: bool = False,
    ts_s: np.ndarray | None = None,
) -> Batch:
    """Validate columns (each a list of ``n`` values, ``None`` = absent) into a :class:`Batch`.

    Every check runs on every row before the batch is refused, so one answer lists
    all kinds of problems (bounded, see :class:`_Errors`). ``text``: the number
    columns are CSV cells; ``ts_s``: timestamps already in Unix seconds (emonCMS).
    """
    ts = parse_timestamps(columns["ts"], errors) if ts_s is None else ts_s
    now_s = time.time() if now_s is None else now_s
    errors.add_rows(ts > now_s + limits.future_tolerance_s, "ts", lambda r: (
        f"timestamp {_show(columns['ts'][r])} is {int(ts[r] - now_s)} s after the server "
        f"clock (tolerance {limits.future_tolerance_s} s)"), "value_error")
    errors.add_rows(ts < READINGS_FROM_S, "ts", lambda r: "timestamp before 1990",
                    "value_error")

    names = columns["array"]
    known = list(arrays)
    ids_by_name = {k: a.array_id for k, a in arrays.items()}
    index_by_name = {k: j for j, k in enumerate(known)}
    unknown = np.zeros(n, bool)
    try:
        idx = np.array([index_by_name[a] for a in names], np.int64)
    except (KeyError, TypeError):
        idx = np.zeros(n, np.int64)
        for r, a in enumerate(names):
            if isinstance(a, str) and a in index_by_name:
                idx[r] = index_by_name[a]
            else:
                unknown[r] = True
                what = "missing" if a is None else f"unknown array {_show(a)}"
                errors.add(r, "array", f"{what}; this site has {', '.join(known)}",
                           "missing" if a is None else "value_error")
    array_ids = np.array([ids_by_name[k] for k in known], np.int64)[idx] if known else idx

    v, v_ok, _ = _floats(columns["voltage_v"], "voltage_v", errors, text)
    i, i_ok, _ = _floats(columns["current_a"], "current_a", errors, text)
    p, p_ok, _ = _floats(columns["power_w"], "power_w", errors, text)
    va, va_ok, _ = _floats(columns["voltage_adc"], "voltage_adc", errors, text)
    ia, ia_ok, _ = _floats(columns["current_adc"], "current_adc", errors, text)

    raw = va_ok | ia_ok
    both_raw = va_ok & ia_ok
    # when every reading sends voltage and current and none raw counts, none of these
    # can apply: the common batch skips building their masks
    checks = np.count_nonzero(raw) or np.count_nonzero(v_ok & i_ok) < n
    for mask, field, msg in () if not checks else (
        # the missing one named (a row without current_adc was reported on voltage_adc)
        (va_ok & ~ia_ok, "current_adc", "a raw reading needs both voltage_adc and current_adc"),
        (ia_ok & ~va_ok, "voltage_adc", "a raw reading needs both voltage_adc and current_adc"),
        (raw & (v_ok | i_ok), "voltage_adc",
         "send either voltage_v/current_a or voltage_adc/current_adc, not both"),
        (~raw & ~v_ok & ~i_ok & ~p_ok, "power_w",
         "no electrical value: send voltage_v and current_a, or power_w alone"),
        (~raw & ~v_ok & i_ok, "voltage_v",
         "voltage_v is missing (send it with current_a, or power_w alone)"),
        (~raw & v_ok & ~i_ok, "current_a",
         "current_a is missing (send it with voltage_v, or power_w alone)"),
    ):
        errors.add_rows(mask, field, lambda r, m=msg: m, "missing")
    if np.count_nonzero(both_raw):
        rows = np.flatnonzero(both_raw)
        for j, name in enumerate(known):
            sel = rows[idx[rows] == j]
            if sel.size == 0:
                continue
            cal = arrays[name].calibration
            for col, field in ((va, "voltage_adc"), (ia, "current_adc")):
                bad = np.zeros(n, bool)
                bad[sel] = ((col[sel] < 0) | (col[sel] > cal.adc_max_counts)
                            | (col[sel] != np.round(col[sel])))
                errors.add_rows(bad, field, lambda r, c=col, cal=cal: (
                    f"ADC count {c[r]:g} is not an integer in 0..{cal.adc_max_counts}"),
                    "value_error")
            v[sel], i[sel] = adc_to_volts_amps(va[sel], ia[sel], cal)

    # NaN (absent or already reported) compares false: no second error for a row. A voltage
    # a little below 0 is a transducer's zero offset at night (a real logger's file, NREL
    # SERF West, was refused at −0.002 V on every night reading: docs/service.md)
    bad_v = (v < limits.min_voltage_v) | (v > limits.max_voltage_v)
    errors.add_rows(bad_v, "voltage_v", lambda r: (
        f"voltage_v {v[r]:g} V outside {limits.min_voltage_v:g}..{limits.max_voltage_v:g} V"),
        "value_error")
    bad_i = (i < limits.min_current_a) | (i > limits.max_current_a)
    errors.add_rows(bad_i, "current_a",
                    lambda r: (f"current_a {i[r]:g} A outside {limits.min_current_a:g}.."
                               f"{limits.max_current_a:g} A"), "value_error")
    vi = v * i
    p = np.where(p_ok, p, vi)
    mismatch = p_ok & (np.abs(p - vi) > 0.05 * np.abs(vi) + limits.power_tolerance_w)
    errors.add_rows(mismatch, "power_w", lambda r: (f"power_w {p[r]:g} W disagrees with "
                                          f"voltage_v·current_a = {vi[r]:g} W"), "value_error")
    p_low = min(limits.max_voltage_v * min(limits.min_current_a, 0.0),
                limits.min_voltage_v * limits.max_current_a) - limits.power_tolerance_w
    p_high = limits.max_voltage_v * limits.max_current_a
    outside = p_ok & ((p < p_low) | (p > p_high))
    errors.add_rows(outside, "power_w", lambda r: (
        f"power_w {p[r]:g} W outside {p_low:g}..{p_high:g} W (the voltage and current "
        "limits)"), "value_error")
    # each array's own rating (the voltage and current limits are the service's, any array;
    # one error a row: not where those refused it)
    stc = np.array([np.nan if arrays[k].stc_power_w is None else arrays[k].stc_power_w
                    for k in known] or [np.nan])[idx]
    stc = np.where(outside | bad_v | bad_i | mismatch | unknown, np.nan, stc)
    errors.add_rows(p > MAX_STC_MULTIPLE * stc + limits.power_tolerance_w, "power_w",
                    lambda r: (f"power_w {p[r]:g} W is over {MAX_STC_MULTIPLE:g} × array "
                               f"{_show(names[r])}'s rating ({stc[r]:g} W at STC): a power in "
                               f"the wrong unit, or more modules than the site's config "
                               f"says (fix its arrays)"), "value_error")
    only_p = p_ok & ~(v_ok & i_ok)
    errors.add_rows(only_p & (p < MIN_STC_SHARE * stc - limits.power_tolerance_w), "power_w",
                    lambda r: (f"power_w {p[r]:g} W is below "
                               f"{MIN_STC_SHARE * stc[r] - limits.power_tolerance_w:g} W "
                               f"({100 * MIN_STC_SHARE:g} % of array {_show(names[r])}'s "
                               f"rating, less the tolerance): an array makes power; a "
                               f"reversed current sensor or meter?"), "value_error")
    sensors = _sensor_columns(columns, n, errors, text)
    errors.raise_if_any()
    return Batch(array_ids, ts, v, i, p, sensors)


def _sensor_columns(columns: dict[str, list[Any]], n: int, errors: _Errors, text: bool
                    ) -> np.ndarray | None:
    """The optional sensor fields (:data:`SENSOR_FIELDS`) checked against their ranges,
    as ``(n, k)`` columns with NaN where absent; None when the batch sends none."""
    if all(columns[f.name].count(None) == n for f in SENSOR_FIELDS):
        return None
    out = np.full((n, len(SENSOR_FIELDS)), np.nan)
    for j, f in enumerate(SENSOR_FIELDS):
        col, _, _ = _floats(columns[f.name], f.name, errors, text)
        errors.add_rows((col < f.low) | (col > f.high), f.name, lambda r, c=col, f=f: (
            f"{f.name} {c[r]:g} outside {f.low:g}..{f.high:g}"), "value_error")
        out[:, j] = np.where(np.isfinite(col), col, np.nan)
    return normalise_sensors(out)


def _check_rows(n: int, limits: Limits) -> None:
    if n > limits.max_rows:
        raise body_error(413, "readings", "too_large",
                          f"{n} readings in one request; the limit is {limits.max_rows}: "
                          "split the batch")
    if n == 0:
        raise body_error(422, "readings", "missing", "no readings in the request")


def load_json(body: bytes) -> Any:
    """A logger's JSON document (HTTP's body, MQTT's state payload), a leading byte order
    mark dropped (Windows tools write one; it is not JSON but no reason to refuse); NaN,
    Infinity and 1e400 are read as Python reads them, so the rows' checks name each field
    (orjson's "line 1 column 76" named none). Else an :class:`IngestError`."""
    body = body.removeprefix(BOM)
    try:
        return orjson.loads(body)
    except orjson.JSONDecodeError as exc:
        try:
            return json.loads(body)
        except (ValueError, RecursionError):
            raise body_error(422, None, "json_invalid", f"invalid JSON: {exc}") from exc


def decimal_value(text: str, field: str) -> float:
    """One number in plain decimal notation (a CSV cell's rule: MQTT's single values),
    surrounding blanks ignored; else an :class:`IngestError` naming ``field``."""
    errors = _Errors(csv_lines=False)
    col = _floats([text.strip()], field, errors, text=True)[0]
    errors.raise_if_any()
    return float(col[0])


def parse_json_batch(
    body: bytes, arrays: dict[str, IngestArray], limits: Limits
) -> Batch:
    """Validate a JSON body: ``{"readings": [{ts, array, voltage_v, current_a, ...}]}``, or
    emonCMS-style rows ``[[unix_s, array, voltage_v, current_a, power_w], ...]``."""
    errors = _Errors(csv_lines=False)
    body = body.removeprefix(BOM)  # for the repeated keys' check too
    doc = load_json(body)
    if isinstance(doc, list):
        _check_rows(len(doc), limits)
        columns = _emoncms_columns(doc, errors)
        ts = _unix_seconds(columns["ts"], errors)
        return build_batch(columns, len(doc), arrays, limits, errors, ts_s=ts)
    readings = doc.get("readings") if isinstance(doc, dict) else None
    if not isinstance(readings, list):
        raise body_error(422, "readings", "missing",
                          'body must be {"readings": [ ... ]} or [[unix_s, array, voltage_v, '
                          'current_a, power_w], ...]')
    for key in list(doc)[:MAX_ERRORS_PER_FIELD]:
        if key != "readings":
            errors.add(None, key[:40], f"unknown field {_show(key)}; the body has only "
                                       "'readings'", "extra_forbidden")
    if not readings:  # {"readings": [...], "readings": []}: say so, not "no readings"
        _check_repeated_keys(body, doc, None, errors)
        errors.raise_if_any()
    _check_rows(len(readings), limits)
    columns, flat = _columns(readings, errors)
    _check_repeated_keys(body, doc, columns if flat else None, errors)
    return build_batch(columns, len(readings), arrays, limits, errors)


def _csv_rows(text: str) -> tuple[list[str], list[list[str]]]:
    """Header and data rows; quoting errors name the line where the bad cell starts."""
    # universal newlines: a file of classic Mac line ends (CR alone) reads as lines too
    reader = csv.reader(io.StringIO(text, newline=None), strict=True)
    rows: list[list[str]] = []
    start = 1
    try:
        for row in reader:
            rows.append(row)
            if len(rows) == 1 and len(row) > MAX_COLUMNS:
                raise body_error(422, "header", "value_error",
                                  f"CSV header has {len(row)} columns; it names at most "
                                  f"{len(FIELDS)} ({', '.join(FIELDS)})", line=1)
            start = reader.line_num + 1
    except csv.Error as exc:
        what = (f"a quoted cell opened on line {start} is never closed"
                if "unexpected end of data" in str(exc) else f"bad quoting ({exc})")
        if "field larger" in str(exc):
            what = f"a cell is longer than {csv.field_size_limit()} characters"
        raise body_error(422, None, "value_error", f"CSV line {start}: {what}",
                          line=start) from exc
    while rows and not any(cell.strip() for cell in rows[-1]):
        rows.pop()
    if not rows:
        raise body_error(422, "readings", "missing", "no readings in the request")
    return [h.strip() for h in rows[0]], rows[1:]


def parse_csv_batch(
    body: bytes, arrays: dict[str, IngestArray], limits: Limits
) -> Batch:
    """Validate a CSV body with a header row naming the same columns as the JSON form."""
    errors = _Errors(csv_lines=True)
    try:
        text = body.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise body_error(422, None, "value_error", f"CSV is not UTF-8: {exc}") from exc
    header, data = _csv_rows(text)
    sep = next((c for c in ";\t|" if len(header) == 1 and c in header[0]), None)
    if sep:  # a portal's export in its own dialect (Europe: ';' and a decimal comma)
        raise body_error(422, "header", "value_error",
                          f"CSV header {_show(header[0])} is one column: the file is separated "
                          f"by {sep!r}; separate the columns with commas (and write numbers "
                          f"with a decimal point), or post the file as it is with heliotwin "
                          f"readings import", line=1)
    seen = Counter(header)  # linear in the header, whatever its length
    unknown = [h for h in seen if h not in _FIELD_SET]
    twice = [h for h, k in seen.items() if k > 1 and h in _FIELD_SET]
    missing = [f for f in ("ts", "array") if f not in seen]
    if unknown or twice or missing:
        parts = []
        for label, names in (("unknown", unknown), ("twice", twice), ("missing", missing)):
            if names:
                more = f" and {len(names) - 5} more" if len(names) > 5 else ""
                parts.append(f"{label}: {', '.join(_show(h) for h in names[:5])}{more}")
        raise body_error(422, "header", "value_error",
                          f"CSV header must name ts, array and voltage_v,current_a[,power_w], "
                          f"power_w alone or voltage_adc,current_adc (optional: "
                          f"{', '.join(SENSOR_NAMES)}); {'; '.join(parts)}", line=1)
    _check_rows(len(data), limits)
    width = len(header)
    for r, row in enumerate(data):
        if not any(cell.strip() for cell in row):
            errors.add(r, None, "an empty line between readings; remove it (empty lines "
                                "are taken only at the end)", "value_error")
        elif len(row) != width:
            errors.add(r, None, f"{len(row)} cells, the header has {width}", "value_error")
    errors.raise_if_any()
    columns: dict[str, list[Any]] = {}
    for f in FIELDS:
        if f in seen:
            k = header.index(f)
            columns[f] = [row[k].strip() or None for row in data]
        else:
            columns[f] = [None] * len(data)
    return build_batch(columns, len(data), arrays, limits, errors, text=True)
