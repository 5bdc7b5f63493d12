"""``heliotwin vision``: find the sun in an image file, or calibrate a fisheye camera.

    heliotwin vision detect sky.jpg --camera fisheye --px-per-deg 11.7 --cx-px 972 \\
        --cy-px 956 --timestamp 2016-06-15T08:39:00Z --lat 53.52 --lon 10.105 --json
    heliotwin vision detect frame.png --camera pinhole --fov-deg 67 --json
    heliotwin vision detect sky.jpg --calibration-id 3 --timestamp 2016-06-15T08:39:00Z \\
        --site guadalajara_fisheye
    heliotwin vision calibrate a.jpg b.jpg c.jpg --timestamps T1 T2 T3 --lat 53.52 \\
        --lon 10.105 --json > cam.json
    heliotwin vision detect sky.jpg --calibration-file cam.json --timestamp T
    heliotwin vision calibrate Wettermast_*UTCp1*.jpg --lat 53.52 --lon 10.105  # times from names

The same library (``vision``), ephemeris (``sim.sun``, SPA) and frame rule
(``backend.vision.frames.frame_inputs``: a fisheye without ``--px-per-deg`` takes the
scale of its image circle, a frame without ``--timestamp`` the time in its file name;
``vision calibrate`` without ``--timestamps`` the same, ``frame_time``) as
``POST /api/v1/vision/sun`` and ``/calibrations``; nothing is stored
(``--calibration-id`` reads a calibration the service stored, from the database
of ``HELIOTWIN_DATABASE_URL``; ``--calibration-file`` one ``vision calibrate --json``
wrote, applied the same way: its camera with radial terms and tilt, its size, its place).
Heavy imports happen inside the commands.
"""

from __future__ import annotations

import argparse
import json
import os
from datetime import datetime
from pathlib import Path
from typing import Any

from backend.cli import fail
from backend.vision.options import (
    N_RADIAL_CHOICES,
    N_RADIAL_DEFAULT,
    PROJECTION_CHOICES,
    PROJECTION_DEFAULT,
)


