"""``/api/v1/vision``: find the sun in uploaded frames, calibrate fisheye cameras, evaluate.

- ``POST /sun`` — one frame (multipart ``file``) and a camera (``camera`` with
  its parameters, or ``calibration_id``), optional ``timestamp`` and place
  (``site_id`` or ``latitude_deg``/``longitude_deg``/``elevation_m``) → the
  detection (``vision.analyse.analyse_frame``), the ephemeris (SPA, apparent
  elevation; for a fisheye also its pixel ``ephemeris.centroid_px`` through
  the same camera model) and the error (``error.separation_deg`` on the
  sphere, ``error.distance_px``). Stored. A ``calibration_id`` is only valid on a frame
  that decodes to the calibration's size (422 naming it otherwise).
- ``POST /calibrations`` — ``files`` with one ``timestamps`` each and a place
  (nothing else: no centre, scale, rotation or mirror) → a fitted fisheye camera
  (``vision.calibrate.self_calibrate``: outlying frames named and left out), stored
  with its per-frame residuals and the frames' decoded size; fewer than three distinct
  sun directions (422 ``timestamps``) or a fit beyond ``vision.calibrate.MAX_RMS_DEG``
  (422 ``files``), one most frames disagree with or whose optical centre lies far from the image
  circle's centre (times in a wrong zone; 422 ``timestamps``,
  ``backend/vision/checks.py``) is refused; a calibration made without a token is kept within
  ``anonymous_keep_rows``, as detections are.
- ``GET /calibrations``, ``GET /calibrations/{id}``.
- ``POST /evaluate`` — a batch against SPA for each detection method: seed
  003's Table 2 (per frame) and Table 3 (MAD/MSE/RMSE/MAPE).
- ``GET /detections?site_id=&start=&end=`` — stored detections for the day's
  trajectory on the dashboard.

Uploads are bounded: the body is read in chunks and refused with 413 past
``vision.max_image_bytes`` — a batch's (``/calibrations``, ``/evaluate``) past
``vision.max_batch_bytes`` (Content-Length is not trusted alone); each image's size
is read from its PNG/JPEG header and refused (413) above
``vision_max_pixels`` before anything is decoded; a non-image or a corrupt
one is a 415/422 naming the field. The image and database work runs in worker
threads; a batch is decoded one frame at a time, so it holds one decoded frame.
"""

from __future__ import annotations

import asyncio
import datetime as dt
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Annotated, Any
from zoneinfo import ZoneInfo

import anyio
import numpy as np
import orjson
from fastapi import APIRouter, HTTPException, Path, Query, Request
from fastapi.responses import Response
from starlette.datastructures import FormData, UploadFile

from backend.api.deps import (
    ContextDep,
    SessionDep,
    VisionTokenDep,
    bearer_token,
    check_site_admin,
    is_admin_token,
    token_site,
)
from backend.api.forms import form_flag, read_form
from backend.api.schemas.vision import (
    CalibrationDeletedRead,
    CalibrationsRead,
    DetectionsDeletedRead,
    DetectionsRead,
    EvaluationRead,
    FittedCalibrationRead,
    FrameNameTimeRead,
    FrameTimesRead,
    StoredCalibrationRead,
    SunDetectionRead,
)
from backend.limits import Busy, prune_anonymous
from backend.storage.tables import VisionCalibration, VisionDetection
from backend.text import one_line_problem
from backend.timestamps import TimestampError, parse_day_or_instant, parse_instant
from backend.vision.checks import error_warnings
from backend.vision.frames import FrameInputs, NameZoneError, frame_inputs, time_from_name
from backend.vision.options import (
    N_RADIAL_CHOICES,
    N_RADIAL_DEFAULT,
    PROJECTION_CHOICES,
    PROJECTION_DEFAULT,
    parse_n_radial,
    parse_projection,
)
from backend.vision.service import (
    CAMERA_PARAMS,
    Frame,
    Place,
    Upload,
    analyse,
    calibrate,
    calibration_answer,
    calibration_place,
    check_calibration_size,
    check_image,
    check_no_camera_with_calibration,
    decode,
    detection_row,
    evaluate,
    free_place,
    is_oriented,
    iso,
    name_zone,
)
from backend.vision.store import (
    delete_calibration,
    delete_detections,
    get_calibration,
    insert_calibration,
    insert_detection,
    list_calibrations,
    list_detections,
)
from vision.analyse import disc_scale_warning
from vision.calibrate import CALIBRATION_PASSES
from vision.cameras import (
    EAST_SIDES,
    PROJECTIONS,
    FisheyeCamera,
    PinholeCamera,
    camera_from_params,
)
from vision.detect import METHODS

