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
  camera is wrong, not the detector: say so rather than store a silent 110°. A
  calibrated camera that puts the ephemeris sun beyond the frame's edge (a fisheye
  circle the frame cuts) says that what was found at the edge is its glare.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from typing import Any

import numpy as np

from backend.errors import InputError
from vision.calibrate import MAX_RMS_DEG, MAX_TILT_DEG, SKY_MIN_ELEVATION_DEG
from vision.cameras import PROJECTIONS, px_per_deg_for_horizon
from vision.fov import image_circle, to_gray
from vision.sphere import angular_separation_deg

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
        raise InputError(422, f"px_per_deg: required for this {w}×{h} px frame — no image "
                              "circle to derive the scale from was found (a lit disc filling "
                              "at least a fifth of the frame, within dark corners; "
                              "vision.fov.estimate_fov), or give calibration_id")
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
        d_el = abs(float(err.get("elevation_deg") or 0.0))
        if float(sep) > limit and d_el <= limit:
            # the sun's height is right and only its bearing is off: the frame turned or
            # mirrored against the calibration's frames, not a wrong place or time (a
            # tester's frame turned 90°: 57° off, 0.01° in elevation)
            out.append(f"an error of {float(sep):.1f}° is far beyond this calibration's worst "
                       f"residual ({calibration_max_deg:.2f}°), all of it in azimuth "
                       f"({float(err.get('azimuth_deg') or 0.0):+.1f}°; elevation "
                       f"{d_el:.2f}° off): is the frame turned or mirrored against the frames "
                       f"the camera was calibrated on (a camera mounted anew, images rotated "
                       f"or flipped on export)? Or is its time off (near noon an hour moves "
                       f"the sun mostly in azimuth)?")
        elif float(sep) > limit:
            out.append(f"an error of {float(sep):.1f}° is far beyond this calibration's worst "
                       f"residual ({calibration_max_deg:.2f}°): is the place or the time right?")
    out += _off_frame_warning(res, calibration_max_deg)
    return out


def _off_frame_warning(res: dict[str, Any], calibration_max_deg: float | None) -> list[str]:
    """A sun found while the calibrated camera puts the ephemeris sun off the frame (a
    fisheye circle cut by the frame's top and bottom): what was found at the edge is the
    glare of a sun beyond it, not the sun's position. A tester's 3000 × 2000 frame with the
    sun 21 px above its top edge was answered as a sun 45 px from it (5.0° from the
    ephemeris) at confidence 0.95, with no warning: just under the error warning's 5°.
    Only for a calibration: a camera's guessed north puts the ephemeris anywhere."""
    eph_px = (res.get("ephemeris") or {}).get("centroid_px")
    size = res.get("image_size_px")
    if calibration_max_deg is None or not res.get("sun_found") or eph_px is None or not size:
        return []
    ex, ey = (float(v) for v in eph_px)
    w, h = (int(v) for v in size)
    if -0.5 <= ex <= w - 0.5 and -0.5 <= ey <= h - 0.5:
        return []
    cx, cy = (float(v) for v in res["centroid_px"])
    return [f"the calibrated camera puts the ephemeris sun at ({ex:.0f}, {ey:.0f}) px, off "
            f"the {w}×{h} px frame: the bright region found at ({cx:.0f}, {cy:.0f}) px is "
            f"likely the glare of a sun beyond the frame's edge, not the sun's position"]


MAX_OUTLIER_SHARE = 1 / 3
"""A calibration whose outliers are more than this share of the frames it fitted is refused:
its consensus is not a clear majority. The robust fit draws 20 samples of three frames
(``vision.calibrate._RANSAC_TRIALS``), enough to find a clean sample with probability above
0.999 while at most a third disagree ((1 − (2/3)³)²⁰ < 0.001); when more disagree, the
frames that "agree" are as likely a chance fit of wrong times (the 12 even Wolf frames
given their times reversed: 7 outliers, 5 fitted to 0.38° by a mirrored camera 130 px off
centre)."""


