"""Synthetic frames: deterministic, and the sun where the camera model puts it."""

from __future__ import annotations

import numpy as np

from vision.cameras import FisheyeCamera, PinholeCamera
from vision.synth import fisheye_frame, tracker_frame


def test_tracker_frame_deterministic_and_seeded() -> None:
    a = tracker_frame(1.0, -0.5, seed=4, cloud_cover=0.3)
    b = tracker_frame(1.0, -0.5, seed=4, cloud_cover=0.3)
    c = tracker_frame(1.0, -0.5, seed=5, cloud_cover=0.3)
    assert np.array_equal(a.image, b.image)
    assert not np.array_equal(a.image, c.image)
    assert a.image.shape == (480, 640, 3) and a.image.dtype == np.uint8


def test_tracker_sun_pixel_follows_pointing_error() -> None:
    cam = PinholeCamera()
    f = cam.focal_px
    fr = tracker_frame(2.0, 0.0, camera=cam, noise_dn=0)
    assert abs(fr.sun_px[0] - 319.5 - f * np.tan(np.radians(2.0))) < 1e-9
    assert abs(fr.sun_px[1] - 239.5) < 1e-9
    # the brightest (saturated) region is centred there
    ys, xs = np.nonzero(fr.image[:, :, 1] == 255)
    assert abs(xs.mean() - fr.sun_px[0]) < 0.5 and abs(ys.mean() - fr.sun_px[1]) < 0.5


def test_fisheye_frame_geometry() -> None:
    cam = FisheyeCamera(319.5, 239.5, 2.6)
    fr = fisheye_frame(135.0, 40.0, camera=cam, noise_dn=0)
    x, y = cam.sky_to_pixel(135.0, 40.0)
    assert fr.sun_px == (float(x), float(y))
    assert fr.sun_visible
    # black outside the horizon circle, sky inside
    assert fr.image[2, 2].max() < 20 and fr.image[239, 319].max() > 60


def test_skyline_hides_a_low_sun() -> None:
    fr = fisheye_frame(90.0, 1.0, skyline_deg=8.0, seed=1)
    assert not fr.sun_visible


def test_clouds_dim_the_sun() -> None:
    hits = [fisheye_frame(200.0, 45.0, seed=s, cloud_cover=0.9, cloud_optical_depth=3.0)
            for s in range(4)]
    assert min(h.truth["transmittance"] for h in hits) < 0.5
