"""Rollups and the energy rule (``measurements/rollups.py``) against a dense integration."""

from __future__ import annotations

import numpy as np
import pytest

from backend.measurements.fields import SENSOR_NAMES
from backend.measurements.rollups import (
    ROLLUP_COLUMNS,
    ROLLUP_SUMMED,
    SeriesWindow,
    affected_runs,
    energy_per_bucket,
    increment_rows,
    rollup_rows,
)
from sim.energy import energy_wh


def _series(seed: int, n: int = 400, mixed: bool = False) -> SeriesWindow:
    """A series with one long gap; ``mixed``: a third of the readings power-only and
    sensor fields present on a random half of the readings, each field apart."""
    rng = np.random.default_rng(seed)
    ts = np.cumsum(rng.integers(20, 200, n)).astype(np.int64) + 1_000_000
    ts[150:] += 2000  # one long gap
    p = 500 * rng.random(n)
    v, i = np.full(n, 25.0) + rng.random(n), p / 25.0
    if not mixed:
        return SeriesWindow(ts, v, i, p)
    power_only = rng.random(n) < 1 / 3
    v[power_only] = i[power_only] = np.nan
    sensors = 100 * rng.random((n, len(SENSOR_NAMES)))
    sensors[rng.random(sensors.shape) < 0.5] = np.nan
    return SeriesWindow(ts, v, i, p, sensors)


def _dense_wh(w: SeriesWindow, t0: float, t1: float, max_gap_s: float) -> float:
    """Sample the piecewise-linear power every second, skipping long gaps, and sum."""
    total = 0.0
    for a, b, pa, pb in zip(w.ts_s[:-1], w.ts_s[1:], w.power_w[:-1], w.power_w[1:], strict=True):
        if b - a > max_gap_s:
            continue
        lo, hi = max(a, t0), min(b, t1)
        if hi <= lo:
            continue
        grid = np.linspace(lo, hi, int(hi - lo) * 4 + 1)
        total += float(np.trapezoid(np.interp(grid, [a, b], [pa, pb]), grid))
    return total / 3600


@pytest.mark.parametrize("phase", [0, 1800, 2700])
def test_buckets_add_up_to_the_dense_integral(phase: int) -> None:
    w = _series(1)
    k0 = (int(w.ts_s[0]) - phase) // 3600
    k1 = (int(w.ts_s[-1]) - phase) // 3600
    e = energy_per_bucket(w, k0, k1, phase, 600)
    for j, k in enumerate(range(k0, k1 + 1)):
        lo, hi = k * 3600 + phase, (k + 1) * 3600 + phase
        assert e[j] == pytest.approx(_dense_wh(w, lo, hi, 600), rel=1e-9, abs=1e-9)
    assert energy_wh(w.ts_s, w.power_w, 600, 1_003_000, 1_030_000) == pytest.approx(
        _dense_wh(w, 1_003_000, 1_030_000, 600), rel=1e-9)


def _merge(stored: dict, incs: list) -> None:
    """Apply increments as the writer's SQL upsert does (NaN: NULL, ignored by extremes)."""
    col = {c: j for j, c in enumerate(ROLLUP_COLUMNS)}
    for inc in incs:
        b = inc[0]
        if b not in stored:
            stored[b] = list(inc)
            continue
        s = stored[b]
        for c in ROLLUP_SUMMED:
            s[col[c]] += inc[col[c]]
        for c, j in col.items():
            if c.startswith(("min_", "max_")):
                s[j] = (np.fmin if c.startswith("min_") else np.fmax)(s[j], inc[j])
        s[col["first_ts_s"]] = min(s[col["first_ts_s"]], inc[col["first_ts_s"]])
        s[col["last_ts_s"]] = max(s[col["last_ts_s"]], inc[col["last_ts_s"]])


def _part(w: SeriesWindow, sel: slice | np.ndarray) -> SeriesWindow:
    return SeriesWindow(*(a[sel] for a in (w.ts_s, w.voltage_v, w.current_a, w.power_w)),
                        None if w.sensors is None else w.sensors[sel])


def test_rollups_of_power_only_and_sensor_readings_match_direct_aggregates() -> None:
    """Means over the readings that have a value: ``n_vi`` and per-sensor counts and sums,
    extremes of voltage and current over the readings that have them, checked per hour."""
    w = _series(4, mixed=True)
    k0, k1 = int(w.ts_s[0]) // 3600, int(w.ts_s[-1]) // 3600
    col = {c: j for j, c in enumerate(ROLLUP_COLUMNS)}
    rows = rollup_rows(w, k0, k1, 0, 600)
    assert rows
    for r in rows:
        sel = w.ts_s // 3600 * 3600 == r[0]
        vi = sel & ~np.isnan(w.voltage_v)
        assert r[col["n"]] == sel.sum() and r[col["n_vi"]] == vi.sum()
        assert r[col["sum_voltage_v"]] == pytest.approx(w.voltage_v[vi].sum())
        assert r[col["sum_power_w"]] == pytest.approx(w.power_w[sel].sum())
        if vi.any():
            assert r[col["min_current_a"]] == w.current_a[vi].min()
            assert r[col["max_voltage_v"]] == w.voltage_v[vi].max()
        else:
            assert np.isnan(r[col["min_current_a"]]) and np.isnan(r[col["max_voltage_v"]])
        for j, f in enumerate(SENSOR_NAMES):
            has = sel & ~np.isnan(w.sensors[:, j])
            assert r[col[f"n_{f}"]] == has.sum()
            assert r[col[f"sum_{f}"]] == pytest.approx(w.sensors[has, j].sum())
    assert sum(r[col["n_vi"]] for r in rows) < sum(r[col["n"]] for r in rows)  # some power-only


@pytest.mark.parametrize("mixed", [False, True], ids=["vi", "power_only_and_sensors"])
@pytest.mark.parametrize("hole", [(250, 400), (0, 120), (100, 103), (140, 160), (399, 400),
                                  (0, 1), (148, 152), (10, 15)])
def test_increments_equal_a_recomputation(hole: tuple[int, int], mixed: bool) -> None:
    """Fill a hole (or the end, or the start) of a series: merged increments = recomputed.

    Holes of up to ``SMALL`` readings take the plain-Python path, longer ones NumPy's;
    ``mixed`` series hold power-only readings and sensor fields.
    """
    w = _series(2, mixed=mixed)
    a, b = hole
    keep = np.r_[0:a, b:w.ts_s.size]
    have = _part(w, keep)
    new = _part(w, slice(a, b))
    k0 = int(w.ts_s[0]) // 3600
    k1 = int(w.ts_s[-1]) // 3600
    stored = {r[0]: list(r) for r in rollup_rows(have, k0, k1, 0, 600)}
    prev = (int(w.ts_s[a - 1]), float(w.power_w[a - 1])) if a > 0 else None
    nxt = (int(w.ts_s[b]), float(w.power_w[b])) if b < w.ts_s.size else None
    _merge(stored, increment_rows(prev, nxt, new, 0, 600))
    full = rollup_rows(w, k0, k1, 0, 600)
    assert sorted(stored) == [r[0] for r in full]
    for r in full:
        assert stored[r[0]] == pytest.approx(list(r), rel=1e-9, abs=1e-9, nan_ok=True)


def test_affected_runs_cover_the_neighbours() -> None:
    assert affected_runs(np.array([7200 + 100]), 0, 600) == [(1, 2)]
    assert affected_runs(np.array([7200 + 1800]), 0, 600) == [(2, 2)]
    assert affected_runs(np.array([3600 + 3500, 36000]), 0, 600) == [(1, 2), (9, 10)]
