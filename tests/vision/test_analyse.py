"""``vision.analyse``: the answer of ``POST /api/v1/vision/sun`` for one frame.

The ephemeris sun's pixel is checked against seed 003's closed form (eqs.
9–11, written out here, not taken from ``vision.cameras``) for a levelled
equidistant camera, and — for a camera with a radial term and tilt — against
where the detector finds the sun in a frame rendered through that camera's
inverse map (pixel → sky).
"""

from __future__ import annotations

import numpy as np
import pytest

from vision.analyse import analyse_frame
from vision.cameras import FisheyeCamera, PinholeCamera
from vision.synth import fisheye_frame, tracker_frame


def _seed003_pixel(az: float, el: float, cx: float, cy: float, k: float, delta: float
                   ) -> tuple[float, float]:
    """Seed 003, eqs. 9–11 with east left (raw view from below): r = k·z, angle Δ − A."""
    r = k * (90.0 - el)
    phi = np.radians(delta - az)
    return cx + r * np.sin(phi), cy - r * np.cos(phi)


def test_ephemeris_pixel_matches_seed003_closed_form() -> None:
    cam = FisheyeCamera(319.5, 239.5, 2.6, north_offset_deg=12.0)
    az, el = 140.0, 52.0
    frame = fisheye_frame(az, el, camera=cam, seed=3)
    out = analyse_frame(frame.image, cam, "robust", (az, el))
    want = _seed003_pixel(az, el, 319.5, 239.5, 2.6, 12.0)
    assert out["ephemeris"]["centroid_px"] == pytest.approx(list(want), abs=1e-6)
    assert out["ephemeris"]["azimuth_deg"] == az and out["ephemeris"]["elevation_deg"] == el
    # the detection agrees with it: angle and pixel distance
    assert out["error"]["separation_deg"] < 0.2
    assert out["error"]["distance_px"] < 0.5
    assert out["error"]["distance_px"] == pytest.approx(
        np.hypot(out["centroid_px"][0] - want[0], out["centroid_px"][1] - want[1]))


def test_ephemeris_pixel_uses_radial_terms_and_tilt() -> None:
    cam = FisheyeCamera(330.0, 230.0, 2.4, north_offset_deg=-20.0, east="right",
                        radial_coeffs=(0.08,), tilt_north_deg=3.0, tilt_east_deg=-2.0)
    plain = FisheyeCamera(330.0, 230.0, 2.4, north_offset_deg=-20.0, east="right")
    az, el = 250.0, 35.0
    frame = fisheye_frame(az, el, camera=cam, seed=5)
    out = analyse_frame(frame.image, cam, "robust", (az, el))
    ex, ey = out["ephemeris"]["centroid_px"]
    px, py = plain.sky_to_pixel(az, el)
    assert np.hypot(ex - px, ey - py) > 5.0  # the radial term and tilt move it
    # the sun drawn through the camera's inverse map is found where the forward map puts it
    assert out["sun_found"]
    assert np.hypot(out["centroid_px"][0] - ex, out["centroid_px"][1] - ey) < 1.0
    assert out["error"]["separation_deg"] < 0.3


def test_ephemeris_below_horizon_has_no_pixel_and_pinhole_none() -> None:
    cam = FisheyeCamera(319.5, 239.5, 2.6)
    frame = fisheye_frame(100.0, 40.0, camera=cam, seed=1)
    out = analyse_frame(frame.image, cam, "robust", (100.0, -5.0))
    assert out["ephemeris"]["centroid_px"] is None
    assert out["error"]["separation_deg"] == pytest.approx(45.0, abs=0.3)
    pin = analyse_frame(tracker_frame(0.5, -0.2, seed=2).image, PinholeCamera(), "robust",
                        (100.0, 40.0))
    assert "centroid_px" not in pin["ephemeris"] and "error" not in pin
    assert pin["pointing_error_deg"][0] > 0 > pin["pointing_error_deg"][1]


def test_no_sun_gives_no_angles() -> None:
    img = np.full((480, 640, 3), 90, np.uint8)
    out = analyse_frame(img, FisheyeCamera(319.5, 239.5, 2.6), "robust", (100.0, 40.0))
    assert not out["sun_found"] and out["centroid_px"] is None
    assert out["azimuth_deg"] is None and "error" not in out
    assert out["ephemeris"]["centroid_px"] is not None


def test_a_sun_the_ephemeris_puts_well_below_the_horizon_is_no_sun() -> None:
    """A tester's moonlit night (the sun 35° down, a saturated moon) was answered
    ``sun_found`` true at confidence 1.00, only a warning saying the sun was down. With the
    time and place known, a bright disc while the sun is more than 5° down is the moon or a
    light: no sun, and the reason says so and what else could be wrong (the time, the
    place). Within the margin, or with no time (blind), the detector's answer stands."""
    cam = FisheyeCamera(319.5, 239.5, 2.6, north_offset_deg=12.0)
    moon = fisheye_frame(140.0, 35.0, camera=cam, seed=4).image  # a plain bright disc
    night = analyse_frame(moon, cam, "robust", (320.0, -35.3))
    assert not night["sun_found"] and night["confidence"] == 0.0
    assert night["centroid_px"] is None and night["azimuth_deg"] is None
    assert "error" not in night
    assert "35.3° below the horizon" in night["reason"] and "moon or a light" in night["reason"]
    assert "the time (its zone) or the place is wrong" in night["reason"]
    assert analyse_frame(moon, cam, "robust", (320.0, -4.0))["sun_found"]  # inside the margin
    assert analyse_frame(moon, cam, "robust", None)["sun_found"]  # no time: blind, as before
