"""Controllers and their world: frames vs vision.synth, moves vs sim.dynamics/sim.motors,
each controller's behaviour, each disturbance's signature, clouds."""

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pvlib
import pytest

from sim import dynamics, motors
from sim.control import CONTROLLERS, ControlSettings, ephemeris_joint_targets, make_controller
from sim.disturbances import Disturbances, sun_in_camera
from sim.frames import CloudField, pointing_error_deg, render_sun_roi
from sim.pointing_model import PointingModel, fit_pointing_model
from sim.sites import load_site
from sim.sun import solar_position
from sim.tracking import (
    CameraSetup,
    DriveLimits,
    Move,
    _trapezoid_position,
    move_energies_wh,
    trapezoid_duration_s,
)
from sim.twin import simulate
from vision.cameras import PinholeCamera
from vision.detect import detect_seed000, detect_seed003
from vision.sphere import enu_from_sky
from vision.synth import tracker_frame

TZ = "America/Mexico_City"


@pytest.fixture(scope="module")
def site():
    return load_site("tehuantepec")


def _noon_window(site, hours: float = 2.0, day: str = "2024-03-15", **kw):
    start = pd.Timestamp(f"{day} 12:00", tz=TZ)
    return simulate(site, start, start + pd.Timedelta(hours=hours), **kw)


# ---------------------------------------------------------------- frames (vs vision.synth)


@pytest.mark.parametrize(("h", "v", "glare"),
                         [(0.0, 0.0, 0.8), (1.0, 0.5, 0.8), (-3.0, 2.2, 0.8), (0.4, 0.1, 0.2)])
def test_roi_is_a_crop_of_vision_synth_frame(h: float, v: float, glare: float) -> None:
    cam = PinholeCamera()
    full = tracker_frame(h, v, cam, noise_dn=0.0, bloom=0.0, glare_deg=glare).image
    sx, sy = cam.pixel_from_pointing_error(h, v)
    roi = render_sun_roi(cam.pixel_to_direction(sx, sy), cam, 24, glare_deg=glare,
                         noise_dn=0.0, colour=True)
    crop = full[roi.y0_px:roi.y0_px + roi.image.shape[0], roi.x0_px:roi.x0_px + roi.image.shape[1]]
    assert roi.image.shape == (48, 48, 3)
    # float32 rounding in either renderer: at most 1 DN apart
    assert np.abs(crop.astype(int) - roi.image.astype(int)).max() <= 1
    grey = render_sun_roi(cam.pixel_to_direction(sx, sy), cam, 24, glare_deg=glare,
                          noise_dn=0.0)
    assert grey.image.ndim == 2


def test_detected_error_from_roi_matches_the_truth_and_the_camera_model() -> None:
    cam = PinholeCamera()
    rng = np.random.default_rng(3)
    for h, v in [(0.3, -0.2), (1.5, 1.0), (-2.0, 0.4)]:
        sx, sy = cam.pixel_from_pointing_error(h, v)
        roi = render_sun_roi(cam.pixel_to_direction(sx, sy), cam, 16, rng=rng)
        for det in (detect_seed003(roi.image), detect_seed000(roi.image)):
            assert det.centroid_px is not None  # the sun is in the crop
            x, y = det.centroid_px[0] + roi.x0_px, det.centroid_px[1] + roi.y0_px
            eh, ev = pointing_error_deg(cam, x, y)
            ref = cam.pointing_error(x, y)
            assert (eh, ev) == pytest.approx((float(ref[0]), float(ref[1])), abs=1e-12)
            # 0.008 deg (0.1 px) at most measured over these frames and both detectors
            assert eh == pytest.approx(h, abs=0.02) and ev == pytest.approx(v, abs=0.02)
    off = cam.pixel_to_direction(-500.0, 10.0)  # outside the frame
    assert not render_sun_roi(off, cam).sun_in_frame


def test_clouds_dim_the_sun_and_drift() -> None:
    c = CloudField(cover=0.5, optical_depth=3.0, seed=2)
    seen = np.array([c.at_sun(t) for t in range(0, 2000, 10)])
    # the share of the time the sun is dimmed follows the cover (measured 0.485 for 0.5)
    assert np.mean(seen > 0.1) == pytest.approx(0.5, abs=0.04)
    assert seen.max() == pytest.approx(1.0)
    assert CloudField(cover=0.0).at_sun(5.0) == 0.0


def test_cached_optics_keep_cameras_apart_and_cannot_be_written() -> None:
    # the renderer caches each camera's pixel grid: interleaving two cameras (and a sky
    # level) must give each the frame it gets alone, and no caller may alter the cache
    from sim.frames import _optics

    narrow, wide = PinholeCamera(), PinholeCamera(fov_deg=90.0, width_px=320, height_px=240)
    s = narrow.pixel_to_direction(*narrow.pixel_from_pointing_error(0.4, -0.3))
    alone = [render_sun_roi(s, cam, 16, sky_level=sky, noise_dn=0.0).image
             for cam, sky in ((narrow, 0.35), (wide, 0.35), (narrow, 0.6))]
    mixed = [render_sun_roi(s, cam, 16, sky_level=sky, noise_dn=0.0).image
             for cam, sky in ((wide, 0.35), (narrow, 0.6), (narrow, 0.35))]
    assert (alone[0] == mixed[2]).all() and (alone[1] == mixed[0]).all()
    assert (alone[2] == mixed[1]).all() and not (alone[0] == alone[2]).all()
    o = _optics(narrow, 0.3, 0.35)
    with pytest.raises(ValueError):
        o.dirs[0, 0, 0] = 0.0


