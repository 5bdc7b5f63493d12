"""Reads for dashboards and people: measurements (raw or downsampled) and energy.

Both are answered from the hourly rollups (``measurement_rollups``) for the
whole hours of a range and from the raw rows only for the partial hours at its
edges, so a year costs a few thousand rollup rows instead of half a million
readings. Downsampled buckets carry min/mean/max so peaks survive.
"""

from __future__ import annotations

import datetime as dt
import math
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from zoneinfo import ZoneInfo

import numpy as np
from sqlalchemy import Connection, Engine

from backend.measurements.buckets import ROLLUP_WIDTH_S, grid_ceil, grid_floor
from backend.measurements.fields import ELECTRICAL, SENSOR_NAMES
from backend.storage.sqlraw import fetch
from sim.energy import energy_per_period_wh, energy_wh

QUANTITIES = ELECTRICAL
_NS = len(SENSOR_NAMES)
_RAW_ALL = (
    f"SELECT ts_s, voltage_v, current_a, power_w, {', '.join(SENSOR_NAMES)} FROM measurements "
    "WHERE array_id = ? AND source = ? AND ts_s >= ? AND ts_s < ? ORDER BY ts_s"
)

_RAW = (
    "SELECT ts_s, voltage_v, current_a, power_w FROM measurements "
    "WHERE array_id = ? AND source = ? AND ts_s >= ? AND ts_s < ? ORDER BY ts_s"
)
#: A series' readings in a range, then how many carry each sensor field (raw, and the
#: rollups' sums for whole hours)
_RAW_COUNT = (
    f"SELECT COUNT(*), {', '.join(f'COUNT({f})' for f in SENSOR_NAMES)} FROM measurements "
    "WHERE array_id = ? AND source = ? AND ts_s >= ? AND ts_s < ?"
)
_ROLLUP_COUNT = (
    f"SELECT COALESCE(SUM(n), 0), {', '.join(f'COALESCE(SUM(n_{f}), 0)' for f in SENSOR_NAMES)} "
    "FROM measurement_rollups WHERE array_id = ? AND source = ? AND bucket_s >= ? AND bucket_s < ?"
)
# bucket aggregates: k, n, 3 sums, 3 minima, 3 maxima, n_vi, sensor sums, sensor counts
_ROLLUP_BUCKETS = (
    "SELECT (bucket_s - ?) / ?, SUM(n), SUM(sum_voltage_v), SUM(sum_current_a), SUM(sum_power_w), "
    "MIN(min_voltage_v), MIN(min_current_a), MIN(min_power_w), "
    "MAX(max_voltage_v), MAX(max_current_a), MAX(max_power_w), SUM(n_vi), "
    f"{', '.join(f'SUM(sum_{f})' for f in SENSOR_NAMES)}, "
    f"{', '.join(f'SUM(n_{f})' for f in SENSOR_NAMES)} FROM measurement_rollups "
    "WHERE array_id = ? AND source = ? AND bucket_s >= ? AND bucket_s < ? "
    "GROUP BY 1 ORDER BY 1"
)
_RAW_BUCKETS = (
    "SELECT (ts_s - ?) / ?, COUNT(*), SUM(voltage_v), SUM(current_a), SUM(power_w), "
    "MIN(voltage_v), MIN(current_a), MIN(power_w), MAX(voltage_v), MAX(current_a), MAX(power_w), "
    f"COUNT(voltage_v), {', '.join(f'COALESCE(SUM({f}), 0)' for f in SENSOR_NAMES)}, "
    f"{', '.join(f'COUNT({f})' for f in SENSOR_NAMES)} "
    "FROM measurements WHERE array_id = ? AND source = ? AND ts_s >= ? AND ts_s < ? "
    "GROUP BY 1 ORDER BY 1"
)
_WIDTH = 12 + 2 * _NS  # columns of a bucket row
#: Energy and readings per (array, source, period), summed by the database: the periods
#: are a VALUES table (the first row typed for PostgreSQL), each joined to its rollups by a
#: primary-key range per series (source named, so the key's whole prefix is used). The
#: periods are the outer loop (SQLite keeps a CROSS JOIN's order): with a plain JOIN its
#: planner put the rollups outside past some 300 periods and compared every rollup row with
#: every period: a year's energy per day took 1.41 s instead of 0.04 s (bench_service).
_ROLLUP_PERIODS = (
    "WITH p(i, lo, hi) AS (VALUES (CAST(? AS INTEGER), CAST(? AS BIGINT), CAST(? AS BIGINT))"
    "{more}) "
    "SELECT r.array_id, r.source, p.i, SUM(r.energy_wh), SUM(r.n) "
    "FROM p CROSS JOIN measurement_rollups r WHERE r.array_id IN ({ids}) "
    "AND r.source IN (0, 1) AND r.bucket_s >= p.lo AND r.bucket_s < p.hi "
    "GROUP BY r.array_id, r.source, p.i"
)
#: Periods per statement of :data:`_ROLLUP_PERIODS` (3 parameters each; SQLite allows 32,766).
PERIODS_PER_QUERY = 1000


