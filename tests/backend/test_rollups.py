"""Rollups and the energy rule (``measurements/rollups.py``) against a dense integration."""

from __future__ import annotations

import numpy as np
import pytest

from backend.measurements.rollups import (
    SeriesWindow,
    affected_runs,
    energy_per_bucket,
    increment_rows,
    integrate_clipped_wh,
    rollup_rows,
)


def _series(seed: int, n: int = 400) -> SeriesWindow:
    rng = np.random.default_rng(seed)
    ts = np.cumsum(rng.integers(20, 200, n)).astype(np.int64) + 1_000_000
    ts[150:] += 2000  # one long gap
    p = 500 * rng.random(n)
    return SeriesWindow(ts, np.full(n, 25.0), p / 25.0, p)


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
    assert integrate_clipped_wh(w.ts_s, w.power_w, 1_003_000, 1_030_000, 600) == pytest.approx(
        _dense_wh(w, 1_003_000, 1_030_000, 600), rel=1e-9)


def _merge(stored: dict, incs: list) -> None:
    """Apply increments as the writer's SQL upsert does."""
    for inc in incs:
        b = inc[0]
        if b not in stored:
            stored[b] = list(inc)
            continue
        s = stored[b]
        s[1:6] = [x + y for x, y in zip(s[1:6], inc[1:6], strict=True)]
        s[6:9] = [min(x, y) for x, y in zip(s[6:9], inc[6:9], strict=True)]
        s[9:12] = [max(x, y) for x, y in zip(s[9:12], inc[9:12], strict=True)]
        s[12], s[13] = min(s[12], inc[12]), max(s[13], inc[13])


def _part(w: SeriesWindow, sel: slice | np.ndarray) -> SeriesWindow:
    return SeriesWindow(*(a[sel] for a in (w.ts_s, w.voltage_v, w.current_a, w.power_w)))


@pytest.mark.parametrize("hole", [(250, 400), (0, 120), (100, 103), (140, 160), (399, 400),
                                  (0, 1), (148, 152), (10, 15)])
def test_increments_equal_a_recomputation(hole: tuple[int, int]) -> None:
    """Fill a hole (or the end, or the start) of a series: merged increments = recomputed.

    Holes of up to ``SMALL`` readings take the plain-Python path, longer ones NumPy's.
    """
    w = _series(2)
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
        assert stored[r[0]] == pytest.approx(list(r), rel=1e-9, abs=1e-9)


def test_affected_runs_cover_the_neighbours() -> None:
    assert affected_runs(np.array([7200 + 100]), 0, 600) == [(1, 2)]
    assert affected_runs(np.array([7200 + 1800]), 0, 600) == [(2, 2)]
    assert affected_runs(np.array([3600 + 3500, 36000]), 0, 600) == [(1, 2), (9, 10)]
