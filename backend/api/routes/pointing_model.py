"""``/api/v1/sites/{site_id}/pointing-model``: the tracker's mount terms from its camera's
sun offsets, and ``…/command``: the encoder angles to command under that model (issue 25;
``backend/diagnosis/pointing_model.py``, ``docs/pointing-model.md``)."""

from __future__ import annotations

import datetime as dt
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query

from backend.api.deps import ContextDep, RangeEnd, RangeStart, site_or_404
from backend.api.schemas.pointing_model import PointingCommandRead, PointingModelRead
from backend.context import ServiceContext
from backend.diagnosis.pointing_model import (
    TooFewObservations,
    command,
    fit_site,
    model_body,
    observations,
)
from backend.sites import SiteInfo
from backend.timestamps import parse_instant, parse_range
from sim.pointing_model import PointingFit

router = APIRouter(prefix="/api/v1/sites", tags=["pointing-model"])


def _fit(ctx: ServiceContext, info: SiteInfo, start: str, end: str) -> PointingFit:
    try:
        t0, t1 = parse_range(start, end, info.zone)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    try:
        with ctx.engine.connect() as conn:  # closed before the fit: it holds no connection
            rows = observations(conn, info, t0, t1)
        return fit_site(rows, info)
    except TooFewObservations as exc:
        raise HTTPException(422, str(exc)) from None


@router.get("/{site_id}/pointing-model", response_model=PointingModelRead,
            responses={404: {}, 422: {}})
def get_pointing_model(site_id: str, ctx: ContextDep, start: RangeStart,
                       end: RangeEnd) -> PointingModelRead:
    """Mount terms with standard errors from the tracker's readings with sun offsets in
    ``[start, end)``; outliers (glints) rejected; which terms the sky coverage separates."""
    info = site_or_404(ctx, site_id)
    return PointingModelRead.model_validate(model_body(info, _fit(ctx, info, start, end)))


@router.get("/{site_id}/pointing-model/command", response_model=PointingCommandRead,
            responses={404: {}, 422: {}})
def get_pointing_command(
    site_id: str, ctx: ContextDep, start: RangeStart, end: RangeEnd,
    time: Annotated[str, Query(min_length=1, max_length=64,
                               description="ISO date-time with offset")],
) -> PointingCommandRead:
    """Encoder angles to command at ``time`` so the real optical axis points at the sun,
    under the model fitted from ``[start, end)``."""
    info = site_or_404(ctx, site_id)
    try:
        when: dt.datetime = parse_instant(time, "time")
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    return PointingCommandRead.model_validate(command(info, _fit(ctx, info, start, end), when))