# ---------------------------------------------------------------- moves (vs sim.dynamics/motors)


@pytest.mark.parametrize("delta_deg", [0.05, 0.3, 12.0, -40.0])
def test_trapezoid_matches_dynamics_move_profile(delta_deg: float) -> None:
    lim = DriveLimits()
    rate, acc = lim.axis(0)
    t, q, _, _ = dynamics.move_profile(math.radians(delta_deg), math.radians(rate),
                                       math.radians(acc), 0.01)
    ours = [_trapezoid_position(delta_deg, rate, acc, float(tt)) for tt in t]
    assert np.allclose(np.radians(ours), q, atol=1e-12)
    assert trapezoid_duration_s(delta_deg, rate, acc) == pytest.approx(t[-1], abs=0.01)


def test_move_energies_match_motors_tracking_motion_energy() -> None:
    lim = DriveLimits()
    rng = np.random.default_rng(0)
    # joint targets in which one axis changes at a time (az at even k, el at odd k)
    az_t, el_t = [120.0], [40.0]
    moves = []
    for k in range(1, 30):
        axis = k % 2
        delta = float(rng.uniform(-0.4, 0.4) if axis else rng.uniform(0.0, 0.6))
        start = el_t[-1] if axis else az_t[-1]
        moves.append(Move(axis, float(k), delta, start, el_t[-1], 0.0))
        az_t.append(az_t[-1] + (0.0 if axis else delta))
        el_t.append(el_t[-1] + (delta if axis else 0.0))
    ref = motors.tracking_motion_energy(az_t, el_t, max_rate_rad_s=math.radians(lim.axis(0)[0]),
                                        max_accel_rad_s2=math.radians(lim.axis(0)[1]))
    each, total, beyond = move_energies_wh(moves, lim)
    assert total == pytest.approx(ref["motion_wh"], rel=1e-6)
    assert each.sum() == pytest.approx(total) and (each > 0).all()
    # a gust against the motion costs more, one with it less
    against = [Move(m.axis, m.t0_s, m.delta_deg, m.start_deg, m.elevation_deg,
                    -2.0 * math.copysign(1, m.delta_deg)) for m in moves]
    assert move_energies_wh(against, lim)[1] > 1.2 * total
    assert not beyond.any()  # well inside the drives
    # a gust past the gearbox's 60 N m rating: every move asks more than the drive gives
    stalled = [m._replace(gust_nm=-200.0 * math.copysign(1, m.delta_deg)) for m in moves]
    assert move_energies_wh(stalled, lim).beyond_drive.all()


# ---------------------------------------------------------------- controllers


def test_controllers_and_misuse(site) -> None:
    assert CONTROLLERS == ("ideal", "open_loop_spa", "open_loop_duffie_beckman", "chronological",
                           "closed_loop_camera", "hybrid", "open_loop_model")
    with pytest.raises(ValueError, match="no control loop"):
        make_controller("ideal", site)
    with pytest.raises(ValueError, match="controller must be one of"):
        make_controller("pid", site)
    with pytest.raises(ValueError, match="dead_band_deg"):
        ControlSettings(dead_band_deg=-1)
    with pytest.raises(ValueError, match="receiver"):
        _noon_window(site, 0.1, controller="open_loop_spa", receiver="dish")
    with pytest.raises(ValueError, match="pointing_model_terms: only the open_loop_model"):
        _noon_window(site, 0.1, controller="hybrid",
                     pointing_model_terms={"azimuth_zero_deg": 1.0})
    with pytest.raises(ValueError, match="yaw_deg: not a pointing-model term"):
        make_controller("open_loop_model", site, pointing_model_terms={"yaw_deg": 1.0})


def test_open_loop_follows_the_sun_within_dead_band_and_lag(site) -> None:
    r = _noon_window(site, 3.0, controller="open_loop_spa")
    s = r.summary()
    # 60 s updates aimed 30 s ahead: the sun moves <= 0.25 deg/min, so <= ~2.2 mrad at the
    # samples, plus up to the 0.1 deg (1.75 mrad) dead band
    assert s["pointing_error_max_mrad"] < 4.0 and s["pointing_error_rms_mrad"] < 2.5
    assert s["moves"] > 100 and s["actuator_move_energy_wh"] > 0
    cmd = r.series[["azimuth_command_deg", "elevation_command_deg"]]
    assert cmd.notna().all().all()
    # 2 mrad cost next to nothing (the diffuse terms change to first order in the tilt: +-;
    # measured 2.4e-5 of the energy)
    assert abs(s["pointing_loss_wh"]) < 6e-5 * s["tracker_energy_wh"]


def _enu(zenith_deg: np.ndarray, azimuth_deg: np.ndarray) -> np.ndarray:
    z, a = np.radians(zenith_deg), np.radians(azimuth_deg)
    return np.stack([np.sin(z) * np.sin(a), np.sin(z) * np.cos(a), np.cos(z)], axis=-1)


