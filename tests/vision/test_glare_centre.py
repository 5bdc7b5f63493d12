"""The centre of a large glare (issue 24 item 3): vision.glare.symmetric_glare_centre, and
the detector taking only its component across the radius from the optical centre.

Expected values: the pixel a frame was drawn about (synthetic), the sun's position from
pvlib's SPA through a fisheye fitted to the frames (real Wolf frames) — never this code.
"""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pvlib
import pytest

from vision.calibrate import fit_fisheye
from vision.cameras import FisheyeCamera
from vision.detect import _across_from_glare, detect_sun
from vision.detection import FovCircle
from vision.glare import symmetric_glare_centre
from vision.skyrender import SkyScene, render

REAL_SKY = Path(__file__).resolve().parents[1] / "data" / "real-sky"


def _ragged_glare(sun: tuple[float, float]) -> np.ndarray:
    """A 700² colour frame: a glare falling off as (1 + (r/40)²)^-1.2 about ``sun`` on a blue
    sky brightening toward +y by 0.1 levels a pixel, clipped at 255, and a saturated lobe
    (a lens ray) stuck to the core on its −x side: the clipped region is not centred on the
    sun."""
    yy, xx = np.mgrid[0:700, 0:700].astype(float)
    r = np.hypot(xx - sun[0], yy - sun[1])
    lum = 120.0 + 0.1 * (yy - sun[1]) + 400.0 * (1.0 + (r / 40.0) ** 2) ** -1.2
    lobe = (np.abs(yy - sun[1]) < 12) & (xx > sun[0] - 95) & (xx < sun[0])
    lum[lobe] = np.maximum(lum[lobe], 340.0)
    img = np.stack([lum * 1.1, lum * 0.95, lum * 0.8], axis=-1)  # B, G, R: a blue sky
    return np.clip(img, 0, 255).astype(np.uint8)


def test_a_ragged_core_is_centred_by_its_glare() -> None:
    sun = (352.0, 340.0)
    img = _ragged_glare(sun)
    low = img.min(axis=2)
    clipped = np.argwhere(low >= 252)
    cy, cx = clipped.mean(axis=0)
    radius = float(np.sqrt(len(clipped) / np.pi))
    assert sun[0] - cx > 10.0  # the lobe pulls the clipped region's centroid 16 px toward −x
    got = symmetric_glare_centre(img, float(cx), float(cy), radius, FovCircle(350, 350, 349))
    assert got is not None
    assert np.hypot(got[0] - sun[0], got[1] - sun[1]) < 1.0  # measured 0.5 px


def test_a_monochrome_glare_is_centred_on_its_top_grey_level() -> None:
    """A colour camera's frame made monochrome (BT.601 luma): a white core 38 px in radius
    about the sun, inside a blue sky's glare clipped in blue and green (red 246: grey 252)
    that reaches 60 px about a point 20 px toward the brighter sky, in an image circle of
    480 px (5.4 px/°: the core is 7° wide). The grey core (above 250) is the blue glare's
    disc, whose limb fits put the sun 15.5 px off; its pixels within 1 grey level of the top
    are the white core (vision.candidates._white_core), centred as in colour (measured
    1.3 px)."""
    sun = (600.0, 450.0)
    yy, xx = np.mgrid[0:1000, 0:1000].astype(float)
    r = np.hypot(xx - sun[0], yy - sun[1])
    lum = 140.0 + 0.05 * (xx - 500) + 300.0 * (1.0 + (r / 45.0) ** 2) ** -1.0
    img = np.stack([lum * 1.15, lum * 1.0, lum * 0.8], axis=-1)  # B, G, R: a blue sky
    blue = np.hypot(xx - sun[0] - 20.0, yy - sun[1]) < 60.0
    img[blue] = np.maximum(img[blue], (255.0, 255.0, 246.0))
    img[r < 38.0] = 255.0
    img[np.hypot(xx - 500, yy - 500) > 480] = 5.0
    grey = cv2.cvtColor(np.clip(img, 0, 255).astype(np.uint8), cv2.COLOR_BGR2GRAY)
    d = detect_sun(grey)
    assert d.sun_found
    assert np.hypot(d.centroid_px[0] - sun[0], d.centroid_px[1] - sun[1]) <= 3.0


@pytest.mark.parametrize("seed", [113, 202])
def test_a_thin_band_of_blue_glare_is_no_reason_for_the_white_core(seed: int) -> None:
    """Second-renderer development scenes (clear, the sun 11° and 23° high, 5.2 and 3.5
    px/°, JPEG 60, a lateral colour fringe of 1.0–1.5 px at the rim): a saturated core
    ≈ 30 px in radius whose white core JPEG's colour coding erodes by 3 px on its outer
    side, so the grey core passes the 1.3 × area test with a band of 3–4 px. Before, the
    white core answered 3.4–4.1 px inside the truth (1.03°, 0.97°); a blue glare narrower
    than half a JPEG coding unit now leaves the core to the limb fits (measured 0.24°,
    0.23°)."""
    from vision.skyrender import random_scene
    from vision.sphere import angular_separation_deg

    s = random_scene(seed, sky="clear")
    d = detect_sun(render(s).image, camera=s.camera)
    assert d.sun_found and d.centroid_px is not None
    az, el = s.camera.pixel_to_sky(*d.centroid_px)
    assert angular_separation_deg(az, el, s.azimuth_deg, s.elevation_deg) < 0.35


