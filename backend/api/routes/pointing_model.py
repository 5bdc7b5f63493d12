"""``/api/v1/sites/{site_id}/pointing-model``: the tracker's mount terms from its camera's
sun offsets (with the observations' residuals before and after the model, for the
dashboard), ``…/command``: the encoder angles to command under that model, and
``POST …/observations``: a tracker-camera frame turned into an observation (issue 25
items 1b and 3; ``backend/diagnosis/pointing_model.py``, ``docs/pointing-model.md``).
"""

from __future__ import annotations

import datetime as dt
import math
from typing import Annotated, Any

import anyio
import numpy as np
import orjson
from fastapi import APIRouter, HTTPException, Query, Request
from starlette.datastructures import FormData, UploadFile

from backend.api.deps import (
    ContextDep,
    RangeEnd,
    RangeStart,
    anonymous_read_route,
    check_site_token,
    site_or_404,
    site_range,
)
from backend.api.forms import read_form
from backend.api.schemas.pointing_model import (
    PointingCommandRead,
    PointingCoverageRead,
    PointingModelPointsRead,
    PointingObservationRead,
)
from backend.context import ServiceContext
from backend.diagnosis.pointing_model import (
    MAX_POINTS,
    TooFewObservations,
    cached_range_fit,
    command,
    count_observations,
    fit_site,
    frame_offsets,
    model_body,
    observations,
    range_key,
    remember_range_fit,
    residual_points,
)
from backend.limits import Busy, metered
from backend.measurements import ingest
from backend.measurements.parse import IngestError, Limits, parse_json_batch
from backend.measurements.queries import iso_utc
from backend.sites import SiteInfo
from backend.timestamps import parse_instant, parse_range
from backend.vision.service import check_image, decode
from sim.pointing_model import MIN_OBSERVATIONS, PointingFit
from vision.cameras import PinholeCamera, camera_from_params

router = APIRouter(prefix="/api/v1/sites", tags=["pointing-model"])


def _fit(ctx: ServiceContext, info: SiteInfo, t0: dt.datetime, t1: dt.datetime
         ) -> tuple[np.ndarray, PointingFit]:
    try:
        with ctx.engine.connect() as conn:  # closed before the fit: it holds no connection
            rows = observations(conn, info, t0, t1)
        return rows, fit_site(rows, info)
    except TooFewObservations as exc:
        raise HTTPException(422, str(exc)) from None


@router.get("/{site_id}/pointing-model", response_model=PointingModelPointsRead,
            **anonymous_read_route({404: {}, 422: {}}))
def get_pointing_model(
    site_id: str, ctx: ContextDep, start: RangeStart, end: RangeEnd,
    max_points: Annotated[int, Query(ge=1, le=MAX_POINTS, description=(
        "at most this many observations in points (evenly spaced)"))] = MAX_POINTS,
) -> PointingModelPointsRead:
    """Mount terms with standard errors from the tracker's readings with sun offsets in
    ``[start, end)``; outliers (glints) rejected; which terms the sky coverage separates;
    the observations' offsets and residuals (``points``, at most ``max_points``). Without a
    token its CPU time comes out of the address's ``HELIOTWIN_ANONYMOUS_READ_CPU_S_PER_MIN``."""
    with metered():
        info, t0, t1 = site_range(ctx, site_id, start, end)
        rows, fit = _fit(ctx, info, t0, t1)
        return PointingModelPointsRead.model_validate(
            {**model_body(info, fit), "points": residual_points(rows, info, fit, max_points)})


@router.get("/{site_id}/pointing-model/coverage", response_model=PointingCoverageRead,
            **anonymous_read_route({404: {}, 422: {}}))
def get_pointing_coverage(
    site_id: str, ctx: ContextDep, start: RangeStart, end: RangeEnd,
) -> PointingCoverageRead:
    """How many observations ``GET …/pointing-model`` would fit over ``[start, end)`` (the
    tracker's readings with encoder angles and sun offsets) and the fewest it takes, counted
    without reading them: a range or site without them is a 200 saying so, which the
    dashboard shows as its empty state instead of asking for a fit that fails."""
    with metered():
        info, t0, t1 = site_range(ctx, site_id, start, end)
        with ctx.engine.connect() as conn:
            n = count_observations(conn, info, t0, t1)
        return PointingCoverageRead(site_id=info.site_id, has_tracker=n is not None,
                                    n_observations=n or 0, min_observations=MIN_OBSERVATIONS)


@router.get("/{site_id}/pointing-model/command", response_model=PointingCommandRead,
            **anonymous_read_route({404: {}, 422: {}}))