router = APIRouter(prefix="/api/v1/vision", tags=["vision"])

_JSON = "application/json"
_MAX_FILES = 64
_MAX_ID = 2**31 - 1  # ids are 32-bit integers on PostgreSQL


def _json(data: Any, status: int = 200) -> Response:
    return Response(orjson.dumps(data, option=orjson.OPT_SERIALIZE_NUMPY), status_code=status,
                    media_type=_JSON)


# --------------------------------------------------------------------------- input


async def _read_form(request: Request, limit: int, limit_name: str,
                     field: str = "file") -> FormData:
    """The form; a text field sent as a file part is a 422 naming it (it was dropped).
    ``limit``: the body's bound in bytes, from the setting ``limit_name``; ``field``: the
    images' field, which a 415 and a 422 for too many files name."""
    expected = "an image in the field 'file'" if field == "file" else \
        f"images in the field {field!r}"
    form = await read_form(request, limit, expected, _MAX_FILES, limit_name=limit_name,
                           files_field=field)
    _fields(form)
    return form


async def _batch_form(request: Request, ctx: Any) -> FormData:
    """The form of a batch (a calibration, an evaluation: up to :data:`_MAX_FILES` frames),
    bounded by ``HELIOTWIN_VISION_MAX_BATCH_BYTES`` rather than the single frame's
    ``HELIOTWIN_VISION_MAX_IMAGE_BYTES``: 12 ordinary frames (1920² px, JPEG quality 92,
    ≈ 1.17 MB each) passed 10 MB (a tester's finding). The frames are decoded one at a
    time (:func:`_timed_frames`), so the bound is on the bytes held, not on pixels."""
    return await _read_form(request, ctx.settings.vision.max_batch_bytes,
                            "HELIOTWIN_VISION_MAX_BATCH_BYTES", field="files")


def _cut(text: str, keep: int = 40) -> str:
    """``text`` quoted for an error message, its first ``keep`` characters only (as
    timestamps are): a refusal does not echo a 2 MB field back."""
    return repr(text[:keep]) + (f" … ({len(text)} characters)" if len(text) > keep else "")


def _not_a_file(name: str, v: object) -> None:
    """A text field sent as a file part (``-F site_id=@file``) is a 422 naming it, not
    silently dropped."""
    if isinstance(v, UploadFile):
        raise HTTPException(422, f"{name}: sent as a file ({_cut(v.filename or '')}); send "
                                 f"it as a text field")


def _scale_warnings(found: tuple[Any, Any], cam: object, fov_text: str | None) -> list[str]:
    """A pinhole camera sent without ``fov_deg`` whose sun's disc belies the default 67°
    (:func:`vision.analyse.disc_scale_warning`), as a one-item list; else none."""
    image, centroid = found
    if not isinstance(cam, PinholeCamera) or fov_text or centroid is None:
        return []
    warning = disc_scale_warning(image, (float(centroid[0]), float(centroid[1])), cam)
    return [] if warning is None else [warning]


def _text(form: FormData, name: str) -> str | None:
    v = form.get(name)
    _not_a_file(name, v)
    if v is None or isinstance(v, UploadFile):
        return None
    v = v.strip()
    return v or None


def _texts(form: FormData, name: str) -> list[str]:
    values = form.getlist(name)
    for v in values:
        _not_a_file(name, v)
    return [v.strip() for v in values if isinstance(v, str) and v.strip()]


def _fields(form: FormData, files: tuple[str, ...] = ("file", "files")) -> dict[str, object]:
    for k, v in form.multi_items():
        if k not in files:
            _not_a_file(k, v)
    return {k: v for k, v in form.multi_items() if isinstance(v, str)}


async def _upload(upload: Any, field: str, max_pixels: int) -> Upload:
    """The file's bytes with its header checked (:func:`backend.vision.service.check_image`)."""
    if not isinstance(upload, UploadFile):
        raise HTTPException(422, f"{field}: an image file is required")
    return check_image(await upload.read(), upload.filename or field, field, max_pixels)


