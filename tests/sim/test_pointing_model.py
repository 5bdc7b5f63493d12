"""Pointing model (issue 25): fitted back from a misaligned mount built independently.

The reference mount is built from scipy's :class:`Rotation` (extrinsic Euler
angles: R = R_y(t_east)·R_x(−t_north), pose Rz(−az)·Rx(el)), with the offsets
defined as in issue 25 (1000·atan2(s·h, s·n), 1000·atan2(s·u, s·n)); the fit
uses its own component-wise formulation (sim/pointing_model.py). The twin's
disturbances (sim/disturbances.py) are fitted back too, to show the two mean
the same thing.
"""

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from sim import disturbances as dist
from sim.pointing_model import (
    CORE_TERMS,
    MAX_DETERMINED_STD_DEG,
    PointingModel,
    command_angles,
    fit_pointing_model,
    pointing_std_mrad,
    predict_offsets_mrad,
)
from sim.sites import load_site
from sim.sun import solar_position
from vision.sphere import enu_from_sky

SITE = load_site("tehuantepec")
TRUE = {"azimuth_zero_deg": 1.7, "elevation_zero_deg": -0.8,
        "pedestal_tilt_north_deg": 0.6, "pedestal_tilt_east_deg": -1.3}


def _day(date: str) -> tuple[pd.DatetimeIndex, pd.DataFrame]:
    """1-minute UTC times of one local day with the apparent sun above 5°."""
    times = pd.date_range(pd.Timestamp(date, tz=SITE.timezone), periods=24 * 60, freq="1min")
    sun = solar_position(times, SITE.latitude, SITE.longitude, SITE.altitude)
    up = sun["apparent_elevation"].to_numpy() > 5.0
    return sun.index[up], sun[up]


def _reference_axes(terms: dict[str, float], az_enc: np.ndarray, el_enc: np.ndarray):
    """(h, n, u) of the real mount, ENU, by scipy rotations (independent of the fit's code)."""
    mount = Rotation.from_euler("xy", [-terms["pedestal_tilt_north_deg"],
                                       terms["pedestal_tilt_east_deg"]], degrees=True)
    pose = Rotation.from_euler("xz", np.stack([el_enc + terms["elevation_zero_deg"],
                                               -(az_enc + terms["azimuth_zero_deg"])], axis=1),
                               degrees=True)
    r = mount * pose
    return r.apply([1.0, 0.0, 0.0]), r.apply([0.0, 1.0, 0.0]), r.apply([0.0, 0.0, 1.0])


def _offsets_mrad(s, h, n, u):
    sn = np.einsum("ij,ij->i", s, n)
    return (1000 * np.arctan2(np.einsum("ij,ij->i", s, h), sn),
            1000 * np.arctan2(np.einsum("ij,ij->i", s, u), sn))


@pytest.fixture(scope="module")
def observed_day():
    """Open loop on SPA through the misaligned mount, 0.3 mrad noise, 40 % clouded, 2 % glints."""
    rng = np.random.default_rng(25)
    times, sun = _day("2026-03-10")
    az_enc, el_enc = sun["azimuth"].to_numpy(), sun["apparent_elevation"].to_numpy()
    s = enu_from_sky(az_enc, el_enc)
    h, n, u = _reference_axes(TRUE, az_enc, el_enc)
    ox, oy = _offsets_mrad(s, h, n, u)
    ox, oy = ox + rng.normal(0, 0.3, ox.size), oy + rng.normal(0, 0.3, oy.size)
    seen = rng.random(ox.size) >= 0.4
    glint = rng.random(ox.size) < 0.02
    ang = rng.uniform(0, 2 * np.pi, ox.size)
    mag = rng.uniform(15, 40, ox.size)
    ox = np.where(glint, ox + mag * np.cos(ang), ox)
    oy = np.where(glint, oy + mag * np.sin(ang), oy)
    return times[seen], az_enc[seen], el_enc[seen], ox[seen], oy[seen], glint[seen]


@pytest.fixture(scope="module")
def fitted(observed_day):
    times, az, el, ox, oy, _ = observed_day
    return fit_pointing_model(times, az, el, ox, oy, SITE.latitude, SITE.longitude,
                              SITE.altitude)