def check_consensus(frames: list[dict[str, Any]], loo_rms_deg: float | None,
                    other_setting: Callable[[], tuple[str, str] | None] | None = None
                    ) -> None:
    """Refuse (422 naming ``timestamps``) a calibration whose inliers are not a clear
    majority (:data:`MAX_OUTLIER_SHARE`) of the frames with a sun found, or whose outliers
    leave too few frames to check the fit by leaving each out (``loo_rms_deg`` None).

    ``other_setting``, asked only on a refusal, names a setting the caller forced (``east``,
    ``n_radial``, ``projection``) whose other choice fits the same suns, and how: the
    refusal then names that field, not the times (Wolf's frames mirrored, ``east=left``
    forced: 9 of 12 disagreed, "are the times in the order…", while ``east=auto`` fits
    them, east right, to 0.34°)."""
    fitted = [f for f in frames if f.get("used") or f.get("outlier")]
    out = [f for f in fitted if f.get("outlier")]
    if not out:
        return
    why = (f"{len(out)} of {len(fitted)} frames disagree with the fit (their suns lie more "
           f"than 1° from where the camera fitted to the other {len(fitted) - len(out)} "
           f"puts them: {', '.join(str(f.get('filename') or f.get('name')) for f in out)})")
    hint = ("are the times in the order of the files, and in the right zone (UTC, or with "
            "their offset)?")
    if len(out) > MAX_OUTLIER_SHARE * len(fitted):
        why += "; a calibration needs at least two thirds of its frames to agree"
    elif loo_rms_deg is None:
        why += (", and the rest are too few sun directions to check the fit by leaving each "
                "out in turn")
        hint += " Or send more frames"
    else:
        return
    named = other_setting() if other_setting is not None else None
    if named is not None:
        field, how = named
        raise InputError(422, f"{field}: {why}; {how}: is the {field} you gave right?")
    raise InputError(422, f"timestamps: {why}: {hint}")


def check_tilt(tilt_north_deg: float, tilt_east_deg: float) -> None:
    """Refuse (422 naming ``fit_tilt``) a tilt fit that ended at its bound
    (:data:`vision.calibrate.MAX_TILT_DEG`): the frames do not determine the tilt — on
    one day's arc it trades against the centre — so the refusal names the tilt fit, not the
    times a far centre would otherwise blame."""
    worst = max(abs(tilt_north_deg), abs(tilt_east_deg))
    if worst >= MAX_TILT_DEG - 0.01:
        raise InputError(422, f"fit_tilt: the tilt fit ran to its bound ({worst:.1f}° of "
                              f"{MAX_TILT_DEG:g}°): these frames do not determine the tilt "
                              f"(on one day's arc it trades against the centre); calibrate "
                              f"without fit_tilt, or add frames of other days (the sun "
                              f"higher and lower)")


MAX_CENTRE_OFFSET_DEG = 4.0
"""A fitted optical centre farther than this [°, in the fitted scale] from the centre of the
image circle is refused. A fisheye's image circle is centred on its optical axis: on the
real series the fitted centre (a levelled camera's zenith) lies 0.6–1.5° from the circle's
centre (Wolf 12/11/23 frames 0.71/0.61/0.66°, Wettermast 6 frames 1.51°), while times an
hour off fit a camera whose centre is 7.9–9.8° away (Wolf 12 and 23, Wettermast 6; the fit's
RMS stays 0.15–0.41°, as good as the right zone's: a path an hour along is the same arc
turned). The optical centre, not the zenith, so that a camera fitted with its tilt
(``fit_tilt``) is compared where its lens is."""


def image_circle_centre(image: np.ndarray) -> tuple[float, float] | None:
    """The centre of the frame's image circle (``vision.fov.image_circle``: the lit disc
    inside the dark corners), or None when the frame has none."""
    found = image_circle(to_gray(image))
    return None if found is None else (float(found[0].cx_px), float(found[0].cy_px))


