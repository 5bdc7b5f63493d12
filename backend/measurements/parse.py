"""Bulk validation of field-logger readings, without a Python object per reading.

A batch (JSON ``{"readings": [...]}`` or CSV with a header row) is turned into
columns — ``orjson`` to parse, one list comprehension per field, NumPy to check
every row at once — and either becomes a :class:`Batch` of arrays or fails whole
with :class:`IngestError`, whose entries name the row, the field and what was
wrong. Timestamps follow :mod:`backend.timestamps` (vectorised for the form
loggers send) and are stored as whole UTC seconds (a fractional part is dropped).

Raw logger readings carry ADC counts instead of volts and amperes, as the
Arduino logger of seed 000 produces them; they are converted with the array's
stored calibration (:class:`Calibration`, seed 000 eqs. 16–19).
"""

from __future__ import annotations

import csv
import io
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import orjson

from backend.timestamps import READINGS_FROM_S, parse_instants

MAX_ERRORS = 20
#: Python types a number column may hold (``str`` for CSV cells; ``bool`` is not a number).
_SCALARS = frozenset((float, int, str, type(None)))
FIELDS = ("ts", "array", "voltage_v", "current_a", "power_w", "voltage_adc", "current_adc")


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


@dataclass(frozen=True)
class Limits:
    """Plausibility limits applied to every reading (from ``Settings``)."""

    max_rows: int = 100_000
    future_tolerance_s: int = 900
    max_voltage_v: float = 1500.0
    max_current_a: float = 100.0
    min_current_a: float = -1.0
    power_tolerance_w: float = 5.0


@dataclass
class Batch:
    """A validated batch: one entry per reading, arrays of equal length."""

    array_ids: np.ndarray  # int64
    ts_s: np.ndarray  # int64, UTC Unix seconds
    voltage_v: np.ndarray
    current_a: np.ndarray
    power_w: np.ndarray

    def __len__(self) -> int:
        return int(self.ts_s.shape[0])


class IngestError(Exception):
    """A rejected batch: HTTP ``status`` and a list of ``{row, field, msg}`` entries."""

    def __init__(self, status: int, errors: list[dict[str, Any]]) -> None:
        super().__init__(errors[0]["msg"] if errors else "invalid batch")
        self.status = status
        self.errors = errors

    def __reduce__(self) -> tuple[Any, ...]:  # crosses process boundaries (parser pool)
        return (IngestError, (self.status, self.errors))


class _Errors:
    """Collects at most ``MAX_ERRORS`` row/field errors."""

    def __init__(self, csv_lines: bool) -> None:
        self.items: list[dict[str, Any]] = []
        self.csv_lines = csv_lines

    def add(self, row: int | None, field: str | None, msg: str, kind: str) -> None:
        if len(self.items) >= MAX_ERRORS:
            return
        loc: list[Any] = ["body"] if row is None else ["body", "readings", row]
        if field:
            loc.append(field)
        item: dict[str, Any] = {"loc": loc, "msg": msg, "type": kind, "row": row, "field": field}
        if self.csv_lines and row is not None:
            item["line"] = row + 2  # 1-based, after the header line
        self.items.append(item)

    def add_rows(self, rows: np.ndarray, field: str, msg_of: Any, kind: str) -> None:
        for r in rows[: MAX_ERRORS].tolist():
            self.add(int(r), field, msg_of(int(r)), kind)

    def raise_if_any(self, status: int = 422) -> None:
        if self.items:
            raise IngestError(status, self.items)


# ---------------------------------------------------------------- timestamps


def parse_timestamps(values: Sequence[Any], errors: _Errors, field: str = "ts") -> np.ndarray:
    """Timestamps → UTC Unix seconds (int64) by :func:`backend.timestamps.parse_instants`;
    naive, non-string and unparseable stamps are reported per row."""
    ts, problems = parse_instants(values)
    for row, message, code in problems:
        errors.add(row, field, message, code)
    return ts


# ---------------------------------------------------------------- numbers


def _floats(values: list[Any], field: str, errors: _Errors) -> tuple[np.ndarray, np.ndarray]:
    """A float column and its 'present' mask; non-numbers and non-finite values are errors."""
    missing = values.count(None)
    if missing == len(values):
        return np.full(len(values), np.nan), np.zeros(len(values), bool)
    col = None
    if _SCALARS.issuperset(map(type, values)):  # no bool, list, object: NumPy converts all
        try:
            col = np.array(values, dtype=np.float64)
        except ValueError:  # a string that is not a number
            col = None
    if col is None:
        col = np.empty(len(values), np.float64)
        for r, x in enumerate(values):
            try:
                if type(x) not in _SCALARS:
                    raise TypeError
                col[r] = np.nan if x is None else float(x)
            except (TypeError, ValueError, OverflowError):
                errors.add(r, field, f"not a number: {str(x)[:40]!r}", "type_error")
                col[r] = 0.0
    if missing == 0:
        present = np.ones(len(values), bool)
    elif missing == len(values):
        present = np.zeros(len(values), bool)
    else:
        present = np.fromiter((x is not None for x in values), bool, len(values))
    bad = present & ~np.isfinite(col)
    if bad.any():
        errors.add_rows(np.flatnonzero(bad), field, lambda r: f"not finite: {values[r]!r}",
                        "value_error")
    return col, present