def test_every_term_is_recovered_within_its_uncertainty(fitted) -> None:
    for name, value in TRUE.items():
        got = getattr(fitted.model, name)
        assert got == pytest.approx(value, abs=0.01), name  # issue 25 asks 0.05°
        assert abs(got - value) < 4 * fitted.std[name], (name, got, fitted.std[name])
        assert 0 < fitted.std[name] < 0.005, name
    assert set(CORE_TERMS) <= set(fitted.identifiable)
    assert fitted.residual_rms_mrad == pytest.approx(0.3, rel=0.15)


def test_glints_are_the_outliers(observed_day, fitted) -> None:
    glint = observed_day[-1]
    assert glint.sum() >= 5
    assert np.array_equal(fitted.outlier, glint)


def test_noise_free_readings_have_no_outliers_and_minutes_determine_nothing() -> None:
    """Two testers' findings. Noise-free readings (σ ≈ 0): 38 of 138 observations were
    "outliers" at 6e-5 mrad (the robust sigma has a floor, MIN_SIGMA_MRAD). Ten observations
    over 18 minutes: every term uncorrelated, yet uncertain by 0.24–0.33°, was listed as
    separated by the data; a term is determined only within 0.5 mrad."""
    times, sun = _day("2026-03-10")
    az_enc, el_enc = sun["azimuth"].to_numpy(), sun["apparent_elevation"].to_numpy()
    s = enu_from_sky(az_enc, el_enc)
    ox, oy = _offsets_mrad(s, *_reference_axes(TRUE, az_enc, el_enc))
    clean = fit_pointing_model(times, az_enc, el_enc, ox, oy, SITE.latitude, SITE.longitude,
                               SITE.altitude)
    assert clean.n_outliers == 0
    assert set(CORE_TERMS) <= set(clean.identifiable)
    rng = np.random.default_rng(7)
    few = slice(300, 320, 2)  # ten readings over 18 minutes of the morning
    noisy_x, noisy_y = ox + rng.normal(0, 0.3, ox.size), oy + rng.normal(0, 0.3, oy.size)
    short = fit_pointing_model(times[few], az_enc[few], el_enc[few], noisy_x[few],
                               noisy_y[few], SITE.latitude, SITE.longitude, SITE.altitude)
    assert all(short.std[t] > MAX_DETERMINED_STD_DEG for t in CORE_TERMS), short.std
    assert short.identifiable == ()


def test_a_burst_of_frames_selects_no_optional_term() -> None:
    """A tester's finding: 72 frames a second apart (the blob's centroid error changing as it
    crosses a pixel) selected a collimation of 16.9° ± 0.46° beside core terms of 14–50°;
    here both optional terms came in at ± 500–750°. An optional term enters only when the
    data determine it (standard error within MAX_DETERMINED_STD_DEG)."""
    times = pd.date_range(pd.Timestamp("2026-03-10 10:00", tz=SITE.timezone), periods=72,
                          freq="1s")
    sun = solar_position(times, SITE.latitude, SITE.longitude, SITE.altitude)
    az, el = sun["azimuth"].to_numpy(), sun["apparent_elevation"].to_numpy()
    ox, oy = _offsets_mrad(enu_from_sky(az, el), *_reference_axes(TRUE, az, el))
    rng = np.random.default_rng(0)
    drift = 0.2 * ((np.arange(72) - 36) / 36) ** 2  # [mrad]
    fit = fit_pointing_model(times, az, el, ox + drift + rng.normal(0, 0.02, 72),
                             oy + drift + rng.normal(0, 0.02, 72), SITE.latitude,
                             SITE.longitude, SITE.altitude)
    assert fit.fitted_terms == CORE_TERMS
    assert fit.identifiable == ()