def check_centre(centre_px: tuple[float, float], px_per_deg: float,
                 circles: list[tuple[float, float]], frames: list[dict[str, Any]] | None = None,
                 sky_uncertainty_deg: float = 0.0) -> float | None:
    """Refuse (422 naming ``timestamps``) a fitted camera whose optical centre lies more than
    :data:`MAX_CENTRE_OFFSET_DEG` from the median centre of the frames' image circles;
    the offset [°], or None when no frame has a circle (nothing to compare). An offset
    within three times the camera's own uncertainty (``sky_uncertainty_deg``, 1σ) may be
    the frames' geometry, not their times: the refusal then says how close together their
    suns lie (:func:`sun_span`) before it asks about the zone (five Wolf frames within 22
    minutes, their times right: the centre 7.2° off, the camera uncertain by 4.3°; Wolf's
    twelve an hour late: 9.4° off, uncertain by 0.6°)."""
    if not circles:
        return None
    cx, cy = (float(v) for v in np.median(np.asarray(circles, float), axis=0))
    off = float(np.hypot(centre_px[0] - cx, centre_px[1] - cy)) / px_per_deg
    if off > MAX_CENTRE_OFFSET_DEG:
        where = (f"the fitted camera puts its optical centre at ({centre_px[0]:.0f}, "
                 f"{centre_px[1]:.0f}) px, {off:.1f}° from the centre of the image circle "
                 f"({cx:.0f}, {cy:.0f}) px — a fisheye's lies within "
                 f"{MAX_CENTRE_OFFSET_DEG:g}° of it")
        if off <= 3.0 * sky_uncertainty_deg:
            raise InputError(422, f"timestamps: {where}; {sun_span(frames or [])}, too "
                                  f"little of the sky to fix the camera (its directions "
                                  f"are uncertain by up to {sky_uncertainty_deg:.1f}° "
                                  f"elsewhere): {_SPREAD} If they are, are the times UTC, "
                                  f"or given with their offset?")
        raise InputError(422, f"timestamps: {where}. Times in the wrong zone fit such a "
                              f"camera (an hour off moves it 8–10°): are the times UTC, or "
                              f"given with their offset? Is the place right?")
    return off


SKY_UNCERTAINTY_WARN_DEG = 0.5
"""A calibration whose direction is uncertain by more than this somewhere on the sky [°, 1σ;
``vision.calibrate.sky_uncertainty_deg``] is stored with a warning: about the sun's
diameter (0.53°), so such a camera cannot place the sun within its own disc everywhere.
Measured over the sky from 10° up, before it was taken from the lowest fitted sun up
(docs/vision-calibration.md): Wolf's 12 even frames 0.47°, its 11 odd 0.40°,
Wettermast's 6 0.32°; Wolf's morning alone 0.87° (its labels elsewhere 0.69° RMS, 1.28°
worst), three Wolf frames 12:41–13:49 UTC 1.14° (0.88° / 1.45°), eight rendered frames 2 min
apart 7.6° (0.58° / 0.91°). Beyond :data:`vision.calibrate.MAX_RMS_DEG` a calibration is
refused: it could not guide the ephemeris-guided search, whose radius that is."""

_SPREAD = ("send frames whose suns lie far apart on the sky: hours apart on one day, "
           "better still on days months apart (the sun higher and lower).")


def sun_span(frames: list[dict[str, Any]]) -> str:
    """In words, how much of the sun's path the used frames span: the largest angle between
    their ephemeris suns and the time between the first and the last."""
    used = [f for f in frames if f.get("used") and f.get("ephemeris")]
    if len(used) < 2:
        return f"the frames' suns lie in {len(used)} place{'' if len(used) == 1 else 's'}"
    az = np.array([f["ephemeris"]["azimuth_deg"] for f in used], float)
    el = np.array([f["ephemeris"]["elevation_deg"] for f in used], float)
    sep = np.asarray(angular_separation_deg(az[:, None], el[:, None], az[None], el[None]))
    text = f"the {len(used)} frames' suns lie within {float(sep.max()):.1f}° of one another"
    times = sorted(str(f["timestamp"]) for f in used if f.get("timestamp"))
    if len(times) == len(used):
        first, last = (dt.datetime.fromisoformat(t.replace("Z", "+00:00"))
                       for t in (times[0], times[-1]))
        minutes = (last - first).total_seconds() / 60.0
        text += (f" on the sun's path, taken over {minutes:.0f} minutes" if minutes < 180
                 else f" on the sun's path, taken over {minutes / 60:.1f} hours")
    return text