def get_pointing_command(
    site_id: str, ctx: ContextDep, start: RangeStart, end: RangeEnd,
    time: Annotated[str, Query(min_length=1, max_length=64,
                               description="ISO date-time with offset")],
) -> PointingCommandRead:
    """Encoder angles to command at ``time`` so the real optical axis points at the sun,
    under the model fitted from ``[start, end)`` (remembered for the range's observations
    as they are: a command under it reads no rows). Without a token its CPU time comes out
    of the address's ``HELIOTWIN_ANONYMOUS_READ_CPU_S_PER_MIN``."""
    with metered():
        return _command(ctx, site_or_404(ctx, site_id), start, end, time)


def _command(ctx: ServiceContext, info: SiteInfo, start: str, end: str, time: str
             ) -> PointingCommandRead:
    """The answer of :func:`get_pointing_command` for a known site."""
    try:
        when: dt.datetime = parse_instant(time, "time")
        t0, t1 = parse_range(start, end, info.zone)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    # a command under a remembered fit reads no rows; the key and the rows are read in one
    # transaction (one snapshot), and the fit runs after the connection is closed
    try:
        with ctx.engine.connect() as conn:
            key = range_key(conn, info, t0, t1)
            fit = cached_range_fit(key)
            if fit is None:
                rows = observations(conn, info, t0, t1)
        if fit is None:
            fit = fit_site(rows, info)
            remember_range_fit(key, fit)
    except TooFewObservations as exc:
        raise HTTPException(422, str(exc)) from None
    return PointingCommandRead.model_validate(command(info, fit, when))


#: The form fields of ``POST …/observations`` besides ``file``: the reading's (its time and
#: electrical values as a logger sends them, the encoder angles) and the pinhole camera's.
_READING_FIELDS = ("ts", "azimuth_deg", "elevation_deg", "power_w", "voltage_v", "current_a")
_CAMERA_FIELDS = ("fov_deg", "cx_px", "cy_px", "reference_x_px", "reference_y_px")

_OBSERVATION_DOC = {
    "requestBody": {"content": {"multipart/form-data": {"schema": {
        "type": "object", "required": ["file", "ts", "azimuth_deg", "elevation_deg"],
        "properties": {
            "file": {"type": "string", "format": "binary",
                     "description": "PNG or JPEG frame of the tracker's narrow camera"},
            "ts": {"type": "string", "description": "the frame's time, ISO 8601 with offset"},
            "azimuth_deg": {"type": "number", "description": "encoder azimuth at ts [°]"},
            "elevation_deg": {"type": "number", "description": "encoder elevation at ts [°]"},
            "power_w": {"type": "number", "description": "the tracker's power at ts [W] (or "
                                                         "voltage_v and current_a)"},
            "voltage_v": {"type": "number"}, "current_a": {"type": "number"},
            "fov_deg": {"type": "number", "description": "horizontal field of view [°] (67, "
                                                         "seed 000)"},
            "cx_px": {"type": "number"}, "cy_px": {"type": "number"},
            "reference_x_px": {"type": "number",
                               "description": "the pixel of the camera's axis (default the "
                                              "optical centre)"},
            "reference_y_px": {"type": "number"},
        }}}}, "required": True},
}


def _form_reading(form: FormData, array: str) -> dict[str, Any]:
    """The reading the form describes (offsets not yet known): 422 naming a field that is
    unknown, given twice or not a finite number."""
    unknown = sorted({k for k in form if k not in ("file", *_READING_FIELDS, *_CAMERA_FIELDS)})
    if unknown:
        raise HTTPException(422, f"{unknown[0]}: unknown field; known: file, "
                                 f"{', '.join(_READING_FIELDS + _CAMERA_FIELDS)}")
    reading: dict[str, Any] = {"array": array}
    for name in _READING_FIELDS:
        values = form.getlist(name)
        if len(values) > 1:
            raise HTTPException(422, f"{name}: given {len(values)} times")
        if not values or not isinstance(values[0], str) or not values[0].strip():
            continue
        text = values[0].strip()
        if name == "ts":
            reading["ts"] = text
            continue
        try:
            value = float(text)
        except ValueError:
            raise HTTPException(422, f"{name}: {text[:40]!r} is not a number") from None
        if not math.isfinite(value):
            raise HTTPException(422, f"{name}: {text[:40]!r} is not a finite number")
        reading[name] = value
    for name in ("ts", "azimuth_deg", "elevation_deg"):
        if name not in reading:
            raise HTTPException(422, f"{name}: required (the frame's time and the encoder "
                                     "angles at it)")
    return reading


def _checked(reading: dict[str, Any], info: SiteInfo, limits: Limits) -> None:
    """The ingest path's own validation of the reading (time, array, electrical values,
    ranges), before the frame is decoded: a 422 naming the field, as for a logger."""
    try:
        parse_json_batch(orjson.dumps({"readings": [reading]}), info.ingest_arrays(), limits)
    except IngestError as exc:
        raise HTTPException(exc.status, "; ".join(
            f"{e.get('field') or 'body'}: {e['msg']}" for e in exc.errors)) from None


