"""Hourly rollups of a measurement series and the energy rule.

Energy is the trapezoid integral of ``power_w`` over time between consecutive
readings of one series (array and source). Two readings further apart than
``max_gap_s`` are not bridged: that interval adds nothing, so a logger outage
shows as missing energy instead of an invented straight line. An interval that
crosses a bucket edge is split there, with the power at the edge interpolated
linearly, so hourly buckets add up exactly to the integral over any range made
of whole buckets.

The rule itself is :mod:`sim.energy` (:func:`sim.energy.trapezoid_wh`, the one
energy rule of the product), used by every path here and by queries; the bucket
grid is :mod:`backend.measurements.buckets`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from backend.measurements.buckets import ROLLUP_WIDTH_S, bucket_index
from backend.measurements.fields import SENSOR_NAMES
from sim.energy import energy_per_period_wh, trapezoid_wh

#: A rollup row. ``n`` counts readings, ``n_vi`` those with voltage and current (the
#: others are power-only), ``n_<sensor>`` those with that sensor field; sums over
#: the readings that have the value, extremes NULL (NaN here) when none has it.
ROLLUP_COLUMNS = (
    "bucket_s", "n", "energy_wh",
    "sum_voltage_v", "sum_current_a", "sum_power_w",
    "min_voltage_v", "min_current_a", "min_power_w",
    "max_voltage_v", "max_current_a", "max_power_w",
    "first_ts_s", "last_ts_s", "n_vi",
    *(f"sum_{f}" for f in SENSOR_NAMES), *(f"n_{f}" for f in SENSOR_NAMES),
)
#: Columns a merge of increments adds up.
ROLLUP_SUMMED = tuple(c for c in ROLLUP_COLUMNS[1:]
                      if c.startswith(("n", "sum_")) or c == "energy_wh")
_NS = len(SENSOR_NAMES)


def affected_runs(
    ts_s: np.ndarray, phase_s: int, max_gap_s: int, width_s: int = ROLLUP_WIDTH_S
) -> list[tuple[int, int]]:
    """Runs ``(k_first, k_last)`` of buckets whose rollup new readings at ``ts_s`` can change.

    A reading at ``t`` changes the intervals to its neighbours, which lie within
    ``max_gap_s`` of ``t`` when they count at all (``max_gap_s <= width_s``).
    """
    ts = np.asarray(ts_s, np.int64)
    ks = np.unique(np.concatenate([
        bucket_index(ts - max_gap_s, phase_s, width_s),
        bucket_index(ts, phase_s, width_s),
        bucket_index(ts + max_gap_s, phase_s, width_s),
    ]))
    if ks.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(ks) > 1)
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks, [ks.size - 1]])
    return [(int(ks[a]), int(ks[b])) for a, b in zip(starts, ends, strict=True)]


@dataclass
class SeriesWindow:
    """Readings of one series over a window, sorted by time (NaN: no value)."""

    ts_s: np.ndarray
    voltage_v: np.ndarray
    current_a: np.ndarray
    power_w: np.ndarray
    #: ``(n, len(SENSOR_NAMES))`` sensor values, or None when no reading has any
    sensors: np.ndarray | None = None

    def part(self, sel: slice) -> SeriesWindow:
        """The readings ``sel`` of the window."""
        return SeriesWindow(self.ts_s[sel], self.voltage_v[sel], self.current_a[sel],
                            self.power_w[sel], None if self.sensors is None else self.sensors[sel])


def energy_per_bucket(
    w: SeriesWindow, k_first: int, k_last: int, phase_s: int, max_gap_s: int,
    width_s: int = ROLLUP_WIDTH_S,
) -> np.ndarray:
    """Energy [Wh] of buckets ``k_first..k_last`` from the readings in ``w``.

    ``w`` must hold every reading in ``[start(k_first) − max_gap_s, end(k_last) + max_gap_s]``.
    """
    edges = phase_s + width_s * np.arange(k_first, k_last + 2, dtype=np.float64)
    return energy_per_period_wh(w.ts_s, w.power_w, max_gap_s, edges)


def _stats(
    w: SeriesWindow, k_first: int, k_last: int, phase_s: int, width_s: int
) -> tuple[np.ndarray, list[list[float | int]]]:
    """Bucket indices and per-bucket columns (n, sums, mins, maxs, first, last) in a range."""
    k = bucket_index(w.ts_s, phase_s, width_s)
    inside = (k >= k_first) & (k <= k_last)
    if not inside.any():
        return np.zeros(0, np.int64), []
    ki = k[inside]
    ts = w.ts_s[inside]
    cols = [w.voltage_v[inside], w.current_a[inside], w.power_w[inside]]
    uk, first = np.unique(ki, return_index=True)
    counts = np.diff(np.concatenate([first, [ki.size]]))
    last = first + counts - 1
    has_vi = ~np.isnan(cols[0])
    out = [counts.tolist()]
    if has_vi.all():
        out += [np.add.reduceat(c, first).tolist() for c in cols]
    else:  # power-only readings: sums over the others, extremes NaN where none has a value
        out += [np.add.reduceat(np.nan_to_num(c), first).tolist() for c in cols]
    out += [np.fmin.reduceat(c, first).tolist() for c in cols]
    out += [np.fmax.reduceat(c, first).tolist() for c in cols]
    out += [ts[first].tolist(), ts[last].tolist(), np.add.reduceat(has_vi, first).tolist()]
    if w.sensors is None:
        out += [[0.0] * uk.size] * _NS + [[0] * uk.size] * _NS
    else:
        s = w.sensors[inside]
        present = ~np.isnan(s)
        sums = np.add.reduceat(np.where(present, s, 0.0), first, axis=0)
        ns = np.add.reduceat(present.astype(np.int64), first, axis=0)
        out += [sums[:, j].tolist() for j in range(_NS)] + [ns[:, j].tolist() for j in range(_NS)]
    return uk, out


def rollup_rows(
    w: SeriesWindow, k_first: int, k_last: int, phase_s: int, max_gap_s: int,
    width_s: int = ROLLUP_WIDTH_S,
) -> list[tuple[float | int, ...]]:
    """Rollup rows (``ROLLUP_COLUMNS`` order) of the non-empty buckets ``k_first..k_last``."""
    uk, cols = _stats(w, k_first, k_last, phase_s, width_s)
    if uk.size == 0:
        return []
    energy = energy_per_bucket(w, k_first, k_last, phase_s, max_gap_s, width_s)
    return list(zip((uk * width_s + phase_s).tolist(), cols[0],
                    energy[uk - k_first].tolist(), *cols[1:], strict=True))


def increment_rows(
    prev: tuple[int, float] | None, nxt: tuple[int, float] | None, w: SeriesWindow,
    phase_s: int, max_gap_s: int, width_s: int = ROLLUP_WIDTH_S,
) -> list[tuple[float | int, ...]]:
    """Rollup *increments* for readings ``w`` put into a hole of a stored series.

    ``prev``/``nxt`` are ``(ts_s, power_w)`` of the stored readings just before and
    after ``w`` (None at either end of the series); no stored reading lies between
    them. Counts, sums and energy are to be added to the stored rollups (energy:
    the new intervals prev → w → nxt minus the old interval prev → nxt),
    minima/maxima and first/last merged. A bucket that only changes energy gets
    ``n = 0`` and neutral extremes.
    """
    if w.ts_s.size <= SMALL:
        return _increment_rows_small(prev, nxt, w, phase_s, max_gap_s, width_s)
    ends = [p for p in (prev, nxt) if p is not None]
    k_all = bucket_index(np.concatenate([w.ts_s, [e[0] for e in ends]]).astype(np.int64),
                         phase_s, width_s)
    k_first, k_last = int(k_all.min()), int(k_all.max())
    ts = np.concatenate([[prev[0]] if prev else [], w.ts_s, [nxt[0]] if nxt else []])
    pw = np.concatenate([[prev[1]] if prev else [], w.power_w, [nxt[1]] if nxt else []])
    nan = np.full(ts.size, np.nan)
    energy = energy_per_bucket(SeriesWindow(ts.astype(np.int64), nan, nan, pw),
                               k_first, k_last, phase_s, max_gap_s, width_s)
    if prev is not None and nxt is not None:
        old = SeriesWindow(np.array([prev[0], nxt[0]], np.int64), nan[:2], nan[:2],
                           np.array([prev[1], nxt[1]]))
        energy -= energy_per_bucket(old, k_first, k_last, phase_s, max_gap_s, width_s)
    uk, cols = _stats(w, k_first, k_last, phase_s, width_s)
    rows = {int(k): [int(k) * width_s + phase_s, c[0], float(energy[int(k) - k_first]), *c[1:]]
            for k, *c in zip(uk.tolist(), *cols, strict=True)}
    for j in np.flatnonzero(energy).tolist():
        k = k_first + j
        if k not in rows:
            rows[k] = _energy_only_row(k, float(energy[j]), phase_s, width_s)
    return [tuple(rows[k]) for k in sorted(rows)]


SMALL = 8  # at most this many new readings: plain Python beats NumPy's per-call cost


def _interval_wh(t0: int, p0: float, t1: int, p1: float, phase_s: int, max_gap_s: int,
                 width_s: int) -> list[tuple[int, float]]:
    """``(bucket, Wh)`` parts of one interval, split at a bucket edge (as energy_per_bucket)."""
    if t1 - t0 > max_gap_s:
        return []
    k0 = (t0 - phase_s) // width_s
    k1 = (t1 - 1 - phase_s) // width_s
    if k0 == k1:
        return [(k0, trapezoid_wh(t0, p0, t1, p1, t0, t1))]
    b = (k0 + 1) * width_s + phase_s
    return [(k0, trapezoid_wh(t0, p0, t1, p1, t0, b)), (k1, trapezoid_wh(t0, p0, t1, p1, b, t1))]


def _energy_only_row(k: int, energy_wh: float, phase_s: int, width_s: int
                     ) -> list[float | int]:
    """A rollup increment for a bucket whose energy changes but that gains no reading:
    ``n = 0``, neutral sums and extremes, so merging it changes only the energy."""
    nan = float("nan")  # stored as NULL, which a merge ignores
    return [k * width_s + phase_s, 0, energy_wh, 0.0, 0.0, 0.0,
            nan, nan, nan, nan, nan, nan, 2**62, -(2**62), 0, *[0.0] * _NS, *[0] * _NS]


def _fmin(a: float, b: float) -> float:
    """min ignoring NaN (no value) on either side, as the SQL merge."""
    return b if a != a or b < a else a


def _fmax(a: float, b: float) -> float:
    """max ignoring NaN (no value) on either side, as the SQL merge."""
    return b if a != a or b > a else a


def _increment_rows_small(
    prev: tuple[int, float] | None, nxt: tuple[int, float] | None, w: SeriesWindow,
    phase_s: int, max_gap_s: int, width_s: int,
) -> list[tuple[float | int, ...]]:
    """:func:`increment_rows` for a few readings, in plain Python."""
    ts = w.ts_s.tolist()
    vs, cs, ps = w.voltage_v.tolist(), w.current_a.tolist(), w.power_w.tolist()
    pts = ([prev] if prev else []) + list(zip(ts, ps, strict=True)) + ([nxt] if nxt else [])
    energy: dict[int, float] = {}
    for (t0, p0), (t1, p1) in zip(pts[:-1], pts[1:], strict=True):
        for k, e in _interval_wh(t0, p0, t1, p1, phase_s, max_gap_s, width_s):
            energy[k] = energy.get(k, 0.0) + e
    if prev is not None and nxt is not None:
        for k, e in _interval_wh(prev[0], prev[1], nxt[0], nxt[1], phase_s, max_gap_s, width_s):
            energy[k] = energy.get(k, 0.0) - e
    rows: dict[int, list[float | int]] = {}
    sensors = w.sensors.tolist() if w.sensors is not None else [None] * len(ts)
    for t, v, c, p, sv in zip(ts, vs, cs, ps, sensors, strict=True):
        k = (t - phase_s) // width_s
        r = rows.get(k)
        if r is None:
            r = rows[k] = [k * width_s + phase_s, 0, 0.0, 0.0, 0.0, 0.0, v, c, p, v, c, p, t, t,
                           0, *[0.0] * _NS, *[0] * _NS]
        else:
            r[6], r[7], r[8] = _fmin(r[6], v), _fmin(r[7], c), min(r[8], p)
            r[9], r[10], r[11] = _fmax(r[9], v), _fmax(r[10], c), max(r[11], p)
            r[12], r[13] = min(r[12], t), max(r[13], t)
        r[1] += 1
        r[5] += p
        if v == v:  # not a power-only reading
            r[3] += v
            r[4] += c
            r[14] += 1
        if sv is not None:
            for j, x in enumerate(sv):
                if x == x:
                    r[15 + j] += x
                    r[15 + _NS + j] += 1
    for k, e in energy.items():
        if e == 0.0:
            continue
        r = rows.get(k)
        if r is None:
            rows[k] = _energy_only_row(k, e, phase_s, width_s)
        else:
            r[2] = e
    return [tuple(rows[k]) for k in sorted(rows)]