@asynccontextmanager
async def _admitted(ctx: Any, request: Request, token_site: str | None,
                    frames: list[Upload], passes: int = 1) -> AsyncIterator[None]:
    """The bounds of ``backend/limits.py`` around decoding ``frames`` (one at a time,
    each ``passes`` times): without a token the client's per-minute pixel allowance
    (429 with Retry-After), a batch costing more than the whole allowance refused
    outright (413 naming ``files``: no wait would admit it), then one frame's share of
    the decode budget, waited for in a bounded queue (503). Only admitted work is
    charged: a request refused by the queue (503) or gone while it waited gets its
    pixels back."""
    taken: tuple[str, float] | None = None
    entered = False
    try:
        if token_site is None:
            cost = passes * sum(w * h for w, h in (f.size_px for f in frames))
            allowance = ctx.limits.vision_pixels.capacity
            if len(frames) > 1 and cost > allowance:
                raise HTTPException(413, f"files: {len(frames)} frames decoded {passes}× are "
                                         f"{cost} pixels, more than a request without a token "
                                         f"may cost ({allowance:.0f} pixels, "
                                         f"HELIOTWIN_ANONYMOUS_VISION_PIXELS_PER_MIN); send "
                                         f"fewer or smaller frames, or a write token")
            client = request.client.host if request.client else "?"
            ctx.limits.vision_pixels.take(client, cost)
            taken = (client, cost)
        async with ctx.limits.decode.hold(max(w * h for w, h in (f.size_px for f in frames))):
            entered = True
            yield
    except BaseException as exc:
        if taken is not None and not entered:  # never admitted: nothing was decoded
            ctx.limits.vision_pixels.refund(*taken)
        if isinstance(exc, Busy):
            raise HTTPException(exc.status_code, exc.message, headers=exc.headers) from None
        raise


async def _store(ctx: Any, insert: Any, table: Any, row: dict[str, Any], anonymous: bool
                 ) -> int:
    """Insert a detection or a calibration; an anonymous one keeps only the newest
    ``anonymous_keep_rows`` anonymous rows of its table (``prune_anonymous``)."""
    keep = ctx.settings.vision.anonymous_keep_rows

    def store(conn: Any) -> int:
        new_id = int(insert(conn, {**row, "anonymous": anonymous}))
        if anonymous:
            prune_anonymous(conn, table, keep)
        return new_id

    return int(await asyncio.wrap_future(ctx.writer.call(store)))


async def _store_detection(ctx: Any, row: dict[str, Any], anonymous: bool) -> int:
    return await _store(ctx, insert_detection, VisionDetection, row, anonymous)


async def _store_calibration(ctx: Any, row: dict[str, Any], anonymous: bool) -> int:
    return await _store(ctx, insert_calibration, VisionCalibration, row, anonymous)


def _timestamp(text: str | None, field: str = "timestamp") -> dt.datetime | None:
    if text is None:
        return None
    try:
        return parse_instant(text, field)
    except TimestampError as exc:
        raise HTTPException(422, str(exc)) from None


def _place(ctx: Any, form: FormData, required: bool = False) -> Place | None:
    site_id = _text(form, "site_id")
    lat, lon = _text(form, "latitude_deg"), _text(form, "longitude_deg")
    if site_id is not None:
        if lat is not None or lon is not None:
            raise HTTPException(422, "give site_id or latitude_deg/longitude_deg, not both")
        place = _site_place(ctx, site_id)
        if place is None:
            known = ", ".join(ctx.registry.sites) or "none"
            raise HTTPException(404, f"site_id: unknown site {_cut(site_id)}; known: {known}")
        return place
    if lat is None and lon is None:
        if required:
            raise HTTPException(422, "a place is required: site_id, or latitude_deg and "
                                     "longitude_deg")
        return None
    if lat is None or lon is None:
        raise HTTPException(422, "latitude_deg and longitude_deg go together")
    la, lo = _float(lat, "latitude_deg"), _float(lon, "longitude_deg")
    el = _float(_text(form, "elevation_m") or "0", "elevation_m")
    return free_place(la, lo, el)


def _writes_site(token_site: str | None, place: Place | None, what: str) -> None:
    """A token writes its own site's history only: a ``site_id`` of another site is a 403
    naming ``site_id`` (a free place, or no token, writes no site's history of another)."""
    if token_site is not None and place is not None and place.site_id is not None \
            and place.site_id != token_site:
        raise HTTPException(403, f"site_id: this token writes to site {token_site!r}, not "
                                 f"{place.site_id!r}: {what} of site {place.site_id!r} need "
                                 f"a token of that site")