def _time(text: str) -> datetime:
    """An ISO 8601 time with offset (:mod:`backend.timestamps`)."""
    from backend.timestamps import TimestampError, parse_instant

    try:
        return parse_instant(text, "timestamp")
    except TimestampError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _place_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--site", help="a configured site id (its latitude/longitude/altitude)")
    p.add_argument("--lat", type=float, help="latitude [deg], north positive")
    p.add_argument("--lon", type=float, help="longitude [deg], east positive")
    p.add_argument("--elevation-m", type=float, default=0.0, help="altitude [m] (default 0)")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``vision detect`` and ``vision calibrate``."""
    p = subparsers.add_parser("vision", help="sun detection and fisheye calibration on files",
                              description="Sun detection and fisheye calibration on image files.")
    sub = p.add_subparsers(dest="vision_command", metavar="ACTION", required=True)

    d = sub.add_parser("detect", help="find the sun in one image",
                       description="Find the sun in one PNG/JPEG image.")
    d.add_argument("image", type=Path)
    d.add_argument("--camera", choices=("pinhole", "fisheye"),
                   help="camera model (required unless --calibration-id)")
    d.add_argument("--calibration-id", type=int, metavar="ID",
                   help="a fisheye calibration stored by the service (POST "
                        "/api/v1/vision/calibrations; database of HELIOTWIN_DATABASE_URL)")
    d.add_argument("--calibration-file", type=Path, metavar="FILE",
                   help="a calibration written by 'vision calibrate --json > FILE' (its "
                        "radial terms and tilt included), applied as the service applies a "
                        "stored one")
    d.add_argument("--method", default="robust",
                   choices=("robust", "seed000_hsv", "seed003_gray240"))
    d.add_argument("--fov-deg", type=float, help="pinhole horizontal field of view (67)")
    d.add_argument("--cx-px", type=float, help="optical centre column (image centre)")
    d.add_argument("--cy-px", type=float, help="optical centre row (image centre)")
    d.add_argument("--reference-x-px", type=float, help="pinhole reference pixel column")
    d.add_argument("--reference-y-px", type=float, help="pinhole reference pixel row")
    d.add_argument("--projection",  # None: equidistant (None tells a calibration's clash)
                   choices=("equidistant", "equisolid", "stereographic", "orthographic"),
                   help="fisheye projection (default equidistant)")
    d.add_argument("--px-per-deg", type=float,
                   help="fisheye radial scale [px/deg] (default: from the image circle, "
                        "taken as the horizon of a 180-degree lens, as the service does)")
    d.add_argument("--north-offset-deg", type=float,
                   help="where north lies, clockwise from image-up (default 0, a guess: "
                        "the ephemeris then does not guide the detection)")
    d.add_argument("--east", choices=("left", "right"),
                   help="east left of north (raw view from below, default) or right")
    d.add_argument("--timestamp", type=_time,
                   help="frame time, ISO 8601 with offset (default: the time in the file "
                        "name, e.g. _20160615_093900UTCp1, read in the place's zone when the "
                        "name states none; backend/vision/frames.py)")
    _place_args(d)
    d.add_argument("--json", action="store_true", help="print JSON")
    d.set_defaults(func=run_detect)

    c = sub.add_parser("calibrate", help="fit a fisheye camera to timestamped images",
                       description="Fit centre, scale, north offset and mirror of a fisheye "
                                   "camera to the sun in timestamped images (SPA ephemeris).")
    c.add_argument("images", type=Path, nargs="+")
    c.add_argument("--timestamps", type=_time, nargs="+",
                   help="one ISO 8601 time with offset per image, same order (default: the "
                        "time in each file name, e.g. _20160615_093900UTCp1, read in the "
                        "place's zone when the name states none, as vision detect reads it; "
                        "backend/vision/frames.py)")
    c.add_argument("--projection", default=PROJECTION_DEFAULT, choices=PROJECTION_CHOICES,
                   help="the lens's projection; auto (default, as the service): the one the "
                        "frames support by leave-one-out, equidistant unless another is "
                        "clearly better")
    c.add_argument("--east", choices=("auto", "left", "right"), default="auto")
    c.add_argument("--n-radial", choices=N_RADIAL_CHOICES, default=N_RADIAL_DEFAULT,
                   help="radial polynomial terms to fit; auto (default, as the service): as "
                        "many as lower the leave-one-out error")
    c.add_argument("--fit-tilt", action="store_true", help="also fit two tilt angles")
    c.add_argument("--method", default="robust",
                   choices=("robust", "seed000_hsv", "seed003_gray240"))
    _place_args(c)
    c.add_argument("--json", action="store_true", help="print JSON")
    c.set_defaults(func=run_calibrate)


#: The CLI reads local files: a bigger frame than the service accepts is fine (not the
#: service's HELIOTWIN_VISION_MAX_PIXELS; a refusal names this bound, not that setting).
_MAX_PIXELS = 400_000_000
_LIMIT_NAME = "the command line's fixed bound on a decoded frame"


def _place(args: argparse.Namespace) -> Any:
    """The ``Place`` of ``--site`` or ``--lat/--lon`` (None when neither is given), checked
    as the service checks ``latitude_deg``/``longitude_deg``/``elevation_m``
    (``backend.vision.service.free_place``: an impossible or NaN place is refused)."""
    from backend.vision.service import free_place

    if args.site:
        from sim.sites import load_site

        return _place_of(load_site(args.site, os.environ.get("HELIOTWIN_SITES_DIR")))
    if args.lat is None and args.lon is None:
        return None
    if args.lat is None or args.lon is None:
        raise ValueError("--lat and --lon go together")
    return free_place(args.lat, args.lon, args.elevation_m, ("--lat", "--lon", "--elevation-m"))


def _site_place(site_id: str) -> Any:
    """The place of a site of the site files (HELIOTWIN_SITES_DIR and the built-in ones),
    or None when there is none of that id."""
    from sim.sites import UnknownSiteError, load_site

    try:
        return _place_of(load_site(site_id, os.environ.get("HELIOTWIN_SITES_DIR")))
    except UnknownSiteError:
        return None


def _place_of(site: Any) -> Any:
    """The vision service's ``Place`` of a ``sim.sites.Site``."""
    from zoneinfo import ZoneInfo

    from backend.vision.service import Place

    return Place(site.site_id, site.latitude, site.longitude, site.altitude,
                 ZoneInfo(site.timezone))


def _upload(path: Path, field: str) -> Any:
    from backend.vision.service import check_image

    return check_image(path.read_bytes(), str(path), field, _MAX_PIXELS, _LIMIT_NAME)


