"""``/api/v1/sites/{site_id}/diagnosis``: per day, the tracker against the weather-aware twin
and the faults found; ``…/pointing``: the pointing error from the tracker's encoder angles
(``backend/diagnosis``, ``docs/diagnosis.md``)."""

from __future__ import annotations

import orjson
from fastapi import APIRouter
from fastapi.responses import Response

from backend.api.deps import (
    CallerDep,
    ContextDep,
    RangeEnd,
    RangeStart,
    anonymous_read_route,
    site_range,
)
from backend.api.schemas.diagnosis import DiagnosisMountRead, PointingRead
from backend.diagnosis.pointing import pointing
from backend.diagnosis.service import computed_days_cap, diagnosis
from backend.limits import metered

router = APIRouter(prefix="/api/v1/sites", tags=["diagnosis"])

@router.get("/{site_id}/diagnosis", response_model=DiagnosisMountRead,
            **anonymous_read_route({404: {}, 422: {}}))
def get_diagnosis(
    site_id: str,
    ctx: ContextDep,
    start: RangeStart,
    end: RangeEnd,
    caller: CallerDep,
) -> Response:
    """Per local day: sky, measured and expected energy, PR, gains and faults; a day not
    yet over (``status`` ``in_progress``) is judged on its minutes before now, a day to come
    (``future``) costs nothing. ``mount``: the mount faults from the tracker camera's sun
    offsets. Without a token a request computes at most ``ANONYMOUS_MAX_COMPUTED_DAYS``
    (31) days not cached yet (422 naming ``end``), and its CPU time comes out of the
    address's ``HELIOTWIN_ANONYMOUS_READ_CPU_S_PER_MIN``."""
    with metered():
        info, t0, t1 = site_range(ctx, site_id, start, end)
        body = diagnosis(ctx, info, t0, t1, max_computed_days=computed_days_cap(caller))
        return Response(orjson.dumps(body), media_type="application/json")


@router.get("/{site_id}/pointing", response_model=PointingRead,
            **anonymous_read_route({404: {}, 422: {}}))
def get_pointing(
    site_id: str,
    ctx: ContextDep,
    start: RangeStart,
    end: RangeEnd,
) -> Response:
    """The tracker's pointing error every minute the sun is up, from the encoder angles
    its logger reports (``azimuth_deg``, ``elevation_deg``): summary, per day, and the
    minutes (every k-th past ``HELIOTWIN_MAX_JSON_POINTS``, ``points_step`` = k). Without a
    token its CPU time comes out of the address's ``HELIOTWIN_ANONYMOUS_READ_CPU_S_PER_MIN``."""
    with metered():
        info, t0, t1 = site_range(ctx, site_id, start, end)
        with ctx.engine.connect() as conn:
            body = pointing(conn, info, t0, t1, ctx.settings.ingest.max_json_points)
        return Response(orjson.dumps(body), media_type="application/json")
