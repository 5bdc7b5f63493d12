"""``/api/v1/vision``: find the sun in uploaded frames, calibrate fisheye cameras, evaluate.

- ``POST /sun`` — one frame (multipart ``file``) and a camera (``camera`` with
  its parameters, or ``calibration_id``), optional ``timestamp`` and place
  (``site_id`` or ``latitude_deg``/``longitude_deg``/``elevation_m``) → the
  detection (``vision.analyse.analyse_frame``), the ephemeris (SPA, apparent
  elevation; for a fisheye also its pixel ``ephemeris.centroid_px`` through
  the same camera model) and the error (``error.separation_deg`` on the
  sphere, ``error.distance_px``). Stored.
- ``POST /calibrations`` — ``files`` with one ``timestamps`` each and a place →
  a fitted fisheye camera (``vision.calibrate``), stored with its residuals.
- ``GET /calibrations``, ``GET /calibrations/{id}``.
- ``POST /evaluate`` — a batch against SPA for each detection method: seed
  003's Table 2 (per frame) and Table 3 (MAD/MSE/RMSE/MAPE).
- ``GET /detections?site_id=&start=&end=`` — stored detections for the day's
  trajectory on the dashboard.

Uploads are bounded: the body is read in chunks and refused with 413 past
``max_upload_bytes`` (Content-Length is not trusted alone); each image's size
is read from its PNG/JPEG header and refused (413) above
``vision_max_pixels`` before anything is decoded; a non-image or a corrupt
one is a 415/422 naming the field. The image and database work runs in worker
threads; a batch is decoded one frame at a time, so it holds one decoded frame.
"""

from __future__ import annotations

import asyncio
import datetime as dt
from typing import Annotated, Any
from zoneinfo import ZoneInfo

import anyio
import numpy as np
import orjson
from fastapi import APIRouter, HTTPException, Path, Query, Request
from fastapi.responses import Response
from starlette.datastructures import FormData, UploadFile

from backend.api.deps import ContextDep, SessionDep, VisionTokenDep
from backend.timestamps import TimestampError, parse_day_or_instant, parse_instant
from backend.vision.service import (
    Frame,
    Place,
    Upload,
    analyse,
    calibrate,
    calibration_answer,
    check_image,
    decode,
    detection_row,
    evaluate,
    iso,
)
from backend.vision.store import (
    get_calibration,
    insert_calibration,
    insert_detection,
    list_calibrations,
    list_detections,
)
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


async def _read_form(request: Request, limit: int) -> FormData:
    """The multipart form, read in chunks and refused past ``limit`` bytes (413)."""
    ctype = request.headers.get("content-type", "")
    if not ctype.lower().startswith("multipart/form-data"):
        raise HTTPException(415, "send multipart/form-data (an image in the field 'file')")
    length = request.headers.get("content-length")
    if length is not None and length.isdigit() and int(length) > limit:
        raise HTTPException(413, f"body of {length} bytes; the limit is {limit} bytes "
                                 "(HELIOTWIN_MAX_UPLOAD_BYTES)")
    chunks: list[bytes] = []
    size = 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > limit:
            raise HTTPException(413, f"body over {limit} bytes (HELIOTWIN_MAX_UPLOAD_BYTES)")
        chunks.append(chunk)
    body = b"".join(chunks)

    async def receive() -> dict[str, Any]:
        return {"type": "http.request", "body": body, "more_body": False}

    try:
        return await Request(request.scope, receive).form(
            max_files=_MAX_FILES, max_fields=256, max_part_size=limit)
    except Exception as exc:  # starlette's HTTPException(400) for a malformed body or limits
        text = str(getattr(exc, "detail", exc))
        if "Too many files" in text:
            raise HTTPException(422, f"files: at most {_MAX_FILES} files per request") from None
        if "Too many fields" in text:
            raise HTTPException(422, "form: at most 256 fields per request") from None
        raise HTTPException(400, f"malformed multipart body: {text}") from None


def _text(form: FormData, name: str) -> str | None:
    v = form.get(name)
    if v is None or isinstance(v, UploadFile):
        return None
    v = v.strip()
    return v or None


def _texts(form: FormData, name: str) -> list[str]:
    return [v.strip() for v in form.getlist(name) if isinstance(v, str) and v.strip()]


def _fields(form: FormData) -> dict[str, object]:
    return {k: v for k, v in form.multi_items() if isinstance(v, str)}


async def _upload(upload: Any, field: str, max_pixels: int) -> Upload:
    """The file's bytes with its header checked (:func:`backend.vision.service.check_image`)."""
    if not isinstance(upload, UploadFile):
        raise HTTPException(422, f"{field}: an image file is required")
    return check_image(await upload.read(), upload.filename or field, field, max_pixels)