def check_sky_coverage(sky_uncertainty_deg: float, frames: list[dict[str, Any]]) -> list[str]:
    """Warnings for a calibration the frames fix poorly over the sky
    (:data:`SKY_UNCERTAINTY_WARN_DEG`); a refusal (422 naming ``timestamps``) past
    :data:`vision.calibrate.MAX_RMS_DEG`, a camera too uncertain to guide detection."""
    if sky_uncertainty_deg > MAX_RMS_DEG:
        raise InputError(422, f"timestamps: {sun_span(frames)}, too little of the sky to fix "
                              f"the camera: fitted to them, its directions elsewhere are "
                              f"uncertain by up to {_degrees(sky_uncertainty_deg)} (1σ), "
                              f"more than the {MAX_RMS_DEG:g}° within which detection "
                              f"searches around a calibration's prediction; {_SPREAD}")
    if sky_uncertainty_deg > SKY_UNCERTAINTY_WARN_DEG:
        return [f"{sun_span(frames)}: however well they fit (rms_deg), they fix the "
                f"camera only to {sky_uncertainty_deg:.1f}° (1σ, sky_uncertainty_deg) "
                f"somewhere on the sky, more than the sun's diameter "
                f"({SKY_UNCERTAINTY_WARN_DEG:g}°); {_SPREAD}"]
    return []


LOWEST_SUN_WARN_DEG = SKY_MIN_ELEVATION_DEG + 5.0
"""A calibration whose lowest fitted sun is higher than this [°] warns that the sky below it
is extrapolated: the sky a calibration is for reaches down to
:data:`vision.calibrate.SKY_MIN_ELEVATION_DEG`, and a sun within one row (5°) of the grid
:func:`vision.calibrate.sky_uncertainty_deg` is computed on counts as reaching it."""


def check_fitted_band(fitted_elevation_deg: tuple[float, float], sky_uncertainty_deg: float,
                      frames: list[dict[str, Any]]) -> list[str]:
    """A warning when no sun below :data:`LOWEST_SUN_WARN_DEG` was fitted: the directions
    below the lowest fitted sun are extrapolated (the radial law, an unmodelled tilt), and
    ``sky_uncertainty_deg`` holds only from that sun up (:func:`vision.calibrate.sky_band_deg`).
    A tester's tilted equisolid camera: its three suns below 25° left out (the detector put
    them 3–6° outward, in the glare along the horizon), fitted on suns 34–60° up, 0.19°
    claimed with no warning, 6° RMS true at 5–15° up. Names the frames with a lower sun
    that were left out as outliers, when there are any."""
    low, high = fitted_elevation_deg
    if low <= LOWEST_SUN_WARN_DEG:
        return []
    lower = [f for f in frames if f.get("outlier") and f.get("ephemeris")
             and f["ephemeris"]["elevation_deg"] < low]
    left = (f"; {len(lower)} frame{'' if len(lower) == 1 else 's'} with a lower sun "
            f"{'was' if len(lower) == 1 else 'were'} left out as "
            f"outlier{'' if len(lower) == 1 else 's'} "
            f"({', '.join(str(f.get('filename') or f.get('name')) for f in lower)})"
            if lower else "")
    return [f"no sun below {low:.0f}° was fitted (the suns used lie {low:.1f}–{high:.1f}° "
            f"up){left}: directions below {low:.0f}° are extrapolated — the lens's radial "
            f"law and any tilt are not checked there and can be off by degrees near the "
            f"horizon — and sky_uncertainty_deg ({sky_uncertainty_deg:.2f}°) holds only "
            f"from {max(low, SKY_MIN_ELEVATION_DEG):.0f}° up; send frames with the sun "
            f"lower (mornings and evenings)"]


def _degrees(value: float) -> str:
    return "any angle" if not np.isfinite(value) else f"{value:.1f}°"
