"""``POST /api/v1/simulations/weather``: a twin scenario on an uploaded TMY3 or EPW file.

Multipart: the weather file in ``file`` and the fields of ``POST /api/v1/simulations``
(``site_id``, ``start``, ``end``, ``step_s``, ``controller``, ``receiver``,
``background`` and the machine parameters) as form fields, plus ``force``. The
typical year is read by :func:`sim.sky.read_typical_year` and laid onto the run's
calendar (:func:`backend.twin.scenario.run_scenario`); a station more than
:data:`backend.twin.scenario.MAX_STATION_DISTANCE_KM` from the site is a 422
unless ``force`` is true. The body is bounded by ``HELIOTWIN_MAX_UPLOAD_BYTES``
(413 past it). The answer is that of ``POST /api/v1/simulations`` (the summary,
or 202 with a ``run_id``), submitted through the same queue and limits.
"""

from __future__ import annotations

import dataclasses
import io
from typing import Any

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import Response
from pydantic import ValidationError
from starlette.datastructures import FormData, UploadFile

from backend.api.deps import ContextDep, site_or_404
from backend.api.forms import form_flag, read_form
from backend.api.routes.simulations import (
    _BUSY_DOC,
    SUBMIT_RESPONSES,
    SimulationCreate,
    _params,
    submit_scenario,
)
from backend.api.schemas.simulations import SimulationSummaryRead
from backend.twin.scenario import StationTooFar, check_station
from sim.sky import read_typical_year

router = APIRouter(prefix="/api/v1/simulations", tags=["simulations"])

def _field(form: FormData, name: str) -> str | None:
    value = form.get(name)
    return value if isinstance(value, str) else None


async def _weather(upload: Any) -> tuple[Any, dict[str, Any]]:
    """The typical year and station of the uploaded file; 422 naming ``file`` when unreadable."""
    if not isinstance(upload, UploadFile):
        raise HTTPException(422, "file: a TMY3 or EPW weather file is required")
    raw = await upload.read()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    try:
        return read_typical_year(io.StringIO(text))
    except (ValueError, KeyError, IndexError) as exc:
        raise HTTPException(422, f"file: {upload.filename or 'the upload'} is not a readable "
                                 f"TMY3 or EPW typical year: {exc}") from None


@router.post("/weather", response_model=SimulationSummaryRead,
             responses={**SUBMIT_RESPONSES, 400: {}, 404: {}, 413: {}, 415: {}, 422: {},
                        **_BUSY_DOC},
             openapi_extra={"security": [{}, {"bearerAuth": []}]})
async def create_simulation_on_weather(request: Request, ctx: ContextDep) -> Response:
    """Run a twin scenario on an uploaded TMY3/EPW typical year instead of clear sky."""
    form = await read_form(request, ctx.settings.server.max_upload_bytes,
                           "the weather file in 'file'", max_files=1, max_fields=64)
    fields: dict[str, Any] = {k: v for k, v in form.multi_items()
                              if k not in ("file", "force", "background") and isinstance(v, str)}
    force = form_flag(_field(form, "force"), "force")
    background = form_flag(_field(form, "background"), "background")
    try:
        body = SimulationCreate.model_validate(fields, strict=False)  # form fields are text
    except ValidationError as exc:
        problems = "; ".join(f"{'.'.join(str(x) for x in e['loc'])}: {e['msg']}"
                             for e in exc.errors())
        raise HTTPException(422, problems) from None
    typical, meta = await _weather(form.get("file"))
    info = site_or_404(ctx, body.site_id, "site_id")
    try:
        station = check_station(meta, info.site, force,
                                'force (tick "distant station" on the simulation form)')
    except StationTooFar as exc:
        raise HTTPException(422, f"force: {exc}") from None
    params = dataclasses.replace(_params(ctx, body), weather=typical, station=station)
    return await submit_scenario(ctx, request, params, background)

