"""Sun detection on synthetic frames whose truth comes from the camera model."""

from __future__ import annotations

import cv2
import numpy as np
import pandas as pd
import pvlib
import pytest

from vision import metrics
from vision.cameras import FisheyeCamera, PinholeCamera
from vision.detect import (
    METHODS,
    detect_robust,
    detect_seed000,
    detect_seed003,
    detect_sun,
    estimate_fov,
    threshold_moments,
)
from vision.synth import fisheye_frame, tracker_frame


def _disc_frame() -> np.ndarray:
    img = np.full((480, 640, 3), 40, np.uint8)
    cv2.circle(img, (400, 200), 9, (255, 255, 255), -1)
    ok, jpg = cv2.imencode(".jpg", img)
    assert ok
    return cv2.imdecode(jpg, cv2.IMREAD_COLOR)


@pytest.mark.parametrize("method", METHODS)
def test_every_method_finds_a_plain_disc(method: str) -> None:
    d = detect_sun(_disc_frame(), method=method)
    assert d.sun_found and d.method == method
    x, y = d.centroid_px
    assert abs(x - 400) < 0.5 and abs(y - 200) < 0.5


def test_flat_and_dark_frames_have_no_sun() -> None:
    for img in (np.full((480, 640, 3), 200, np.uint8), np.zeros((480, 640, 3), np.uint8)):
        d = detect_robust(img)
        assert not d.sun_found and d.centroid_px is None and d.confidence < 0.5


def test_unknown_method_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="method"):
        detect_sun(_disc_frame(), method="brightest")


def _tracker_errors_mrad(n: int, **kw: object) -> tuple[np.ndarray, int]:
    cam = PinholeCamera()
    rng = np.random.default_rng(7)
    errs, missed = [], 0
    for i in range(n):
        h, v = rng.uniform(-10.0, 10.0, 2)
        fr = tracker_frame(h, v, camera=cam, seed=i, **kw)
        d = detect_robust(fr.image, camera=cam)
        if not d.sun_found:
            missed += 1
            continue
        hh, vv, _ = cam.pointing_error(*d.centroid_px)
        errs.append(1000.0 * np.radians(np.hypot(float(hh) - h, float(vv) - v)))
    return np.asarray(errs), missed


def test_tracker_pointing_error_below_half_mrad() -> None:
    """Issue 4: synthetic tracker frames at 640 × 480 / 67°, ≤ 0.5 mrad RMS."""
    errs, missed = _tracker_errors_mrad(16)
    assert missed == 0
    assert float(np.sqrt(np.mean(errs**2))) <= 0.5


def test_tracker_with_flare_and_ghost() -> None:
    errs, missed = _tracker_errors_mrad(8, flare=True, ghost=True)
    assert missed == 0
    assert float(np.sqrt(np.mean(errs**2))) <= 0.5


def _day_track(n_days: int = 2) -> pd.DataFrame:
    """Sun positions through days at seed 003's site, from pvlib's SPA."""
    frames = []
    for day in ("2018-03-02", "2018-06-21", "2018-12-21")[:n_days]:
        t = pd.date_range(f"{day} 07:00", f"{day} 18:30", freq="45min", tz="Etc/GMT+6")
        frames.append(pvlib.solarposition.get_solarposition(t, 20.8667, -103.05,
                                                            method="nrel_numpy"))
    sp = pd.concat(frames)
    return sp[sp.apparent_elevation > 8]


def _fisheye_errors(sp: pd.DataFrame, **kw: object) -> tuple[dict, int]:
    cam = FisheyeCamera(319.5, 239.5, 2.6)
    ref_az, ref_el, az, el, missed = [], [], [], [], 0
    for i, (a, e) in enumerate(zip(sp.azimuth, sp.apparent_elevation, strict=True)):
        fr = fisheye_frame(a, e, camera=cam, seed=i, **kw)
        d = detect_robust(fr.image, camera=cam)
        if not d.sun_found:
            missed += 1
            continue
        a2, e2 = cam.pixel_to_sky(*d.centroid_px)
        ref_az.append(a)
        ref_el.append(e)
        az.append(float(a2))
        el.append(float(e2))
    return metrics.error_table(ref_az, ref_el, az, el), missed


