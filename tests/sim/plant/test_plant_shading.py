"""Inter-shading against twoaxistracking and brute-force ray sampling (never against itself)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from plant_reference import sampled_fractions, twoaxistracking_fractions, utc_from_true_solar_time

from sim.plant.layout import load_plant
from sim.plant.shading import (
    FACING,
    FIXED,
    GENERIC,
    BinTable,
    _bin_table,
    band_union_areas,
    collector_axes,
    pair_vectors,
    plant_shade,
    shades_anyone,
    union_area,
)
from sim.sun import solar_position
from vision.sphere import enu_from_sky

PLANT = load_plant("penarroya")
W, H = PLANT.collector.width, PLANT.collector.height


def test_sun_tracking_fractions_equal_twoaxistracking() -> None:
    rng = np.random.default_rng(4)
    az = rng.uniform(45, 315, 60)
    el = rng.uniform(0.5, 35, 60)
    ours = plant_shade(PLANT.positions, az, el, az, el, W, H).fraction
    ref = twoaxistracking_fractions(PLANT.positions, az, el, W, H)
    assert (ref > 0).mean() > 0.2, "the sample must hold shaded collectors"
    # same geometry, exact polygon areas in both: agreement to rounding
    np.testing.assert_allclose(ours, ref, atol=1e-9)


def _instant(day: str, tst_h: float) -> tuple[float, float]:
    t = utc_from_true_solar_time(day, tst_h, PLANT.longitude)
    pos = solar_position(t, PLANT.latitude, PLANT.longitude, PLANT.altitude)
    return float(pos["azimuth"].iloc[0]), float(pos["apparent_elevation"].iloc[0])


@pytest.mark.parametrize(("day", "tst_h", "n_shaded"), [
    ("2021-12-21", 8.4, 23), ("2021-12-21", 15.4, 24),
    ("2021-06-21", 7.5, 0), ("2021-06-21", 15.8, 0),
])
def test_seed_004_instants(day: str, tst_h: float, n_shaded: int) -> None:
    """Seed 004 Fig. 6's instants: who is shaded, and the plant's mean shaded fraction."""
    az, el = _instant(day, tst_h)
    shade = plant_shade(PLANT.positions, [az], [el], [az], [el], W, H)
    ref = twoaxistracking_fractions(PLANT.positions, [az], [el], W, H)[0]
    sampled = sampled_fractions(PLANT.positions, az, el, az, el, W, H)
    assert int(shade.shaded[0].sum()) == n_shaded == int((ref > 0).sum())
    np.testing.assert_array_equal(shade.shaded[0], ref > 0)
    assert shade.fraction[0].mean() == pytest.approx(ref.mean(), abs=1e-12)
    # ray sampling on a 0.1 m grid: within a sample cell's share of the collector
    np.testing.assert_allclose(shade.fraction[0], sampled, atol=1.5e-3)


def test_shaded_by_names_the_sunward_neighbour() -> None:
    az, el = _instant("2021-12-21", 8.4)           # morning: the sun in the south-east
    shade = plant_shade(PLANT.positions, [az], [el], [az], [el], W, H)
    ids = PLANT.tracker_ids
    k = ids.index(8)
    by = [ids[b] for b in shade.shaded_by(0, k)]
    assert by, "tracker 8 is shaded at 08:24"
    for b in by:  # every shading tracker lies towards the sun from tracker 8
        d = PLANT.positions[ids.index(b)] - PLANT.positions[k]
        assert np.degrees(np.arctan2(d[0], d[1])) % 360 == pytest.approx(az, abs=60)


@pytest.mark.parametrize(("n_az", "n_el"), [(150.0, 40.0), (200.0, 25.0), (120.0, 60.0)])
def test_non_sun_orientations_match_ray_sampling(n_az: float, n_el: float) -> None:
    """A common orientation off the sun (backtracking, sky scan): oblique projection."""
    az, el = 135.0, 12.0
    ours = plant_shade(PLANT.positions, [az], [el], [n_az], [n_el], W, H).fraction[0]
    sampled = sampled_fractions(PLANT.positions, az, el, n_az, n_el, W, H)
    np.testing.assert_allclose(ours, sampled, atol=2e-3)
    assert shades_anyone(PLANT.positions, az, el, n_az, n_el, W, H)[0] == bool((ours > 0).any())


def test_union_area_of_overlapping_rectangles() -> None:
    rects = np.array([[[0, 2, 0, 2], [1, 3, 1, 3], [0, 0, 0, 0]]], dtype=float)
    assert union_area(rects)[0] == pytest.approx(7.0)          # 4 + 4 − 1
    assert union_area(rects, clip=[0, 1, 0, 3])[0] == pytest.approx(2.0)


def test_night_is_nan_and_flat_collectors_never_shade() -> None:
    shade = plant_shade(PLANT.positions, [180.0, 100.0], [-5.0, 3.0], [180.0, 100.0],
                        [90.0, 90.0], W, H)
    assert np.isnan(shade.fraction[0]).all()
    assert (shade.fraction[1] == 0).all()
    with pytest.raises(ValueError, match="shape"):
        plant_shade(PLANT.positions[:, :2], [1.0], [1.0], [1.0], [1.0], W, H)


def test_sun_bin_edges_equal_twoaxistracking() -> None:
    """Suns on the corners of the candidate table's bins (1° × 0.5°): no pair is missed."""
    rng = np.random.default_rng(12)
    az = rng.integers(60, 300, 50) + rng.choice([-1e-7, 1e-7], 50)
    el = rng.integers(2, 50, 50) * 0.5 + rng.choice([-1e-7, 1e-7], 50)
    ours = plant_shade(PLANT.positions, az, el, az, el, W, H).fraction
    ref = twoaxistracking_fractions(PLANT.positions, az, el, W, H)
    assert (ref > 0).any(axis=1).mean() > 0.3, "the sample must hold shaded steps"
    np.testing.assert_allclose(ours, ref, atol=1e-9)