def test_only_the_component_across_the_radius_is_taken(monkeypatch) -> None:
    """The core's centre 300 px right of the optical centre, the glare's 5 px inward and
    3 px across: the answer is the core's distance from the centre, the glare's side."""
    import vision.detect as detect

    monkeypatch.setattr(detect, "symmetric_glare_centre", lambda *a, **k: (795.0, 503.0))
    camera = FisheyeCamera(500.0, 500.0, 10.0)

    class Core:
        cx, cy = 800.0, 500.0

    x, y, r = _across_from_glare(np.zeros((4, 4, 3), np.uint8), Core(), 60.0, None,
                                 (800.0, 500.0, 60.0), camera)  # type: ignore[arg-type]
    assert (x, y, r) == pytest.approx((800.0, 503.0, 60.0))


def _wolf() -> tuple[list[np.ndarray], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    with (REAL_SKY / "metadata.csv").open(newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["filename"].startswith("Wolf")]
    t = pd.DatetimeIndex([pd.Timestamp(r["utc_time"]) for r in rows])
    sp = pvlib.solarposition.get_solarposition(t, float(rows[0]["lat"]), float(rows[0]["lon"]),
                                               method="nrel_numpy")
    imgs = [cv2.imread(str(REAL_SKY / r["filename"])) for r in rows]
    lx = np.array([float(r["sun_col_label"]) for r in rows])
    ly = np.array([float(r["sun_row_label"]) for r in rows])
    return imgs, sp["azimuth"].to_numpy(), sp["apparent_elevation"].to_numpy(), lx, ly


def test_wolf_centres_with_a_camera_agree_with_the_ephemeris() -> None:
    """The 23 Wolf suns found on the ephemeris-guided path (a camera given: its optical
    centre and the search window; here the fit of the hand labels) lie on one equidistant
    camera through SPA's suns within 3.67 px RMS (measured; the white core alone: 5.13 px;
    the hand labels themselves: 3.43 px), 2.7 px from their labels at the median and
    8.6 px at worst (the white core alone: 15.3 px)."""
    imgs, az, el, lx, ly = _wolf()
    size = (imgs[0].shape[1], imgs[0].shape[0])
    cam = fit_fisheye(lx, ly, az, el, size).camera
    xy = []
    for img, a, e in zip(imgs, az, el, strict=True):
        px, py = cam.sky_to_pixel(a, e)
        d = detect_sun(img, camera=cam, expected_px=(float(px), float(py)))
        assert d.sun_found
        xy.append(d.centroid_px)
    _wolf_centres_hold(np.array(xy), az, el, lx, ly, size)



def _wolf_centres_hold(xy: np.ndarray, az: np.ndarray, el: np.ndarray, lx: np.ndarray,
                       ly: np.ndarray, size: tuple[int, int]) -> None:
    """The 23 Wolf centres ``xy`` on one equidistant camera through SPA's suns within
    3.9 px RMS, ≤ 3.0 px from their labels at the median and ≤ 9.5 px at worst (both paths
    measured 3.62–3.67, 2.7–2.84 and 8.6 px)."""
    assert fit_fisheye(xy[:, 0], xy[:, 1], az, el, size).rms_px < 3.9
    dist = np.hypot(xy[:, 0] - lx, xy[:, 1] - ly)
    assert float(np.median(dist)) <= 3.0
    assert float(dist.max()) <= 9.5

def test_second_renderer_glare_centre_is_unbiased_across_the_radius() -> None:
    """The second renderer's sun (a Moffat aureole, symmetric on the sphere) on a CIE clear
    sky brighter toward the horizon, with vignetting (1 − 0.25 r²), 5.35 px/°, a core
    ≈ 50 px in radius: across the radius from the optical centre the glare's centre is
    within 0.17 px of the truth on every frame (measured); along it, it is pulled inward by
    3.3–4.4 px, where the core's centre is 1.3–1.6 px in — the reason the detector keeps
    the core's distance from the optical centre (vision.detect._across_from_glare)."""
    cam = FisheyeCamera(479.5, 479.5, 5.35, 344.5, "left", "equidistant")
    along, across = [], []
    for i, (az, el) in enumerate(((110.0, 47.0), (160.0, 57.0), (235.0, 48.0))):
        s = SkyScene(az, el, 960, 960, cam, sky="clear", glare_deg=6.0, sky_level=0.45,
                     vignetting=0.25, seed=300 + i)
        img = render(s).image
        d = detect_sun(img)
        assert d.sun_found and d.area_px is not None
        got = symmetric_glare_centre(img, *d.candidate_px, float(np.sqrt(d.area_px / np.pi)),
                                     d.fov, start=d.centroid_px)
        assert got is not None
        tx, ty = (float(v) for v in cam.sky_to_pixel(az, el))
        u = np.array([tx - cam.cx_px, ty - cam.cy_px])
        u /= np.linalg.norm(u)
        e = np.array(got) - (tx, ty)
        along.append(float(e @ u))
        across.append(float(e @ (-u[1], u[0])))
    assert max(abs(v) for v in across) < 0.25  # measured 0.17 px
    assert max(along) < -2.0


def test_wolf_centres_blind_agree_with_the_ephemeris() -> None:
    """Blind (no camera: only the frame), the white core is moved across the radius from
    the image circle's centre — the field stop's edge fitted behind Wolf's trees
    (vision.fov._rim_circle), 6–10 px from the labels' optical centre where the bright
    region's enclosing circle was 37–111 px off. The 23 suns lie on one equidistant camera
    through SPA within 3.62 px RMS (measured; the white core alone: 5.13 px), 2.84 px from
    their labels at the median (2.70) and 8.6 px at worst (15.3)."""
    imgs, az, el, lx, ly = _wolf()
    size = (imgs[0].shape[1], imgs[0].shape[0])
    got = []
    for img in imgs:
        d = detect_sun(img)
        assert d.sun_found
        got.append(d.centroid_px)
    _wolf_centres_hold(np.array(got), az, el, lx, ly, size)