def test_fisheye_clear_sky_rmse_below_0_2_deg() -> None:
    """Issue 4: synthetic fisheye 640 × 480, azimuth/elevation RMSE ≤ 0.2° on clear skies."""
    table, missed = _fisheye_errors(_day_track())
    assert missed == 0
    assert table["azimuth"]["rmse_deg"] <= 0.2
    assert table["elevation"]["rmse_deg"] <= 0.2


def test_fisheye_thin_cloud_is_reported_within_a_degree() -> None:
    table, missed = _fisheye_errors(_day_track(1), cloud_cover=0.4, cloud_optical_depth=0.6)
    assert missed <= 4
    assert table["separation"]["rmse_deg"] <= 1.0


def test_ghost_opposite_the_sun_is_not_taken() -> None:
    cam = FisheyeCamera(319.5, 239.5, 2.6)
    fr = fisheye_frame(120.0, 40.0, camera=cam, ghost=True, glare_deg=1.0, seed=3)
    d = detect_robust(fr.image, camera=cam)
    assert d.sun_found
    assert np.hypot(d.centroid_px[0] - fr.sun_px[0], d.centroid_px[1] - fr.sun_px[1]) < 1.0


def test_cut_glare_blob_is_centred_on_its_limb() -> None:
    """A 10 k px glare half hidden by a box and crossed by a mast: the limb fit holds."""
    n = 960
    cam = FisheyeCamera((n - 1) / 2, (n - 1) / 2, 5.2)
    fr = fisheye_frame(250.0, 60.0, camera=cam, width_px=n, height_px=n, glare_deg=8.0, seed=2)
    img = fr.image.copy()
    x, y = fr.sun_px
    r = 8.0 * 5.2
    cv2.line(img, (int(x - 3 * r), int(y + 0.3 * r)), (int(x + 3 * r), int(y - 0.2 * r)),
             (40, 40, 40), 4)
    cv2.rectangle(img, (int(x + 0.35 * r), int(y - 2 * r)), (int(x + 3 * r), int(y + 2 * r)),
                  (30, 30, 30), -1)
    gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    ys, xs = np.nonzero(gray >= 250)
    assert xs.size > 4000
    naive = np.hypot(xs.mean() - x, ys.mean() - y)
    for camera in (cam, None):
        d = detect_robust(img, camera=camera)
        assert d.sun_found
        err = np.hypot(d.centroid_px[0] - x, d.centroid_px[1] - y)
        assert err < 1.0 < naive


def test_fov_circle_found_on_fisheye_not_on_pinhole() -> None:
    fr = fisheye_frame(200.0, 50.0)
    fov = estimate_fov(cv2.cvtColor(fr.image, cv2.COLOR_BGR2GRAY))
    assert fov is not None
    assert abs(fov.cx_px - 319.5) < 3 and abs(fov.cy_px - 239.5) < 3
    assert 0.9 * 234 < fov.radius_px < 1.02 * 234
    tr = tracker_frame(1.0, 1.0)
    assert estimate_fov(cv2.cvtColor(tr.image, cv2.COLOR_BGR2GRAY)) is None


def test_seed003_is_the_binary_centroid_of_mean_grey() -> None:
    """Independent re-implementation of seed 003 eqs. 5–8 in numpy."""
    fr = fisheye_frame(150.0, 45.0, cloud_cover=0.5, seed=5)
    grey = np.rint(fr.image.astype(float).mean(axis=2))
    ys, xs = np.nonzero(grey > 240)
    d = detect_seed003(fr.image)
    assert d.centroid_px == pytest.approx((xs.mean(), ys.mean()), abs=0.05)