@pytest.mark.parametrize("step_s", [60, 10])
def test_the_uncertainty_covers_a_camera_whose_error_persists_from_frame_to_frame(
        step_s: int) -> None:
    """A tester's finding: the standard errors took each frame's error as independent, but a
    camera's centroid is biased by the sub-pixel phase of the sun's blob, which changes
    slowly; frames every 10 s over a day with a 0.3 mrad phase bias put the terms up to 21
    standard errors from the truth (every 60 s, up to 9). The errors are widened by the
    residuals' autocorrelation time; the terms are unchanged."""
    times = pd.date_range(pd.Timestamp("2026-03-10", tz=SITE.timezone),
                          periods=86400 // step_s, freq=f"{step_s}s")
    sun = solar_position(times, SITE.latitude, SITE.longitude, SITE.altitude)
    up = sun["apparent_elevation"].to_numpy() > 5.0
    times, sun = times[up], sun[up]
    az, el = sun["azimuth"].to_numpy(), sun["apparent_elevation"].to_numpy()
    ox, oy = _offsets_mrad(enu_from_sky(az, el), *_reference_axes(TRUE, az, el))
    rng = np.random.default_rng(0)
    px_per_mrad = 0.55  # seed 000's camera: 505 px of focal length

    def seen(offset_mrad: np.ndarray, phase: float) -> np.ndarray:
        bias = 0.3 * np.sin(2 * np.pi * (offset_mrad * px_per_mrad + phase))
        return offset_mrad + bias + rng.normal(0, 0.05, offset_mrad.size)

    fit = fit_pointing_model(times, az, el, seen(ox, 0.3), seen(oy, 0.8), SITE.latitude,
                             SITE.longitude, SITE.altitude)
    for name, value in TRUE.items():
        got = getattr(fit.model, name)
        assert abs(got - value) < 3 * fit.std[name], (name, got, value, fit.std[name])
        assert abs(got - value) < 0.01, name


def test_next_days_commands_put_the_real_axis_on_the_sun(fitted) -> None:
    _, sun = _day("2026-03-11")
    saz, sel = sun["azimuth"].to_numpy(), sun["apparent_elevation"].to_numpy()
    s = enu_from_sky(saz, sel)

    def error_mrad(az_cmd, el_cmd):
        _, n, _ = _reference_axes(TRUE, az_cmd, el_cmd)
        return 1000 * np.arccos(np.clip(np.einsum("ij,ij->i", s, n), -1, 1))

    corrected = error_mrad(*command_angles(fitted.model, saz, sel))
    open_loop = error_mrad(saz, sel)
    assert corrected.max() < 0.3
    assert np.sqrt(np.mean(open_loop**2)) > 20.0


@pytest.mark.parametrize(("label", "every", "largest_std_mrad"),
                         [("a day, every 10 min", "10min", 0.2), ("72 s of frames", "1s", None)])
def test_a_commands_stated_uncertainty_covers_its_miss(label: str, every: str,
                                                       largest_std_mrad: float | None) -> None:
    """A tester's finding: a model fitted from 72 s of frames commanded the next afternoon
    39–52 mrad off the sun, worse than no model, with nothing said. The command's standard
    error (pointing_std_mrad) says so: it covers the miss of the next day's commands, small
    under a day's model, tens of mrad under the burst's."""
    rng = np.random.default_rng(4)
    start = pd.Timestamp("2026-03-10 07:00" if every == "10min" else "2026-03-10 10:00",
                         tz=SITE.timezone)
    times = pd.date_range(start, periods=60 if every == "10min" else 72, freq=every)
    sun = solar_position(times, SITE.latitude, SITE.longitude, SITE.altitude)
    az, el = sun["azimuth"].to_numpy(), sun["apparent_elevation"].to_numpy()
    ox, oy = _offsets_mrad(enu_from_sky(az, el), *_reference_axes(TRUE, az, el))
    fit = fit_pointing_model(times, az, el, ox + rng.normal(0, 0.3, az.size),
                             oy + rng.normal(0, 0.3, az.size), SITE.latitude, SITE.longitude,
                             SITE.altitude)
    _, next_day = _day("2026-03-11")
    saz, sel = next_day["azimuth"].to_numpy(), next_day["apparent_elevation"].to_numpy()
    caz, cel = command_angles(fit.model, saz, sel)
    _, n, _ = _reference_axes(TRUE, caz, cel)
    miss = 1000 * np.arccos(np.clip(np.einsum("ij,ij->i", enu_from_sky(saz, sel), n), -1, 1))
    std = pointing_std_mrad(fit, saz, sel, caz, cel)
    assert np.all(miss < 3 * std), (label, float((miss / std).max()))
    if largest_std_mrad is None:
        assert np.median(std) > 10.0 and np.median(miss) > 10.0, label
    else:
        assert std.max() < largest_std_mrad, label


def test_command_angles_invert_the_forward_model_with_collimation_and_npae() -> None:
    model = PointingModel(azimuth_zero_deg=-1.0, elevation_zero_deg=0.5,
                          pedestal_tilt_north_deg=-0.7, pedestal_tilt_east_deg=1.1,
                          collimation_deg=0.8, nonperpendicularity_deg=-0.6)
    saz = np.array([80.0, 130.0, 180.0, 250.0, 300.0])
    sel = np.array([10.0, 45.0, 70.0, 30.0, 8.0])
    ox, oy = predict_offsets_mrad(model, saz, sel, *command_angles(model, saz, sel))
    assert np.abs(ox).max() < 1e-6 and np.abs(oy).max() < 1e-6
    # without the Newton steps the closed form alone would be off by ~ the collimation
    ox0, _ = predict_offsets_mrad(model, saz, sel, *command_angles(model, saz, sel, iterations=0))
    assert np.abs(ox0).max() > 5.0


def test_the_twins_disturbances_mean_the_same_terms() -> None:
    """A mount simulated by sim.disturbances fits back to the same terms (signs and frames).

    The twin's base rotation R_tilt(tilt, tilt_azimuth)·Rz(−yaw) is decomposed by scipy
    into issue 25's R_y(t_east)·R_x(−t_north)·Rz(−azimuth_zero); the camera's offset
    up is an elevation zero to the camera (the offsets cannot tell them apart), its
    offset right the collimation: equal boresights, (sin c, cos c·cos e, cos c·sin e) =
    (sin r·cos u, cos r·cos u, sin u).
    """
    d = dist.Disturbances(pedestal_yaw_deg=1.5, pedestal_tilt_deg=1.2,
                          pedestal_tilt_azimuth_deg=230.0, camera_offset_up_deg=0.4,
                          camera_offset_right_deg=0.6, elevation_zero_deg=-0.3)
    times, sun = _day("2026-06-02")
    times, sun = times[::3], sun.iloc[::3]
    saz, sel = sun["azimuth"].to_numpy(), sun["apparent_elevation"].to_numpy()
    s = enu_from_sky(saz, sel)
    cam = np.array([dist.sun_in_camera(a, e, d, v) for a, e, v in zip(saz, sel, s, strict=True)])
    ox, oy = 1000 * np.arctan2(cam[:, 0], cam[:, 2]), 1000 * np.arctan2(cam[:, 1], cam[:, 2])
    fit = fit_pointing_model(times, saz, sel, ox, oy, SITE.latitude, SITE.longitude,
                             SITE.altitude)
    minus_az0, minus_tn, te = Rotation.from_matrix(dist.base_rotation(d)).as_euler(
        "zxy", degrees=True)
    r, u = np.radians(0.6), np.radians(0.4)
    c = np.arcsin(np.sin(r) * np.cos(u))
    expected = {"azimuth_zero_deg": -minus_az0, "pedestal_tilt_north_deg": -minus_tn,
                "pedestal_tilt_east_deg": te,
                # the encoder's zero plus the camera's boresight above the panel's normal
                "elevation_zero_deg": -0.3 + np.degrees(np.arctan2(np.sin(u),
                                                                   np.cos(r) * np.cos(u))),
                "collimation_deg": np.degrees(c)}
    assert fit.fitted_terms == (*CORE_TERMS, "collimation_deg")
    for name, value in expected.items():  # 1.2e-4° measured: the camera's roll
        # (second order in the offsets) differs between the two compositions
        assert getattr(fit.model, name) == pytest.approx(value, abs=3e-4), name
    assert fit.residual_rms_mrad < 1e-3
    # to first order the twin's tilt is (tilt·cos, tilt·sin) of its azimuth, its yaw the zero
    assert expected["pedestal_tilt_north_deg"] == pytest.approx(1.2 * np.cos(np.radians(230)),
                                                                abs=0.01)
    assert expected["pedestal_tilt_east_deg"] == pytest.approx(1.2 * np.sin(np.radians(230)),
                                                               abs=0.01)
    assert expected["azimuth_zero_deg"] == pytest.approx(1.5, abs=0.02)


def test_a_significant_nonperpendicularity_is_selected_and_recovered() -> None:
    """NPAE built independently: the elevation turns about the axis (cos np, 0, sin np) of
    the azimuth frame (scipy rotation vector), its +h end raised by np."""
    rng = np.random.default_rng(3)
    npae = 0.4
    times, sun = _day("2026-06-02")
    times, sun = times[::2], sun.iloc[::2]
    az, el = sun["azimuth"].to_numpy(), sun["apparent_elevation"].to_numpy()
    axis = np.array([np.cos(np.radians(npae)), 0.0, np.sin(np.radians(npae))])
    mount = Rotation.from_euler("xy", [-TRUE["pedestal_tilt_north_deg"],
                                       TRUE["pedestal_tilt_east_deg"]], degrees=True)
    r = (mount * Rotation.from_euler("z", -(az + TRUE["azimuth_zero_deg"])[:, None], degrees=True)
         * Rotation.from_rotvec(np.radians(el + TRUE["elevation_zero_deg"])[:, None] * axis))
    h, n, u = (r.apply(v) for v in np.eye(3))
    ox, oy = _offsets_mrad(enu_from_sky(az, el), h, n, u)
    ox, oy = ox + rng.normal(0, 0.3, ox.size), oy + rng.normal(0, 0.3, oy.size)
    fit = fit_pointing_model(times, az, el, ox, oy, SITE.latitude, SITE.longitude, SITE.altitude)
    assert fit.fitted_terms == (*CORE_TERMS, "nonperpendicularity_deg")
    for name, value in {**TRUE, "nonperpendicularity_deg": npae}.items():
        got = getattr(fit.model, name)
        assert abs(got - value) < 4 * fit.std[name], (name, got, value, fit.std[name])


def test_terms_are_read_as_the_route_answers_them_or_as_numbers() -> None:
    answered = {"azimuth_zero_deg": {"value": 1.5, "std": 0.001},
                "pedestal_tilt_east_deg": {"value": -0.4, "std": None}}
    assert PointingModel.from_terms(answered) == PointingModel(azimuth_zero_deg=1.5,
                                                               pedestal_tilt_east_deg=-0.4)
    assert PointingModel.from_terms({"collimation_deg": 2}) == PointingModel(collimation_deg=2.0)
    assert PointingModel.from_terms({}) == PointingModel()
    for bad, match in (({"yaw_deg": 1.0}, "yaw_deg: not a pointing-model term"),
                       ({"elevation_zero_deg": float("nan")}, "elevation_zero_deg: nan"),
                       ({"elevation_zero_deg": 45.0}, "within"),
                       ({"azimuth_zero_deg": {"std": 1.0}}, "azimuth_zero_deg: None"),
                       ({"azimuth_zero_deg": "1.5"}, "azimuth_zero_deg: '1.5'"),
                       ({"azimuth_zero_deg": True}, "azimuth_zero_deg: True")):
        with pytest.raises(ValueError, match=match):
            PointingModel.from_terms(bad)


def test_the_robust_pass_on_a_sample_finds_the_same_outliers_and_terms(
        observed_day, fitted, monkeypatch) -> None:
    """Above ROBUST_SAMPLE observations the robust pass runs on an evenly spaced sample; the
    outliers are judged and the terms fitted on all of them, so nothing changes."""
    import sim.pointing_model as pm

    times, az, el, ox, oy, glint = observed_day
    assert times.size > 200
    monkeypatch.setattr(pm, "ROBUST_SAMPLE", 60)
    sampled = fit_pointing_model(times, az, el, ox, oy, SITE.latitude, SITE.longitude,
                                 SITE.altitude)
    assert np.array_equal(sampled.outlier, glint)
    for name in CORE_TERMS:  # the same inliers, the same least squares: 1e-10° apart
        assert getattr(sampled.model, name) == pytest.approx(getattr(fitted.model, name),
                                                             abs=1e-8)
