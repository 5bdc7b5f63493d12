"""Disturbances: base-frame rotations against scipy's Rotation, camera axes, drift, gusts."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sim import disturbances as dist
from sim.kinematics import TrackerGeometry, forward_kinematics
from vision.sphere import angular_separation_deg, enu_from_sky, sky_from_enu


def test_pedestal_yaw_turns_every_pose_by_the_yaw() -> None:
    d = dist.Disturbances(pedestal_yaw_deg=2.0)
    az = np.array([-80.0, 10.0, 135.0, 250.0, 400.0])
    el = np.array([5.0, 30.0, 60.0, 85.0, 45.0])
    n_az, n_el = sky_from_enu(dist.normal_enu(az, el, d))
    assert np.allclose((n_az - az - 2.0 + 180) % 360 - 180, 0.0, atol=1e-9)
    assert np.allclose(n_el, el, atol=1e-9)


@pytest.mark.parametrize(("tilt", "tilt_az", "yaw"), [(1.5, 90.0, 0.0), (3.0, 200.0, -2.0)])
def test_base_rotation_matches_scipy(tilt: float, tilt_az: float, yaw: float) -> None:
    # independent construction: a clockwise yaw about up, then a tilt about the horizontal
    # axis 90° counter-clockwise (seen from above) from the lean direction
    d = dist.Disturbances(pedestal_yaw_deg=yaw, pedestal_tilt_deg=tilt,
                          pedestal_tilt_azimuth_deg=tilt_az)
    axis_az = tilt_az - 90.0  # up x lean points 90 deg anticlockwise of the lean
    axis = enu_from_sky(axis_az, 0.0)
    r_ref = Rotation.from_rotvec(np.radians(tilt) * axis) * Rotation.from_euler(
        "z", -yaw, degrees=True)
    assert np.allclose(dist.base_rotation(d), r_ref.as_matrix(), atol=1e-12)
    # the pedestal's axis leans by `tilt` towards `tilt_az`
    up = dist.base_rotation(d) @ np.array([0.0, 0.0, 1.0])
    a, e = sky_from_enu(up)
    assert e == pytest.approx(90.0 - tilt, abs=1e-9)
    assert a == pytest.approx(tilt_az % 360, abs=1e-9)


def test_elevation_zero_raises_the_panel_and_its_camera_by_the_zero() -> None:
    d = dist.Disturbances(elevation_zero_deg=-0.8, pedestal_yaw_deg=1.0, pedestal_tilt_deg=0.5)
    moved = dist.Disturbances(pedestal_yaw_deg=1.0, pedestal_tilt_deg=0.5)
    az = np.array([80.0, 135.0, 250.0])
    el = np.array([10.0, 60.0, 35.0])
    assert np.allclose(dist.normal_enu(az, el, d), dist.normal_enu(az, el - 0.8, moved),
                       atol=1e-15)
    sun = enu_from_sky(150.0, 55.0)
    assert np.allclose(dist.camera_axes(160.0, 50.0, d), dist.camera_axes(160.0, 49.2, moved),
                       atol=1e-15)
    assert np.allclose(dist.sun_in_camera(160.0, 50.0, d, sun),
                       dist.camera_axes(160.0, 50.0, d) @ sun, atol=1e-12)
    assert dist.real_elevation_deg(50.0, d) == pytest.approx(49.2)
    assert d.to_dict()["elevation_zero_deg"] == -0.8 and d.any
    with pytest.raises(ValueError, match="elevation_zero_deg"):
        dist.Disturbances(elevation_zero_deg=31.0)


def test_no_disturbance_is_the_kinematics() -> None:
    az = np.linspace(-90, 450, 13)
    el = np.linspace(0, 90, 13)
    n = dist.normal_enu(az, el, dist.Disturbances())
    assert np.allclose(n, forward_kinematics(az, el, TrackerGeometry()), atol=1e-15)
    assert not dist.Disturbances().any and dist.Disturbances(clock_offset_s=1).any


def test_camera_axes_and_offset() -> None:
    s = enu_from_sky(160.0, 50.0)
    m = dist.camera_axes(160.0, 50.0, dist.Disturbances())
    assert np.allclose(m @ m.T, np.eye(3), atol=1e-12)
    assert np.allclose(m[2], s, atol=1e-12)  # forward = the normal
    assert abs(m[0, 2]) < 1e-12  # right is horizontal
    # a sun a little to the west (larger azimuth) of the pose appears to the right
    assert (m @ enu_from_sky(161.0, 50.0))[0] > 0 and (m @ enu_from_sky(160.0, 51.0))[1] > 0
    d = dist.Disturbances(camera_offset_right_deg=1.0, camera_offset_up_deg=-0.5)
    mo = dist.camera_axes(160.0, 50.0, d)
    assert np.allclose(mo @ mo.T, np.eye(3), atol=1e-12)
    ang = math.degrees(math.acos(float(mo[2] @ m[2])))
    assert ang == pytest.approx(math.degrees(math.acos(math.cos(math.radians(1.0))
                                                       * math.cos(math.radians(0.5)))), abs=1e-9)
    # the sun on the camera's boresight is 1 deg right and 0.5 deg down of the normal
    f_az, f_el = sky_from_enu(mo[2])
    assert float(angular_separation_deg(f_az, f_el, 160.0, 50.0)) == pytest.approx(ang, abs=1e-9)
    for dd in (dist.Disturbances(), d, dist.Disturbances(pedestal_yaw_deg=2, pedestal_tilt_deg=1)):
        sun = enu_from_sky(150.0, 55.0)
        assert np.allclose(dist.sun_in_camera(160.0, 50.0, dd, sun),
                           dist.camera_axes(160.0, 50.0, dd) @ sun, atol=1e-12)


def test_encoder_drift_and_backlash() -> None:
    d = dist.Disturbances(encoder_drift_mrad_per_h=10.0, backlash_deg=0.4)
    assert float(dist.encoder_error_deg(7200.0, d)) == pytest.approx(math.degrees(0.020))
    assert np.allclose(dist.backlash_offset_deg([1, -1], d), [-0.2, 0.2])


def test_gusts_are_seeded_three_level_and_off_by_default() -> None:
    t = np.arange(0, 200_000, 5.0)
    assert not np.any(dist.gust_torque_nm(t, dist.Disturbances()))
    d = dist.Disturbances(gust_torque_nm=3.0, seed=4)
    g = dist.gust_torque_nm(t, d)
    assert g.shape == (len(t), 2) and set(np.unique(g)) == {-3.0, 0.0, 3.0}
    assert np.array_equal(g, dist.gust_torque_nm(t, d))  # deterministic
    assert not np.array_equal(g, dist.gust_torque_nm(t, dist.Disturbances(gust_torque_nm=3.0)))
    # constant over each 10 s window, about 1/4, 1/2, 1/4 of the windows
    assert np.array_equal(g[0::2], g[1::2])
    frac = [np.mean(g[::2, 0] == v) for v in (3.0, 0.0, -3.0)]
    assert frac == pytest.approx([0.25, 0.5, 0.25], abs=0.02)


def test_misuse_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="backlash_deg"):
        dist.Disturbances(backlash_deg=-1)
    with pytest.raises(ValueError, match="finite"):
        dist.Disturbances(pedestal_yaw_deg=float("nan"))
    with pytest.raises(ValueError, match="pedestal_tilt_deg"):
        dist.Disturbances(pedestal_tilt_deg=60)