def test_seed000_keys_on_the_picked_colour() -> None:
    """Seed 000 segments by HSV colour around the brightest (picked) pixel, not by grey."""
    img = np.full((480, 640, 3), 30, np.uint8)
    cv2.circle(img, (200, 200), 25, (0, 255, 255), -1)  # a large yellow disc: the pick
    cv2.circle(img, (450, 300), 6, (255, 255, 255), -1)  # a small white one
    d = detect_seed000(img)
    assert d.centroid_px == pytest.approx((200.0, 200.0), abs=0.5)


def test_threshold_moments_kernel() -> None:
    g = cv2.cvtColor(_disc_frame(), cv2.COLOR_BGR2GRAY)
    x, y = threshold_moments(g)
    assert abs(x - 400) < 0.5 and abs(y - 200) < 0.5
    assert threshold_moments(np.zeros((10, 10), np.uint8)) is None


def test_ghost_beside_a_sun_near_the_optical_centre() -> None:
    """Tracking well, the sun sits near the centre and its ghost right beside it."""
    cam = PinholeCamera()
    fr = tracker_frame(1.07, -0.33, camera=cam, seed=11, flare=True, ghost=True)
    d = detect_robust(fr.image, camera=cam)
    assert d.sun_found and d.ghosts_rejected >= 1
    hh, vv, _ = cam.pointing_error(*d.centroid_px)
    assert 1000 * np.radians(np.hypot(float(hh) - 1.07, float(vv) + 0.33)) < 0.2


@pytest.mark.parametrize("with_sun", [False, True])
def test_white_text_overlay_inside_the_sky_is_no_sun(with_sun: bool) -> None:
    """A burned-in time stamp (white on a dark box) is round-ish and saturated, not a sun."""
    if with_sun:
        fr = fisheye_frame(150.0, 50.0, seed=3)
    else:
        fr = fisheye_frame(150.0, 50.0, seed=3, cloud_cover=1.0, cloud_optical_depth=5.0)
    img = fr.image.copy()
    cv2.rectangle(img, (200, 100), (420, 130), (20, 20, 20), -1)
    cv2.putText(img, "2024/03/15 10:00 o O", (205, 122), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                (255, 255, 255), 1)
    d = detect_robust(img)
    assert d.sun_found is with_sun
    if with_sun:
        assert np.hypot(d.centroid_px[0] - fr.sun_px[0], d.centroid_px[1] - fr.sun_px[1]) < 0.5


@pytest.mark.parametrize("glare_deg", [0.8, 2.0])
def test_strong_blooming_along_the_columns(glare_deg: float) -> None:
    """Charge spilling up and down the columns turns the sun into a spindle; still ≤ 0.5 mrad."""
    errs, missed = _tracker_errors_mrad(6, bloom=1.0, glare_deg=glare_deg)
    assert missed == 0
    assert float(np.sqrt(np.mean(errs**2))) <= 0.5


@pytest.mark.parametrize("method", METHODS)
def test_frame_filled_by_a_saturated_box_does_not_crash(method: str) -> None:
    """A blob that fills its bounding box has no zero pixel for the distance transform."""
    img = np.full((600, 800, 3), 10, np.uint8)
    img[:, :400] = 255
    d = detect_sun(img, method=method)
    if method == "robust":
        assert not d.sun_found  # a half-white frame is no sun
    assert d.confidence <= 1.0


def test_large_glare_with_a_streak_uses_the_shrunk_opening() -> None:
    """A 300 px radius disc with a smear column: the core (a disc) is found at its centre."""
    img = np.full((1600, 1600, 3), 30, np.uint8)
    cv2.circle(img, (820, 760), 300, (255, 255, 255), -1)
    cv2.line(img, (820, 0), (820, 1599), (255, 255, 255), 9)
    d = detect_sun(img)
    assert d.sun_found
    assert d.centroid_px == pytest.approx((820, 760), abs=1.0)


