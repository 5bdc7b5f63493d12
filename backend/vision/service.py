"""The vision service: find the sun in uploaded frames, calibrate fisheye cameras, evaluate.

What ``/api/v1/vision`` does once the request is parsed (``backend/api/routes/vision.py``
parses and shapes): each frame's header is checked before anything is decoded
(:func:`check_image`), frames are decoded one at a time in the worker thread
that does the work, the ephemeris is NREL SPA (``sim.sun.solar_position``,
apparent elevation), detection and calibration are ``vision``'s. Bad input
raises :class:`backend.errors.InputError` naming the field.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any
from zoneinfo import ZoneInfo

import numpy as np
import pandas as pd

from backend.errors import InputError
from backend.vision.checks import (
    check_centre,
    check_consensus,
    check_fitted_band,
    check_sky_coverage,
    check_tilt,
    image_circle_centre,
)
from sim.sun import solar_position
from vision.analyse import analyse_frame
from vision.calibrate import (
    DISTINCT_DEG,
    MIN_DIRECTIONS,
    PROJECTION_FROM_FRAMES,
    SelfCalibration,
    calibrate_positions,
    n_directions,
    self_calibrate,
)
from vision.cameras import PROJECTIONS, FisheyeCamera, PinholeCamera
from vision.imageio import ImageError, decode_image, image_size
from vision.metrics import error_table

#: what names the pixel limit in a refusal: the service's setting (the CLI passes its own)
SERVICE_PIXEL_LIMIT = "HELIOTWIN_VISION_MAX_PIXELS"


@dataclass(frozen=True)
class Upload:
    """An uploaded image whose header has been checked, not yet decoded.

    ``size_px`` is the header's (width, height): its pixel count bounds the decode before
    anything is allocated. It is not always the decoded size — a JPEG's EXIF orientation
    5–8 swaps width and height (:func:`vision.imageio.decode_image`) — so anything that
    depends on the shape (a calibration's size, a camera's centre) takes the decoded one.
    """

    field: str
    filename: str
    data: bytes
    size_px: tuple[int, int]
    limit_name: str = SERVICE_PIXEL_LIMIT


Frame = tuple[Upload, dt.datetime]
"""A checked upload and its UTC time."""


def _image_error(field: str, name: str, exc: ImageError, limit_name: str) -> InputError:
    status = 413 if exc.too_large else (415 if "not a PNG or JPEG" in str(exc) else 422)
    extra = f" ({limit_name})" if exc.too_large else ""
    return InputError(status, f"{field} {name!r}: {exc}{extra}")


def check_image(data: bytes, filename: str, field: str, max_pixels: int,
                limit_name: str = SERVICE_PIXEL_LIMIT) -> Upload:
    """The file's PNG/JPEG header read and its pixel count checked (nothing decoded).

    ``limit_name`` says in a refusal where ``max_pixels`` comes from (the service's
    setting, or the CLI's own bound), so the message names what to change.
    """
    if not data:
        raise InputError(422, f"{field}: the file {filename!r} is empty")
    try:
        fmt, w, h = image_size(data)
        if w * h > max_pixels:
            raise ImageError(f"{fmt.upper()} image of {w}×{h} = {w * h} pixels exceeds the "
                             f"limit of {max_pixels} pixels", too_large=True)
    except ImageError as exc:
        raise _image_error(field, filename, exc, limit_name) from None
    return Upload(field, filename, data, (w, h), limit_name)


def decode(up: Upload, max_pixels: int) -> np.ndarray:
    """Decode in the calling (worker) thread; a corrupt file is a 4xx naming its field."""
    try:
        return decode_image(up.data, max_pixels)
    except ImageError as exc:
        raise _image_error(up.field, up.filename, exc, up.limit_name) from None


@dataclass(frozen=True)
class Place:
    site_id: str | None
    latitude_deg: float
    longitude_deg: float
    elevation_m: float
    zone: ZoneInfo


def name_zone(place: Place | None) -> ZoneInfo | None:
    """The zone a frame's file name without one is read in: a site's; None (UTC, said so)
    at a bare latitude and longitude, whose zone is not known."""
    return place.zone if place is not None and place.site_id is not None else None


#: A typed camera's parameters, which a stored calibration replaces (the form's names).
CAMERA_PARAMS = ("px_per_deg", "cx_px", "cy_px", "north_offset_deg", "east", "projection",
                 "fov_deg", "reference_x_px", "reference_y_px")


def check_no_camera_with_calibration(given: list[str], spell: Callable[[str], str] = str
                                     ) -> None:
    """422 when a calibration is used with typed camera parameters (``given``: the
    :data:`CAMERA_PARAMS` the caller set), naming the first as the caller spells it
    (``spell``: the form's name over HTTP, the flag on the CLI) — they were ignored silently."""
    if given:
        raise InputError(422, f"{spell(given[0])}: a {spell('calibration_id')} carries its own "
                              f"camera (centre, scale, north, mirror, projection); give "
                              f"{spell('calibration_id')} or {', '.join(map(spell, given))}, "
                              f"not both")


def calibration_place(cal: dict[str, Any], site_place: Callable[[str], Place | None]
                      ) -> tuple[Place, str]:
    """Where a stored calibration was fitted, for a detection given none: its site (its
    place and zone, ``site_place``: the service's registry or the CLI's site files) while
    the site is known, else its latitude, longitude and altitude; and the answer's
    ``place_source`` saying so."""
    place = site_place(cal["site_id"]) if cal.get("site_id") else None
    if place is None:
        place = free_place(float(cal["latitude_deg"]), float(cal["longitude_deg"]),
                           float(cal.get("elevation_m") or 0.0))
    where = (f"site {place.site_id}" if place.site_id is not None
             else f"{place.latitude_deg:.5f}, {place.longitude_deg:.5f}")
    return place, (f"calibration {cal['calibration_id']} (no place given: the place it was "
                   f"fitted at, {where})")


def free_place(latitude_deg: float, longitude_deg: float, elevation_m: float,
               fields: tuple[str, str, str] = ("latitude_deg", "longitude_deg", "elevation_m")
               ) -> Place:
    """A place given by latitude, longitude and altitude (times read in UTC), checked the one
    way HTTP and the CLI do: latitude in [-90, 90], longitude in [-180, 180], altitude in
    [-500, 9000] m, all finite (a NaN fails every bound), else a 422 naming the field as the
    caller spells it (``fields``: ``latitude_deg`` over HTTP, ``--lat`` on the CLI)."""
    lat_f, lon_f, el_f = fields
    if not -90.0 <= latitude_deg <= 90.0:
        raise InputError(422, f"{lat_f}: {latitude_deg} is outside [-90, 90]")
    if not -180.0 <= longitude_deg <= 180.0:
        raise InputError(422, f"{lon_f}: {longitude_deg} is outside [-180, 180]")
    if not -500.0 <= elevation_m <= 9000.0:
        raise InputError(422, f"{el_f}: {elevation_m} is outside [-500, 9000]")
    return Place(None, latitude_deg, longitude_deg, elevation_m, ZoneInfo("UTC"))


def check_calibration_size(calibration: dict[str, Any], size_px: tuple[int, int],
                           field: str = "calibration_id") -> None:
    """Refuse (422 naming ``field``) a frame whose decoded size is not the size the stored
    ``calibration`` was fitted on: its centre and scale are pixels of that size, so on a
    rescaled or cropped frame every angle is wrong (a 4000-px rescale of a 1920-px camera's
    frame gave the sun at −70°)."""
    w, h = calibration["image_size_px"]
    cal_size = (int(w), int(h))
    if tuple(size_px) != cal_size:
        raise InputError(422, f"{field}: the frame decodes to {size_px[0]}×{size_px[1]} px, "
                              f"but calibration {calibration['calibration_id']} was fitted on "
                              f"{cal_size[0]}×{cal_size[1]} px frames: send the camera's "
                              f"frames at their own size, or calibrate this size")


def ephemeris(times: list[dt.datetime], place: Place) -> pd.DataFrame:
    """SPA sun positions (``sim.sun.solar_position``): apparent elevation, azimuth."""
    return solar_position(pd.DatetimeIndex(times), place.latitude_deg, place.longitude_deg,
                          altitude=place.elevation_m)


def analyse(img: np.ndarray, cam: PinholeCamera | FisheyeCamera, method: str,
             ts: dt.datetime | None, place: Place | None, oriented: bool) -> dict[str, Any]:
    """Ephemeris (when time and place are known) and analysis, in one worker-thread hop.
    ``oriented``: the camera's north is known (:func:`is_oriented`); only then does the
    ephemeris guide the detection (:func:`vision.analyse.analyse_frame`)."""
    eph = None
    if ts is not None and place is not None:
        sp = ephemeris([ts], place)
        eph = (float(sp["azimuth"].iloc[0]), float(sp["apparent_elevation"].iloc[0]))
    return analyse_frame(img, cam, method, eph, oriented)


def is_oriented(calibrated: bool, north_offset_deg: object) -> bool:
    """Whether a request's fisheye has a known north: a stored calibration, or a north
    offset the caller gave (the default 0 is a guess, not a measurement)."""
    return calibrated or north_offset_deg is not None


def detection_row(res: dict[str, Any], ts: dt.datetime | None, place: Place | None,
                   cal_id: int | None) -> dict[str, Any]:
    c = res["centroid_px"] or [None, None]
    pe = res.get("pointing_error_deg") or [None, None]
    eph = res.get("ephemeris") or {}
    return {
        "ts_ms": None if ts is None else int(round(ts.timestamp() * 1000)),
        "site_id": place.site_id if place else None,
        "latitude_deg": place.latitude_deg if place else None,
        "longitude_deg": place.longitude_deg if place else None,
        "camera": res["camera"], "calibration_id": cal_id, "method": res["method"],
        "image_width_px": res["image_size_px"][0], "image_height_px": res["image_size_px"][1],
        "sun_found": bool(res["sun_found"]), "confidence": float(res["confidence"]),
        "centroid_x_px": c[0], "centroid_y_px": c[1],
        "azimuth_deg": res.get("azimuth_deg"), "elevation_deg": res.get("elevation_deg"),
        "pointing_error_horizontal_deg": pe[0], "pointing_error_vertical_deg": pe[1],
        "pointing_error_mrad": res.get("pointing_error_mrad"),
        "ephemeris_azimuth_deg": eph.get("azimuth_deg"),
        "ephemeris_elevation_deg": eph.get("elevation_deg"),
        "error_deg": (res.get("error") or {}).get("separation_deg"),
    }


def iso(ts: dt.datetime | None) -> str | None:
    return None if ts is None else ts.isoformat().replace("+00:00", "Z")


def calibrate(frames: list[Frame], place: Place, projection: str, east: str,
              n_radial: int | None, fit_tilt: bool, method: str, max_pixels: int
              ) -> dict[str, Any]:
    """Ephemeris for each frame, then ``vision.calibrate.self_calibrate``; a stored row.

    Needs nothing but the frames, their times and the place: the centre, scale,
    north offset and mirror are fitted, frames whose sun disagrees with the
    consensus are reported as outliers and left out, and ``n_radial=None`` lets
    the frames decide the radial terms (leave-one-out). Each frame is decoded once
    per detection pass (:data:`vision.calibrate.CALIBRATION_PASSES`), one at a time.

    Refused before decoding (422): times that put the sun in fewer than three distinct
    directions (``timestamps``; frames closer than :data:`vision.calibrate.DISTINCT_DEG`
    count once, so an image sent twice with its time adds nothing; sent with another
    time it is a frame whose clock is wrong, an outlier); after the fit, a camera that
    leaves more than :data:`vision.calibrate.MAX_RMS_DEG` RMS (``files``, with every
    frame's residual) — such a fit is no calibration, so nothing is stored; so are a fit
    more than a third of the frames disagree with, and a fitted optical centre far from
    the image circles' centre, the sign of times in a wrong zone (``timestamps``,
    :func:`backend.vision.checks.check_consensus`, :func:`~backend.vision.checks.check_centre`;
    each frame's image circle is found as it is first decoded). The stored
    size is the frames' decoded size (EXIF orientation applied), the size detection
    with this calibration must match.
    """
    sp = ephemeris([f[1] for f in frames], place)
    az, el = sp["azimuth"].to_numpy(), sp["apparent_elevation"].to_numpy()
    above = el > 0
    if n_directions(az[above], el[above]) < MIN_DIRECTIONS:
        raise InputError(422, f"timestamps: the {len(frames)} times put the sun above the "
                              f"horizon in only {n_directions(az[above], el[above])} distinct "
                              f"directions (more than {DISTINCT_DEG:g}° apart; frames of one "
                              f"direction count once): a calibration needs at least "
                              f"{MIN_DIRECTIONS}, from frames taken at different times")
    centres: dict[int, tuple[float, float] | None] = {}

    def load(i: int) -> np.ndarray:
        img = decode(frames[i][0], max_pixels)
        if i not in centres:  # the image circle of each frame, on its first decode
            centres[i] = image_circle_centre(img)
        return img

    try:
        cal = self_calibrate(load, az, el,
                             names=[f[0].filename for f in frames], method=method,
                             projection=projection, east=east, n_radial=n_radial,
                             fit_tilt=fit_tilt)
    except InputError:
        raise
    except ValueError as exc:  # too few suns found, sizes that differ, a failed fit
        raise InputError(422, f"files: {exc}") from None
    res = cal.fit
    report = []
    for i, (r, (up, ts)) in enumerate(zip(cal.frames, frames, strict=True)):
        r = {"filename": up.filename, "timestamp": iso(ts),
             **{k: v for k, v in r.items() if k != "name"}}
        r["ephemeris"] = {"azimuth_deg": float(az[i]), "elevation_deg": float(el[i])}
        report.append(r)
    # a fit is not yet a calibration: a tilt the frames determine, most frames agreeing,
    # and a camera's optical centre near its image circle's centre (backend.vision.checks)
    if fit_tilt:
        check_tilt(res.camera.tilt_north_deg, res.camera.tilt_east_deg)
    check_consensus(report, cal.loo_rms_deg,
                    lambda: _other_setting(cal, az, el, projection, east, n_radial, fit_tilt))
    warnings = check_sky_coverage(cal.sky_uncertainty_deg, report) + check_fitted_band(
        cal.fitted_elevation_deg, cal.sky_uncertainty_deg, report)
    check_centre((float(res.camera.cx_px), float(res.camera.cy_px)), res.camera.px_per_deg,
                 [c for c in centres.values() if c is not None], report,
                 cal.sky_uncertainty_deg)
    out = res.to_dict()
    cam = out["camera"]
    w, h = cal.image_size_px
    return {
        "site_id": place.site_id, "latitude_deg": place.latitude_deg,
        "longitude_deg": place.longitude_deg, "elevation_m": place.elevation_m,
        "projection": cam["projection"], "cx_px": cam["cx_px"], "cy_px": cam["cy_px"],
        "px_per_deg": cam["px_per_deg"], "north_offset_deg": cam["north_offset_deg"],
        "east": cam["east"], "radial_coeffs": cam["radial_coeffs"],
        "tilt_north_deg": cam["tilt_north_deg"], "tilt_east_deg": cam["tilt_east_deg"],
        "image_width_px": w, "image_height_px": h, "n_frames": res.n_frames,
        "rms_px": out["rms_px"], "max_px": out["max_px"], "rms_deg": out["rms_deg"],
        "max_deg": out["max_deg"], "n_outliers": cal.n_outliers,
        "loo_rms_deg": cal.loo_rms_deg, "model_selection": cal.model_selection,
        "sky_uncertainty_deg": cal.sky_uncertainty_deg,
        "fitted_elevation_deg": list(cal.fitted_elevation_deg), "warnings": warnings,
        "frames": report,
    }


def _other_setting(cal: SelfCalibration, az: np.ndarray, el: np.ndarray, projection: str,
                   east: str, n_radial: int | None, fit_tilt: bool) -> tuple[str, str] | None:
    """A setting the caller forced whose other choice fits the calibration's suns by the
    consensus rule (:func:`backend.vision.checks.check_consensus`), and how: ``east`` given
    left or right (the other mirror, fitted), ``projection`` given (each other one: a named
    projection may not be the lens's; ``auto`` compared them already), ``n_radial`` given
    (chosen from the frames),
    ``fit_tilt`` asked for (no tilt). The suns are the ones already found
    (no frame is decoded again); the one leaving the fewest out, then the closest fit;
    None when no such choice fits."""
    idx = [i for i, r in enumerate(cal.frames) if r.get("used") or r.get("outlier")]
    xy = np.array([cal.frames[i]["centroid_px"] for i in idx], float)
    given: dict[str, Any] = {"projection": projection, "east": east, "n_radial": n_radial,
                             "fit_tilt": fit_tilt}
    tries: list[tuple[str, dict[str, Any]]] = \
        ([("east", {"east": "auto"})] if east != "auto" else []) + \
        [("projection", {"projection": p}) for p in PROJECTIONS
         if projection not in (p, PROJECTION_FROM_FRAMES)] + \
        ([("n_radial", {"n_radial": None})] if n_radial is not None else []) + \
        ([("fit_tilt", {"fit_tilt": False})] if fit_tilt else [])
    fits: list[tuple[int, float, str, str]] = []
    for name, change in tries:
        try:
            pf = calibrate_positions(xy[:, 0], xy[:, 1], az[idx], el[idx], cal.image_size_px,
                                     **{**given, **change})
        except ValueError:
            continue
        loo = float(np.sqrt(np.mean(pf.loo_deg**2))) if pf.loo_deg.size else None
        try:
            check_consensus([{"used": bool(u), "outlier": not u} for u in pf.fit.inlier], loo)
        except InputError:
            continue
        cam, n_out, rms = pf.fit.result.camera, int(np.sum(~pf.fit.inlier)), pf.fit.result.rms_deg
        value = {"east": cam.east, "n_radial": len(cam.radial_coeffs),
                 "projection": cam.projection, "fit_tilt": "false"}[name]
        was = str(given[name]).lower()  # fit_tilt's True as the form spells it
        fits.append((n_out, rms, name, f"with {name}={value} instead of {was} the same "
                                       f"suns fit a camera to {rms:.2f}° RMS, {n_out} of "
                                       f"{len(idx)} left out"))
    return min(fits)[2:] if fits else None  # the fewest left out, then the closest fit


def evaluate(frames: list[Frame], place: Place,
             camera: Callable[[int, int], FisheyeCamera], methods: list[str],
             max_pixels: int) -> dict[str, Any]:
    """Each method on each frame (decoded one at a time) against SPA: seed 003's Tables 2, 3.

    ``camera(width, height)`` gives the camera for the first frame's decoded size (its
    default centre is that image's; a stored calibration checks the size); every other
    frame must decode to the same size (422 naming it).
    """
    sp = ephemeris([f[1] for f in frames], place)
    az, el = sp["azimuth"].to_numpy(), sp["apparent_elevation"].to_numpy()
    rows: list[dict[str, Any]] = []
    per: dict[str, dict[str, list[float]]] = {m: {"ra": [], "re": [], "a": [], "e": []}
                                              for m in methods}
    cam: FisheyeCamera | None = None
    size: tuple[int, int] | None = None
    for i, (up, ts) in enumerate(frames):
        img = decode(up, max_pixels)
        if cam is None or size is None:
            size = (int(img.shape[1]), int(img.shape[0]))
            cam = camera(*size)
        elif (img.shape[1], img.shape[0]) != size:
            raise InputError(422, f"files: every frame must have the same size; {up.field} "
                                  f"{up.filename!r} decodes to {img.shape[1]}×{img.shape[0]}"
                                  f" px, the first to {size[0]}×{size[1]} px")
        row: dict[str, Any] = {"filename": up.filename, "timestamp": iso(ts),
                               "ephemeris_azimuth_deg": float(az[i]),
                               "ephemeris_elevation_deg": float(el[i])}
        for m in methods:
            res = analyse_frame(img, cam, m, (float(az[i]), float(el[i])))
            row[f"{m}_sun_found"] = res["sun_found"]
            row[f"{m}_azimuth_deg"] = res["azimuth_deg"]
            row[f"{m}_elevation_deg"] = res["elevation_deg"]
            if res["azimuth_deg"] is not None and el[i] > 0:
                per[m]["ra"].append(float(az[i]))
                per[m]["re"].append(float(el[i]))
                per[m]["a"].append(res["azimuth_deg"])
                per[m]["e"].append(res["elevation_deg"])
        rows.append(row)
    table3: dict[str, Any] = {}
    for m, v in per.items():
        table3[m] = {"n_found": len(v["a"]), "n_frames": len(frames),
                     "metrics": error_table(v["ra"], v["re"], v["a"], v["e"]) if v["a"] else None}
    return {"n_frames": len(frames), "site_id": place.site_id,
            "latitude_deg": place.latitude_deg, "longitude_deg": place.longitude_deg,
            "camera": cam.to_dict() if cam is not None else None, "table2": rows,
            "table3": table3}


CAMERA_FIELDS = ("projection", "cx_px", "cy_px", "px_per_deg", "north_offset_deg", "east",
                 "radial_coeffs", "tilt_north_deg", "tilt_east_deg")


def calibration_record(body: dict[str, Any], name: str) -> dict[str, Any]:
    """A calibration's answer (``vision calibrate --json``, the body of ``POST
    /api/v1/vision/calibrations``) in the shape of a stored one
    (``backend.vision.store.calibration_to_dict``): what detection with a calibration
    reads — the camera (radial terms and tilt included), the size it was fitted on, the
    place, the worst residual. ``name`` stands for its id in what is said of it (a CLI
    user's file is stored nowhere). A KeyError/ValueError when a field is missing or bad."""
    camera = {k: body["camera"][k] for k in CAMERA_FIELDS}
    FisheyeCamera.from_dict(camera)  # a camera it can build, else a ValueError now
    return {"calibration_id": body.get("calibration_id") or name,
            "site_id": body.get("site_id"), "latitude_deg": float(body["latitude_deg"]),
            "longitude_deg": float(body["longitude_deg"]),
            "elevation_m": float(body.get("elevation_m") or 0.0),
            "image_size_px": [int(body["image_width_px"]), int(body["image_height_px"])],
            "max_deg": float(body["max_deg"]), "camera": camera}


def calibration_answer(row: dict[str, Any]) -> dict[str, Any]:
    """What a calibration answers (HTTP and CLI): the stored row with its ``camera``."""
    body = {k: v for k, v in row.items() if k != "radial_coeffs"}
    body["camera"] = {k: row[k] for k in CAMERA_FIELDS}
    return body