def detect(args: argparse.Namespace) -> dict[str, Any]:
    """The answer of ``vision detect``: the service's analysis (``backend.vision.service``,
    the same as ``POST /api/v1/vision/sun`` without the stored ids): the same checks of
    the place and of a stored calibration's size, and the same ``warnings``."""
    from backend.errors import InputError
    from backend.vision.checks import error_warnings
    from backend.vision.frames import frame_inputs
    from backend.vision.service import (
        CAMERA_PARAMS,
        analyse,
        calibration_place,
        check_calibration_size,
        check_no_camera_with_calibration,
        decode,
        is_oriented,
        name_zone,
    )
    from vision.cameras import FisheyeCamera, PinholeCamera, camera_from_params

    place = _place(args)  # refused before the frame is read, as the service does
    img = decode(_upload(args.image, "image"), _MAX_PIXELS)
    h, w = img.shape[:2]
    params = {k: getattr(args, k) for k in ("fov_deg", "cx_px", "cy_px", "reference_x_px",
                                           "reference_y_px", "projection", "px_per_deg",
                                           "north_offset_deg", "east")}
    if args.calibration_id is not None and args.calibration_file is not None:
        raise ValueError("--calibration-file: give --calibration-id or --calibration-file, "
                         "not both")
    flag = "--calibration-id" if args.calibration_id is not None else "--calibration-file"
    calibrated = args.calibration_id is not None or args.calibration_file is not None
    if calibrated and args.camera not in (None, "fisheye"):
        raise ValueError(f"--camera: a {flag} is a fisheye camera")
    if calibrated:  # as the service: a typed camera is not ignored
        check_no_camera_with_calibration(
            [k for k in CAMERA_PARAMS if params.get(k) is not None],
            lambda name: flag if name == "calibration_id" else "--" + name.replace("_", "-"))
    if not calibrated and args.camera is None:
        raise ValueError("--camera: required (pinhole or fisheye), or give --calibration-id "
                         "or --calibration-file")
    cal = None
    place_source = None if place is None else "given"
    if calibrated:  # as the service: only on frames of its size
        cal = (_stored_calibration(args.calibration_id) if args.calibration_id is not None
               else _file_calibration(args.calibration_file))
        check_calibration_size(cal, (w, h), flag)
        if place is None:  # as the service: where the calibration was fitted
            place, place_source = calibration_place(cal, _site_place)
    try:  # the service's rule (POST /api/v1/vision/sun): scale and time the frame implies
        frame = frame_inputs(img, args.image.name, None if calibrated else args.camera,
                             params, args.timestamp, name_zone(place))
    except InputError as exc:
        raise ValueError(str(exc).replace("px_per_deg:", "--px-per-deg:", 1)
                         .replace("timestamp:", "--timestamp:", 1)) from None
    cam: PinholeCamera | FisheyeCamera
    if cal is not None:
        cam = FisheyeCamera.from_dict(cal["camera"])
    else:
        cam = camera_from_params(args.camera, frame.params, w, h)
    oriented = is_oriented(cal is not None, args.north_offset_deg)
    out = {"image": str(args.image), **analyse(img, cam, args.method, frame.timestamp, place,
                                               oriented)}
    if frame.camera_derived is not None:
        out["camera_derived"] = frame.camera_derived
    out["timestamp"] = None if frame.timestamp is None else frame.timestamp.isoformat()
    out["timestamp_source"] = frame.timestamp_source
    out["place_source"] = place_source
    out["warnings"] = error_warnings(out, None if cal is None else cal["max_deg"])
    if isinstance(cam, PinholeCamera) and args.fov_deg is None and out.get("centroid_px"):
        from vision.analyse import disc_scale_warning
        scale = disc_scale_warning(img, tuple(out["centroid_px"]), cam)
        out["warnings"] = ([] if scale is None else [scale.replace("fov_deg", "--fov-deg")])\
            + out["warnings"]
    if args.calibration_id is not None:
        out["calibration_id"] = args.calibration_id
    if args.calibration_file is not None:
        out["calibration_file"] = str(args.calibration_file)
    return out


def _file_calibration(path: Path) -> dict[str, Any]:
    """A calibration written by ``vision calibrate --json`` (or the body of ``POST
    /api/v1/vision/calibrations``), in the shape of a stored one
    (:func:`backend.vision.service.calibration_record`)."""
    from backend.vision.service import calibration_record

    try:
        body = json.loads(path.read_text())
        return calibration_record(body, f"file {path}")
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError,
            ValueError) as exc:
        raise ValueError(f"--calibration-file: {path} is not a calibration written by "
                         f"'heliotwin vision calibrate --json' ({type(exc).__name__}: "
                         f"{exc})") from None


def _stored_calibration(calibration_id: int) -> dict[str, Any]:
    """A calibration stored by the service (``backend.vision.store``): camera, size,
    residuals."""
    from backend.settings import get_settings
    from backend.storage.engine import make_engine
    from backend.vision.store import get_calibration

    engine = make_engine(get_settings())
    try:
        with engine.connect() as conn:
            cal = get_calibration(conn, calibration_id)
    finally:
        engine.dispose()
    if cal is None:
        raise ValueError(f"--calibration-id: no calibration {calibration_id} in the database")
    return cal