@pytest.mark.parametrize("offset_deg", [0.0, 4.0])
def test_guided_window_does_not_cut_a_wide_glare(offset_deg: float) -> None:
    """A saturated core wider (12.9° in radius) than the 8° search window around the
    ephemeris prediction: the window grows until the core no longer reaches its edge, so
    the guided answer is the blind one — not a core cut around the prediction and so
    pulled toward it (before: 1,373 of 3,539 px, 4.9 px off with a prediction 4° away,
    where blind is 0.4 px off)."""
    cam = FisheyeCamera(319.5, 239.5, 2.6)
    fr = fisheye_frame(150.0, 50.0, glare_deg=10.0, seed=3)
    blind = detect_sun(fr.image, camera=cam)
    ex, ey = cam.sky_to_pixel(150.0, 50.0 - offset_deg)
    guided = detect_sun(fr.image, camera=cam, expected_px=(float(ex), float(ey)))
    assert blind.sun_found and guided.sun_found
    assert guided.area_px == blind.area_px
    assert guided.centroid_px == pytest.approx(blind.centroid_px, abs=1e-9)
    assert np.hypot(guided.centroid_px[0] - fr.sun_px[0],
                    guided.centroid_px[1] - fr.sun_px[1]) < 1.0


def _cut_frame(outline_px: np.ndarray, ground_y: float = 690.0) -> np.ndarray:
    """A 960² fisheye frame (``FisheyeCamera(479.5, 479.5, 5.0)``), sky at 100, a saturated
    core bounded by ``outline_px`` (its radius at 360 angles about (560, 700), [px] at
    5 px/°, drawn on the camera's sphere as a glare is) with a glare falling off outside
    it, the ground (grey 8) below y = ``ground_y`` cutting the lower part of the core."""
    cam = FisheyeCamera(479.5, 479.5, 5.0)
    yy, xx = np.mgrid[0:960, 0:960].astype(float)
    ang = (np.degrees(np.arctan2(yy - 700.0, xx - 560.0)) % 360).astype(int)
    sun = cam.pixel_to_direction(np.array([560.0]), np.array([700.0]))[0]
    view = np.nan_to_num(cam.pixel_to_direction(xx.ravel(), yy.ravel())).reshape(960, 960, 3)
    rel = np.degrees(np.arccos(np.clip(view @ sun, -1.0, 1.0))) / (outline_px[ang] / 5.0)
    lum = 100 + 155 * np.clip(1.0 / np.maximum(rel, 1e-3), 0, 1.6)
    lum = np.where(yy > ground_y, 8.0, lum)
    lum = np.where(np.hypot(xx - 479.5, yy - 479.5) <= 0.98 * 90 * 5, lum, 0)
    g = np.clip(np.rint(lum), 0, 255).astype(np.uint8)
    return cv2.merge([g, g, g])