def iso_utc(ts_s: np.ndarray | list[int]) -> list[str]:
    """ISO 8601 UTC strings (``…Z``) of Unix seconds."""
    if len(ts_s) < 8:  # an ingest answer's one stamp: NumPy's call would cost more than it
        return [time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(int(t))) for t in ts_s]
    return np.datetime_as_string(np.asarray(ts_s, "datetime64[s]"), unit="s",
                                 timezone="UTC").tolist()


def count_rows(conn: Connection, array_id: int, source: int, start: int, end: int,
               phase: int) -> tuple[int, list[str]]:
    """Readings of a series in ``[start, end)``, and the :data:`SENSOR_NAMES` some of them
    carry: rollup counts inside, raw counts at the edges (no reading is held in memory)."""
    a, b = grid_ceil(start, phase), grid_floor(end, phase)
    if a >= b:
        parts = [(_RAW_COUNT, start, end)]
    else:
        parts = [(_ROLLUP_COUNT, a, b)] + [(_RAW_COUNT, lo, hi) for lo, hi in
                                           ((start, a), (b, end)) if lo < hi]
    n = np.zeros(1 + _NS, np.int64)
    for sql, lo, hi in parts:
        n += np.array(fetch(conn, sql, (array_id, source, lo, hi))[0], np.int64)
    return int(n[0]), [f for f, k in zip(SENSOR_NAMES, n[1:].tolist(), strict=True) if k]


def raw_rows(conn: Connection, array_id: int, source: int, start: int, end: int,
             sensors: bool = False, limit: int | None = None) -> np.ndarray:
    """Stored readings ``(ts_s, voltage_v, current_a, power_w)`` in ``[start, end)``, with
    the :data:`SENSOR_NAMES` columns after them when ``sensors``; NULL is NaN. With
    ``limit``, the first ``limit`` of them."""
    sql = _RAW_ALL if sensors else _RAW
    params: tuple[int, ...] = (array_id, source, start, end)
    if limit is not None:
        sql, params = sql + " LIMIT ?", (*params, limit)
    rows = fetch(conn, sql, params)
    return np.array(rows, np.float64).reshape(-1, 4 + _NS if sensors else 4)


def raw_pages(engine: Engine, array_id: int, source: int, start: int, end: int,
              sensors: bool, page_rows: int = 20_000) -> Iterator[np.ndarray]:
    """:func:`raw_rows` of ``[start, end)`` in pages of at most ``page_rows`` readings, each
    read on a connection of its own, so a streamed export holds one page at a time (a year
    read whole, 16 at once, had taken the service from 0.4 to 2.4 GB) and no connection
    while the client reads."""
    while start < end:
        with engine.connect() as conn:
            rows = raw_rows(conn, array_id, source, start, end, sensors, page_rows)
        if rows.shape[0]:
            yield rows
        if rows.shape[0] < page_rows:
            return
        start = int(rows[-1, 0]) + 1


def sensor_columns(rows: np.ndarray, names: Sequence[str]) -> dict[str, list[object]]:
    """The columns ``names`` (of :data:`SENSOR_NAMES`) of :func:`raw_rows` (``sensors=True``)."""
    return {f: rows[:, 4 + SENSOR_NAMES.index(f)].tolist() for f in names}


