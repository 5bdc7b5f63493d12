"""Tests of sim/kinematics.py.

Expected values come from independent constructions: explicit unit vectors
from azimuth/elevation, pvlib.irradiance.aoi, scipy.spatial.transform.Rotation,
and seed 002's printed product matrix (eq. 2).
"""

import numpy as np
import pandas as pd
import pvlib
import pytest
from scipy.spatial.transform import Rotation

from sim.kinematics import (
    TrackerGeometry,
    dh_from_joint_angles,
    forward_kinematics,
    inverse_kinematics,
    joint_angles_from_dh,
    joint_transforms,
    morning_azimuth,
    normal_to_tilt_azimuth,
    panel_axes,
    panel_axes_from_trig,
    tracking_angles,
)

GEOM = TrackerGeometry()
RNG_SEED = 20240315


def _random_upper_hemisphere(n: int, rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _az_el_of(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth clockwise from north and elevation of ENU vectors [deg]."""
    az = np.degrees(np.arctan2(v[:, 0], v[:, 1]))  # in (-180, 180]: exercises wrap
    el = np.degrees(np.arcsin(np.clip(v[:, 2], -1, 1)))
    return az, el


def test_defaults_from_seed_002() -> None:
    assert GEOM.d1_m == pytest.approx(0.355)  # seed 002, section II-A
    assert GEOM.a2_m == pytest.approx(0.091)


def test_fk_of_ik_recovers_random_sun_directions() -> None:
    rng = np.random.default_rng(RNG_SEED)
    v = _random_upper_hemisphere(5000, rng)
    az, el = _az_el_of(v)
    az_j, el_j = inverse_kinematics(az, el, GEOM)
    assert np.all((az_j >= GEOM.azimuth_min_deg) & (az_j <= GEOM.azimuth_max_deg))
    n = forward_kinematics(az_j, el_j, GEOM)
    assert n.shape == (5000, 3)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(n, v, atol=1e-9)


def test_fk_of_ik_with_narrow_azimuth_range_inside_limits() -> None:
    geom = TrackerGeometry(azimuth_min_deg=-180.0, azimuth_max_deg=180.0,
                           elevation_min_deg=10.0, elevation_max_deg=85.0)
    rng = np.random.default_rng(RNG_SEED + 1)
    v = _random_upper_hemisphere(4000, rng)
    az, el = _az_el_of(v)
    keep = (el >= 10.0) & (el <= 85.0)
    az_j, el_j = inverse_kinematics(az[keep] + 360.0, el[keep], geom)
    assert np.all((az_j >= -180.0) & (az_j <= 180.0))
    np.testing.assert_allclose(forward_kinematics(az_j, el_j, geom), v[keep], atol=1e-9)


def test_ideal_tracking_has_zero_aoi_in_pvlib() -> None:
    rng = np.random.default_rng(RNG_SEED + 2)
    solar_azimuth = rng.uniform(0.0, 360.0, 3000)
    solar_elevation = rng.uniform(0.5, 89.5, 3000)
    az_j, el_j = inverse_kinematics(solar_azimuth, solar_elevation, GEOM)
    tilt, surf_az = normal_to_tilt_azimuth(forward_kinematics(az_j, el_j, GEOM))
    aoi = pvlib.irradiance.aoi(tilt, surf_az, 90.0 - solar_elevation, solar_azimuth)
    assert np.max(aoi) < 1e-5


def test_normal_agrees_with_pvlib_aoi_for_any_pose() -> None:
    """cos(aoi) from pvlib equals the dot product of our normal and the sun."""
    rng = np.random.default_rng(RNG_SEED + 3)
    az_j = rng.uniform(-90.0, 450.0, 2000)
    el_j = rng.uniform(0.0, 90.0, 2000)
    sun = _random_upper_hemisphere(2000, rng)
    sun_az, sun_el = _az_el_of(sun)
    n = forward_kinematics(az_j, el_j, GEOM)
    tilt, surf_az = normal_to_tilt_azimuth(n)
    aoi = pvlib.irradiance.aoi(tilt, surf_az, 90.0 - sun_el, np.mod(sun_az, 360.0))
    expected = np.degrees(np.arccos(np.clip(np.sum(n * sun, axis=1), -1, 1)))
    np.testing.assert_allclose(aoi, expected, atol=1e-6)


def test_tilt_azimuth_round_trip_and_known_poses() -> None:
    rng = np.random.default_rng(RNG_SEED + 4)
    az_j = rng.uniform(0.0, 360.0, 1000)
    el_j = rng.uniform(0.0, 89.0, 1000)
    tilt, surf_az = normal_to_tilt_azimuth(forward_kinematics(az_j, el_j, GEOM))
    np.testing.assert_allclose(tilt, 90.0 - el_j, atol=1e-9)
    np.testing.assert_allclose(surf_az, az_j, atol=1e-9)
    # the fixed array of seed 000: 16 deg tilt facing south
    tilt, surf_az = normal_to_tilt_azimuth(forward_kinematics(180.0, 74.0, GEOM))
    assert tilt == pytest.approx(16.0) and surf_az == pytest.approx(180.0)
    np.testing.assert_allclose(
        forward_kinematics(180.0, 30.0, GEOM), [0.0, -np.cos(np.pi / 6), 0.5], atol=1e-12
    )
    np.testing.assert_allclose(forward_kinematics(90.0, 0.0, GEOM), [1.0, 0.0, 0.0], atol=1e-12)
    tilt, surf_az = normal_to_tilt_azimuth(np.array([0.0, 0.0, 2.0]))
    assert tilt == pytest.approx(0.0) and surf_az == pytest.approx(180.0)


@pytest.mark.parametrize(
    ("solar_azimuth", "expected"),
    [(-170.0, 190.0), (190.0, 190.0), (370.0, 10.0), (-360.0, 0.0), (540.0, 180.0)],
)
def test_azimuth_wrap_default_range(solar_azimuth: float, expected: float) -> None:
    az_j, _ = inverse_kinematics(solar_azimuth, 40.0, GEOM)
    assert float(az_j) == pytest.approx(expected)


def test_reference_azimuth_gives_continuous_motion_through_north() -> None:
    # sun passing north at noon (tropical summer): 350 -> 0 -> 10 deg
    sun_az = np.array([350.0, 355.0, 0.0, 5.0, 10.0])
    az_prev = 340.0
    out = []
    for a in sun_az:
        az_prev = float(inverse_kinematics(a, 80.0, GEOM, reference_azimuth=az_prev)[0])
        out.append(az_prev)
    np.testing.assert_allclose(out, [350.0, 355.0, 360.0, 365.0, 370.0])
    # the other way round: starting east of north stays below 0 via the wrap
    az_j, _ = inverse_kinematics(355.0, 80.0, GEOM, reference_azimuth=2.0)
    assert float(az_j) == pytest.approx(-5.0)


def test_plus_minus_180_crossing_with_symmetric_range() -> None:
    geom = TrackerGeometry(azimuth_min_deg=-270.0, azimuth_max_deg=270.0)
    # reference near +180: a sun at -179 (= 181) stays on the +side
    az_j, _ = inverse_kinematics(-179.0, 30.0, geom, reference_azimuth=179.0)
    assert float(az_j) == pytest.approx(181.0)
    az_j, _ = inverse_kinematics(179.0, 30.0, geom, reference_azimuth=-179.0)
    assert float(az_j) == pytest.approx(-181.0)
    # without reference: nearest the range centre (0)
    az_j, _ = inverse_kinematics(190.0, 30.0, geom)
    assert float(az_j) == pytest.approx(-170.0)


def test_unreachable_azimuth_goes_to_nearer_limit() -> None:
    geom = TrackerGeometry(azimuth_min_deg=60.0, azimuth_max_deg=300.0)
    az_j, _ = inverse_kinematics(np.array([20.0, 340.0, 90.0, 300.0]), 30.0, geom)
    np.testing.assert_allclose(az_j, [60.0, 300.0, 90.0, 300.0])


def test_elevation_limits_and_nan() -> None:
    geom = TrackerGeometry(elevation_min_deg=5.0, elevation_max_deg=80.0)
    _, el_j = inverse_kinematics(180.0, np.array([-10.0, 3.0, 45.0, 85.0, np.nan]), geom)
    np.testing.assert_allclose(el_j[:4], [5.0, 5.0, 45.0, 80.0])
    assert np.isnan(el_j[4])
    az_j, _ = inverse_kinematics(np.nan, 30.0, geom)
    assert np.isnan(az_j)


def test_bad_geometry_is_rejected() -> None:
    with pytest.raises(ValueError, match="azimuth_min_deg"):
        TrackerGeometry(azimuth_min_deg=10.0, azimuth_max_deg=0.0)
    with pytest.raises(ValueError, match="elevation"):
        TrackerGeometry(elevation_min_deg=-5.0)


def test_dh_mapping_round_trip() -> None:
    az = np.array([-90.0, 0.0, 123.4, 450.0])
    el = np.array([0.0, 10.0, 45.0, 90.0])
    t1, t2 = dh_from_joint_angles(az, el)
    np.testing.assert_allclose(t1, np.radians([180.0, 90.0, -33.4, -360.0]))
    az2, el2 = joint_angles_from_dh(t1, t2)
    np.testing.assert_allclose(az2, az)
    np.testing.assert_allclose(el2, el)


def test_joint_transforms_against_scipy_rotations() -> None:
    rng = np.random.default_rng(RNG_SEED + 5)
    az_j = rng.uniform(-90.0, 450.0, 200)
    el_j = rng.uniform(0.0, 90.0, 200)
    t01, t02, t0p = joint_transforms(az_j, el_j, GEOM)
    assert t01.shape == t02.shape == t0p.shape == (200, 4, 4)
    theta1 = np.radians(90.0 - az_j)  # D-H angle from east, counter-clockwise
    theta2 = np.radians(el_j)
    # A1 = Rz(t1) Tz(d1) Rx(90 deg); A1 A2 = ... Rz(t2) Tx(a2): intrinsic Z-X-Z
    r1 = Rotation.from_euler("ZX", np.column_stack([theta1, np.full(200, np.pi / 2)]))
    r2 = Rotation.from_euler(
        "ZXZ", np.column_stack([theta1, np.full(200, np.pi / 2), theta2])
    )
    np.testing.assert_allclose(t01[:, :3, :3], r1.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(t01[:, :3, 3], np.tile([0, 0, 0.355], (200, 1)), atol=1e-12)
    np.testing.assert_allclose(t02[:, :3, :3], r2.as_matrix(), atol=1e-12)
    x2 = r2.as_matrix()[:, :, 0]
    np.testing.assert_allclose(t02[:, :3, 3], [0, 0, 0.355] + 0.091 * x2, atol=1e-12)
    # panel frame: z is the normal, x along the horizontal elevation axis
    rp = (r2 * Rotation.from_euler("y", np.pi / 2)).as_matrix()
    np.testing.assert_allclose(t0p[:, :3, :3], rp, atol=1e-12)
    np.testing.assert_allclose(t0p[:, :3, 2], forward_kinematics(az_j, el_j, GEOM), atol=1e-12)
    np.testing.assert_allclose(t0p[:, 2, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(t0p[:, 3], np.tile([0, 0, 0, 1.0], (200, 1)))


def test_joint_transforms_match_seed_002_eq_2() -> None:
    """Seed 002 prints 0A2 = A1 A2 explicitly (eq. 2)."""
    d1, a2 = 0.355, 0.091
    for az, el in [(180.0, 30.0), (75.0, 62.0), (300.0, 5.0), (-45.0, 89.0)]:
        th1, th2 = np.radians(90.0 - az), np.radians(el)
        c1, s1, c2, s2 = np.cos(th1), np.sin(th1), np.cos(th2), np.sin(th2)
        eq2 = np.array(
            [
                [c1 * c2, -c1 * s2, s1, a2 * c1 * c2],
                [s1 * c2, -s1 * s2, -c1, a2 * s1 * c2],
                [s2, c2, 0.0, a2 * s2 + d1],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
        np.testing.assert_allclose(joint_transforms(az, el, GEOM)[1], eq2, atol=1e-12)


def test_vectorised_shapes_broadcast() -> None:
    az = np.array([[10.0, 200.0, 350.0]])  # (1, 3)
    el = np.array([[20.0], [60.0]])  # (2, 1)
    az_j, el_j = inverse_kinematics(az, el, GEOM, reference_azimuth=np.array([0.0, 180.0, 400.0]))
    assert az_j.shape == el_j.shape == (2, 3)
    np.testing.assert_allclose(az_j[0], [10.0, 200.0, 350.0])
    assert forward_kinematics(az_j, el_j, GEOM).shape == (2, 3, 3)
    tilt, surf_az = normal_to_tilt_azimuth(forward_kinematics(az_j, el_j, GEOM))
    assert tilt.shape == surf_az.shape == (2, 3)
    assert [t.shape for t in joint_transforms(az_j, el_j, GEOM)] == [(2, 3, 4, 4)] * 3


def test_tracking_angles_stow_flat_at_night_and_track_by_day() -> None:
    """Sun up: the same angles as inverse kinematics; sun down: panel flat."""
    geometry = TrackerGeometry()
    az, el = tracking_angles([100.0, 250.0, 300.0], [35.0, -0.5, -20.0], geometry)
    ik_az, ik_el = inverse_kinematics([100.0, 250.0, 300.0], [35.0, -0.5, -20.0], geometry)
    assert az[0] == pytest.approx(ik_az[0])
    np.testing.assert_allclose(az[1:], 90.0)  # no night azimuth given: held due east
    assert el[0] == pytest.approx(35.0)
    np.testing.assert_allclose(el[1:], geometry.elevation_max_deg)
    tilt, _ = normal_to_tilt_azimuth(forward_kinematics(az[1:], el[1:], geometry))
    np.testing.assert_allclose(tilt, 0.0, atol=1e-9)


@pytest.mark.parametrize("latitude, longitude, zone", [
    (16.28875, -95.240871, "America/Mexico_City"),  # Tehuantepec (seed 000)
    (-33.45, -70.66, "America/Santiago"),  # a southern site, the noon sun to the north
])
def test_the_azimuth_joint_stays_put_all_night_at_the_mornings_azimuth(
        latitude: float, longitude: float, zone: str) -> None:
    """Stowed at night, the azimuth joint holds one angle from dusk to dawn — the sun's
    azimuth at the next sunrise — so the dawn move is a fraction of a degree. The sun here is
    pvlib's SPA (``spa_python``), sunrise its ``sun_rise_set_transit_spa``; day by day the
    held angle is checked against pvlib's geometric sunrise azimuth (Spencer's
    declination, an independent formula): cos A = −sin δ / cos φ … to within 1.5°."""
    times = pd.date_range("2024-06-20", "2024-06-24", freq="5min", tz=zone, inclusive="left")
    sp = pvlib.solarposition.spa_python(times, latitude, longitude)
    el = sp["apparent_elevation"].to_numpy()
    hold = morning_azimuth(times, latitude, longitude)
    az_j, el_j = tracking_angles(sp["azimuth"].to_numpy(), el, GEOM,
                                 reference_azimuth=np.full(len(times), 180.0),
                                 night_azimuth=hold)
    night = el <= 0
    starts = np.flatnonzero(np.diff(night.astype(int)) == 1) + 1  # first night step
    ends = np.flatnonzero(np.diff(night.astype(int)) == -1)  # last night step
    assert len(starts) >= 3
    for a, b in zip(starts, ends[ends > starts[0]], strict=False):
        assert np.ptp(az_j[a:b + 1]) == 0.0, "the azimuth joint moved during the night"
        assert np.all(el_j[a:b + 1] == GEOM.elevation_max_deg)
        dawn_move = abs(az_j[b + 1] - az_j[b])
        assert dawn_move < 1.5, f"{dawn_move:.2f}° at dawn"
        # pvlib's geometric sunrise (hour angle −ω_s): azimuth from declination and latitude
        day = times[b + 1].normalize()
        decl = pvlib.solarposition.declination_spencer71(day.day_of_year)
        cos_a = np.sin(decl) / np.cos(np.deg2rad(latitude))
        assert az_j[b] == pytest.approx(np.rad2deg(np.arccos(cos_a)), abs=1.5)


def test_morning_azimuth_needs_aware_times_and_polar_night_is_nan() -> None:
    with pytest.raises(ValueError, match="timezone-aware"):
        morning_azimuth(pd.date_range("2024-06-01", periods=3, freq="h"), 10.0, 0.0)
    polar = morning_azimuth(pd.date_range("2024-12-21", periods=3, freq="h", tz="UTC"),
                            85.0, 0.0)
    assert np.isnan(polar).all()
    az, _ = tracking_angles([10.0], [-30.0], GEOM, night_azimuth=polar[:1])
    assert az[0] == pytest.approx(90.0)  # NaN (no sunrise): held due east


def test_panel_axes_are_the_panel_frame_of_the_dh_chain() -> None:
    """The closed-form panel axes (the one rule every caller uses) against scipy's rotations
    of the D–H chain and the panel's fixed turn: x along the width, y up the slope, n."""
    rng = np.random.default_rng(RNG_SEED + 6)
    az_j = rng.uniform(-90.0, 450.0, 200)
    el_j = rng.uniform(0.0, 90.0, 200)
    r2 = Rotation.from_euler("ZXZ", np.column_stack([np.radians(90.0 - az_j),
                                                      np.full(200, np.pi / 2), np.radians(el_j)]))
    rp = (r2 * Rotation.from_euler("y", np.pi / 2)).as_matrix()
    x, y, n = panel_axes(az_j, el_j)
    np.testing.assert_allclose(np.stack([x, y, n], axis=-1), rp, atol=1e-12)
    assert np.all(x[:, 2] == 0.0) and np.all(y[:, 2] >= 0.0)
    # scalar arithmetic (a camera frame) gives the same numbers as the arrays
    a, e = np.radians(az_j[0]), np.radians(el_j[0])
    scalar = panel_axes_from_trig(np.sin(a), np.cos(a), np.sin(e), np.cos(e))
    np.testing.assert_array_equal(np.array(scalar, dtype=float), [x[0], y[0], n[0]])
