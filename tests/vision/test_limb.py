"""The contained limb fit: a saturated core grown on one side by thin cloud."""

from __future__ import annotations

import cv2
import numpy as np

from vision.cameras import FisheyeCamera
from vision.limb import _robust_limb_centre, contained_limb_centre

CAM = FisheyeCamera(319.5, 239.5, 2.6)


def _clouded_core(cloud: float) -> tuple[np.ndarray, tuple[float, float]]:
    """A θ⁻² glare saturating 4° from the sun on a flat sky, plus a cloud adding ``cloud``
    (in full-well units) beyond a straight edge 2° from the sun: the core bulges there."""
    sx, sy = (float(v) for v in CAM.sky_to_pixel(140.0, 50.0))
    yy, xx = np.mgrid[0:480, 0:640].astype(float)
    d = CAM.pixel_to_direction(xx.ravel(), yy.ravel()).reshape(480, 640, 3)
    sun = CAM.pixel_to_direction(np.array([sx]), np.array([sy]))[0]
    ang = np.degrees(np.arccos(np.clip(d @ sun, -1.0, 1.0)))
    lum = 0.3 + 0.7 * (4.0 / np.maximum(ang, 0.27)) ** 2
    lum += cloud * ((xx - sx) + 0.5 * (yy - sy) > 2.0 * CAM.px_per_deg)
    return np.clip(np.rint(255 * lum), 0, 255).astype(np.uint8), (sx, sy)


def _outline(gray: np.ndarray) -> tuple[np.ndarray, tuple[float, float]]:
    core = (gray >= 250).astype(np.uint8)
    contours, _ = cv2.findContours(core, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    pts = max(contours, key=len).reshape(-1, 2).astype(float)
    m = cv2.moments(core, True)
    return pts, (m["m10"] / m["m00"], m["m01"] / m["m00"])


def test_a_clear_core_is_centred() -> None:
    gray, (sx, sy) = _clouded_core(0.0)
    pts, _ = _outline(gray)
    got = contained_limb_centre(pts, CAM)
    assert got is not None and got[2] > 0.9
    assert np.hypot(got[0] - sx, got[1] - sy) < 0.3  # measured 0.12 px


def test_a_core_grown_by_cloud_is_centred_on_its_clear_arc() -> None:
    gray, (sx, sy) = _clouded_core(0.3)
    pts, (mx, my) = _outline(gray)
    # the bulge drags the core's centroid, and a plain RANSAC circle, toward the cloud
    # (measured 2.4 px both) ...
    assert np.hypot(mx - sx, my - sy) > 1.5
    plain = _robust_limb_centre(pts, CAM)
    assert np.hypot(plain[0] - sx, plain[1] - sy) > 1.5
    got = contained_limb_centre(pts, CAM)
    assert got is not None and 0.3 <= got[2] < 0.9
    # ... while the circle through the clear arc that contains the core stays on the sun
    # (measured 0.08 px)
    assert np.hypot(got[0] - sx, got[1] - sy) < 0.3
