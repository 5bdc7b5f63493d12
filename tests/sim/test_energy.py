"""The energy rule (``sim/energy.py``) against independent integrations.

The references are NumPy's own ``trapezoid`` and ``interp`` on the segments the gap
rule keeps, and a dense one-second sampling of the piecewise-linear power: neither
uses the code under test.
"""

from __future__ import annotations

import numpy as np
import pytest

from sim.energy import energy_wh, gain_pct, interval_middles, on_grid


def _irregular(seed: int, n: int = 300) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    ts = 1_000_000 + np.cumsum(rng.integers(30, 1000, n)).astype(np.float64)
    return ts, 800.0 * rng.random(n)


def _segments(ts: np.ndarray, max_gap_s: float) -> list[slice]:
    cuts = np.flatnonzero(np.diff(ts) > max_gap_s) + 1
    bounds = np.concatenate([[0], cuts, [ts.size]])
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


@pytest.mark.parametrize("seed", range(4))
def test_whole_series_is_numpy_trapezoid_of_each_unbroken_run(seed: int) -> None:
    ts, p = _irregular(seed)
    want = sum(np.trapezoid(p[s], ts[s]) for s in _segments(ts, 600.0)) / 3600.0
    assert energy_wh(ts, p, 600.0) == pytest.approx(want, rel=1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_clipped_ranges_match_dense_sampling_and_add_up(seed: int) -> None:
    ts, p = _irregular(seed, 120)
    lo, mid, hi = ts[5] + 17.0, ts[60] + 0.5 * (ts[61] - ts[60]), ts[110] - 3.0
    dense_t = np.arange(lo, hi, 0.25)
    dense_p = np.interp(dense_t, ts, p)
    k = np.searchsorted(ts, dense_t, side="right")
    dense_p[(ts[k] - ts[k - 1]) > 600.0] = 0.0  # inside an unbridged gap
    want = np.sum(dense_p) * 0.25 / 3600.0
    got = energy_wh(ts, p, 600.0, lo, hi)
    assert got == pytest.approx(want, rel=2e-4)
    assert energy_wh(ts, p, 600.0, lo, mid) + energy_wh(ts, p, 600.0, mid, hi) \
        == pytest.approx(got, rel=1e-12)


def test_nan_readings_are_dropped_not_read_as_zero() -> None:
    ts = np.array([0.0, 60.0, 120.0, 180.0])
    p = np.array([100.0, np.nan, 100.0, 100.0])
    assert energy_wh(ts, p, 600.0) == pytest.approx(100.0 * 180.0 / 3600.0)
    assert energy_wh(ts, p, 100.0) == pytest.approx(100.0 * 60.0 / 3600.0)  # 0→120 too long


@pytest.mark.parametrize("cadence_s", [60, 120, 300, 900])
def test_energy_of_a_day_does_not_depend_on_cadence(cadence_s: int) -> None:
    """A smooth day sampled at any cadence: within the trapezoid's own error of the
    1-minute energy (a half-sine of 12 h; the error bound is L³·max|p''|/12 per hour)."""
    day = 86400.0
    t1 = np.arange(0.0, day + 1, 60.0)

    def power(t: np.ndarray) -> np.ndarray:
        return np.clip(900.0 * np.sin(np.pi * (t - 6 * 3600) / (12 * 3600)), 0.0, None)

    ref = energy_wh(t1, power(t1), 1200.0)
    tc = np.arange(0.0, day + 1, float(cadence_s))
    assert energy_wh(tc, power(tc), 1200.0) == pytest.approx(ref, rel=1e-3)
    assert ref == pytest.approx(900.0 * 12 * 2 / np.pi, rel=1e-4)  # ∫ half-sine [Wh]


def test_on_grid_is_numpy_interp_within_the_gap_and_nan_outside() -> None:
    ts, p = _irregular(7, 200)
    grid = np.arange(ts[0] - 300.0, ts[-1] + 300.0, 60.0)
    got = on_grid(ts, p, grid, 600.0)
    want = np.interp(grid, ts, p, left=np.nan, right=np.nan)
    k = np.clip(np.searchsorted(ts, grid, side="right"), 1, ts.size - 1)
    on_reading = np.isin(grid, ts)
    want[((ts[k] - ts[k - 1]) > 600.0) & ~on_reading] = np.nan
    np.testing.assert_allclose(got, want, rtol=1e-12, equal_nan=True)
    assert np.isnan(got).any() and np.isfinite(got).any()


def test_on_grid_then_energy_is_the_series_energy_when_the_grid_holds_every_reading() -> None:
    ts = np.array([0.0, 300.0, 600.0, 1500.0, 3300.0, 3600.0, 3900.0])  # one 30-min gap
    p = np.array([0.0, 200.0, 400.0, 500.0, 300.0, 100.0, 0.0])
    grid = np.arange(0.0, 3901.0, 60.0)
    g = on_grid(ts, p, grid, 1200.0)
    assert energy_wh(grid, g, 1200.0) == pytest.approx(energy_wh(ts, p, 1200.0), rel=1e-12)
    assert np.isnan(g[(grid > 1500.0) & (grid < 3300.0)]).all()


def test_on_grid_columns_are_independent_series() -> None:
    ts = np.array([0.0, 60.0, 120.0])
    v = np.array([[1.0, 10.0], [np.nan, 20.0], [3.0, 30.0]])
    got = on_grid(ts, v, np.array([0.0, 30.0, 60.0, 90.0]), 600.0)
    np.testing.assert_allclose(got, [[1.0, 10.0], [1.5, 15.0], [2.0, 20.0], [2.5, 25.0]])


def test_gain() -> None:
    assert gain_pct(1280.0, 1000.0) == pytest.approx(28.0)
    assert gain_pct(None, 1000.0) is None
    assert gain_pct(1000.0, 0.0) is None
    assert gain_pct(1000.0, float("nan")) is None
    # per watt of rating: a 1,640 W tracker making 2,560 Wh beside an 820 W fixed array's
    # 1,000 Wh gains 28 % (each watt 1.5610 Wh against 1.2195 Wh), not 156 %
    assert gain_pct(2560.0, 1000.0, (1640.0, 820.0)) == pytest.approx(28.0, rel=1e-12)
    assert gain_pct(1280.0, 1000.0, (820.0, 820.0)) == gain_pct(1280.0, 1000.0)  # exactly


def test_interval_middles_put_each_mean_at_its_intervals_middle() -> None:
    """sim.energy.interval_middles: instants stay; a mean stamped at its interval's end
    moves back half the spacing to the reading before, one stamped at the start forward
    half the spacing to the one after; across a gap longer than max_gap_s (and for the
    first or last reading) the series' median spacing stands in."""
    ts = np.array([0.0, 3600.0, 7200.0, 10800.0, 30000.0, 33600.0])
    assert np.array_equal(interval_middles(ts, "instant", 3600), ts)
    np.testing.assert_allclose(interval_middles(ts, "interval_end", 3600),
                               [-1800, 1800, 5400, 9000, 28200, 31800])
    np.testing.assert_allclose(interval_middles(ts, "interval_start", 3600),
                               [1800, 5400, 9000, 12600, 31800, 35400])
    assert interval_middles(ts[:1], "interval_end", 3600).tolist() == [0.0]
    with pytest.raises(ValueError, match="stamped"):
        interval_middles(ts, "middle", 3600)
    # the site format offers exactly these (sim.site_config.SiteConfig.readings_stamped)
    from typing import get_args

    from sim.energy import READING_STAMPS
    from sim.site_config import SiteConfig

    assert get_args(SiteConfig.model_fields["readings_stamped"].annotation) == READING_STAMPS
