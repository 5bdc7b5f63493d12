"""A plainly visible sun far from the ephemeris prediction is reported, never hidden.

A wrong place, time or time zone moves the prediction, not the sun: the
detector must still answer with the disc it sees and say how far it is from
the prediction (``distance_from_ephemeris_px``), and the service warns when no
camera error can explain the difference (``backend.vision.checks``). The
distance is a feature of the confidence that cannot count against a plain
disc (``vision.confidence``), never a veto. References: the disc's drawn
position, the hand labels and pvlib's SPA.
"""

from __future__ import annotations

import cv2
import numpy as np
import pandas as pd
import pvlib
import pytest

from backend.vision.checks import error_warnings
from vision import confidence as conf
from vision.analyse import analyse_frame
from vision.calibrate import fit_fisheye
from vision.cameras import FisheyeCamera, PinholeCamera
from vision.detect import detect_robust
from vision.evalset import disc_frame, wrong_ephemeris_discs, wrong_ephemeris_scenes


def _contract_frame() -> np.ndarray:
    """``contract-check vision``'s frame: a white disc of 9 px at (400, 200) on grey 40, JPEG."""
    img = np.full((480, 640, 3), 40, np.uint8)
    cv2.circle(img, (400, 200), 9, (255, 255, 255), -1)
    ok, jpg = cv2.imencode(".jpg", img)
    assert ok
    return cv2.imdecode(jpg, cv2.IMREAD_COLOR)


def test_contract_disc_50_deg_from_the_ephemeris_is_the_sun() -> None:
    """The contract's fisheye request: Tehuantepec at local noon puts the sun at
    (157.2°, 70.5°), the disc is 50.8° away — found, with its distance, as blind."""
    img = _contract_frame()
    cam = FisheyeCamera(320.0, 240.0, 2.6, north_offset_deg=0.0, east="left")
    sp = pvlib.solarposition.get_solarposition(
        pd.DatetimeIndex([pd.Timestamp("2024-03-15T12:00:00-06:00")]), 16.28875, -95.240871,
        altitude=50.0, method="nrel_numpy")
    eph = (float(sp.azimuth.iloc[0]), float(sp.apparent_elevation.iloc[0]))
    res = analyse_frame(img, cam, "robust", eph)
    assert res["sun_found"] and res["confidence"] >= 0.9, res
    x, y = res["centroid_px"]
    assert abs(x - 400) < 1 and abs(y - 200) < 1
    assert 270 < res["azimuth_deg"] < 360  # up-right of centre, north up, east left: NW
    ex, ey = res["ephemeris"]["centroid_px"]
    assert res["distance_from_ephemeris_px"] == pytest.approx(np.hypot(x - ex, y - ey))
    assert res["error"]["separation_deg"] > 45
    blind = detect_robust(img, camera=cam)
    assert blind.sun_found and res["confidence"] >= blind.confidence - 0.05
    # the pinhole request of the same contract: no ephemeris, the disc found
    d = detect_robust(img, camera=PinholeCamera())
    assert d.sun_found and abs(d.centroid_px[0] - 400) < 1 and abs(d.centroid_px[1] - 200) < 1


def test_a_wrong_place_gives_the_sun_and_a_warning() -> None:
    """Sun drawn at 30° elevation, the ephemeris (a wrong place) at 72°: a detection, and
    the service's warning that no north offset or mirror explains 42° of zenith angle."""
    cam = FisheyeCamera(319.5, 239.5, 2.6, north_offset_deg=25.0, east="right")
    fr = disc_frame(cam, 200.0, 30.0, 8.0, 60)
    res = analyse_frame(fr.image, cam, "robust", (150.0, 72.0))
    assert res["sun_found"] and res["confidence"] >= 0.5
    assert np.hypot(res["centroid_px"][0] - fr.sun_px[0], res["centroid_px"][1] - fr.sun_px[1]) < 1
    assert res["elevation_deg"] == pytest.approx(30.0, abs=0.5)
    warnings = error_warnings(res, None)
    assert warnings and "zenith angle" in warnings[0]


def test_a_frame_turned_against_its_calibration_is_named() -> None:
    """A tester's frame turned 90° against the frames its camera was calibrated on: the
    sun's height right, its bearing 57° off, and the warning asked "is the place or the
    time right?". The sun drawn at azimuth 200°, the calibration's frame turned by a
    quarter (the camera's north 90° off): the warning names the turn and the time."""
    turned = FisheyeCamera(319.5, 239.5, 2.6, north_offset_deg=25.0 + 90.0, east="right")
    fr = disc_frame(turned, 200.0, 40.0, 8.0, 60)
    cam = FisheyeCamera(319.5, 239.5, 2.6, north_offset_deg=25.0, east="right")
    res = analyse_frame(fr.image, cam, "robust", (200.0, 40.0))
    assert res["sun_found"] and abs(res["error"]["elevation_deg"]) < 0.5
    (warning,) = error_warnings(res, 0.3)
    assert "all of it in azimuth" in warning and "turned or mirrored" in warning, warning
    assert "time off" in warning
    # a sun off in height too is the place or the time
    res = analyse_frame(fr.image, cam, "robust", (200.0, 60.0))
    assert [w for w in error_warnings(res, 0.3) if "place or the time" in w]