@dataclass
class Buckets:
    """Per-bucket aggregates, parallel arrays (index = bucket number from ``origin``)."""

    origin_s: int
    width_s: int
    k: np.ndarray
    n: np.ndarray
    sums: np.ndarray  # (m, 3)
    mins: np.ndarray  # NaN: no reading of the bucket has the value
    maxs: np.ndarray
    n_vi: np.ndarray  # readings with voltage and current
    sensor_sums: np.ndarray  # (m, len(SENSOR_NAMES))
    sensor_n: np.ndarray

    def points(self, sensors: Sequence[str] | None = None) -> dict[str, list[object]]:
        """Columns of the answer: ts, n, mean/min/max per quantity (means over the
        readings that have the value; NaN, null in JSON, where none has it), and the
        mean of every sensor field some reading of the range carried (``sensors``: of
        these, so that the pages of one export have the same columns)."""
        out: dict[str, list[object]] = {
            "ts": list(iso_utc(self.origin_s + self.k * self.width_s)), "n": self.n.tolist(),
        }
        with np.errstate(invalid="ignore", divide="ignore"):
            for j, q in enumerate(QUANTITIES):
                count = self.n if q == "power_w" else self.n_vi
                out[q] = np.where(count > 0, self.sums[:, j] / count, np.nan).tolist()
                out[f"{q}_min"] = self.mins[:, j].tolist()
                out[f"{q}_max"] = self.maxs[:, j].tolist()
            for j, f in enumerate(SENSOR_NAMES):
                if f in sensors if sensors is not None else self.sensor_n[:, j].any():
                    c = self.sensor_n[:, j]
                    out[f] = np.where(c > 0, self.sensor_sums[:, j] / c, np.nan).tolist()
        return out


def _buckets_from_rows(rows: list[tuple[object, ...]], origin: int, width: int) -> Buckets:
    a = np.array(rows, np.float64).reshape(-1, _WIDTH)  # NULL → NaN
    return Buckets(origin, width, a[:, 0].astype(np.int64), a[:, 1].astype(np.int64),
                   a[:, 2:5], a[:, 5:8], a[:, 8:11], a[:, 11].astype(np.int64),
                   a[:, 12:12 + _NS], a[:, 12 + _NS:].astype(np.int64))


def _merge(parts: list[Buckets], origin: int, width: int) -> Buckets:
    parts = [p for p in parts if p.k.size]
    if not parts:
        return _buckets_from_rows([], origin, width)
    k = np.concatenate([p.k for p in parts])
    uk, inv = np.unique(k, return_inverse=True)
    m = uk.size

    def total(name: str) -> np.ndarray:
        cols = np.concatenate([getattr(p, name) for p in parts])
        out = np.zeros((m, *cols.shape[1:]), cols.dtype)
        np.add.at(out, inv, cols)
        return out

    mins = np.full((m, 3), np.nan)
    maxs = np.full((m, 3), np.nan)
    np.fmin.at(mins, inv, np.concatenate([p.mins for p in parts]))  # NaN: no value
    np.fmax.at(maxs, inv, np.concatenate([p.maxs for p in parts]))
    return Buckets(origin, width, uk, total("n"), total("sums"), mins, maxs, total("n_vi"),
                   total("sensor_sums"), total("sensor_n"))


def bucket_grid(start: int, end: int, max_points: int, phase: int) -> tuple[int, int]:
    """``(origin_s, width_s)`` of at most ``max_points`` buckets over ``[start, end)``.

    Widths of an hour or more are whole hours on the rollup grid (so the rollups
    answer); shorter widths group the raw rows, starting at ``start``.
    """
    width = max(1, math.ceil((end - start) / max_points))
    if width < ROLLUP_WIDTH_S:
        return start, width
    origin = grid_floor(start, phase)  # buckets from here: at most max_points of them
    return origin, ROLLUP_WIDTH_S * math.ceil((end - origin) / max_points / ROLLUP_WIDTH_S)


def _buckets_of(conn: Connection, array_id: int, source: int, start: int, end: int,
                origin: int, width: int, phase: int) -> Buckets:
    """The buckets of :func:`bucket_grid`'s ``(origin, width)`` over ``[start, end)``: raw
    rows grouped for widths under an hour, else the rollups of the whole hours and the raw
    rows of the partial hours at the edges."""
    if width < ROLLUP_WIDTH_S:
        rows = fetch(conn, _RAW_BUCKETS, (origin, width, array_id, source, start, end))
        return _buckets_from_rows(rows, origin, width)
    a, b = grid_ceil(start, phase), grid_floor(end, phase)
    parts: list[Buckets] = []
    if a < b:
        rows = fetch(conn, _ROLLUP_BUCKETS, (origin, width, array_id, source, a, b))
        parts.append(_buckets_from_rows(rows, origin, width))
    for lo, hi in ((start, min(a, end)), (max(b, start), end)):
        if lo < hi and not (a < b and lo == a):
            rows = fetch(conn, _RAW_BUCKETS, (origin, width, array_id, source, lo, hi))
            parts.append(_buckets_from_rows(rows, origin, width))
    return _merge(parts, origin, width)