def _column(readings: list[Any], key: str, errors: _Errors) -> list[Any]:
    try:
        return [r.get(key) for r in readings]
    except AttributeError:
        for r, item in enumerate(readings):
            if not isinstance(item, dict):
                errors.add(r, None, f"a reading must be an object, got {type(item).__name__}",
                           "type_error")
        errors.raise_if_any()
        raise


def _columns(readings: list[Any], errors: _Errors) -> dict[str, list[Any]]:
    """Every field as a column; fast when all readings have the keys of the first one."""
    first = readings[0]
    n = len(readings)
    if isinstance(first, dict):
        keys = [k for k in first if k in FIELDS]
        try:
            # every reading has these keys (else KeyError) and no others (sum of sizes)
            if sum(map(len, readings)) == len(first) * n:
                none = [None] * n
                cols = {k: [r[k] for r in readings] for k in keys}
                return {f: cols.get(f, none) for f in FIELDS}
        except (KeyError, TypeError):
            pass
    return {f: _column(readings, f, errors) for f in FIELDS}


# ---------------------------------------------------------------- batches


def build_batch(
    columns: dict[str, list[Any]],
    n: int,
    arrays: dict[str, tuple[int, Calibration]],
    limits: Limits,
    errors: _Errors,
    now_s: float | None = None,
) -> Batch:
    """Validate columns (each a list of ``n`` values, ``None`` = absent) into a :class:`Batch`."""
    ts = parse_timestamps(columns["ts"], errors)
    now_s = time.time() if now_s is None else now_s
    late = ts > now_s + limits.future_tolerance_s
    if late.any():
        errors.add_rows(np.flatnonzero(late), "ts", lambda r: (
            f"timestamp {columns['ts'][r]} is {int(ts[r] - now_s)} s after the server clock "
            f"(tolerance {limits.future_tolerance_s} s)"), "value_error")
    early = ts < READINGS_FROM_S
    if early.any():
        errors.add_rows(np.flatnonzero(early), "ts", lambda r: "timestamp before 1990",
                        "value_error")

    names = columns["array"]
    known = list(arrays)
    ids_by_name = {k: v[0] for k, v in arrays.items()}
    index_by_name = {k: j for j, k in enumerate(known)}
    try:
        idx = np.array([index_by_name[a] for a in names], np.int64)
    except (KeyError, TypeError):
        idx = np.zeros(n, np.int64)
        for r, a in enumerate(names):
            if isinstance(a, str) and a in index_by_name:
                idx[r] = index_by_name[a]
            else:
                what = "missing" if a is None else f"unknown array {str(a)[:40]!r}"
                errors.add(r, "array", f"{what}; this site has {', '.join(known)}",
                           "missing" if a is None else "value_error")
    array_ids = np.array([ids_by_name[k] for k in known], np.int64)[idx] if known else idx

    v, v_ok = _floats(columns["voltage_v"], "voltage_v", errors)
    i, i_ok = _floats(columns["current_a"], "current_a", errors)
    p, p_ok = _floats(columns["power_w"], "power_w", errors)
    va, va_ok = _floats(columns["voltage_adc"], "voltage_adc", errors)
    ia, ia_ok = _floats(columns["current_adc"], "current_adc", errors)

    raw = va_ok | ia_ok
    both_raw = va_ok & ia_ok
    for mask, field, msg in (
        (raw & ~both_raw, "voltage_adc", "a raw reading needs both voltage_adc and current_adc"),
        (raw & (v_ok | i_ok), "voltage_adc",
         "send either voltage_v/current_a or voltage_adc/current_adc, not both"),
        (~raw & ~v_ok, "voltage_v", "voltage_v is missing"),
        (~raw & v_ok & ~i_ok, "current_a", "current_a is missing"),
    ):
        if mask.any():
            errors.add_rows(np.flatnonzero(mask), field, lambda r, m=msg: m, "missing")
    if both_raw.any():
        rows = np.flatnonzero(both_raw)
        for j, name in enumerate(known):
            sel = rows[idx[rows] == j]
            if sel.size == 0:
                continue
            cal = arrays[name][1]
            for col, field in ((va, "voltage_adc"), (ia, "current_adc")):
                bad = sel[(col[sel] < 0) | (col[sel] > cal.adc_max_counts)
                          | (col[sel] != np.round(col[sel]))]
                errors.add_rows(bad, field, lambda r, c=col, cal=cal: (
                    f"ADC count {c[r]:g} is not an integer in 0..{cal.adc_max_counts}"),
                    "value_error")
            v[sel], i[sel] = adc_to_volts_amps(va[sel], ia[sel], cal)
    errors.raise_if_any()

    bad_v = (v < 0) | (v > limits.max_voltage_v)
    errors.add_rows(np.flatnonzero(bad_v), "voltage_v", lambda r: (
        f"voltage_v {v[r]:g} V outside 0..{limits.max_voltage_v:g} V"), "value_error")
    bad_i = (i < limits.min_current_a) | (i > limits.max_current_a)
    errors.add_rows(np.flatnonzero(bad_i), "current_a", lambda r: (
        f"current_a {i[r]:g} A outside {limits.min_current_a:g}..{limits.max_current_a:g} A"),
        "value_error")
    vi = v * i
    p = np.where(p_ok, p, vi)
    bad_p = np.abs(p - vi) > 0.05 * np.abs(vi) + limits.power_tolerance_w
    errors.add_rows(np.flatnonzero(bad_p & p_ok), "power_w", lambda r: (
        f"power_w {p[r]:g} W disagrees with voltage_v·current_a = {vi[r]:g} W"), "value_error")
    errors.raise_if_any()
    return Batch(array_ids, ts, v, i, p)