def test_a_sun_where_the_ephemeris_puts_it_keeps_its_blind_confidence() -> None:
    """The model's small penalty for a known ephemeris (a search near a prediction picks
    something) lowered a tester's clear suns found blind at 0.62–0.73 to 0.39–0.48, refused
    as "overcast", exactly where the ephemeris put them: agreement is no evidence against
    a candidate (vision.confidence.agreeing_probability); far from the prediction the
    penalties stand."""
    from vision import confidence as conf

    x = conf.features(1.0, 1.0, 1.0, 255.0, 148.0, 2.0, 0.0, 0.6, None)
    blind = conf.probability(x)
    assert 0.5 < blind < 0.75  # a bright sky: a low but clear margin
    known = x.copy()
    known[conf.FEATURES.index("ephemeris_known")] = 1.0
    assert conf.probability(known) < blind  # the fitted penalty
    assert conf.agreeing_probability(known, 0.2) == pytest.approx(blind)
    unclear = conf.features(0.6, 0.3, 1.0, 255.0, 148.0, 2.0, 0.0, 0.6, 12.0)
    assert conf.agreeing_probability(unclear, 12.0) == conf.probability(unclear)
    # a tester's hazy sun: "0.31° in radius, smaller than a sun's core" read as contradicting
    # the 0.27° solar radius; the bound is the saturated core with its glare
    small = conf.features(1.0, 0.3, 1.0, 255.0, 100.0, 0.31, 0.0, 0.6, None)
    words = conf.reason(small, {"radius_deg": 0.31})
    assert words.startswith("brightest region is 0.31° in radius, under the 0.5° of a "
                            "saturated sun's core with its glare"), words


@pytest.mark.parametrize("split", ["development", "heldout"])
def test_wrong_ephemeris_discs_always_found(split: str) -> None:
    """The contract-like frames of both splits (a disc 20–70° from the prediction)."""
    for lf in wrong_ephemeris_discs(split, 12):
        ex, ey = lf.camera.sky_to_pixel(*lf.predicted_deg)
        d = detect_robust(lf.frame.image, camera=lf.camera, expected_px=(float(ex), float(ey)))
        assert d.sun_found and d.confidence >= 0.9, (lf.seed, d.confidence, d.reason)
        sx, sy = lf.frame.sun_px
        assert np.hypot(d.centroid_px[0] - sx, d.centroid_px[1] - sy) < 1.0
        assert d.distance_from_ephemeris_px == pytest.approx(np.hypot(sx - ex, sy - ey), abs=1.0)


def test_wrong_ephemeris_scenes_held_out() -> None:
    """Second-renderer scenes with a wrong ephemeris (held-out): every sun found blind and
    guided (15 of 15; a low sun whose glare the ground cuts, seed 16003, was missed by both
    until a cut core was judged on its free arc: vision.detect._cut_shape)."""
    blind_found = guided_found = 0
    for lf in wrong_ephemeris_scenes("heldout", 18):
        cam = lf.camera
        ex, ey = cam.sky_to_pixel(*lf.predicted_deg)
        b = detect_robust(lf.frame.image, camera=cam)
        g = detect_robust(lf.frame.image, camera=cam, expected_px=(float(ex), float(ey)))
        blind_found += b.sun_found
        guided_found += g.sun_found
        if g.sun_found:
            sx, sy = lf.frame.sun_px
            assert np.hypot(g.centroid_px[0] - sx, g.centroid_px[1] - sy) < 8.0
    assert blind_found == 15 and guided_found == 15


def test_real_frame_with_the_clock_three_hours_off(real_sky) -> None:
    """A development Wettermast frame, the camera calibrated on the development frames, the
    ephemeris for a clock 3 h fast (the sun ~40° away): the sun found at its label."""
    dev = [r for r in real_sky if r["sun_row_label"] and r["split"] == "development"
           and r["camera"] == "Wettermast"]
    times = pd.DatetimeIndex([pd.Timestamp(r["utc_time"]) for r in dev])
    sp = pvlib.solarposition.get_solarposition(times, float(dev[0]["lat"]),
                                               float(dev[0]["lon"]), method="nrel_numpy")
    imgs = [cv2.imread(r["path"]) for r in dev]
    xy = np.array([detect_robust(i).centroid_px for i in imgs])
    cam = fit_fisheye(xy[:, 0], xy[:, 1], sp.azimuth.values, sp.apparent_elevation.values,
                      (1920, 1920)).camera
    wrong = pvlib.solarposition.get_solarposition(times + pd.Timedelta(hours=3),
                                                  float(dev[0]["lat"]), float(dev[0]["lon"]),
                                                  method="nrel_numpy")
    for r, img, a, e in zip(dev, imgs, wrong.azimuth, wrong.apparent_elevation, strict=True):
        ex, ey = cam.sky_to_pixel(float(a), float(e))
        d = detect_robust(img, camera=cam, expected_px=(float(ex), float(ey)))
        if d.features["ephemeris_far_unclear"] > 0.0:
            # not a plain disc (the 83 px² hazy core of 11:24: plain_disc 0.84): the distance
            # from a calibrated camera's ephemeris counts against it in proportion (issue 24
            # item 2); refused, it must say so
            assert d.sun_found or "ephemeris" in str(d.reason), (r["filename"], d.reason)
            continue
        assert d.sun_found, (r["filename"], d.confidence, d.reason)
        lx, ly = float(r["sun_col_label"]), float(r["sun_row_label"])
        assert np.hypot(d.centroid_px[0] - lx, d.centroid_px[1] - ly) <= 10.0
        assert d.distance_from_ephemeris_px / cam.px_per_deg > 20.0


