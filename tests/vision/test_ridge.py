"""A low sun over a mountain ridge, seen blind by an all-sky camera (issue 24: every visible
sun found, no sun where none is visible; ``vision.detect._disc_behind_obstacle``).

The frames come from a renderer of this module's own (not ``vision.synth``, ``vision.skyrender``
or ``benchmarks/lowsun_set.py``): an equisolid (r = 2 f sin(θ/2)) or equidistant (r = f θ)
lens whose horizon fills 93 % of the width, in a 3:2 frame that cuts the image circle top and
bottom, north rotated 37°, a clear sky brighter toward the horizon, an irregular ridge
3–8° high darker than the sky (Abisko, 67.85° N, in spring), and the sun with its glare: the
disc clipped, the aureole and the lens's veiling glare falling off as a power of the angle
from the sun (γ^-2.5 and γ^-1; Moffat 1969, A&A 3:455; ISO 9358) from the clip level at the
core's radius. A disc the ridge hides sends no direct beam into the lens: no veiling glare
then, only the sky's aureole above the ridge. Each frame is detected as the service does with
only ``camera=fisheye``: the image circle's equidistant guess
(``backend.vision.checks.derive_fisheye_scale``).
"""

from __future__ import annotations

import numpy as np
import pytest

from vision.cameras import FisheyeCamera, px_per_deg_for_horizon
from vision.detect import detect_sun
from vision.fov import image_circle, to_gray

SUN_RADIUS_DEG = 0.2666  # the solar disc's mean angular radius


def _ridge_deg(azimuth_deg: np.ndarray, mean_deg: float) -> np.ndarray:
    """The skyline's elevation [°] at ``azimuth_deg``: ``mean_deg`` ± 3.1° of four harmonics."""
    a = np.radians(azimuth_deg)
    return (mean_deg + 1.4 * np.sin(2 * a + 0.4) + 0.9 * np.sin(5 * a + 2.1)
            + 0.5 * np.sin(11 * a + 4.0) + 0.3 * np.sin(23 * a + 1.0))


def _render(lens: str, width_px: int, sun_above_ridge_deg: float, core_deg: float,
            sun_azimuth_deg: float, ridge_mean_deg: float = 5.5, north_deg: float = 37.0
            ) -> tuple[np.ndarray, tuple[float, float]]:
    """A BGR frame and the sun's pixel through the same lens. ``sun_above_ridge_deg``
    below 0 puts the disc behind the ridge; ``core_deg`` is the saturated core's radius."""
    height_px = width_px * 2 // 3
    cx, cy = (width_px - 1) / 2 + 0.013 * width_px, (height_px - 1) / 2 - 0.01 * width_px
    horizon_px = 0.465 * width_px
    f = horizon_px / (2 * np.sin(np.pi / 4)) if lens == "equisolid" else horizon_px / (np.pi / 2)
    yy, xx = np.mgrid[0:height_px, 0:width_px].astype(np.float64)
    dx, dy = xx - cx, yy - cy
    r = np.hypot(dx, dy)
    theta = 2 * np.arcsin(np.clip(r / (2 * f), 0, 1)) if lens == "equisolid" else r / f
    az = (north_deg + np.degrees(np.arctan2(-dx, -dy))) % 360  # east left: seen from below
    el = 90 - np.degrees(theta)
    sun_el = float(_ridge_deg(np.array([sun_azimuth_deg]), ridge_mean_deg)[0]) \
        + sun_above_ridge_deg
    sa, se = np.radians(sun_azimuth_deg), np.radians(sun_el)
    ar, er = np.radians(az), np.radians(el)
    cos_gamma = (np.cos(er) * np.sin(ar) * np.cos(se) * np.sin(sa)
                 + np.cos(er) * np.cos(ar) * np.cos(se) * np.cos(sa) + np.sin(er) * np.sin(se))
    gamma = np.degrees(np.arccos(np.clip(cos_gamma, -1, 1)))
    sky = 120 + 55 * (np.degrees(theta) / 90) ** 3
    g = np.maximum(gamma, 0.05)
    glare = (255 - (120 + 55 * ((90 - sun_el) / 90) ** 3)) * (
        0.8 * (core_deg / g) ** 2.5 + 0.2 * core_deg / g)
    ridge = el < _ridge_deg(az, ridge_mean_deg)
    veiling = 0.15 if sun_above_ridge_deg > 0 else 0.0
    img = np.where(ridge, 45 + 8 * np.sin(np.radians(az) * 40) + veiling * glare, sky + glare)
    img[(gamma <= SUN_RADIUS_DEG) & ~ridge] = 2000.0
    img = img + np.random.default_rng(1).normal(0, 1.5, img.shape)
    img[r > horizon_px] = 3.0
    gray = np.clip(img, 0, 255)
    bgr = np.stack([gray, np.clip(0.85 * gray + 0.15 * np.clip(img - 200, 0, 255), 0, 255),
                    np.clip(0.65 * gray + 0.35 * np.clip(img - 160, 0, 255), 0, 255)], -1)
    theta_sun = np.radians(90 - sun_el)
    r_sun = 2 * f * np.sin(theta_sun / 2) if lens == "equisolid" else f * theta_sun
    phi = np.radians(sun_azimuth_deg - north_deg)
    return bgr.astype(np.uint8), (cx - r_sun * np.sin(phi), cy - r_sun * np.cos(phi))