def _check_rows(n: int, limits: Limits) -> None:
    if n > limits.max_rows:
        raise IngestError(413, [{
            "loc": ["body", "readings"], "row": None, "field": "readings", "type": "too_large",
            "msg": f"{n} readings in one request; the limit is {limits.max_rows}: split the batch",
        }])
    if n == 0:
        raise IngestError(422, [{
            "loc": ["body", "readings"], "row": None, "field": "readings", "type": "missing",
            "msg": "no readings in the request",
        }])


def parse_json_batch(
    body: bytes, arrays: dict[str, tuple[int, Calibration]], limits: Limits
) -> Batch:
    """Validate a JSON body ``{"readings": [{ts, array, voltage_v, current_a, ...}]}``."""
    errors = _Errors(csv_lines=False)
    try:
        doc = orjson.loads(body)
    except orjson.JSONDecodeError as exc:
        raise IngestError(422, [{"loc": ["body"], "row": None, "field": None,
                                 "type": "json_invalid", "msg": f"invalid JSON: {exc}"}]) from exc
    readings = doc.get("readings") if isinstance(doc, dict) else None
    if not isinstance(readings, list):
        raise IngestError(422, [{"loc": ["body", "readings"], "row": None, "field": "readings",
                                 "type": "missing",
                                 "msg": 'body must be {"readings": [ ... ]}'}])
    _check_rows(len(readings), limits)
    columns = _columns(readings, errors)
    return build_batch(columns, len(readings), arrays, limits, errors)


def parse_csv_batch(
    body: bytes, arrays: dict[str, tuple[int, Calibration]], limits: Limits
) -> Batch:
    """Validate a CSV body with a header row naming the same columns as the JSON form."""
    errors = _Errors(csv_lines=True)
    try:
        text = body.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise IngestError(422, [{"loc": ["body"], "row": None, "field": None,
                                 "type": "value_error",
                                 "msg": f"CSV is not UTF-8: {exc}"}]) from exc
    reader = csv.reader(io.StringIO(text))
    try:
        rows = list(reader)
    except csv.Error as exc:
        raise IngestError(422, [{"loc": ["body"], "row": None, "field": None,
                                 "type": "value_error", "line": reader.line_num,
                                 "msg": f"CSV line {reader.line_num}: {exc}"}]) from exc
    while rows and not any(cell.strip() for cell in rows[-1]):
        rows.pop()
    if not rows:
        _check_rows(0, limits)
    header = [h.strip() for h in rows[0]]
    unknown = [h for h in header if h not in FIELDS]
    unknown += sorted({f"{h} (twice)" for h in header if header.count(h) > 1})
    if unknown or "ts" not in header or "array" not in header:
        raise IngestError(422, [{"loc": ["body", "header"], "row": None, "field": "header",
                                 "type": "value_error", "line": 1,
                                 "msg": f"CSV header {header} must name ts, array and "
                                        f"voltage_v,current_a[,power_w] or voltage_adc,"
                                        f"current_adc; unknown: {unknown}"}])
    data = rows[1:]
    _check_rows(len(data), limits)
    width = len(header)
    for r, row in enumerate(data):
        if len(row) != width:
            errors.add(r, None, f"{len(row)} cells, the header has {width}", "value_error")
    errors.raise_if_any()
    columns: dict[str, list[Any]] = {}
    for f in FIELDS:
        if f in header:
            k = header.index(f)
            columns[f] = [row[k].strip() or None for row in data]
        else:
            columns[f] = [None] * len(data)
    return build_batch(columns, len(data), arrays, limits, errors)
