"""One frame → a JSON-ready answer: detection, the camera's angles, the ephemeris comparison.

The shape of ``POST /api/v1/vision/sun`` and ``heliotwin vision detect`` (both
call :func:`analyse_frame`). The ephemeris sun position is the caller's (the
service takes it from SPA); this module only projects it through the same
camera model as the detection and measures the angle between the two.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.cameras import FisheyeCamera, PinholeCamera
from vision.candidates import _median, _ring_values, region_threshold
from vision.detect import detect_sun
from vision.fov import to_gray
from vision.metrics import wrap_deg
from vision.sphere import SUN_RADIUS_DEG, angular_separation_deg


def finite(v: Any) -> float | None:
    """A finite float, or None (NaN is no JSON number)."""
    if v is None:
        return None
    f = float(v)
    return f if np.isfinite(f) else None


SUN_DOWN_DEG = -5.0
"""An ephemeris sun lower than this [°, apparent elevation] cannot be in any frame taken at
that time and place: whatever bright region is found is the moon or a light, not the sun.
The margin bounds everything that lets a sun below the horizon be seen: the upper limb lies
0.27° above the centre; the horizon of the highest place accepted (9000 m) dips 2.9° below
the level (1.76′ √h); refraction at the horizon strays from SPA's standard 0.57° by about a
degree in unusual air. Together 4.2°. No camera model enters: the elevation is the
ephemeris's, so no calibration, right or wrong, moves it. The twilight frame a tester
rendered at −4.7° is dark anyway (no saturated region)."""


def sun_down_reason(elevation_deg: float, found_px: tuple[float, float] | None) -> str:
    """Why a frame whose ephemeris sun is below :data:`SUN_DOWN_DEG` has no sun."""
    what = ("the bright region found" + (f" at ({found_px[0]:.0f}, {found_px[1]:.0f}) px"
                                        if found_px is not None else "")
            + " is the moon or a light")
    return (f"the ephemeris puts the sun {-elevation_deg:.1f}° below the horizon at this time "
            f"and place, so no sun can be in the frame: {what}; if the sun really is in the "
            f"frame, the time (its zone) or the place is wrong")


#: A saturated core whose edge drops this share of its contrast within 2 px of it is the
#: sun's disc itself: a glare that saturates beyond the disc falls off over degrees (the
#: synthetic tracker frames' 0.4-2° glares drop 0.25-0.55 there, haze 0.2-0.25)
SHARP_EDGE_DROP = 0.6
#: … and such a disc this many times the solar disc's radius at the camera's scale is drawn
#: at another scale: blur and the pixel grid add a pixel (1.02-1.2 times on the tester's
#: discs at the right scale); a field of view half the one used makes it 2
SCALE_RATIO = 2.0
#: The window :func:`disc_scale_warning` reads, in disc radii at the assumed scale each side
#: of the sun: a core up to some 15 times the disc (a field of view 15 times narrower than the
#: one assumed) lies in it with its ring.
SCALE_WINDOW_RADII = 16.0


def disc_scale_warning(image: NDArray[Any], centroid_px: tuple[float, float],
                       cam: PinholeCamera) -> str | None:
    """A warning when the sun found at ``centroid_px`` is a sharp-edged disc (the disc itself,
    not a glare: its edge drops :data:`SHARP_EDGE_DROP` of the contrast within 2 px) more
    than :data:`SCALE_RATIO` times the solar disc's radius at ``cam``'s scale — a camera whose
    field of view was not given, read at the default 67° (a tester's 1280 × 960 camera of 20°:
    offsets 3.7 times too large, a mount fit 6.8° off in azimuth, and no word). A glare only
    grows a core, so only a larger, sharp-edged one is looked at; a warning, not a refusal:
    the offsets are still given. None when nothing is wrong.

    Read in a window of :data:`SCALE_WINDOW_RADII` disc radii around the sun (the sky's
    level from every 8th pixel of the frame): on the whole of a 40-megapixel frame its
    labels had raised an upload's peak memory by 180 MB (``test_limits``)."""
    x, y = (int(round(v)) for v in centroid_px)
    h, w = image.shape[:2]
    if not (0 <= x < w and 0 <= y < h):
        return None
    rho = cam.focal_px * float(np.tan(np.radians(SUN_RADIUS_DEG)))
    half = int(np.ceil(max(32.0, SCALE_WINDOW_RADII * rho)))
    x0, y0 = max(x - half, 0), max(y - half, 0)
    gray = to_gray(np.ascontiguousarray(image[y0:y + half + 1, x0:x + half + 1]))
    bg = float(np.median(to_gray(np.ascontiguousarray(image[::8, ::8]))))
    peak = float(gray.max())
    if peak - bg < 20.0:
        return None
    mask = (gray > region_threshold(peak, bg)[1]).astype(np.uint8)
    if not mask[y - y0, x - x0]:
        return None
    _, labels = cv2.connectedComponents(mask, connectivity=8)
    area = float(np.count_nonzero(labels == labels[y - y0, x - x0]))
    r_eq = float(np.sqrt(area / np.pi))
    ring = _ring_values(gray, centroid_px[0] - x0, centroid_px[1] - y0, r_eq + 2.0, None)
    if ring.size < 8 or r_eq <= SCALE_RATIO * rho:
        return None
    if (peak - _median(ring)) / (peak - bg) < SHARP_EDGE_DROP:
        return None
    focal = r_eq / float(np.tan(np.radians(SUN_RADIUS_DEG)))
    implied = float(np.degrees(2.0 * np.arctan(0.5 * cam.width_px / focal)))
    return (f"fov_deg: the sun's disc is {2 * r_eq:.0f} px across with a sharp edge (the disc "
            f"itself, not a glare), {r_eq / rho:.1f} times the {2 * rho:.0f} px a field of "
            f"view of {cam.fov_deg:g}° gives it: the frame looks like a field of view near "
            f"{implied:.0f}° and the offsets about {r_eq / rho:.1f} times too large; give the "
            "camera's fov_deg")