@pytest.mark.parametrize(("az", "el"), [(120.0, 4.0), (135.0, 9.0), (240.0, 6.0), (180.0, 13.0),
                                        (105.0, 5.0)])
def test_fixed_tilt_plant_matches_ray_sampling(az: float, el: float) -> None:
    """The fixed comparison plant (one constant orientation: its own candidate bound)."""
    n_az, n_el = PLANT.fixed_azimuth, 90.0 - PLANT.fixed_tilt
    ours = plant_shade(PLANT.positions, [az], [el], [n_az], [n_el], W, H).fraction[0]
    sampled = sampled_fractions(PLANT.positions, az, el, n_az, n_el, W, H)
    np.testing.assert_allclose(ours, sampled, atol=2e-3)
    assert (ours > 0).any() == (sampled > 0).any()


@pytest.mark.parametrize("k", [3, 6, 11])
def test_band_union_areas_equal_shapely(k: int) -> None:
    """Inclusion–exclusion (≤ 8 rectangles) and the edge grid (more) against shapely's union."""
    import shapely

    rng = np.random.default_rng(k)
    lo = rng.uniform(-3, 2, (40, k, 2))
    size = rng.uniform(0.1, 3, (40, k, 2))
    rects = np.stack([lo[..., 0], lo[..., 0] + size[..., 0], lo[..., 1],
                      lo[..., 1] + size[..., 1]], axis=-1)
    rects[::7, -1] = 0.0                                    # some empty slots
    edges = np.array([-2.5, -1.0, 0.5, 4.0])
    ours = band_union_areas(rects, edges)
    for g in range(len(rects)):
        boxes = [shapely.box(r[0], r[2], r[1], r[3]) for r in rects[g] if r[1] > r[0]]
        union = shapely.union_all(boxes)
        for b in range(3):
            band = shapely.box(-10, edges[b], 10, edges[b + 1])
            assert ours[g, b] == pytest.approx(shapely.area(union & band), abs=1e-9)


def test_string_band_areas_equal_shapely_and_sum_to_the_fraction() -> None:
    """``band_edges``: the strings' shaded areas, from the same union as the fraction."""
    import shapely

    rng = np.random.default_rng(21)
    az, el = rng.uniform(60, 300, 40), rng.uniform(1, 30, 40)
    cuts = PLANT.collector.string_boundaries()
    shade = plant_shade(PLANT.positions, az, el, az, el, W, H, band_edges=cuts)
    plain = plant_shade(PLANT.positions, az, el, az, el, W, H)
    assert len(shade.group_step) > 50, "the sample must hold shaded collectors"
    np.testing.assert_allclose(shade.fraction, plain.fraction, atol=1e-12)
    np.testing.assert_array_equal(shade.band_edges, cuts)
    assert shade.group_band_area is not None
    edges = np.concatenate([[-H / 2], cuts, [H / 2]])
    for g in range(0, len(shade.group_step), 7):
        rects = shade.group_rects[g][shade.group_by[g] >= 0]
        union = shapely.union_all([shapely.box(r[0], r[2], r[1], r[3]) for r in rects])
        for s in range(len(edges) - 1):
            band = shapely.box(-W / 2, edges[s], W / 2, edges[s + 1])
            assert shade.group_band_area[g, s] == pytest.approx(
                shapely.area(union & band), abs=1e-9)