def downsample(conn: Connection, array_id: int, source: int, start: int, end: int,
               max_points: int, phase: int) -> Buckets:
    """Aggregate ``[start, end)`` into at most ``max_points`` buckets (min/mean/max) of
    :func:`bucket_grid`."""
    origin, width = bucket_grid(start, end, max_points, phase)
    return _buckets_of(conn, array_id, source, start, end, origin, width, phase)


def bucket_pages(engine: Engine, array_id: int, source: int, start: int, end: int,
                 max_points: int, phase: int, page_buckets: int = 20_000) -> Iterator[Buckets]:
    """:func:`downsample` of ``[start, end)`` in pages of at most ``page_buckets`` buckets
    (cut at bucket edges, so every bucket is whole in one page), each read on a connection
    of its own, as :func:`raw_pages` does for raw rows: a streamed export holds one page at
    a time (a year of minutes as 492,750 buckets, ``max_points=500000``, had taken the
    service from 262 to 745 MB; raw, streamed, 316 MB)."""
    origin, width = bucket_grid(start, end, max_points, phase)
    lo = start
    while lo < end:
        hi = min(end, origin + ((lo - origin) // width + page_buckets) * width)
        with engine.connect() as conn:
            page = _buckets_of(conn, array_id, source, lo, hi, origin, width, phase)
        if page.k.size:
            yield page
        lo = hi


# ---------------------------------------------------------------- energy


def _first_instant(wall: dt.datetime) -> dt.datetime:
    """A local midnight (or o'clock) as the instant it is, in the wall clock's own terms:
    where a clock change skips it (Santiago, 6 Sep 2026) the day begins at 01:00−03:00,
    which is how it is labelled (it read 00:00−04:00, a time that does not exist there)."""
    return wall.astimezone(dt.UTC).astimezone(wall.tzinfo)


def period_edges(start: dt.datetime, end: dt.datetime, interval: str,
                 zone: ZoneInfo) -> list[dt.datetime]:
    """Edges of local calendar hours, days or months that cover ``[start, end)``, clipped."""
    local = start.astimezone(zone)
    if interval == "hour":
        cur = local.replace(minute=0, second=0, microsecond=0)
    elif interval == "day":
        cur = local.replace(hour=0, minute=0, second=0, microsecond=0)
    else:
        cur = local.replace(day=1, hour=0, minute=0, second=0, microsecond=0)
    edges = [start]
    guard = 0
    while guard < 200_000:
        guard += 1
        if interval == "hour":
            # the next local o'clock: an hour on, floored to the wall clock's hour (after
            # Lord Howe's 30-minute change every hour fell on :30, one across midnight);
            # a floor that falls back to where it started (a repeated half hour) keeps
            # the hour on
            utc = cur.astimezone(dt.UTC) + dt.timedelta(hours=1)
            nxt = utc.astimezone(zone)
            floor = _first_instant(nxt.replace(minute=0, second=0, microsecond=0))
            cur = floor if floor.astimezone(dt.UTC) > cur.astimezone(dt.UTC) else nxt
        elif interval == "day":
            d = cur.date() + dt.timedelta(days=1)
            cur = _first_instant(dt.datetime(d.year, d.month, d.day, tzinfo=zone))
        else:
            y, m = (cur.year + 1, 1) if cur.month == 12 else (cur.year, cur.month + 1)
            cur = _first_instant(dt.datetime(y, m, 1, tzinfo=zone))
        if cur >= end:
            break
        if cur > start:
            edges.append(cur)
    edges.append(end)
    return edges


def _rollup_periods(conn: Connection, array_ids: list[int], edges_s: np.ndarray, phase: int,
                    a: int, b: int, energy: dict[tuple[int, int], np.ndarray],
                    counts: dict[tuple[int, int], np.ndarray]) -> None:
    """Add the whole rollup buckets in ``[a, b)`` to each period's energy and readings.

    A bucket counts in the period that holds all of it: one that a period edge off the
    bucket grid cuts is left to the raw readings (:func:`energy_table`). The sums are the
    database's: one
    row per series and period comes back (a month per day, two arrays: 120 rows, not
    the 2,880 hourly rollups), so a read hands few rows through the driver, each of
    which the reading thread takes the GIL back for.
    """
    edges = np.asarray(edges_s, np.int64)
    lo = np.clip(grid_ceil(edges[:-1], phase), a, b)
    hi = np.clip(grid_floor(edges[1:], phase), a, b)
    in_range = np.flatnonzero(hi > lo)
    ids = ", ".join("?" * len(array_ids))
    for k in range(0, in_range.size, PERIODS_PER_QUERY):
        part = in_range[k:k + PERIODS_PER_QUERY]
        sql = _ROLLUP_PERIODS.format(more=", (?, ?, ?)" * (part.size - 1), ids=ids)
        params = np.column_stack([part, lo[part], hi[part]]).ravel().tolist()
        for array_id, source, p, wh, n in fetch(conn, sql, (*params, *array_ids)):
            energy[(array_id, source)][p] += wh
            counts[(array_id, source)][p] += n


@dataclass
class EnergyTable:
    """Energy [Wh] and reading counts per (array, source, period)."""

    edges_s: np.ndarray
    energy_wh: dict[tuple[int, int], np.ndarray]
    readings: dict[tuple[int, int], np.ndarray]


def energy_table(conn: Connection, array_ids: list[int], edges_s: np.ndarray, phase: int,
                 max_gap_s: int) -> EnergyTable:
    """Energy per period for every array and source; periods ``[edges[i], edges[i+1])``."""
    nper = edges_s.size - 1
    start, end = int(edges_s[0]), int(edges_s[-1])
    keys = [(a, s) for a in array_ids for s in (0, 1)]
    energy = {key: np.zeros(nper) for key in keys}
    counts = {key: np.zeros(nper, np.int64) for key in keys}
    a, b = grid_ceil(start, phase), grid_floor(end, phase)
    if a < b and array_ids:  # a camera site has none (and "IN ()" is no SQL for PostgreSQL)
        _rollup_periods(conn, array_ids, edges_s, phase, a, b, energy, counts)
    # partial hours: before the first and after the last whole rollup bucket, and the
    # bucket around each period edge off the bucket grid (an unaligned start or end; the
    # local midnight of a zone whose offset from the hour moved since the grid was set,
    # Lord Howe's 30-minute DST or Caracas before 2016: its days were split at the hour)
    ends = [(start, min(a, end)), (max(b, start), end)] if a < b else [(start, end)]
    inner = np.asarray(edges_s[1:-1], np.int64)
    off = inner[(inner - phase) % ROLLUP_WIDTH_S != 0]
    pieces: list[tuple[int, int]] = []
    for lo, hi in sorted(ends + [(max(start, int(grid_floor(e, phase))),
                                  min(end, int(grid_ceil(e, phase)))) for e in off]):
        if pieces and lo <= pieces[-1][1]:  # overlapping or touching: one piece
            pieces[-1] = (pieces[-1][0], max(pieces[-1][1], hi))
        else:
            pieces.append((lo, hi))
    for lo, hi in pieces:
        if lo >= hi:
            continue
        for key in keys:
            rows = fetch(conn, _RAW, (key[0], key[1], lo - max_gap_s, hi + max_gap_s))
            if not rows:
                continue
            r = np.array(rows, np.float64)
            inner = edges_s[(edges_s > lo) & (edges_s < hi)]
            cuts = np.concatenate([[lo], inner, [hi]])
            # every cut in one pass (a piece of months cut at every hour cost rows × cuts:
            # 73 s for Lord Howe's standard-time half year of hours, the reviewer measured)
            period = np.searchsorted(edges_s, cuts[:-1], side="right") - 1
            np.add.at(energy[key], period,
                      energy_per_period_wh(r[:, 0], r[:, 3], max_gap_s, cuts))
            np.add.at(counts[key], period, np.diff(np.searchsorted(r[:, 0], cuts, "left")))
    return EnergyTable(edges_s, energy, counts)


_TS = "SELECT ts_s FROM measurements WHERE array_id = ? AND source = ? AND ts_s >= ? AND ts_s < ?"
_TS_POWER = ("SELECT ts_s, power_w FROM measurements WHERE array_id = ? AND source = ? "
             "AND ts_s >= ? AND ts_s < ? ORDER BY ts_s")


def matched_twin_wh(conn: Connection, array_id: int, edges_s: np.ndarray,
                    max_gap_s: int, periods: np.ndarray | None = None) -> np.ndarray:
    """Twin energy [Wh] per period over only the minutes with a measured reading.

    The twin's minute readings that have a measured reading in the same minute,
    integrated by the energy rule (:func:`sim.energy.energy_wh`, gaps over
    ``max_gap_s`` not bridged, as the measured energy): the twin over the same
    minutes as the logger, so a half-day of readings meets a half-day of twin.
    Only the ``periods`` asked for (indices; all by default) are computed, each run
    of consecutive ones with two primary-key range reads matched in NumPy (a join on
    the minute let PostgreSQL pick a nested loop of minutes over a month); the
    others are 0.
    """
    out = np.zeros(edges_s.size - 1)
    asked = np.arange(out.size) if periods is None else np.asarray(periods, np.int64)
    if asked.size == 0:
        return out
    breaks = np.flatnonzero(np.diff(asked) > 1) + 1
    for run in np.split(asked, breaks):
        first, last = int(run[0]), int(run[-1])
        lo, hi = int(edges_s[first]) - max_gap_s, int(edges_s[last + 1]) + max_gap_s
        measured = np.array(fetch(conn, _TS, (array_id, 0, lo, hi + 60)), np.int64).reshape(-1)
        if measured.size < 2:
            continue
        twin = np.array(fetch(conn, _TS_POWER, (array_id, 1, lo, hi)), np.float64).reshape(-1, 2)
        r = twin[np.isin(twin[:, 0].astype(np.int64), measured // 60 * 60)]
        if len(r) < 2:
            continue
        lo_i = np.searchsorted(r[:, 0], edges_s[run] - max_gap_s)
        hi_i = np.searchsorted(r[:, 0], edges_s[run + 1] + max_gap_s)
        for k, p in enumerate(run):
            if hi_i[k] - lo_i[k] >= 2:
                part = r[lo_i[k]:hi_i[k]]
                out[p] = energy_wh(part[:, 0], part[:, 1], max_gap_s, float(edges_s[p]),
                                   float(edges_s[p + 1]))
    return out


def _covered(reading_s: np.ndarray, t_s: np.ndarray, max_gap_s: int) -> np.ndarray:
    """Which instants ``t_s`` a logger's readings (sorted) cover by the energy rule: at a
    reading, or between two readings at most ``max_gap_s`` apart."""
    if reading_s.size == 0:
        return np.zeros(t_s.size, bool)
    i = np.searchsorted(reading_s, t_s, side="right")  # the first reading after each instant
    before = reading_s[np.maximum(i - 1, 0)]
    after = reading_s[np.minimum(i, reading_s.size - 1)]
    at = (i > 0) & (before == t_s)
    between = (i > 0) & (i < reading_s.size) & (after - before <= max_gap_s)
    return at | between


def shared_minutes_wh(conn: Connection, array_ids: Sequence[int], edges_s: np.ndarray,
                      max_gap_s: int, periods: np.ndarray
                      ) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Per array of ``array_ids`` (two loggers) and period: its twin's energy [Wh] over the
    minutes its own readings cover, and over the minutes *every* logger's readings cover
    (covered: by the energy rule, :func:`_covered`). Equal for each array when the loggers
    read the same minutes (:func:`sim.energy.same_minutes`), whatever their cadences or
    phases. Only ``periods`` (indices) are computed, each run of consecutive ones with a
    range read of each series; the others are 0."""
    out = {aid: (np.zeros(edges_s.size - 1), np.zeros(edges_s.size - 1)) for aid in array_ids}
    periods = np.asarray(periods, np.int64)
    if periods.size == 0:
        return out
    for run in np.split(periods, np.flatnonzero(np.diff(periods) > 1) + 1):
        first, last = int(run[0]), int(run[-1])
        lo, hi = int(edges_s[first]) - max_gap_s, int(edges_s[last + 1]) + max_gap_s
        readings = {aid: np.sort(np.array(fetch(conn, _TS, (aid, 0, lo, hi + 60)),
                                          np.int64).reshape(-1)) for aid in array_ids}
        edges = edges_s[first:last + 2]
        for aid in array_ids:
            twin = np.array(fetch(conn, _TS_POWER, (aid, 1, lo, hi)), np.float64).reshape(-1, 2)
            if len(twin) < 2:
                continue
            t = twin[:, 0].astype(np.int64)
            covered = {a: _covered(r, t, max_gap_s) for a, r in readings.items()}
            shared = np.logical_and.reduce(list(covered.values()))
            # the twin's minutes kept are integrated minute to minute (60 s: a hole in the
            # coverage is no gap to bridge)
            for k, mask in enumerate((covered[aid], shared)):
                out[aid][k][first:last + 1] = energy_per_period_wh(
                    twin[:, 0], np.where(mask, twin[:, 1], np.nan), 60, edges)
    return out