def _blind(img: np.ndarray):  # type: ignore[no-untyped-def]
    """Detection with only ``camera=fisheye``: the image circle read as an equidistant 180°
    lens (``backend.vision.checks.derive_fisheye_scale``)."""
    found = image_circle(to_gray(img))
    assert found is not None
    circle, _ = found
    cam = FisheyeCamera(circle.cx_px, circle.cy_px,
                        px_per_deg_for_horizon(circle.radius_px, "equidistant"))
    return detect_sun(img, camera=cam)


@pytest.mark.parametrize(("lens", "below_deg", "core_deg", "azimuth_deg", "ridge_mean_deg"), [
    ("equisolid", 1.0, 4.0, 160.0, 3.5),
    ("equisolid", 1.0, 7.0, 320.0, 6.5),
    ("equisolid", 2.5, 7.0, 280.0, 3.5),
    ("equisolid", 2.5, 12.0, 320.0, 5.5),
    ("equisolid", 4.0, 12.0, 280.0, 5.5),
    ("equidistant", 1.0, 7.0, 280.0, 3.5),
    ("equidistant", 1.0, 7.0, 160.0, 6.5),
])
def test_a_sun_behind_the_ridge_is_not_reported(lens: str, below_deg: float, core_deg: float,
                                                azimuth_deg: float, ridge_mean_deg: float
                                                ) -> None:
    """The disc 1–4° under the skyline, the aureole's clipped cap above it: reported at
    0.93, 0.99, 0.94, 0.99 and 0.99 before, 0.7–2.4 % of the width from the hidden disc. The
    circle through the cap's free arc lies on the hidden disc, near the rim: for the first
    two inside the lens's horizon but beyond the detector's image circle (shrunk 2 % off the
    dark rim), so its evidence was dropped — now the lens's whole circle
    (``vision.fov.lens_circle``); for the last three, on the equisolid lens read as
    equidistant (squashed along the radius there) it is centred beyond the horizon itself,
    and on the equisolid candidate on the disc (``vision.detect._candidate_projections``).
    The two equidistant suns were refused before and are still: a rule that wanted the disc
    dark at every candidate's centre reported them at 0.99 (a candidate's circle 3 px off,
    its disc half on the skyline); one clipped disc at a candidate's centre is what keeps a
    sun."""
    img, _ = _render(lens, 1000, -below_deg, core_deg, azimuth_deg, ridge_mean_deg)
    d = _blind(img)
    print(d.sun_found, d.confidence, d.reason)
    assert not d.sun_found and d.confidence < 0.3, (d.confidence, d.centroid_px)
    assert "behind the obstacle" in str(d.reason)


