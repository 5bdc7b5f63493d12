"""Strategies: backtracking shades nobody and is the POA optimum; overcast scans go flat."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from plant_reference import sampled_fractions, shapely_shades_anyone, utc_from_true_solar_time

from sim.plant.layout import load_plant
from sim.plant.shading import shades_anyone
from sim.plant.simulate import sky_conditions
from sim.plant.strategies import lowest_free_elevation, orientations

PLANT = load_plant("penarroya")
W, H = PLANT.collector.width, PLANT.collector.height


def _sky_at(day: str, tst_h: float) -> dict[str, np.ndarray]:
    t = utc_from_true_solar_time(day, tst_h, PLANT.longitude)
    return sky_conditions(PLANT, pd.DatetimeIndex([t]))


def _pvlib_poa(sky: dict[str, np.ndarray], az: np.ndarray, el: np.ndarray) -> np.ndarray:
    """Perez POA straight from pvlib (not through sim.sky)."""
    from pvlib.irradiance import get_total_irradiance

    tot = get_total_irradiance(90 - el, az, sky["apparent_zenith"][0], sky["solar_azimuth"][0],
                               sky["dni"][0], sky["ghi"][0], sky["dhi"][0],
                               dni_extra=sky["dni_extra"][0],
                               airmass=sky["airmass_relative"][0], albedo=PLANT.albedo,
                               model="perez")
    return np.asarray(tot["poa_global"], dtype=float)


@pytest.mark.parametrize("tst_h", [8.4, 15.4])
def test_backtrack_shades_nobody_and_beats_a_dense_search(tst_h: float) -> None:
    sky = _sky_at("2021-12-21", tst_h)
    az, el = orientations("backtrack", PLANT, sky)
    # nobody shaded, by independent ray sampling
    assert sampled_fractions(PLANT.positions, sky["solar_azimuth"][0],
                             sky["apparent_elevation"][0], az[0], el[0], W, H).max() == 0
    # a dense grid of shade-free orientations (1° × 0.5°) holds nothing better (≤ 0.2 %)
    gaz, gel = np.meshgrid(sky["solar_azimuth"][0] + np.arange(-45, 46, 1.0),
                           np.arange(sky["apparent_elevation"][0], 90, 0.5))
    free = ~shades_anyone(PLANT.positions, sky["solar_azimuth"][0],
                          sky["apparent_elevation"][0], gaz.ravel(), gel.ravel(), W, H)
    best = _pvlib_poa(sky, gaz.ravel()[free] % 360, gel.ravel()[free]).max()
    ours = _pvlib_poa(sky, az % 360, el)[0]
    assert ours >= best * 0.998
    # and it is not simply "raise the collector until the shade clears"
    sun = _pvlib_poa(sky, sky["solar_azimuth"], sky["apparent_elevation"])[0]
    assert ours < sun


def test_sun_orientation_kept_where_it_shades_nobody() -> None:
    sky = _sky_at("2021-06-21", 10.0)
    az, el = orientations("backtrack", PLANT, sky)
    assert (az[0], el[0]) == (sky["solar_azimuth"][0], sky["apparent_elevation"][0])


def test_sky_scan_goes_flat_under_overcast_and_follows_the_sun_when_clear() -> None:
    sky = _sky_at("2021-06-21", 10.0)
    clear_az, clear_el = orientations("sky_scan", PLANT, sky)
    assert abs(clear_el[0] - sky["apparent_elevation"][0]) < 5
    overcast = dict(sky, dni=np.array([0.0]), ghi=np.array([120.0]), dhi=np.array([120.0]))
    _, flat_el = orientations("sky_scan", PLANT, overcast)
    assert flat_el[0] >= 80


def test_sky_scan_is_at_least_backtracking() -> None:
    sky = _sky_at("2021-12-21", 8.4)
    a1, e1 = orientations("backtrack", PLANT, sky)
    a2, e2 = orientations("sky_scan", PLANT, sky)
    assert _pvlib_poa(sky, a2 % 360, e2)[0] >= _pvlib_poa(sky, a1 % 360, e1)[0] - 1e-6
    assert not shades_anyone(PLANT.positions, sky["solar_azimuth"], sky["apparent_elevation"],
                             a2, e2, W, H)[0]


def test_unknown_strategy() -> None:
    with pytest.raises(ValueError, match="strategy must be one of sun, backtrack, sky_scan"):
        orientations("moon", PLANT, _sky_at("2021-06-21", 10.0))


@pytest.mark.parametrize(("day", "tst_h"), [("2021-12-21", 8.4), ("2021-12-21", 15.4),
                                             ("2021-01-20", 16.2)])
def test_lowest_free_elevation_is_the_lowest_by_shapely(day: str, tst_h: float) -> None:
    """The closed form against an independent shapely check of every ordered pair."""
    sky = _sky_at(day, tst_h)
    az0, el0 = float(sky["solar_azimuth"][0]), float(sky["apparent_elevation"][0])
    fan = az0 + np.array([-40.0, -21.0, 0.0, 12.0, 33.0])
    alpha = lowest_free_elevation(PLANT, [az0], [el0], fan[None, :], [el0])[0]
    assert alpha[2] > el0 + 1, "pointing at the sun shades someone at these instants"
    for g, a in zip(fan, alpha, strict=True):
        assert not shapely_shades_anyone(PLANT.positions, az0, el0, g, a, W, H)
        # every elevation between the sun's and the answer shades someone (0.25° grid)
        for e in np.arange(el0, a - 1e-6, 0.25):
            assert shapely_shades_anyone(PLANT.positions, az0, el0, g, e, W, H), (g, e)


@pytest.mark.parametrize("strategy", ["sun", "backtrack", "sky_scan"])
def test_a_plant_of_one_tracker_has_no_neighbour_to_avoid(strategy: str) -> None:
    """One collector shades nobody: every strategy answers (backtracking raised on the empty
    pair list, a 500 on the Plant page of a one-tracker plant file)."""
    from dataclasses import replace

    one = replace(PLANT, tracker_ids=PLANT.tracker_ids[:1], positions=PLANT.positions[:1])
    sky = _sky_at("2021-12-21", 8.4)
    az, el = orientations(strategy, one, sky)
    if strategy != "sky_scan":  # the sun's own orientation (sky_scan may find a brighter one)
        assert (az[0], el[0]) == (sky["solar_azimuth"][0], sky["apparent_elevation"][0])
    assert not shades_anyone(one.positions, sky["solar_azimuth"], sky["apparent_elevation"],
                             az, el, W, H)[0]


@pytest.mark.parametrize("strategy", ["backtrack", "sky_scan"])
def test_flat_is_checked_for_shade_on_sloped_ground(strategy: str) -> None:
    """On a 15° north-facing slope the flat pose shades: the higher rows' collectors stand
    above the lower ones' plane (a tester's finding: 4 × 4 trackers 16 m apart, 21 December
    at 09:45, backtrack and sky_scan answered flat unchecked, 9 of 16 collectors shaded,
    mean shaded fraction 0.388). Both answer an orientation that shades nobody."""
    from dataclasses import replace

    rise_m = 16.0 * np.tan(np.radians(15.0))
    positions = np.array([(16.0 * i, -16.0 * j, rise_m * j) for j in range(4) for i in range(4)])
    plant = replace(PLANT, latitude=37.4, longitude=-5.9, altitude=100.0,
                    timezone="Europe/Madrid", tracker_ids=tuple(range(1, 17)),
                    positions=positions)
    sky = sky_conditions(plant, pd.DatetimeIndex([pd.Timestamp("2021-12-21T08:45Z")]))
    az0, el0 = sky["solar_azimuth"][0], sky["apparent_elevation"][0]
    assert sampled_fractions(positions, az0, el0, 180.0, 90.0, W, H).max() > 0  # flat shades
    az, el = orientations(strategy, plant, sky)
    assert sampled_fractions(positions, az0, el0, az[0], el[0], W, H).max() == 0
    assert not shapely_shades_anyone(positions, az0, el0, az[0], el[0], W, H)


def test_backtrack_turns_steadily_where_the_optimum_does() -> None:
    """A tester's 3 × 3 plant (12 m × 5 m collectors, 24 m east–west, 16 m north–south) at
    Peñarroya, polled every minute on 21 December: the shade-free optimum turns steadily away
    from the sun at the sun's elevation until 16:08, and from 16:09 (the other side of the
    sun: a real change of optimum, the first side 4.8 % below by 16:30) back towards it. The
    served orientation had zig-zagged: its elevation up ~3.2° and down again every few
    minutes, its azimuth by the 0.5° refinement step, which moved with the sun (114 azimuth
    reversals that day, 10 now). Each axis now moves one way in each stretch, shading nobody."""
    from dataclasses import replace

    positions = np.array([(24.0 * i, 16.0 * j, 0.0) for j in range(3) for i in range(3)])
    plant = replace(PLANT, tracker_ids=tuple(range(1, 10)), positions=positions)
    for start, end in (("15:30", "16:08"), ("16:09", "16:50")):
        times = pd.date_range(f"2021-12-21 {start}", f"2021-12-21 {end}", freq="1min",
                              tz="Europe/Madrid")
        sky = sky_conditions(plant, times.tz_convert("UTC"))
        az, el = orientations("backtrack", plant, sky)
        assert np.all(np.diff(az) < 0), (start, np.round(az, 3))
        assert np.all(np.diff(el) <= 0), (start, np.round(el, 3))
        for k in range(len(times)):
            assert not shapely_shades_anyone(positions, sky["solar_azimuth"][k],
                                             sky["apparent_elevation"][k], az[k], el[k], W, H)
