"""``POST /api/v1/simulations/weather``: a twin scenario on an uploaded weather file.

Multipart: the weather file in ``file`` and the fields of ``POST /api/v1/simulations``
(``site_id``, ``start``, ``end``, ``step_s``, ``controller``, ``receiver``,
``background`` and the machine parameters) as form fields, plus ``force``,
``weather_stamped`` and ``weather_timezone``. A TMY3, EPW, PVGIS TMY (CSV or JSON) or
NSRDB typical-year file (by its first line) is a typical year, read by
:func:`sim.sky.read_typical_year` and laid onto the run's calendar
(:func:`backend.twin.scenario.run_scenario`); any other file (an NSRDB actual year among
them) is read as measured weather of its own dates (:func:`sim.sky.read_measured`:
``weather_stamped`` says what its times mark, ``weather_timezone`` the zone of times
without an offset), and a run outside them is a 422 naming them. A station more than
:data:`backend.twin.scenario.MAX_STATION_DISTANCE_KM` from the site is a 422
unless ``force`` is true. The body is bounded by ``HELIOTWIN_MAX_UPLOAD_BYTES``
(413 past it). The answer is that of ``POST /api/v1/simulations`` (the summary,
or 202 with a ``run_id``), submitted through the same queue and limits.
"""

from __future__ import annotations

import dataclasses
import io
from typing import Any

import pandas as pd
from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import Response
from starlette.datastructures import FormData, UploadFile

from backend.api.deps import ContextDep, site_or_404
from backend.api.forms import form_flag, form_model, form_text, read_form
from backend.api.routes.simulations import (
    _BUSY_DOC,
    SUBMIT_RESPONSES,
    SimulationCreate,
    _params,
    submit_scenario,
)
from backend.api.schemas.simulations import SimulationSummaryRead
from backend.twin.scenario import StationTooFar, check_station
from sim.energy import READING_STAMPS
from sim.site_config import check_iana_zone
from sim.sky import (
    MEASURED_STAMPED_DEFAULT,
    nsrdb_is_typical_year,
    read_measured,
    read_typical_year,
    sniff_weather_format,
    weather_text,
)

router = APIRouter(prefix="/api/v1/simulations", tags=["simulations"])

#: The fields of a weather upload besides a route's own: the file and how to read it.
WEATHER_FORM_FIELDS = ("file", "force", "weather_stamped", "weather_timezone")


async def read_weather_upload(form: FormData) -> tuple[Any, dict[str, Any]]:
    """The weather and station of the form's ``file`` (``weather_stamped`` and
    ``weather_timezone`` read for measured weather): a typical year when its first line is a
    TMY3's, an EPW's, a PVGIS TMY's (CSV or JSON) or an NSRDB typical year's, else measured
    weather (an NSRDB actual year among it); 422 naming
    ``file`` when unreadable. The one reading of a weather upload (the twin's and a
    plant's)."""
    upload = form.get("file")
    stamped, timezone = form_text(form, "weather_stamped"), form_text(form, "weather_timezone")
    if not isinstance(upload, UploadFile):
        raise HTTPException(422, "file: a weather file (TMY3, EPW, PVGIS, NSRDB or a "
                                 "measured CSV) is required")
    text = weather_text(await upload.read())
    name = upload.filename or "the upload"
    try:
        fmt = sniff_weather_format(io.StringIO(text))
    except ValueError:
        return _measured(text, name, stamped, timezone)
    if fmt == "nsrdb" and not nsrdb_is_typical_year(io.StringIO(text)):
        return _measured(text, name, stamped, timezone)  # an actual year: of its own dates
    try:
        return read_typical_year(io.StringIO(text))
    except (ValueError, KeyError, IndexError) as exc:
        raise HTTPException(422, f"file: {name} is not a readable TMY3, EPW, PVGIS or NSRDB "
                                 f"typical year: {exc}") from None


def _measured(text: str, name: str, stamped: str | None, timezone: str | None
              ) -> tuple[Any, dict[str, Any]]:
    """Measured weather (:func:`sim.sky.read_measured`); 422 naming the field at fault."""
    if stamped is not None and stamped not in READING_STAMPS:
        raise HTTPException(422, f"weather_stamped: {stamped!r} is not one of "
                                 f"{', '.join(READING_STAMPS)}")
    if timezone is not None:
        try:
            check_iana_zone(timezone)
        except ValueError as exc:
            raise HTTPException(422, f"weather_timezone: {exc}") from None
    try:
        return read_measured(io.StringIO(text), stamped or MEASURED_STAMPED_DEFAULT, timezone,
                             name)
    except (ValueError, pd.errors.ParserError) as exc:
        raise HTTPException(422, f"file: {name} is neither a TMY3, EPW, PVGIS or NSRDB typical "
                                 f"year (by its first line) nor readable measured weather: "
                                 f"{exc}") from None


@router.post("/weather", response_model=SimulationSummaryRead,
             responses={**SUBMIT_RESPONSES, 400: {}, 404: {}, 413: {}, 415: {}, 422: {},
                        **_BUSY_DOC},
             openapi_extra={"security": [{}, {"bearerAuth": []}]})
async def create_simulation_on_weather(request: Request, ctx: ContextDep) -> Response:
    """Run a twin scenario on an uploaded TMY3/EPW/PVGIS/NSRDB typical year, or measured
    weather of its own dates, instead of clear sky."""
    form = await read_form(request, ctx.settings.server.max_upload_bytes,
                           "the weather file in 'file'", max_files=1, max_fields=64)
    force = form_flag(form_text(form, "force"), "force")
    background = form_flag(form_text(form, "background"), "background")
    body = form_model(SimulationCreate, form, WEATHER_FORM_FIELDS + ("background",))
    typical, meta = await read_weather_upload(form)
    info = site_or_404(ctx, body.site_id, "site_id")
    try:
        station = check_station(meta, info.site, force,
                                'force (tick "distant station" on the simulation form)')
    except StationTooFar as exc:
        raise HTTPException(422, f"force: {exc}") from None
    try:
        params = dataclasses.replace(_params(ctx, body), weather=typical, station=station)
    except ValueError as exc:  # a run outside measured weather's dates
        raise HTTPException(422, f"file: {exc}") from None
    return await submit_scenario(ctx, request, params, background)