def test_duffie_beckman_open_loop_is_off_by_its_ephemeris_error(site) -> None:
    # seed 001: D&B vs SPA differ by far less than its 100 mrad drift
    db = _noon_window(site, 4.0, day="2024-09-26", controller="open_loop_duffie_beckman")
    spa = _noon_window(site, 4.0, day="2024-09-26", controller="open_loop_spa")
    e_db, e_spa = db.summary()["pointing_error_rms_mrad"], spa.summary()["pointing_error_rms_mrad"]
    assert e_spa < 2.5
    # the two ephemerides apart over the same minutes (16.5 mrad RMS here), the loop's own
    # error beside it: measured 1.8 % above their quadrature sum
    t = db.series.index
    a = solar_position(t, site.latitude, site.longitude, site.altitude, method="spa")
    b = solar_position(t, site.latitude, site.longitude, site.altitude, method="duffie-beckman")
    cos_apart = (_enu(a["apparent_zenith"].to_numpy(), a["azimuth"].to_numpy())
                 * _enu(b["apparent_zenith"].to_numpy(), b["azimuth"].to_numpy())).sum(-1)
    apart = 1000 * np.arccos(np.clip(cos_apart, -1.0, 1.0))
    assert e_db == pytest.approx(math.hypot(float(np.sqrt(np.mean(apart**2))), e_spa),
                                 rel=0.05)


@pytest.mark.parametrize("minutes", [5, 30, 60])
def test_chronological_steps_every_n_minutes(site, minutes: int) -> None:
    r = _noon_window(site, 4.0, controller="chronological",
                     settings=ControlSettings(chronological_interval_min=minutes))
    s = r.summary()
    steps = 4 * 60 // minutes
    # both axes step at each mark after the start (the run starts on target)
    assert steps - 1 <= s["moves"] / 2 <= steps
    # the sun moves ~0.25 deg/min: pointing at mid-interval leaves <= N/2 minutes of it
    # (measured 0.9 % under, at 5, 30 and 60 min)
    assert s["pointing_error_max_mrad"] == pytest.approx(0.5 * minutes * 4.4, rel=0.02)


def test_dead_band_trades_moves_for_error(site) -> None:
    small = _noon_window(site, 2.0, controller="open_loop_spa",
                         settings=ControlSettings(dead_band_deg=0.05)).summary()
    big = _noon_window(site, 2.0, controller="open_loop_spa",
                       settings=ControlSettings(dead_band_deg=0.5)).summary()
    assert big["moves"] < small["moves"] / 3
    assert big["pointing_error_rms_mrad"] > 2 * small["pointing_error_rms_mrad"]


def test_night_stow_and_morning_wake(site) -> None:
    start = pd.Timestamp("2024-03-15 04:00", tz=TZ)
    r = simulate(site, start, start + pd.Timedelta(hours=4), controller="open_loop_spa")
    s = r.series.tz_convert(TZ)
    night = s[s["apparent_elevation"] < -2]
    assert (night["elevation_joint_deg"] == site.tracker.elevation_max_deg).all()
    day = s[s["apparent_elevation"] > 0]
    # woken before sunrise: facing the sun from the first daylight minute, within the open
    # loop's own bound (test_open_loop_follows_the_sun_within_dead_band_and_lag; 2.0 measured)
    assert day["pointing_error_mrad"].max() < 4.0


@pytest.mark.parametrize("controller", ["open_loop_spa", "hybrid", "closed_loop_camera"])
def test_every_controller_unwinds_a_midnight_sun_at_its_lowest(controller: str) -> None:
    """Tromsø (69.65° N) on 21 June: the sun goes round the sky, lowest (3.3°) due north at
    00:46. Every controller keeps its azimuth within the day's reference ± 180° (0…360°
    here) and unwinds there, once; the closed camera loop, which steps from its encoder
    reading, followed the sun past 360° and ran into the 450° limit at 07:24, turning 358°
    in daylight (a tester's finding)."""
    from sim.sites import relocated_config, site_from_dict

    config = relocated_config(load_site("tehuantepec").to_config(), {
        "site_id": "tromso", "latitude_deg": 69.65, "longitude_deg": 18.96,
        "timezone": "Europe/Oslo"})
    tromso = site_from_dict(config)
    start = pd.Timestamp("2024-06-21 00:20", tz="Europe/Oslo")
    s = simulate(tromso, start, start + pd.Timedelta(minutes=50), controller=controller).series
    joint = s["azimuth_joint_deg"].to_numpy()
    assert joint.min() > -0.5 and joint.max() < 360.5
    assert (np.abs(np.diff(joint)) > 90).sum() in (1, 2)  # one swing (two samples if slow)
    # on the sun again after it (the short way round; measured within 0.1°)
    off = (joint[-10:] - s["solar_azimuth"].to_numpy()[-10:] + 180.0) % 360.0 - 180.0
    assert np.abs(off).max() < 0.5


# ---------------------------------------------------------------- disturbances' signatures