@pytest.mark.parametrize("lens", ["equisolid", "equidistant"])
@pytest.mark.parametrize("above_deg", [4.0, 9.9, 20.0])
@pytest.mark.parametrize("core_deg", [4.0, 7.0])
@pytest.mark.parametrize("ridge_mean_deg", [3.5, 6.5])
def test_a_sun_over_the_ridge_is_found(lens: str, above_deg: float, core_deg: float,
                                       ridge_mean_deg: float) -> None:
    """Issue 24's check on the visible suns (1000 px, the sun at azimuth 320°, a short and a
    long exposure's core): found with confidence ≥ 0.5 within 1 % of the width of the
    disc's pixel, never "behind the obstacle" (measured: equisolid 0.08–0.84 %, its glare
    centred as on an equidistant lens; equidistant ≤ 0.04 %; confidence 0.99)."""
    img, (tx, ty) = _render(lens, 1000, above_deg, core_deg, 320.0, ridge_mean_deg)
    d = _blind(img)
    assert d.sun_found and d.confidence >= 0.5, (d.confidence, d.reason)
    assert np.hypot(d.centroid_px[0] - tx, d.centroid_px[1] - ty) <= 0.01 * 1000


def test_the_testers_sun_ten_degrees_over_the_ridge_on_a_3000_px_frame() -> None:
    """The tester's frame (issue 24, docs/validation-vision.md *A sun behind the obstacle*):
    equisolid, 3000 × 2000, north at 37°, the sun 9.9° above the ridge with a saturated core
    a couple of hundred px wide (7° in radius); found within 1 % of the width (measured
    0.57 %, confidence 0.99)."""
    img, (tx, ty) = _render("equisolid", 3000, 9.9, 7.0, 320.0)
    d = _blind(img)
    assert d.sun_found and d.confidence >= 0.5, (d.confidence, d.reason)
    assert np.hypot(d.centroid_px[0] - tx, d.centroid_px[1] - ty) <= 0.01 * 3000


@pytest.mark.parametrize("lens", ["equisolid", "equidistant"])
def test_a_small_core_low_over_the_ridge_is_found(lens: str) -> None:
    """A 1.5° saturated core 4° over the ridge at 3000 px: refused before as "not
    radially symmetric" (coherence 0.10 and 0.14, confidence 0.09 and 0.39) — the symmetry
    was measured in the image plane, where the lens draws the glare as an oval (and on a
    sphere the gradients were carried as vectors, not as the normals they are). Measured
    on the sphere of each projection the image circle may have
    (``vision.detect._glare_sphere``): coherence 0.77 and 0.85, confidence 0.77 and
    0.96, 0.01 % and 0.00 % of the width off, the equisolid one centred on its own sphere
    (9.9° over the ridge likewise: confidence 0.26 and 0.50 → 0.95 and 0.98)."""
    img, (tx, ty) = _render(lens, 3000, 4.0, 1.5, 320.0)
    d = _blind(img)
    assert d.sun_found and d.confidence >= 0.5, (d.confidence, d.reason)
    assert np.hypot(d.centroid_px[0] - tx, d.centroid_px[1] - ty) <= 0.01 * 3000


def test_an_equisolid_glare_is_centred_on_the_projection_the_glare_tells() -> None:
    """A 12° core 9.9° over the ridge through an equisolid lens, read blind as equidistant:
    the limb fit on the guess's sphere put it 0.98 % of the width off. The glare's gradients
    are most radially symmetric on the equisolid sphere, and the centre is fitted there
    (``vision.detect._glare_sphere``): measured 0.07 % (20° over the ridge 0.61 → 0.06 %)."""
    img, (tx, ty) = _render("equisolid", 1000, 9.9, 12.0, 320.0)
    d = _blind(img)
    assert d.sun_found and d.confidence >= 0.5, (d.confidence, d.reason)
    assert np.hypot(d.centroid_px[0] - tx, d.centroid_px[1] - ty) <= 0.0015 * 1000