async def _image(upload: Any, field: str, max_pixels: int) -> np.ndarray:
    up = await _upload(upload, field, max_pixels)
    return await anyio.to_thread.run_sync(decode, up, max_pixels)


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
        info = ctx.registry.get(site_id)
        if info is None:
            known = ", ".join(ctx.registry.sites) or "none"
            raise HTTPException(404, f"site_id: unknown site {site_id!r}; known: {known}")
        s = info.site
        return Place(site_id, s.latitude, s.longitude, s.altitude, info.zone)
    if lat is None and lon is None:
        if required:
            raise HTTPException(422, "a place is required: site_id, or latitude_deg and "
                                     "longitude_deg")
        return None
    if lat is None or lon is None:
        raise HTTPException(422, "latitude_deg and longitude_deg go together")
    la, lo = _float(lat, "latitude_deg"), _float(lon, "longitude_deg")
    el = _float(_text(form, "elevation_m") or "0", "elevation_m")
    if not -90.0 <= la <= 90.0:
        raise HTTPException(422, f"latitude_deg: {la} is outside [-90, 90]")
    if not -180.0 <= lo <= 180.0:
        raise HTTPException(422, f"longitude_deg: {lo} is outside [-180, 180]")
    if not (np.isfinite(el) and -500.0 <= el <= 9000.0):
        raise HTTPException(422, f"elevation_m: {el} is outside [-500, 9000]")
    return Place(None, la, lo, el, ZoneInfo("UTC"))


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


def _stored_camera(session: Any, form: FormData) -> tuple[FisheyeCamera | None, int | None]:
    raw = _text(form, "calibration_id")
    if raw is None:
        return None, None
    if not raw.isdigit():
        raise HTTPException(422, f"calibration_id: {raw!r} is not an integer id")
    if int(raw) > _MAX_ID:
        raise HTTPException(404, f"calibration_id: no calibration {raw}")
    cal = get_calibration(session, int(raw))
    if cal is None:
        raise HTTPException(404, f"calibration_id: no calibration {raw}")
    return FisheyeCamera.from_dict(cal["camera"]), int(raw)


def _camera(form: FormData, stored: FisheyeCamera | None, w: int, h: int
            ) -> PinholeCamera | FisheyeCamera:
    kind = _text(form, "camera") or ("fisheye" if stored is not None else None)
    if stored is not None:
        if kind != "fisheye":
            raise HTTPException(422, "camera: a calibration_id is a fisheye camera")
        return stored
    if kind is None:
        raise HTTPException(422, "camera: required ('pinhole' or 'fisheye'), or give "
                                 "calibration_id")
    try:
        return camera_from_params(kind, _fields(form), w, h)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None


# --------------------------------------------------------------------------- work


# --------------------------------------------------------------------------- routes

_SUN_DOC = {
    "requestBody": {"content": {"multipart/form-data": {"schema": {
        "type": "object", "required": ["file"],
        "properties": {
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
        }}}}, "required": True},
}


@router.post("/sun", openapi_extra=_SUN_DOC,
             responses={401: {}, 404: {}, 413: {}, 415: {}, 422: {}})
async def post_sun(request: Request, ctx: ContextDep, session: SessionDep,
                   _token: VisionTokenDep) -> Response:
    """Find the sun in one frame; with time and place, compare with SPA. The result is stored."""
    s = ctx.settings
    form = await _read_form(request, s.max_upload_bytes)
    uploads = form.getlist("file")
    if len(uploads) != 1:
        raise HTTPException(422, f"file: exactly one image is needed, got {len(uploads)}")
    ts = _timestamp(_text(form, "timestamp"))
    place = _place(ctx, form)
    method = _method(form)
    stored, cal_id = await anyio.to_thread.run_sync(_stored_camera, session, form)
    img = await _image(uploads[0], "file", s.vision_max_pixels)
    cam = _camera(form, stored, img.shape[1], img.shape[0])
    res = await anyio.to_thread.run_sync(analyse, img, cam, method, ts, place)
    row = detection_row(res, ts, place, cal_id)
    det_id = await asyncio.wrap_future(ctx.writer.call(lambda c: insert_detection(c, row)))
    res.update({"detection_id": det_id, "calibration_id": cal_id, "timestamp": iso(ts),
                "site_id": place.site_id if place else None,
                "latitude_deg": place.latitude_deg if place else None,
                "longitude_deg": place.longitude_deg if place else None})
    return _json(res)


async def _timed_frames(ctx: Any, form: FormData, min_frames: int
                        ) -> tuple[list[Frame], Place]:
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
    place = _place(ctx, form, required=True)
    assert place is not None
    frames: list[Frame] = []
    for i, (up, text) in enumerate(zip(uploads, stamps, strict=True)):
        ts = _timestamp(text, f"timestamps[{i}]")
        assert ts is not None
        frames.append((await _upload(up, f"files[{i}]", ctx.settings.vision_max_pixels), ts))
    sizes = {f[0].size_px for f in frames}
    if len(sizes) != 1:
        raise HTTPException(422, f"files: every frame must have the same size, got "
                                 f"{sorted(sizes)}")
    return frames, place