def test_clock_offset_shifts_the_hour_angle(site) -> None:
    s = _noon_window(site, 2.0, controller="open_loop_spa",
                     disturbances=Disturbances(clock_offset_s=240.0),
                     settings=ControlSettings(dead_band_deg=0.01)).series
    err = s["pointing_error_mrad"].to_numpy()
    # at a sample the pose is the target set 30 s before for 15 s ahead, on a clock 240 s
    # fast: the sun 225 s ahead, 225 s x 15 deg/h x cos(dec -2.4 deg) = 0.937 deg = 16.35 mrad
    assert np.median(err) == pytest.approx(16.35, abs=0.015)  # measured 16.354


def test_encoder_drift_grows_linearly(site) -> None:
    r = _noon_window(site, 3.0, controller="open_loop_spa",
                     disturbances=Disturbances(encoder_drift_mrad_per_h=10.0),
                     settings=ControlSettings(dead_band_deg=0.01))
    s = r.series
    hours = (s.index - s.index[0]) / pd.Timedelta(hours=1)
    d_el = 1000 * np.radians(s["elevation_joint_deg"] - s["elevation_command_deg"])
    # true joint = command - drift * t (the encoder reads ahead by the drift)
    # (measured within 0.08 mrad)
    assert np.allclose(d_el[10:], -10.0 * np.asarray(hours)[10:], atol=0.2)


def test_backlash_offsets_the_output(site) -> None:
    r = _noon_window(site, 2.0, day="2024-12-10", controller="open_loop_spa",
                     disturbances=Disturbances(backlash_deg=0.5),
                     settings=ControlSettings(dead_band_deg=0.01))
    s = r.series
    d_el = s["elevation_joint_deg"] - s["elevation_command_deg"]
    # gravity presses the elevation gear on one flank (seed 002: G2 < 0): +b/2 all the time
    assert np.median(d_el) == pytest.approx(0.25, abs=1e-9)  # exactly: it rests on the flank
    d_az = s["azimuth_joint_deg"] - s["azimuth_command_deg"]
    # the afternoon azimuth sweep drives the + flank: the output trails by b/2
    assert np.median(d_az) == pytest.approx(-0.25, abs=1e-9)


def test_gusts_cost_energy(site) -> None:
    calm = _noon_window(site, 2.0, controller="open_loop_spa").summary()
    gusty = _noon_window(site, 2.0, controller="open_loop_spa",
                         disturbances=Disturbances(gust_torque_nm=3.0)).summary()
    assert gusty["actuator_move_energy_wh"] > 1.1 * calm["actuator_move_energy_wh"]
    assert calm["actuator_moves_beyond_drive"] == gusty["actuator_moves_beyond_drive"] == 0
    assert calm["actuator_warning"] is None


def test_a_gust_beyond_the_drive_is_said_so(site) -> None:
    """A gust past the gearbox's 60 N m rating asks more than the drive gives: the twin
    still costs the moves as made (4,926 W per axis at 1,000 N m, where a 24 V bus through
    a 1.5 Ω winding gives at most 404 W), and the summary says how many and that the
    energy is not this machine's (a tester's finding: no word of it)."""
    s = _noon_window(site, 2.0, controller="open_loop_spa",
                     disturbances=Disturbances(gust_torque_nm=1000.0)).summary()
    assert 0 < s["actuator_moves_beyond_drive"] <= s["moves"]
    assert "60 N m rating" in s["actuator_warning"]
    assert "not what this machine would draw" in s["actuator_warning"]


def test_a_slow_drive_moves_at_its_rated_speed_and_wakes_in_time(site) -> None:
    """A site's drive rated 0.05° s⁻¹ (a heavy tracker) is moved at that speed, not at
    the default profile's 2.86° s⁻¹: it had swung the 176° from the evening's pose to the
    sunrise's within one 60 s step, every move counted beyond the drive (a tester's
    finding). Moved at its speed, it wakes early enough to face the sun as it rises
    (``DriveLimits.wake_slew_s``, 2 h here): 5 min before sunrise, the slew took the first
    hour of sun — 32.0 Wh m⁻² of beam on the second day, 84 of 1,350 minutes outside the
    pointing statistics. An independent follower (pvlib's sun, 1 s steps, the same 30 s
    commands and dead band, each axis at 0.05° s⁻¹) loses 31.0 Wh m⁻² waking 300 s
    before sunrise and 0.00 waking 3,900 s before; the twin now 0.007."""
    slow = dataclasses.replace(motors.AxisDrive.azimuth_default(),
                               max_output_speed_rad_s=math.radians(0.05))
    slow_site = dataclasses.replace(site, drives={"azimuth": slow, "elevation": dataclasses.replace(
        slow, gear_ratio=motors.AxisDrive.elevation_default().gear_ratio)})
    start = pd.Timestamp("2024-03-14", tz=TZ)
    r = simulate(slow_site, start, start + pd.Timedelta(days=2), controller="open_loop_spa")
    ser, s = r.series, r.summary()
    assert s["actuator_moves_beyond_drive"] == 0
    assert np.abs(np.diff(ser["azimuth_joint_deg"].to_numpy())).max() <= 0.05 * 60 + 1e-6
    assert np.abs(np.diff(ser["elevation_joint_deg"].to_numpy())).max() <= 0.05 * 60 + 1e-6
    assert s["pointing_error_minutes"] == 1350  # every minute with the sun above 5°
    day2 = ser[ser.index >= start + pd.Timedelta(days=1)]
    loc = pvlib.location.Location(site.latitude, site.longitude, altitude=site.altitude)
    dni = loc.get_clearsky(day2.index, model="ineichen")["dni"].to_numpy()
    cos = np.maximum(np.cos(np.radians(day2["tracker_aoi"].to_numpy())), 0.0)
    up = day2["apparent_elevation"].to_numpy() > 0
    assert (dni * (1 - cos))[up].sum() / 60 < 0.1