def test_a_sun_cut_by_the_ground_is_round_on_its_free_arc() -> None:
    """Issue 24 item 2 (round, allowing for the horizon cutting it): a glare 8° in radius
    cut by the ground line. With more than half of it below the line its second moments
    score the shape 0.21; the free arc is one circle (``_cut_shape``): found, at the
    disc's centre while the disc shows (the contained circle of the free arc: the ground's
    edge is no limb, ``vision.detect._true_limb``; measured 0.04 px, 0.45 px when the
    ground's edge was in the limb fits), where a bright patch with lobes cut the same way
    keeps its ragged arc (shape 0.30) and, completed by its mirror image across the ground
    (``vision.detect._mirrored_shape``), is a lobed shape (solidity 0.73).

    With the ground 2° above the disc's centre (y = 690) the disc itself is hidden: the
    glare above the ground is the aureole of a sun behind it, no visible sun
    (``vision.detect._disc_behind_obstacle``; reported at the hidden centre before it). The
    round glare is found with the ground 0.2° below the centre (y = 701), the disc's upper
    part above it (measured 0.05 px)."""
    cam = FisheyeCamera(479.5, 479.5, 5.0)
    d = detect_robust(_cut_frame(np.full(360, 40.0), ground_y=701.0), camera=cam)
    assert d.sun_found and d.features["shape"] >= 0.95, d.features
    assert np.hypot(d.centroid_px[0] - 560.0, d.centroid_px[1] - 700.0) <= 0.3
    d = detect_robust(_cut_frame(np.full(360, 40.0)), camera=cam)
    assert not d.sun_found and d.features["shape"] >= 0.95, d.features
    assert "behind the obstacle" in str(d.reason)
    lobes = 40.0 * (1.0 + 0.35 * np.sin(np.radians(5 * np.arange(360))))
    d = detect_robust(_cut_frame(lobes), camera=cam)
    assert d.features["shape"] < 0.4, d.features


@pytest.mark.parametrize("dark_share", [0.3, 0.6])
def test_a_pinhole_view_framed_by_something_dark_has_no_image_circle(dark_share: float) -> None:
    """The corners are dark by their mean, or on 90 % of their pixels (a station's overlay
    text lifts the mean only): a pinhole view with dark edges across part of each corner (a
    window frame, foliage) is not taken for a fisheye, whose circle would set a false scale.
    Checked to fail when the corners' median pixels sufficed (0.6)."""
    h, w = 480, 640
    img = np.full((h, w), 170, np.uint8)
    border = int(dark_share * w / 12)  # the corner patches are 1/12 of the side
    img[:, :border] = 20
    img[:, -border:] = 20
    cv2.circle(img, (400, 150), 12, 255, -1)
    assert estimate_fov(img) is None


def test_two_cameras_of_one_frame_size_each_get_their_own_image_circle() -> None:
    """The image circle's mask on the thumbnail (the sky's level is read under it) is cached
    across frames (vision.detect._disc_mask): keyed by the circle, so a frame of a second
    camera of the same size after the first gets the answer it gets alone — to the last
    feature."""
    from vision.detect import _disc_mask

    cams = (FisheyeCamera(319.5, 239.5, 2.6), FisheyeCamera(300.0, 250.0, 2.2))
    frames = [fisheye_frame(150.0, 50.0, camera=c, seed=3).image for c in cams]
    _disc_mask.cache_clear()
    alone = detect_sun(frames[1], "robust")
    _disc_mask.cache_clear()
    first = detect_sun(frames[0], "robust")
    after = detect_sun(frames[1], "robust")
    assert first.fov is not None and after.fov is not None
    assert first.fov != after.fov  # two different circles on frames of one size
    assert after.fov == alone.fov
    assert after.sun_found == alone.sun_found
    assert after.centroid_px == alone.centroid_px
    assert after.features == alone.features


def test_an_over_exposed_sun_is_not_called_overcast() -> None:
    """A tester's clear sky at six times the exposure (the sun a saturated disc ~20° in
    radius, the sky 79 grey levels under it) was refused "too little contrast … :
    overcast" — false, the sky was clear. The repository's frame with a 15° glare at twice
    the exposure is that case (74 grey levels): still refused, the reason now says what was
    measured (a round saturated region, its radius, the contrast) and claims no overcast."""
    cam = FisheyeCamera(319.5, 239.5, 2.6)
    frame = fisheye_frame(140.0, 57.0, camera=cam, seed=2, glare_deg=15.0).image
    bright = np.clip(frame.astype(np.float32) * 2.0, 0, 255).astype(np.uint8)
    d = detect_sun(bright, camera=cam)
    assert not d.sun_found and d.reason is not None
    assert "overcast" not in d.reason, d.reason
    assert d.reason.startswith("a round saturated region") and "over-exposed" in d.reason