def test_a_bin_table_kept_across_calls_changes_nothing() -> None:
    """A run in chunks with one BinTable: the same shade as each chunk on its own."""
    times = pd.date_range("2021-12-20", periods=3 * 144, freq="600s", tz="UTC")
    pos = solar_position(times, PLANT.latitude, PLANT.longitude, PLANT.altitude)
    az, el = pos["azimuth"].to_numpy(), pos["apparent_elevation"].to_numpy()
    fixed_az, fixed_el = PLANT.fixed_azimuth, 90.0 - PLANT.fixed_tilt
    table = BinTable()
    for part in np.array_split(np.arange(len(times)), 3):     # one day each: bins recur
        a, e = az[part], el[part]
        for n_az, n_el in ((a, e), (np.full_like(a, fixed_az), np.full_like(a, fixed_el))):
            kept = plant_shade(PLANT.positions, a, e, n_az, n_el, W, H, table=table)
            alone = plant_shade(PLANT.positions, a, e, n_az, n_el, W, H)
            np.testing.assert_array_equal(kept.fraction, alone.fraction)
            np.testing.assert_array_equal(kept.group_rects, alone.group_rects)


@pytest.mark.parametrize("mode", [GENERIC, FACING, FIXED])
def test_bin_table_keeps_every_pair_that_can_shade_inside_the_bin(mode: int) -> None:
    """Sun directions sampled inside each bin: every pair whose collectors overlap there
    (computed directly, per direction) is a candidate of the bin."""
    rng = np.random.default_rng(30 + mode)
    _, _, d = pair_vectors(PLANT.positions)
    n_bins = 300
    az0 = rng.integers(60, 300, n_bins).astype(np.float64)        # bin corners (1° × 0.5°)
    el0 = (rng.integers(0, 80, n_bins) * 0.5).astype(np.float64)
    fixed = collector_axes(PLANT.fixed_azimuth, 90.0 - PLANT.fixed_tilt)
    table = _bin_table(d, az0 + 0.5, el0 + 0.25, np.full(n_bins, mode), W, H,
                       np.stack(fixed) if mode == FIXED else None)
    k = 40                                                        # suns per bin
    az = az0[:, None] + rng.uniform(0, 1, (n_bins, k))
    el = el0[:, None] + rng.uniform(0, 0.5, (n_bins, k))
    s = enu_from_sky(az, el)                                      # (B, k, 3)
    if mode == GENERIC:       # any orientation: the distance of d from the sun ray
        ds = np.einsum("bkc,pc->bkp", s, d)
        can = np.sqrt(np.maximum(np.einsum("pc,pc->p", d, d) - ds**2, 0)) < np.hypot(W, H)
    else:
        n, u, v = (np.broadcast_to(x, s.shape) for x in
                   (collector_axes(az, el) if mode == FACING else fixed))
        sn = np.sum(s * n, axis=-1)[..., None]
        dn = np.einsum("bkc,pc->bkp", n, d)
        du = np.einsum("bkc,pc->bkp", u, d) - np.sum(s * u, axis=-1)[..., None] / sn * dn
        dv = np.einsum("bkc,pc->bkp", v, d) - np.sum(s * v, axis=-1)[..., None] / sn * dn
        can = (sn > 0) & (np.abs(du) < W) & (np.abs(dv) < H)
    assert can.any(axis=1).sum() > 100, "the sample must hold pairs that shade"
    missed = can.any(axis=1) & ~table
    assert not missed.any()


def test_sum_columns_is_numpys_row_sum_bit_for_bit() -> None:
    """The column-by-column sum keeps numpy's order, pairwise from 8 columns on (a collector
    of 8 or more strings): the speed-up changes no result."""
    from sim.plant.shading import sum_columns

    rng = np.random.default_rng(5)
    for n_cols in range(1, 13):
        a = rng.random((2_000, n_cols)) * 10.0 ** rng.integers(-3, 4, (2_000, n_cols))
        assert np.array_equal(sum_columns(a), a.sum(axis=1)), n_cols