def _float(text: str, field: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise HTTPException(422, f"{field}: {text!r} is not a number") from None


def _method(form: FormData) -> str:
    method = _text(form, "method") or "robust"
    if method not in METHODS:
        raise HTTPException(422, f"method: must be one of {', '.join(METHODS)}, got {method!r}")
    return method


#: the typed camera's parameters, which a calibration_id replaces (both given: a 422)
def _pairs(form: FormData) -> None:
    """Fields that only mean something together: one without the other is a 422."""
    if (_text(form, "reference_x_px") is None) != (_text(form, "reference_y_px") is None):
        raise HTTPException(422, "reference_x_px and reference_y_px go together")


def _site_place(ctx: Any, site_id: str) -> Place | None:
    """A known site's place (with the site's zone), or None."""
    info = ctx.registry.get(site_id)
    if info is None:
        return None
    s = info.site
    return Place(site_id, s.latitude, s.longitude, s.altitude, info.zone)


def _stored_camera(session: Any, form: FormData
                   ) -> tuple[FisheyeCamera | None, dict[str, Any] | None]:
    """The camera of ``calibration_id`` and the stored calibration (its size, its residuals),
    or (None, None) when none is given; 422/404 naming ``calibration_id``."""
    raw = _text(form, "calibration_id")
    if raw is None:
        return None, None
    check_no_camera_with_calibration([k for k in CAMERA_PARAMS if _text(form, k) is not None])
    if not raw.isdigit() or int(raw) == 0:
        raise HTTPException(422, f"calibration_id: {_cut(raw)} must be a positive integer id")
    if int(raw) > _MAX_ID:
        raise HTTPException(404, f"calibration_id: no calibration {raw}")
    cal = get_calibration(session, int(raw))
    if cal is None:
        raise HTTPException(404, f"calibration_id: no calibration {raw}")
    return FisheyeCamera.from_dict(cal["camera"]), cal


def _camera(form: FormData, stored: FisheyeCamera | None, cal: dict[str, Any] | None,
            w: int, h: int,
            frame: tuple[np.ndarray, str, dt.datetime | None, Place | None] | None = None
            ) -> tuple[PinholeCamera | FisheyeCamera, FrameInputs | None]:
    """The camera of a request for a frame of ``w``×``h`` px as decoded; with ``frame``
    (image, file name, time given, place) also what
    :func:`backend.vision.frames.frame_inputs` completes, the CLI's rule: a fisheye
    without ``px_per_deg`` gets the scale of its image circle, a frame without a time the
    time of its file name. A stored calibration (``cal``) is only valid on frames of the
    size it was fitted on (422 naming ``calibration_id``)."""
    if cal is not None:
        check_calibration_size(cal, (w, h))
    kind = _text(form, "camera") or ("fisheye" if stored is not None else None)
    if stored is not None and kind != "fisheye":
        raise HTTPException(422, "camera: a calibration_id is a fisheye camera")
    if kind is None:
        raise HTTPException(422, "camera: required ('pinhole' or 'fisheye'), or give "
                                 "calibration_id")
    params, completed = _fields(form), None
    if frame is not None:
        image, filename, ts, place = frame
        completed = frame_inputs(image, filename, None if stored is not None else kind,
                                 params, ts, name_zone(place))
        params = completed.params
    if stored is not None:
        return stored, completed
    try:
        return camera_from_params(kind, params, w, h), completed
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None


# --------------------------------------------------------------------------- work


# --------------------------------------------------------------------------- routes

#: a write token is optional (required with HELIOTWIN_VISION_REQUIRE_TOKEN); without one
#: the caller's address has a pixel allowance, and every upload waits for the decode budget
_OPTIONAL_BEARER: list[dict[str, list[str]]] = [{}, {"bearerAuth": []}]
_BUSY_DOC: dict[int | str, dict[str, Any]] = {
    429: {"description": "rate limit of anonymous uploads (per client address); see "
                         "Retry-After"},
    503: {"description": "the decode budget's queue is full; see Retry-After"},
}

_SUN_PROPERTIES: dict[str, Any] = {
    "file": {"type": "string", "format": "binary", "description": "PNG or JPEG frame"},
    "camera": {"type": "string", "enum": ["pinhole", "fisheye"]},
    "fov_deg": {"type": "number", "description": "pinhole horizontal FOV [°] (67)"},
    "cx_px": {"type": "number"}, "cy_px": {"type": "number"},
    "reference_x_px": {"type": "number"}, "reference_y_px": {"type": "number"},
    "projection": {"type": "string",
                   "enum": ["equidistant", "equisolid", "stereographic",
                            "orthographic"]},
    "px_per_deg": {"type": "number"}, "north_offset_deg": {"type": "number"},
    "east": {"type": "string", "enum": ["left", "right"]},
    "calibration_id": {"type": "integer"},
    "method": {"type": "string", "enum": list(METHODS)},
    "timestamp": {"type": "string", "description": "ISO 8601 with offset"},
    "site_id": {"type": "string"}, "latitude_deg": {"type": "number"},
    "longitude_deg": {"type": "number"}, "elevation_m": {"type": "number"},
}
_SUN_DOC = {
    "security": _OPTIONAL_BEARER,
    "requestBody": {"content": {"multipart/form-data": {"schema": {
        "type": "object", "required": ["file"], "properties": _SUN_PROPERTIES}}},
        "required": True},
}


@router.post("/sun", response_model=SunDetectionRead, openapi_extra=_SUN_DOC,
             responses={400: {"description": "a malformed multipart body"},
                        401: {}, 404: {}, 413: {}, 415: {}, 422: {}, **_BUSY_DOC})
async def post_sun(request: Request, ctx: ContextDep, session: SessionDep,
                   _token: VisionTokenDep) -> Response:
    """Find the sun in one frame; with time and place, compare with SPA. The result is stored."""
    s = ctx.settings
    form = await _read_form(request, s.vision.max_image_bytes,
                            "HELIOTWIN_VISION_MAX_IMAGE_BYTES")
    _known_fields(form, _SUN_PROPERTIES)
    uploads = form.getlist("file")
    if len(uploads) != 1:
        raise HTTPException(422, f"file: exactly one image is needed, got {len(uploads)}")
    ts = _timestamp(_text(form, "timestamp"))
    place = _place(ctx, form)
    _writes_site(_token, place, "detections")
    method = _method(form)
    _pairs(form)
    stored, cal = await anyio.to_thread.run_sync(_stored_camera, session, form)
    cal_id = None if cal is None else int(cal["calibration_id"])
    place_source = None if place is None else "given"
    if place is None and cal is not None:
        place, place_source = calibration_place(cal, lambda sid: _site_place(ctx, sid))
        _writes_site(_token, place, "detections")
    up = await _upload(uploads[0], "file", s.vision.max_pixels)
    async with _admitted(ctx, request, _token, [up]):
        img = await anyio.to_thread.run_sync(decode, up, s.vision.max_pixels)
        cam, frame = await anyio.to_thread.run_sync(_camera, form, stored, cal, img.shape[1],
                                                    img.shape[0], (img, up.filename, ts, place))
        assert frame is not None
        ts = frame.timestamp
        oriented = is_oriented(stored is not None, _text(form, "north_offset_deg"))
        res = await anyio.to_thread.run_sync(analyse, img, cam, method, ts, place, oriented)
        scale = await anyio.to_thread.run_sync(_scale_warnings, (img, res.get("centroid_px")),
                                                cam, _text(form, "fov_deg"))
        del img
    if frame.camera_derived is not None:
        res["camera_derived"] = frame.camera_derived
    res["timestamp_source"] = frame.timestamp_source
    res["warnings"] = scale + error_warnings(res, None if cal is None else cal["max_deg"])
    row = detection_row(res, ts, place, cal_id)
    det_id = await _store_detection(ctx, row, anonymous=_token is None)
    res.update({"detection_id": det_id, "calibration_id": cal_id, "timestamp": iso(ts),
                "place_source": place_source,
                "site_id": place.site_id if place else None,
                "latitude_deg": place.latitude_deg if place else None,
                "longitude_deg": place.longitude_deg if place else None})
    return _json(res)


async def _timed_frames(ctx: Any, form: FormData, min_frames: int,
                        cal: dict[str, Any] | None = None) -> tuple[list[Frame], Place]:
    """Files with their timestamps and the place; headers checked, nothing decoded yet
    (the work decodes one frame at a time, so a batch holds one decoded frame)."""
    uploads = form.getlist("files")
    stamps = _texts(form, "timestamps")
    if len(uploads) < min_frames:
        raise HTTPException(422, f"files: at least {min_frames} images are needed, "
                                 f"got {len(uploads)}")
    if len(stamps) != len(uploads):
        raise HTTPException(422, f"timestamps: one per file in the same order; got "
                                 f"{len(stamps)} for {len(uploads)} files")
    place = _place(ctx, form, required=cal is None)
    if place is None:
        assert cal is not None
        place, _ = calibration_place(cal, lambda sid: _site_place(ctx, sid))
    frames: list[Frame] = []
    for i, (up, text) in enumerate(zip(uploads, stamps, strict=True)):
        ts = _timestamp(text, f"timestamps[{i}]")
        assert ts is not None
        frames.append((await _upload(up, f"files[{i}]", ctx.settings.vision.max_pixels), ts))
    # the headers' sizes, either way round (EXIF orientation may turn a frame when it is
    # decoded); the decoded sizes are compared as each frame is decoded
    sizes = {tuple(sorted(f[0].size_px)) for f in frames}
    if len(sizes) != 1:
        raise HTTPException(422, f"files: every frame must have the same size, got "
                                 f"{sorted({f[0].size_px for f in frames})}")
    return frames, place


_CAL_PROPERTIES: dict[str, Any] = {
    "files": {"type": "array", "items": {"type": "string", "format": "binary"}},
    "timestamps": {"type": "array", "items": {"type": "string"},
                   "description": "ISO 8601 with offset, one per file, same order"},
    "projection": {"type": "string", "enum": list(PROJECTION_CHOICES),
                   "description": "the lens's projection; auto (default): the one the "
                                  "frames support by leave-one-out, equidistant unless "
                                  "another is clearly better"},
    "east": {"type": "string", "enum": ["auto", "left", "right"]},
    "n_radial": {"type": "string", "enum": list(N_RADIAL_CHOICES),
                 "description": "radial polynomial terms; auto (default): as many "
                                "as lower the leave-one-out error"},
    "name": {"type": "string", "maxLength": 100,
             "description": "a name for the calibration, one line (default: projection, "
                            "frames, day)"},
    "fit_tilt": {"type": "boolean"},
    "site_id": {"type": "string"}, "latitude_deg": {"type": "number"},
    "longitude_deg": {"type": "number"}, "elevation_m": {"type": "number"},
}
_CAL_DOC = {
    "security": _OPTIONAL_BEARER,
    "requestBody": {"content": {"multipart/form-data": {"schema": {
        "type": "object", "required": ["files", "timestamps"], "properties": _CAL_PROPERTIES}}},
        "required": True},
}


@router.post("/calibrations", response_model=FittedCalibrationRead, openapi_extra=_CAL_DOC,
             status_code=201,
             responses={400: {"description": "a malformed multipart body"},
                        401: {}, 404: {}, 413: {}, 415: {}, 422: {}, **_BUSY_DOC})
async def post_calibration(request: Request, ctx: ContextDep, _token: VisionTokenDep
                           ) -> Response:
    """Fit a fisheye camera (centre, scale, north offset, mirror) to timestamped frames."""
    form = await _batch_form(request, ctx)
    _known_fields(form, _CAL_PROPERTIES)
    projection = parse_projection(_text(form, "projection") or PROJECTION_DEFAULT)
    east = _text(form, "east") or "auto"
    if east not in ("auto", *EAST_SIDES):
        raise HTTPException(422, f"east: must be auto, left or right, got {east!r}")
    fit_tilt = form_flag(_text(form, "fit_tilt"), "fit_tilt")
    n_radial = parse_n_radial(_text(form, "n_radial") or N_RADIAL_DEFAULT)
    method = _method(form)
    name = _text(form, "name") or ""
    if len(name) > 100:
        raise HTTPException(422, f"name: at most 100 characters, got {len(name)}")
    if (problem := one_line_problem(name)) is not None:  # a NUL was a 500 on PostgreSQL
        raise HTTPException(422, f"name: {problem}")
    frames, place = await _timed_frames(ctx, form, 3)
    _writes_site(_token, place, "calibrations")
    # a bad series is refused by the service (InputError: 422 naming files or timestamps)
    async with _admitted(ctx, request, _token, [f[0] for f in frames], CALIBRATION_PASSES):
        row = await anyio.to_thread.run_sync(
            calibrate, frames, place, projection, east, n_radial, fit_tilt,
            method, ctx.settings.vision.max_pixels)
    row["name"] = name or (f"{row['projection']}, {row['n_frames']} frames, "
                           f"{frames[0][1].date().isoformat()}")
    cal_id = await _store_calibration(ctx, row, anonymous=_token is None)
    return _json({**calibration_answer(row), "calibration_id": cal_id}, 201)


@router.get("/frame-times", response_model=FrameTimesRead)
def get_frame_times(filename: Annotated[list[str], Query(
        min_length=1, max_length=_MAX_FILES,
        description="a file name; repeat for several")]) -> FrameTimesRead:
    """The time each file name carries, as detection and calibration read it when no time is
    sent (``backend.vision.frames.time_from_name``): the dashboard shows these beside its
    files rather than parsing names itself. A name whose zone cannot be read exactly gets
    no time and a ``zone_error`` (detection refuses it without a ``timestamp``)."""
    out = []
    for name in filename:
        try:
            found, error = time_from_name(name[:1000]), None
        except NameZoneError as exc:  # a zone it cannot read: no time, and why
            found, error = None, str(exc)
        out.append(FrameNameTimeRead(
            filename=name, wall_time=None if found is None else found.wall_time.isoformat(),
            utc_offset_h=None if found is None else found.utc_offset_h, zone_error=error))
    return FrameTimesRead(frames=out)


@router.get("/calibrations", response_model=CalibrationsRead)
def get_calibrations(session: SessionDep,
                     limit: Annotated[int, Query(gt=0, le=1000)] = 200) -> Response:
    """Stored calibrations, newest first."""
    return _json({"calibrations": list_calibrations(session, limit)})


@router.get("/calibrations/{calibration_id}", response_model=StoredCalibrationRead,
            responses={404: {}})
def get_one_calibration(calibration_id: Annotated[int, Path(ge=1, le=_MAX_ID)],
                        session: SessionDep) -> Response:
    """One stored calibration with its per-frame residuals."""
    cal = get_calibration(session, calibration_id)
    if cal is None:
        raise HTTPException(404, f"no calibration {calibration_id}")
    return _json(cal)


def _detection_bounds(ctx: Any, site_id: str | None, start: str | None, end: str | None
                      ) -> tuple[int | None, int | None]:
    """[start, end) as Unix ms (bare dates: the site's midnight, else UTC's); 404 for an
    unknown site, 422 naming a bad bound or an end not after the start."""
    zone = ZoneInfo("UTC")
    if site_id is not None:
        info = ctx.registry.get(site_id)
        if info is None:
            raise HTTPException(404, f"site_id: unknown site {_cut(site_id)}")
        zone = info.zone
    bounds: list[int | None] = []
    for name, text in (("start", start), ("end", end)):
        if text is None:
            bounds.append(None)
            continue
        try:
            t = parse_day_or_instant(text, zone, name)
        except ValueError as exc:
            raise HTTPException(422, str(exc)) from None
        bounds.append(int(round(t.timestamp() * 1000)))
    if bounds[0] is not None and bounds[1] is not None and bounds[1] <= bounds[0]:
        raise HTTPException(422, f"end ({end}) must be after start ({start})")
    return bounds[0], bounds[1]


@router.get("/detections", response_model=DetectionsRead, responses={404: {}, 422: {}})
def get_detections(ctx: ContextDep, session: SessionDep,
                   site_id: str | None = None, start: str | None = None,
                   end: str | None = None,
                   limit: Annotated[int, Query(gt=0, le=100_000)] = 10_000) -> Response:
    """Stored detections in [start, end) (bare dates: the site's midnight, else UTC)."""
    lo, hi = _detection_bounds(ctx, site_id, start, end)
    rows = list_detections(session, site_id, lo, hi, limit)
    return _json({"site_id": site_id, "start": start, "end": end, "detections": rows})


_EVAL_PROPERTIES: dict[str, Any] = {
    "files": {"type": "array", "items": {"type": "string", "format": "binary"}},
    "timestamps": {"type": "array", "items": {"type": "string"},
                   "description": "ISO 8601 with offset, one per file, same order"},
    "calibration_id": {"type": "integer", "minimum": 1,
                       "description": "a stored calibration (its camera, and its place when "
                                      "none is given); or the fisheye's parameters below"},
    "camera": {"type": "string", "enum": ["fisheye"]},
    "px_per_deg": {"type": "number"}, "cx_px": {"type": "number"},
    "cy_px": {"type": "number"}, "north_offset_deg": {"type": "number"},
    "east": {"type": "string", "enum": ["left", "right"]},
    "projection": {"type": "string", "enum": list(PROJECTIONS)},
    "methods": {"type": "array", "items": {"type": "string", "enum": list(METHODS)},
                "description": "detection methods to compare (default: all)"},
    "site_id": {"type": "string"}, "latitude_deg": {"type": "number"},
    "longitude_deg": {"type": "number"}, "elevation_m": {"type": "number"},
}
_EVAL_DOC = {
    "security": _OPTIONAL_BEARER,
    "requestBody": {"content": {"multipart/form-data": {"schema": {
        "type": "object", "required": ["files", "timestamps"],
        "properties": _EVAL_PROPERTIES}}}, "required": True},
}


def _known_fields(form: FormData, known: dict[str, Any]) -> None:
    """A field the endpoint does not read is a 422 naming it (it was silently ignored), and
    so is a one-value text field given twice (the last had silently won, as a JSON key given
    twice would: ``camera=fisheye&camera=pinhole`` ran a pinhole camera)."""
    unknown = sorted({k for k in form if k not in known})
    if unknown:
        raise HTTPException(422, f"{_cut(unknown[0])}: unknown field; known: "
                                 f"{', '.join(known)}")
    for name in sorted(set(form)):
        spec, n = known[name], len(form.getlist(name))
        if n > 1 and spec.get("type") != "array" and spec.get("format") != "binary":
            raise HTTPException(422, f"{name}: given {n} times; send it once")


@router.post("/evaluate", response_model=EvaluationRead, openapi_extra=_EVAL_DOC,
             responses={400: {"description": "a malformed multipart body"},
                        401: {}, 404: {}, 413: {}, 415: {}, 422: {}, **_BUSY_DOC})
async def post_evaluate(request: Request, ctx: ContextDep, session: SessionDep,
                        _token: VisionTokenDep) -> Response:
    """Each method's angles against SPA on a batch: seed 003's Table 2 and Table 3."""
    form = await _batch_form(request, ctx)
    _known_fields(form, _EVAL_PROPERTIES)
    methods = _texts(form, "methods") or list(METHODS)
    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise HTTPException(422, f"methods: unknown {', '.join(bad)}; known: "
                                 f"{', '.join(METHODS)}")
    stored, cal = await anyio.to_thread.run_sync(_stored_camera, session, form)
    frames, place = await _timed_frames(ctx, form, 1, cal)

    def camera(w: int, h: int) -> FisheyeCamera:
        """The camera for the frames' decoded size (size and parameters checked)."""
        cam, _ = _camera(form, stored, cal, w, h)
        if not isinstance(cam, FisheyeCamera):
            raise HTTPException(422, "camera: evaluate compares azimuth/elevation, which "
                                     "needs a fisheye camera")
        return cam

    if cal is None:  # parameters refused before anything is decoded (the size is not used)
        camera(*frames[0][0].size_px)
    async with _admitted(ctx, request, _token, [f[0] for f in frames]):
        out = await anyio.to_thread.run_sync(evaluate, frames, place, camera, methods,
                                             ctx.settings.vision.max_pixels)
    return _json(out)


async def _deleting_token(request: Request, ctx: Any, site_id: str | None) -> None:
    """Deleting stored results changes what others see: the admin token or a ``site``-scope
    token of the site (managing its calibrations is the site scope's; a logger's ``ingest``
    token gets a 403), or a write token of any site for results of a free place (401/403
    otherwise), whatever ``vision_require_token`` says."""
    if site_id is not None:
        await check_site_admin(ctx, site_id, request.headers.get("authorization"),
                               f"deleting vision results of site {site_id!r}")
        return
    token = bearer_token(request)
    if is_admin_token(ctx.settings, token):  # it may delete a site's: a free place's too
        return
    if token is None or await token_site(request, token) is None:
        raise HTTPException(401, "deleting results of a free place needs a write token of "
                                 "any site or the admin token: "
                                 + ("send 'Authorization: Bearer <token>'" if token is None
                                    else "this one is unknown, revoked or expired"),
                            headers={"WWW-Authenticate": "Bearer"})


@router.delete("/calibrations/{calibration_id}", response_model=CalibrationDeletedRead,
               responses={401: {}, 403: {}, 404: {}})
async def delete_one_calibration(calibration_id: Annotated[int, Path(ge=1, le=_MAX_ID)],
                                 request: Request, ctx: ContextDep, session: SessionDep
                                 ) -> Response:
    """Delete a calibration and the detections made with it (a token of its site)."""
    cal = await anyio.to_thread.run_sync(get_calibration, session, calibration_id)
    if cal is None:
        raise HTTPException(404, f"no calibration {calibration_id}")
    await _deleting_token(request, ctx, cal["site_id"])
    counts = await asyncio.wrap_future(
        ctx.writer.call(lambda c: delete_calibration(c, calibration_id)))
    if counts is None:
        raise HTTPException(404, f"no calibration {calibration_id}")
    return _json({"calibration_id": calibration_id, **counts})


@router.delete("/detections", response_model=DetectionsDeletedRead,
               responses={401: {}, 403: {}, 404: {}, 422: {}})
async def delete_some_detections(
        request: Request, ctx: ContextDep, start: str, end: str,
        site_id: str | None = None,
        calibration_id: Annotated[int | None, Query(ge=1, le=_MAX_ID)] = None,
        uncalibrated: bool = False) -> Response:
    """Delete stored detections in [start, end) of a site (or of free places): all, or only
    those of one ``calibration_id``, or only those made with typed parameters
    (``uncalibrated=true``)."""
    if calibration_id is not None and uncalibrated:
        raise HTTPException(422, "give calibration_id or uncalibrated=true, not both")
    lo_ms, hi_ms = _detection_bounds(ctx, site_id, start, end)
    assert lo_ms is not None and hi_ms is not None
    await _deleting_token(request, ctx, site_id)
    n = await asyncio.wrap_future(ctx.writer.call(
        lambda c: delete_detections(c, site_id, lo_ms, hi_ms, calibration_id, uncalibrated)))
    return _json({"site_id": site_id, "start": start, "end": end, "detections_deleted": n})