def _observe(data: Any, params: dict[str, object], max_pixels: int) -> dict[str, Any]:
    """Decode the frame and find the sun's offsets in it (a worker thread's work)."""
    image = decode(data, max_pixels)
    try:
        camera = camera_from_params("pinhole", params, image.shape[1], image.shape[0])
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    assert isinstance(camera, PinholeCamera)
    fov_given = str(params.get("fov_deg") or "").strip() != ""
    return frame_offsets(image, camera, fov_given)


@router.post("/{site_id}/pointing-model/observations", response_model=PointingObservationRead,
             openapi_extra=_OBSERVATION_DOC,
             responses={400: {"description": "a malformed multipart body"},
                        401: {"description": "no or unknown token"},
                        403: {"description": "a token of another site"},
                        404: {"description": "unknown site"},
                        409: {"description": "a reading of the tracker at ts is already stored"},
                        413: {"description": "body or image too large"},
                        415: {"description": "not multipart, or not a PNG or JPEG"},
                        422: {"description": "a bad field (named), or no sun in the frame"},
                        503: {"description": "decode budget full or storage unavailable; "
                                             "see Retry-After"}})
async def post_pointing_observation(site_id: str, request: Request, ctx: ContextDep
                                    ) -> PointingObservationRead:
    """A tracker-camera frame with its time and encoder angles → the sun's offsets in it,
    stored as an observation (a reading of the tracker array, through the writer: answered
    once committed). Needs a token of the site (``ingest`` scope or wider); the body is
    bounded by ``HELIOTWIN_VISION_MAX_IMAGE_BYTES``, the image by
    ``HELIOTWIN_VISION_MAX_PIXELS``.
    A frame without a sun is a 422 saying why, and nothing is stored."""
    await check_site_token(ctx, site_id, request.headers.get("authorization"), "ingest",
                           "storing pointing observations")
    info = site_or_404(ctx, site_id)
    tracker = info.array_of_kind("tracker")
    if tracker is None:
        raise HTTPException(422, f"site {site_id!r} has no tracker array to observe")
    s = ctx.settings
    form = await read_form(request, s.vision.max_image_bytes,
                           "a tracker-camera frame in the field 'file'", max_files=1,
                           max_fields=len(_READING_FIELDS) + len(_CAMERA_FIELDS) + 1,
                           limit_name="HELIOTWIN_VISION_MAX_IMAGE_BYTES")
    uploads = form.getlist("file")
    if len(uploads) != 1 or not isinstance(uploads[0], UploadFile):
        raise HTTPException(422, "file: exactly one image of the tracker's camera is needed")
    reading = _form_reading(form, tracker.name)
    limits = Limits.from_settings(s)
    _checked({**reading, "sun_offset_x_mrad": 0.0, "sun_offset_y_mrad": 0.0}, info, limits)
    params: dict[str, object] = {k: v for k, v in form.multi_items()
                                 if k in _CAMERA_FIELDS and isinstance(v, str)}
    up = check_image(await uploads[0].read(), uploads[0].filename or "file", "file",
                     s.vision.max_pixels)
    try:
        async with ctx.limits.decode.hold(up.size_px[0] * up.size_px[1]):
            found = await anyio.to_thread.run_sync(_observe, up, params, s.vision.max_pixels)
    except Busy as exc:
        raise HTTPException(exc.status_code, exc.message, headers=exc.headers) from None
    offsets = {k: found[k] for k in ("sun_offset_x_mrad", "sun_offset_y_mrad")}
    _checked({**reading, **offsets}, info, limits)  # an offset beyond the camera's field
    try:
        stored = await ingest.ingest(ctx.writer, parse_json_batch,
                                     orjson.dumps({"readings": [{**reading, **offsets}]}),
                                     info.ingest_arrays(), limits)
    except ingest.StorageUnavailable as exc:
        raise HTTPException(503, str(exc), headers={"Retry-After": "5"}) from None
    if stored.accepted == 0:
        raise HTTPException(409, f"ts: a reading of {tracker.name!r} at "
                                 f"{iso_utc([stored.stored_through_s])[0]} is already stored "
                                 "(this observation sent before, or the logger's reading of "
                                 "that second); the observation was not stored")
    return PointingObservationRead(
        site_id=site_id, array=tracker.name, ts=iso_utc([stored.stored_through_s])[0],
        azimuth_deg=float(np.mod(reading["azimuth_deg"], 360.0)),
        elevation_deg=reading["elevation_deg"], confidence=found["confidence"],
        centroid_px=found["centroid_px"], warnings=found["warnings"], **offsets)