def test_camera_offset_misleads_the_camera_loop_not_the_ephemeris(site) -> None:
    d = Disturbances(camera_offset_right_deg=1.0)
    hyb = _noon_window(site, 2.0, controller="hybrid", disturbances=d).summary()
    ol = _noon_window(site, 2.0, controller="open_loop_spa", disturbances=d).summary()
    assert hyb["pointing_error_rms_mrad"] == pytest.approx(17.45, abs=2.0)  # 1 deg
    assert ol["pointing_error_rms_mrad"] < 2.5


# ---------------------------------------------------------------- clouds


def test_clouds_do_not_make_the_closed_loop_wander(site) -> None:
    cloudy = CameraSetup(clouds=CloudField(cover=0.5, optical_depth=3.0, seed=1))
    # a quarter of an hour at a frame a second (half an hour gave the same figures, 2x slower)
    r = _noon_window(site, 0.25, controller="closed_loop_camera", camera=cloudy)
    s = r.summary()
    # the clouds hid or cut the sun in over half of the 900 frames (388 used): those were not
    # used
    assert s["camera_frames"] == 900 and s["camera_frames_used"] < 0.5 * s["camera_frames"]
    # ... the loop fell back to the ephemeris and stayed as close as on a clear sky
    # (measured: 2.45 mrad max, 1.5 RMS; clear sky 2.26 max)
    err = r.series["pointing_error_mrad"]
    assert err.max() < 3.0
    # without the gate that ignores dimmed or cut suns it chases the clouds' edges (9.6 mrad)
    loose = ControlSettings(min_peak_dn=0, area_tolerance=1e9, max_jump_deg=1e9,
                            min_confidence=0.0)
    r2 = _noon_window(site, 0.25, controller="closed_loop_camera", camera=cloudy,
                      settings=loose)
    assert r2.series["pointing_error_mrad"].max() > 3 * err.max()
    # with a 2 deg pedestal yaw it never goes beyond the ephemeris's own error (~12 mrad;
    # measured 11.6)
    d = Disturbances(pedestal_yaw_deg=2.0)
    r3 = _noon_window(site, 0.25, controller="closed_loop_camera", camera=cloudy,
                      disturbances=d)
    assert r3.series["pointing_error_mrad"].max() < 12.5


def _relocated(site, **place):
    """``site``'s tracker and arrays at another place (``sim.sites.relocated_config``)."""
    from sim.sites import relocated_config, site_from_dict

    return site_from_dict(relocated_config(site.to_config(), place))


def test_hybrid_keeps_a_yaws_correction_across_the_midnight_suns_unwind(site) -> None:
    """Tromsø, 20-21 June, a 2° pedestal yaw: after the unwind at the sun's lowest the
    encoder reads 358° while the ephemeris's joint azimuth is 0.06°; the correction taken
    from such a frame was 358°, and the hybrid lost the sun for the night and morning
    (1,175 mrad RMS, 1,455 Wh of 3,960 lost over 12 h; a tester's finding). The correction
    is an angle: taken the short way round, 2.08 mrad RMS, beside open_loop_spa's 33."""
    tromso = _relocated(site, site_id="tromso", latitude_deg=69.65, longitude_deg=18.96,
                        timezone="Europe/Oslo")
    start = pd.Timestamp("2024-06-20 18:00", tz="Europe/Oslo")
    s = simulate(tromso, start, start + pd.Timedelta(hours=12), controller="hybrid",
                 disturbances=Disturbances(pedestal_yaw_deg=2.0)).summary()
    assert s["pointing_error_rms_mrad"] < 3.0  # measured 2.08
    assert s["pointing_loss_wh"] < 3.0  # measured 2.64


def test_a_correction_past_the_sweeps_limit_stays_at_it(site) -> None:
    """The equator on the equinox: the noon sun passes 0.1° north of the zenith, the day's
    sweep is 0° ± 180° and ends at the −90° limit, where the sun sets (270.2°). A 2° yaw's
    correction asks for −91.8°: its equivalent 268.2° lies outside the sweep, and the
    hybrid had turned 360° round to it in the afternoon (720.6° of azimuth travel that
    day); it stays at the limit, 1.8° short at worst (31.2 mrad; a tester's finding)."""
    equator = _relocated(site, site_id="equator", latitude_deg=0.0, longitude_deg=32.58,
                         timezone="Africa/Kampala")
    start = pd.Timestamp("2024-03-20", tz="Africa/Kampala")
    r = simulate(equator, start, start + pd.Timedelta(days=1), controller="hybrid",
                 disturbances=Disturbances(pedestal_yaw_deg=2.0))
    joint = r.series["azimuth_joint_deg"].to_numpy()
    assert joint.min() >= -90.0 and joint.max() <= 270.0
    assert np.abs(np.diff(joint)).sum() < 361.0  # measured 359.6: the flip and the night's
    assert r.summary()["pointing_error_max_mrad"] < 32.0  # measured 31.2