_CAL_DOC = {
    "requestBody": {"content": {"multipart/form-data": {"schema": {
        "type": "object", "required": ["files", "timestamps"],
        "properties": {
            "files": {"type": "array", "items": {"type": "string", "format": "binary"}},
            "timestamps": {"type": "array", "items": {"type": "string"},
                           "description": "ISO 8601 with offset, one per file, same order"},
            "projection": {"type": "string"}, "east": {"type": "string",
                                                      "enum": ["auto", "left", "right"]},
            "n_radial": {"type": "integer", "minimum": 0, "maximum": 2},
            "fit_tilt": {"type": "boolean"},
            "site_id": {"type": "string"}, "latitude_deg": {"type": "number"},
            "longitude_deg": {"type": "number"}, "elevation_m": {"type": "number"},
        }}}}, "required": True},
}


@router.post("/calibrations", openapi_extra=_CAL_DOC, status_code=201,
             responses={401: {}, 404: {}, 413: {}, 415: {}, 422: {}})
async def post_calibration(request: Request, ctx: ContextDep, _token: VisionTokenDep
                           ) -> Response:
    """Fit a fisheye camera (centre, scale, north offset, mirror) to timestamped frames."""
    form = await _read_form(request, ctx.settings.max_upload_bytes)
    projection = _text(form, "projection") or "equidistant"
    if projection not in PROJECTIONS:
        raise HTTPException(422, f"projection: must be one of {', '.join(PROJECTIONS)}, "
                                 f"got {projection!r}")
    east = _text(form, "east") or "auto"
    if east not in ("auto", *EAST_SIDES):
        raise HTTPException(422, f"east: must be auto, left or right, got {east!r}")
    tilt_text = (_text(form, "fit_tilt") or "false").lower()
    if tilt_text not in ("1", "true", "yes", "on", "0", "false", "no", "off"):
        raise HTTPException(422, f"fit_tilt: must be true or false, got {tilt_text!r}")
    fit_tilt = tilt_text in ("1", "true", "yes", "on")
    n_radial_text = _text(form, "n_radial") or "0"
    if n_radial_text not in ("0", "1", "2"):
        raise HTTPException(422, f"n_radial: must be 0, 1 or 2, got {n_radial_text!r}")
    method = _method(form)
    frames, place = await _timed_frames(ctx, form, 3)
    try:
        row = await anyio.to_thread.run_sync(
            calibrate, frames, place, projection, east, int(n_radial_text), fit_tilt, method,
            ctx.settings.vision_max_pixels)
    except ValueError as exc:
        raise HTTPException(422, f"files: {exc}") from None
    cal_id = await asyncio.wrap_future(ctx.writer.call(lambda c: insert_calibration(c, row)))
    return _json({**calibration_answer(row), "calibration_id": cal_id}, 201)


@router.get("/calibrations")
def get_calibrations(session: SessionDep,
                     limit: Annotated[int, Query(gt=0, le=1000)] = 200) -> Response:
    """Stored calibrations, newest first."""
    return _json({"calibrations": list_calibrations(session, limit)})


@router.get("/calibrations/{calibration_id}", responses={404: {}})
def get_one_calibration(calibration_id: Annotated[int, Path(ge=1, le=_MAX_ID)],
                        session: SessionDep) -> Response:
    """One stored calibration with its per-frame residuals."""
    cal = get_calibration(session, calibration_id)
    if cal is None:
        raise HTTPException(404, f"no calibration {calibration_id}")
    return _json(cal)


@router.get("/detections", responses={404: {}, 422: {}})
def get_detections(ctx: ContextDep, session: SessionDep,
                   site_id: str | None = None, start: str | None = None,
                   end: str | None = None,
                   limit: Annotated[int, Query(gt=0, le=100_000)] = 10_000) -> Response:
    """Stored detections in [start, end) (bare dates: the site's midnight, else UTC)."""
    zone = ZoneInfo("UTC")
    if site_id is not None:
        info = ctx.registry.get(site_id)
        if info is None:
            raise HTTPException(404, f"site_id: unknown site {site_id!r}")
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
    rows = list_detections(session, site_id, bounds[0], bounds[1], limit)
    return _json({"site_id": site_id, "start": start, "end": end, "detections": rows})


@router.post("/evaluate", openapi_extra=_CAL_DOC,
             responses={401: {}, 404: {}, 413: {}, 415: {}, 422: {}})
async def post_evaluate(request: Request, ctx: ContextDep, session: SessionDep,
                        _token: VisionTokenDep) -> Response:
    """Each method's angles against SPA on a batch: seed 003's Table 2 and Table 3."""
    form = await _read_form(request, ctx.settings.max_upload_bytes)
    methods = _texts(form, "methods") or list(METHODS)
    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise HTTPException(422, f"methods: unknown {', '.join(bad)}; known: "
                                 f"{', '.join(METHODS)}")
    stored, _ = await anyio.to_thread.run_sync(_stored_camera, session, form)
    frames, place = await _timed_frames(ctx, form, 1)
    w, h = frames[0][0].size_px
    cam = _camera(form, stored, w, h)
    if not isinstance(cam, FisheyeCamera):
        raise HTTPException(422, "camera: evaluate compares azimuth/elevation, which needs a "
                                 "fisheye camera")
    out = await anyio.to_thread.run_sync(evaluate, frames, place, cam, methods,
                                         ctx.settings.vision_max_pixels)
    return _json(out)