def test_distance_cannot_count_against_a_plain_disc() -> None:
    """The feature is gated: a round, saturated core with its glare gets the same probability
    at any distance from the prediction; an ambiguous candidate loses some."""
    plain = [conf.features(1.0, 1.0, 1.0, 255.0, 60.0, 2.0, 0.0, 0.9, d) for d in (0.5, 20.0, 90.0)]
    assert all(x[conf.FEATURES.index("ephemeris_far_unclear")] == 0.0 for x in plain)
    p = [conf.probability(x) for x in plain]
    assert max(p) - min(p) < 1e-12 and p[0] > 0.9
    vague = [conf.features(0.5, 0.4, 1.0, 255.0, 60.0, 2.0, 0.0, 0.3, d) for d in (0.5, 30.0)]
    assert vague[1][conf.FEATURES.index("ephemeris_far_unclear")] > 2.0
    assert conf.probability(vague[1]) <= conf.probability(vague[0])


def test_a_clock_an_hour_off_does_not_take_a_piece_of_the_glare_for_the_sun() -> None:
    """Wolf frames with a camera fitted on the 23 hand labels and the clock an hour off:
    the window around the wrong prediction held the edge of the sun's glare or a streak in
    it, which won with 0.96–1.00 while the sun lay 160–244 px away (11 of the 92 frames at
    ±1 and ±2 h; these four among them). The sun is found, within 20 px of its label."""
    import csv
    from pathlib import Path

    real = Path(__file__).parents[1] / "data" / "real-sky"
    rows = [r for r in csv.DictReader((real / "metadata.csv").open(newline=""))
            if r["filename"].startswith("Wolf")]
    lat, lon = float(rows[0]["lat"]), float(rows[0]["lon"])

    def spa(times: list[pd.Timestamp]) -> tuple[np.ndarray, np.ndarray]:
        sp = pvlib.solarposition.get_solarposition(pd.DatetimeIndex(times), lat, lon,
                                                   method="nrel_numpy")
        return sp.azimuth.to_numpy(), sp.apparent_elevation.to_numpy()

    times = [pd.Timestamp(r["utc_time"]) for r in rows]
    az, el = spa(times)
    x = np.array([float(r["sun_col_label"]) for r in rows])
    y = np.array([float(r["sun_row_label"]) for r in rows])
    cam = fit_fisheye(x, y, az, el, (1920, 1920)).camera
    for stamp, hours in (("102400", 1), ("103100", 1), ("095000", -1), ("144000", -1)):
        i = next(k for k, r in enumerate(rows) if f"_{stamp}_" in r["filename"])
        img = cv2.imread(str(real / rows[i]["filename"]))
        assert img.shape[:2] == (1920, 1920)
        a, e = spa([times[i] + pd.Timedelta(hours=hours)])
        res = analyse_frame(img, cam, "robust", (float(a[0]), float(e[0])))
        assert res["sun_found"], (stamp, res["reason"])
        cx, cy = res["centroid_px"]
        assert np.hypot(cx - x[i], cy - y[i]) < 20.0, (stamp, cx, cy, x[i], y[i])


def test_a_sun_the_calibration_puts_off_the_frame_is_named() -> None:
    """A 3000 × 2000 frame whose fisheye circle the frame cuts, the sun 21 px above its top
    edge: its glare at the edge was answered as the sun, 5.0° from the ephemeris, with no
    warning (a tester's finding). A calibrated camera putting the ephemeris off the frame
    says so; one putting it on the frame, or a camera without a calibration, does not."""
    res = {"sun_found": True, "centroid_px": [1137.7, 20.0], "image_size_px": [3000, 2000],
           "ephemeris": {"azimuth_deg": 110.9, "elevation_deg": 6.6,
                         "centroid_px": [1155.6, -44.0]},
           "error": {"separation_deg": 4.96, "azimuth_deg": 1.0, "elevation_deg": 4.8}}
    (warning,) = error_warnings(res, 0.64)
    assert "(1156, -44) px, off the 3000×2000 px frame" in warning, warning
    assert "glare of a sun beyond the frame's edge" in warning
    assert error_warnings(res, None) == []
    res["ephemeris"]["centroid_px"] = [1155.6, 44.0]
    assert error_warnings(res, 0.64) == []