def test_a_sun_path_past_the_range_still_turns_round(site) -> None:
    """A ±180° azimuth range facing Tehuantepec's southern sun: the sun's own path leaves
    the range at noon, and the tracker turns round once (the range's cost: 485 mrad for a
    sample, 1.9 Wh of the day). Staying at the limit is for a correction past it only:
    applied to the sun's path it held the tracker at 180° all afternoon (665 mrad RMS,
    979 Wh lost; a tester's own first fix)."""
    narrow = dataclasses.replace(site, tracker=dataclasses.replace(
        site.tracker, azimuth_min_deg=-180.0, azimuth_max_deg=180.0))
    start = pd.Timestamp("2024-03-15", tz=TZ)
    s = simulate(narrow, start, start + pd.Timedelta(days=1), controller="open_loop_spa")
    assert s.summary()["pointing_loss_wh"] < 3.0  # measured 1.90
    assert s.summary()["pointing_error_p95_mrad"] < 3.0  # measured 2.35


def test_hybrid_takes_no_correction_from_a_slewing_tracker_near_the_zenith(site) -> None:
    """A drive at 0.05° s⁻¹ at the equator on the equinox needs an hour for the noon
    flip, with the sun within 3° of the zenith. The camera still sees the sun, 13° of
    azimuth and then 123° off; ``A + h / cos E`` with cos E floored at 0.05 took 9° and
    then 99° of correction from those frames, kept them, and the panel lay flat at 2 pm
    (a tester's finding). Frames where the small-angle conversion does not hold are not
    used: the hybrid points as the open loop does through the flip (77.1 mrad RMS each
    from 12:30 to 14:30, the flip's lag) and is back on the sun after it (1.4 mrad)."""
    slow = dataclasses.replace(motors.AxisDrive.azimuth_default(),
                               max_output_speed_rad_s=math.radians(0.05))
    equator = dataclasses.replace(
        _relocated(site, site_id="equator", latitude_deg=0.0, longitude_deg=32.58,
                   timezone="Africa/Kampala"), drives={"azimuth": slow, "elevation": slow})
    start = pd.Timestamp("2024-03-20 12:30", tz="Africa/Kampala")
    runs = {c: simulate(equator, start, start + pd.Timedelta(hours=2), controller=c)
            for c in ("hybrid", "open_loop_spa")}
    hyb, ol = (runs[c].summary() for c in ("hybrid", "open_loop_spa"))
    assert hyb["pointing_loss_wh"] == pytest.approx(ol["pointing_loss_wh"], rel=0.02)
    assert hyb["pointing_error_max_mrad"] < 160.0  # measured 158.6, the open loop's 158.5
    assert runs["hybrid"].series["pointing_error_mrad"].iloc[-1] < 3.0  # measured 1.36


def test_hybrid_still_removes_a_large_yaw(site) -> None:
    """The small-angle rule leaves the hybrid its reach: a 28° pedestal yaw is removed
    within minutes of noon (measured 2.58 mrad max over the last hour of the window; with
    a 10° bound it was never corrected, 150 mrad RMS)."""
    r = _noon_window(site, 2.0, controller="hybrid",
                     disturbances=Disturbances(pedestal_yaw_deg=28.0))
    assert r.series["pointing_error_mrad"].iloc[-60:].max() < 3.0


def test_hybrid_keeps_its_correction_through_clouds(site) -> None:
    cloudy = CameraSetup(clouds=CloudField(cover=0.6, optical_depth=4.0, seed=5))
    d = Disturbances(pedestal_yaw_deg=2.0)
    r = _noon_window(site, 3.0, controller="hybrid", disturbances=d, camera=cloudy)
    clear = _noon_window(site, 3.0, controller="hybrid", disturbances=d).series
    s = r.summary()
    # 60 % cover, optical depth 4: most frames go unused (measured 18 % used)
    assert s["camera_frames_used"] < 0.4 * s["camera_frames"]
    # after the first correction (the run starts uncorrected, ~30 mrad off) the cloudy run
    # stays as close to the sun as the clear one
    late = r.series.index > r.series.index[0] + pd.Timedelta(minutes=30)
    assert r.series.loc[late, "pointing_error_mrad"].max() < 6.0
    rms = float(np.sqrt(np.mean(r.series.loc[late, "pointing_error_mrad"] ** 2)))
    rms_clear = float(np.sqrt(np.mean(clear.loc[late, "pointing_error_mrad"] ** 2)))
    assert rms < rms_clear + 0.5


def _weather(dni_until_noon: float, dni_after: float) -> pd.DataFrame:
    """Hourly weather around 2024-03-15 at Tehuantepec: the beam ``dni_until_noon`` [W m⁻²]
    up to 11:00, ``dni_after`` from 12:00 (linear between), a diffuse 150 W m⁻²."""
    index = pd.date_range("2024-03-14", "2024-03-17", freq="h", tz=TZ)
    dni = np.where(index.hour < 12, dni_until_noon, dni_after)
    return pd.DataFrame({"ghi": 150.0 + 0.8 * dni, "dni": dni, "dhi": 150.0}, index=index)


