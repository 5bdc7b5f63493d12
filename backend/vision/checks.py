"""What the vision service infers or doubts about an upload: a derived fisheye scale, and
whether a detection's error against the ephemeris is one any calibration could leave.

- :func:`derive_fisheye_scale`: a fisheye sent without ``px_per_deg`` gets the scale
  its image circle implies (the circle of a 180° lens is the horizon, θ = 90°;
  ``vision.cameras.px_per_deg_for_horizon``), and its centre when none is given;
  the answer says so in ``camera_derived``.
- :func:`error_warnings`: a sun found while the ephemeris puts it below the
  horizon, or a zenith-angle difference that no north offset or mirror can
  explain (they only turn the sky about the zenith), or an error far beyond the
  stored calibration's own residuals, means the place, the time (its zone) or the
  camera is wrong, not the detector: say so rather than store a silent 110°.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from backend.errors import InputError
from vision.cameras import PROJECTIONS, px_per_deg_for_horizon
from vision.fov import image_circle, to_gray

ZENITH_ANGLE_LIMIT_DEG = 15.0
"""A zenith-angle error larger than this needs a scale or centre off by more than any
plausible fisheye model; rotation (north offset) and mirroring cannot make one."""

CALIBRATION_ERROR_FACTOR = 5.0
"""A calibrated camera's error beyond this many times its worst calibration residual
(at least 1°) is not the camera's."""


def derive_fisheye_scale(image: np.ndarray, params: dict[str, object]
                         ) -> tuple[dict[str, object], dict[str, Any]]:
    """``params`` completed with ``px_per_deg`` (and ``cx_px``/``cy_px`` if absent) from the
    image circle, and a note of what was derived; a 422 naming ``px_per_deg`` when the
    frame has no circle to measure."""
    projection = str(params.get("projection") or "equidistant")
    if projection not in PROJECTIONS:
        raise InputError(422, f"projection: must be one of {', '.join(PROJECTIONS)}, "
                              f"got {projection!r}")
    found = image_circle(to_gray(image))
    if found is None:
        h, w = image.shape[:2]
        raise InputError(422, f"px_per_deg: required for this {w}×{h} px frame — it has no "
                              "dark corners around an image circle to derive the scale from "
                              "(or give calibration_id)")
    circle, clipped = found
    out = dict(params)
    derived: dict[str, Any] = {
        "px_per_deg": round(px_per_deg_for_horizon(circle.radius_px, projection), 4),
        "image_circle_radius_px": round(circle.radius_px, 1),
        "projection": projection,
        "how": (f"image circle radius {circle.radius_px:.0f} px taken as the horizon "
                f"(θ = 90°, a 180° lens), {projection} projection"),
    }
    out["px_per_deg"] = derived["px_per_deg"]
    for key, value in (("cx_px", circle.cx_px), ("cy_px", circle.cy_px)):
        if params.get(key) in (None, ""):
            out[key] = derived[key] = round(value, 1)
    if clipped:
        derived["warning"] = ("the image circle reaches the frame's edge, so the lens's "
                              "horizon was not seen whole: the derived scale is rough; "
                              "calibrate the camera for accurate angles")
    else:
        derived["warning"] = ("a scale from the image circle assumes a 180° lens; "
                              "calibrate the camera for accurate angles")
    return out, derived


def error_warnings(res: dict[str, Any], calibration_max_deg: float | None) -> list[str]:
    """Plain-language warnings for a detection whose error vs the ephemeris is implausible."""
    eph = res.get("ephemeris") or {}
    err = res.get("error") or {}
    if not res.get("sun_found") or "elevation_deg" not in eph:
        return []
    out: list[str] = []
    eph_el = float(eph["elevation_deg"])
    if eph_el < -1.0:
        out.append(f"a sun was found, but at this time and place the ephemeris puts it "
                   f"{-eph_el:.1f}° below the horizon: check the time, its zone and the place")
    det_el = res.get("elevation_deg")
    if det_el is not None and eph_el >= -1.0:
        dz = abs(float(det_el) - eph_el)
        if dz > ZENITH_ANGLE_LIMIT_DEG:
            out.append(f"the detected sun is {dz:.1f}° from the ephemeris in zenith angle, which "
                       f"no north offset or mirror can explain (limit "
                       f"{ZENITH_ANGLE_LIMIT_DEG:.0f}°): check the place, the time and its zone, "
                       f"or the camera's scale and centre")
    sep = err.get("separation_deg")
    if sep is not None and calibration_max_deg is not None:
        limit = CALIBRATION_ERROR_FACTOR * max(1.0, calibration_max_deg)
        if float(sep) > limit:
            out.append(f"an error of {float(sep):.1f}° is far beyond this calibration's worst "
                       f"residual ({calibration_max_deg:.2f}°): is the place or the time right?")
    return out