def ephemeris_block(cam: PinholeCamera | FisheyeCamera, azimuth_deg: float,
                    elevation_deg: float) -> dict[str, Any]:
    """``{"azimuth_deg", "elevation_deg"[, "centroid_px"]}`` for the ephemeris sun.

    For a fisheye camera ``centroid_px`` is the ephemeris sun's pixel ``[x, y]``
    through the camera model (projection, radial terms and tilt included,
    :meth:`FisheyeCamera.sky_to_pixel`; seed 003, eqs. 9–11), or None when the
    sun is below the horizon or outside the lens's domain. A pinhole camera's
    pointing is unknown here, so it gets no pixel.
    """
    out: dict[str, Any] = {"azimuth_deg": float(azimuth_deg),
                           "elevation_deg": float(elevation_deg)}
    if isinstance(cam, FisheyeCamera):
        px = None
        if elevation_deg >= 0.0:
            x, y = cam.sky_to_pixel(azimuth_deg, elevation_deg)
            fx, fy = finite(x), finite(y)
            px = [fx, fy] if fx is not None and fy is not None else None
        out["centroid_px"] = px
    return out


def analyse_frame(image: NDArray[Any], cam: PinholeCamera | FisheyeCamera,
                  method: str = "robust",
                  ephemeris_deg: tuple[float, float] | None = None,
                  oriented: bool = True) -> dict[str, Any]:
    """Detect the sun in ``image`` and express it in ``cam``'s terms.

    Returns ``sun_found``, ``confidence`` (a calibrated probability), ``reason``
    (why not, on a "no sun" answer; None otherwise), ``centroid_px``, ``method``,
    ``distance_from_ephemeris_px`` (fisheye with an ephemeris: the detection's
    distance from the predicted pixel, which is searched first; else None),
    ``image_size_px``, ``camera`` and — fisheye — ``azimuth_deg``/``elevation_deg``
    or — pinhole — ``pointing_error_deg`` [right, up] and ``pointing_error_mrad``.
    With ``ephemeris_deg = (azimuth, elevation)``: ``ephemeris`` (see
    :func:`ephemeris_block`) and, when both suns are known, ``error`` with the
    angle between them on the sphere (``separation_deg``), the azimuth
    (wrapped) and elevation differences, detected − ephemeris, and for a
    fisheye the pixel distance between the two (``distance_px``).

    A sun the ephemeris puts below :data:`SUN_DOWN_DEG` is no sun, whatever is found
    (``sun_found`` false, confidence 0, the reason :func:`sun_down_reason`): a tester's
    moonlit night (sun 35° down) was answered as a sun at confidence 1.00.

    ``oriented``: whether the fisheye's north offset is known (a calibration, or given).
    Only then does the ephemeris's pixel guide the search and count in the confidence
    (issue 24: evidence against a sun is "the ephemeris of a *calibrated* camera puts
    the sun far away"); a camera sent without one is searched blind and the ephemeris
    only compared — its default north offset of 0 is a guess that put a plain sun of
    EUROCONTROL 128° from its prediction, refused at confidence 0.02.
    """
    expected = None
    if ephemeris_deg is not None and isinstance(cam, FisheyeCamera) and oriented \
            and ephemeris_deg[1] >= 0:
        ex, ey = (finite(v) for v in cam.sky_to_pixel(*(float(v) for v in ephemeris_deg)))
        expected = (ex, ey) if ex is not None and ey is not None else None
    d = detect_sun(image, method=method, camera=cam if method == "robust" else None,
                   expected_px=expected)
    if ephemeris_deg is not None and ephemeris_deg[1] < SUN_DOWN_DEG:
        d = replace(d, sun_found=False, confidence=0.0, centroid_px=None,
                    distance_from_ephemeris_px=None,
                    reason=sun_down_reason(float(ephemeris_deg[1]),
                                           d.centroid_px if d.sun_found else None))
    c = d.centroid_px
    out: dict[str, Any] = {
        "sun_found": d.sun_found,
        "confidence": d.confidence,
        "reason": d.reason,
        "centroid_px": [float(c[0]), float(c[1])] if c is not None else None,
        "method": d.method,
        "image_size_px": [int(image.shape[1]), int(image.shape[0])],
        "distance_from_ephemeris_px": finite(d.distance_from_ephemeris_px),
    }
    if isinstance(cam, FisheyeCamera):
        out["camera"] = "fisheye"
        az = el = None
        if c is not None:
            a, e = cam.pixel_to_sky(*c)
            az, el = finite(a), finite(e)
        out["azimuth_deg"], out["elevation_deg"] = az, el
    else:
        out["camera"] = "pinhole"
        out["pointing_error_deg"] = out["pointing_error_mrad"] = None
        if c is not None:
            hh, vv, tot = cam.pointing_error(*c)
            out["pointing_error_deg"] = [finite(hh), finite(vv)]
            out["pointing_error_mrad"] = finite(tot)
    if ephemeris_deg is None:
        return out
    eaz, eel = (float(v) for v in ephemeris_deg)
    eph = ephemeris_block(cam, eaz, eel)
    out["ephemeris"] = eph
    if out.get("azimuth_deg") is not None and out.get("elevation_deg") is not None:
        err: dict[str, Any] = {
            "separation_deg": float(angular_separation_deg(out["azimuth_deg"],
                                                           out["elevation_deg"], eaz, eel)),
            "azimuth_deg": float(wrap_deg(out["azimuth_deg"] - eaz)),
            "elevation_deg": out["elevation_deg"] - eel,
        }
        if c is not None and eph.get("centroid_px") is not None:
            ex, ey = eph["centroid_px"]
            err["distance_px"] = float(np.hypot(c[0] - ex, c[1] - ey))
        out["error"] = err
    return out