def test_the_camera_sees_the_sun_only_in_the_weathers_beam(site) -> None:
    """With weather the frames show the sun only while the beam is at least the WMO's
    sunshine threshold (DNI ≥ 120 W m⁻², ``sim.tracking.SUNSHINE_DNI_W_M2``): ``hybrid``
    keeps its last correction through the overcast afternoon and ``closed_loop_camera``
    falls back to the ephemeris. The camera found the sun on a day of DNI 0 in 652 of 657
    frames and removed a 2° yaw as on a clear day (a tester's finding)."""
    d = Disturbances(pedestal_yaw_deg=2.0)
    overcast_pm = _weather(800.0, 0.0)  # DNI below 120 W m⁻² from 11:51
    start = pd.Timestamp("2024-03-15 10:00", tz=TZ)
    r = simulate(site, start, start + pd.Timedelta(hours=4), controller="hybrid",
                 disturbances=d, weather=overcast_pm)
    s = r.summary()
    # a frame a minute: 240 taken, the sun in those up to 11:51 only (measured 112)
    assert s["camera_frames"] == 240 and 105 <= s["camera_frames_found"] <= 112
    # the morning's correction kept: as close as with the sun in view (open loop: 24 mrad)
    err = r.series["pointing_error_mrad"]
    assert err[err.index > start + pd.Timedelta(minutes=30)].max() < 4.0
    # the closed loop under the overcast sky: no sun found, the ephemeris's own error
    at_one = pd.Timestamp("2024-03-15 13:00", tz=TZ)
    runs = {dni: simulate(site, at_one, at_one + pd.Timedelta(minutes=10),
                          controller="closed_loop_camera", disturbances=d,
                          weather=_weather(dni, dni)) for dni in (0.0, 800.0)}
    assert runs[0.0].summary()["camera_frames_found"] == 0
    # each minute's sample: 10.3-11.7 mrad overcast, 0.6-2.2 in the sun after the first
    assert runs[0.0].series["pointing_error_mrad"].min() > 10.0
    assert runs[800.0].summary()["camera_frames_found"] == 600
    assert runs[800.0].series["pointing_error_mrad"].iloc[1:].max() < 3.0


def test_cpv_loses_the_beam_outside_its_acceptance(site) -> None:
    d = Disturbances(pedestal_yaw_deg=2.0)  # 2 deg x cos(elevation): 10-20 mrad off
    narrow = _noon_window(site, 2.0, controller="open_loop_spa", disturbances=d,
                          receiver="cpv", acceptance_angle_deg=0.2).summary()
    wide = _noon_window(site, 2.0, controller="open_loop_spa", disturbances=d,
                        receiver="cpv", acceptance_angle_deg=3.0).summary()
    assert narrow["tracker_energy_wh"] == pytest.approx(0.0, abs=1e-9)
    assert narrow["pointing_loss_wh"] == pytest.approx(wide["tracker_energy_wh"], rel=1e-9)
    assert wide["pointing_loss_wh"] == pytest.approx(0.0, abs=1e-9)
    # the Fresnel spot at seed 001's 1.5 m: f tan(theta) (measured 0.14 % apart: the RMS of
    # the tangents against the tangent of the RMS)
    assert wide["spot_displacement_rms_m"] == pytest.approx(
        1.5 * math.tan(wide["pointing_error_rms_mrad"] / 1000), rel=0.004)


def test_flat_pointing_loss_is_the_beam_cosine(site) -> None:
    r = _noon_window(site, 2.0, controller="open_loop_spa",
                     disturbances=Disturbances(clock_offset_s=1800.0))
    s, ser = r.summary(), r.series
    theta = ser["pointing_error_mrad"].to_numpy() / 1000.0  # ~130 mrad
    ideal = _noon_window(site, 2.0).series
    # the plane of array loses the beam's (1 - cos theta), pvlib's clear-sky DNI; the diffuse
    # terms (Hay-Davies) move to first order in the tilt, both ways: measured 9 % less
    loc = pvlib.location.Location(site.latitude, site.longitude, altitude=site.altitude)
    dni = loc.get_clearsky(ideal.index, model="ineichen")["dni"].to_numpy()
    lost_poa = ideal["tracker_poa_global"].to_numpy() - ser["tracker_poa_global"].to_numpy()
    assert lost_poa.sum() == pytest.approx((dni * (1.0 - np.cos(theta))).sum(), rel=0.2)
    # the modules turn that share of their irradiance into a smaller share of their power
    # (a cooler cell, the voltage's log of the irradiance): measured 0.79
    lost_share = lost_poa / ideal["tracker_poa_global"].to_numpy()
    by_share_wh = float((ideal["tracker_power_w"].to_numpy() * lost_share).sum() / 60.0)
    assert 0.7 < s["pointing_loss_wh"] / by_share_wh < 0.9


# ---------------------------------------------------------------- open loop through a model