def calibrate(args: argparse.Namespace) -> dict[str, Any]:
    """The answer of ``vision calibrate``: the service's calibration against SPA
    (``backend.vision.service.calibrate``, as ``POST /api/v1/vision/calibrations``)."""
    from backend.vision.options import parse_n_radial
    from backend.vision.service import calibrate as fit
    from backend.vision.service import calibration_answer

    if args.timestamps is not None and len(args.timestamps) != len(args.images):
        raise ValueError(f"--timestamps: {len(args.timestamps)} times for "
                         f"{len(args.images)} images")
    place = _place(args)
    if place is None:
        raise ValueError("a place is needed: --site, or --lat and --lon")
    times = args.timestamps or _times_from_names(args.images, place)
    frames = [(_upload(p, f"images[{i}]"), t)
              for i, (p, t) in enumerate(zip(args.images, times, strict=True))]
    return calibration_answer(fit(frames, place, args.projection, args.east,
                                  parse_n_radial(args.n_radial, "--n-radial"), args.fit_tilt,
                                  args.method, _MAX_PIXELS))


def _times_from_names(images: list[Path], place: Any) -> list[Any]:
    """Each image's time from its file name, by the rule ``vision detect`` applies to a
    frame without ``--timestamp`` (``backend.vision.frames.frame_time``: the name's zone,
    else the place's); an image whose name holds no time asks for ``--timestamps``."""
    from backend.errors import InputError
    from backend.vision.frames import frame_time
    from backend.vision.service import name_zone

    times = []
    for path in images:
        try:
            t, _ = frame_time(path.name, None, name_zone(place))
        except InputError as exc:
            raise ValueError(f"--timestamps: {path.name}: "
                             f"{str(exc).removeprefix('timestamp: ')}") from None
        if t is None:
            raise ValueError(f"--timestamps: no time in the file name {path.name!r}: give "
                             "one time per image (ISO 8601 with offset)")
        times.append(t)
    return times


def _run(fn: Any, args: argparse.Namespace) -> int:
    from vision.imageio import ImageError

    try:
        out = fn(args)
    except (ValueError, ImageError, OSError) as exc:
        fail(str(exc))
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        print(_summary(out))
    return 0


def _summary(out: dict[str, Any]) -> str:
    if "camera" in out and isinstance(out["camera"], dict):
        c = out["camera"]
        return (f"{c['projection']} centre ({c['cx_px']:.1f}, {c['cy_px']:.1f}) px, "
                f"{c['px_per_deg']:.3f} px/deg, north {c['north_offset_deg']:.2f} deg, "
                f"east {c['east']}; residual rms {out['rms_px']:.2f} px / "
                f"{out['rms_deg']:.3f} deg over {out['n_frames']} frames"
                + (f"; suns fitted {out['fitted_elevation_deg'][0]:.1f}-"
                   f"{out['fitted_elevation_deg'][1]:.1f} deg up, direction uncertain by up "
                   f"to {out['sky_uncertainty_deg']:.2f} deg (1 sigma) from the lowest up"
                   if out.get("sky_uncertainty_deg") is not None else "")
                + "".join(f"\nwarning: {w}" for w in out.get("warnings") or []))
    if not out["sun_found"]:
        return f"no sun (confidence {out['confidence']:.2f})"
    x, y = out["centroid_px"]
    text = f"sun at ({x:.2f}, {y:.2f}) px, confidence {out['confidence']:.2f}"
    if out.get("azimuth_deg") is not None:
        text += f"; azimuth {out['azimuth_deg']:.2f} deg, elevation {out['elevation_deg']:.2f} deg"
    if out.get("pointing_error_mrad") is not None:
        h, v = out["pointing_error_deg"]
        text += f"; pointing error ({h:.3f}, {v:.3f}) deg = {out['pointing_error_mrad']:.2f} mrad"
    if "ephemeris" in out:
        e = out["ephemeris"]
        text += f"; SPA {e['azimuth_deg']:.2f}/{e['elevation_deg']:.2f} deg"
    if "error" in out:
        err = out["error"]
        text += (f"; error against SPA {err['separation_deg']:.3f} deg (azimuth "
                 f"{err['azimuth_deg']:+.3f}, elevation {err['elevation_deg']:+.3f} deg)")
    for warning in out.get("warnings") or []:
        text += f"\nwarning: {warning}"
    return text


def run_detect(args: argparse.Namespace) -> int:
    """``heliotwin vision detect``."""
    return _run(detect, args)


def run_calibrate(args: argparse.Namespace) -> int:
    """``heliotwin vision calibrate``."""
    return _run(calibrate, args)