def test_open_loop_model_without_terms_is_open_loop_spa(site) -> None:
    times = pd.date_range(pd.Timestamp("2024-03-15 07:00", tz=TZ), periods=60, freq="10min")
    plain = ephemeris_joint_targets(times, site)
    perfect = ephemeris_joint_targets(times, site, pointing_model=PointingModel())
    for k in plain:  # through the ENU round trip: 1e-12° apart
        assert np.allclose(plain[k], perfect[k], rtol=0.0, atol=1e-9), k
    assert make_controller("open_loop_model", site).pointing_model == PointingModel()


@dataclass(frozen=True)
class _OvercastFrom(CloudField):
    """A sky that is clear until ``from_s`` (since the run's start) and overcast after."""

    from_s: float = 0.0

    def density(self, x_deg, y_deg, t_s: float):  # type: ignore[no-untyped-def]
        shape = np.broadcast_shapes(np.shape(x_deg), np.shape(y_deg))
        return np.full(shape, 1.0 if t_s >= self.from_s else 0.0)


#: Issue 25 item 4's mount: pedestal yaw (= azimuth zero), elevation zero and both tilts
#: 0.5–2° (1.2° toward azimuth 135°: north −0.85°, east +0.85°).
MOUNT = Disturbances(pedestal_yaw_deg=1.5, pedestal_tilt_deg=1.2,
                     pedestal_tilt_azimuth_deg=135.0, elevation_zero_deg=-0.8)


@pytest.fixture(scope="module")
def model_of_the_day_before(site):
    """The pointing model fitted from the day before's camera offsets: the tracker ran open
    loop on SPA (its encoders at the commands) and its camera saw the sun at the offsets of
    the twin's own camera geometry (sim.disturbances.sun_in_camera), 0.3 mrad of noise."""
    day = pd.Timestamp("2024-03-14", tz=TZ)
    s = simulate(site, day, day + pd.Timedelta(days=1), controller="open_loop_spa",
                 disturbances=MOUNT).series
    on = np.isfinite(s["pointing_error_mrad"].to_numpy())
    az, el = s["azimuth_command_deg"].to_numpy()[on], s["elevation_command_deg"].to_numpy()[on]
    sun = enu_from_sky(s["solar_azimuth"].to_numpy()[on], s["apparent_elevation"].to_numpy()[on])
    cam = np.array([sun_in_camera(a, e, MOUNT, v) for a, e, v in zip(az, el, sun, strict=True)])
    rng = np.random.default_rng(4)
    ox = 1000 * np.arctan2(cam[:, 0], cam[:, 2]) + rng.normal(0.0, 0.3, len(cam))
    oy = 1000 * np.arctan2(cam[:, 1], cam[:, 2]) + rng.normal(0.0, 0.3, len(cam))
    return fit_pointing_model(s.index[on], az, el, ox, oy, site.latitude, site.longitude,
                              site.altitude)


def test_open_loop_model_holds_the_sun_all_day_where_hybrid_loses_it_under_clouds(
        site, model_of_the_day_before) -> None:
    """Issue 25 item 4: the camera clouded from 12:30 on; ``hybrid`` holds the sun while its
    camera sees it, then keeps a morning correction that does not fit the afternoon sky;
    ``open_loop_model`` (the day before's fit, its terms passed as GET …/pointing-model
    answers them) holds it all day."""
    fit = model_of_the_day_before
    assert fit.model.elevation_zero_deg == pytest.approx(-0.8, abs=0.01)
    day = pd.Timestamp("2024-03-15", tz=TZ)
    end = day + pd.Timedelta(days=1)
    overcast_s = (pd.Timestamp("2024-03-15 12:30", tz=TZ) - day).total_seconds()
    camera = CameraSetup(clouds=_OvercastFrom(cover=1.0, optical_depth=4.0, from_s=overcast_s))
    terms = {k: {"value": v, "std": fit.std.get(k)} for k, v in fit.model.as_dict().items()}
    hybrid = simulate(site, day, end, controller="hybrid", disturbances=MOUNT, camera=camera)
    model = simulate(site, day, end, controller="open_loop_model", disturbances=MOUNT,
                     camera=camera, pointing_model_terms=terms)
    hour = hybrid.series.index.tz_convert(TZ).hour
    morning, afternoon = (hour >= 8) & (hour < 12), hour >= 13
    err_h = hybrid.series["pointing_error_mrad"]
    err_m = model.series["pointing_error_mrad"]
    # the camera saw the sun in the morning only: a frame a minute from sunrise to 12:30
    assert 330 < hybrid.summary()["camera_frames_used"] < 390  # measured 360
    # measured: hybrid 3.3 mrad at most from 8:00 to 12:00, from 13:00 on 9-54 mrad (median
    # 34); open_loop_model 2.4 mrad at most all day, 1.40 RMS (the 0.1° dead band alone is
    # 1.7 mrad); open loop on SPA through this mount: 30 mrad RMS
    assert err_h[morning].max() < 4.0
    assert err_h[afternoon].median() > 25.0 and err_h[afternoon].max() > 45.0
    assert err_m.max() < 3.0
    assert model.summary()["pointing_error_rms_mrad"] < 1.6
    assert model.summary()["camera_frames"] == 0
