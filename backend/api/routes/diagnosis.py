"""``/api/v1/sites/{site_id}/diagnosis``: per day, the tracker against the weather-aware twin
and the faults found (``backend/diagnosis``, ``docs/diagnosis.md``)."""

from __future__ import annotations

import orjson
from fastapi import APIRouter, HTTPException
from fastapi.responses import Response

from backend.api.deps import ContextDep, RangeEnd, RangeStart, site_or_404
from backend.diagnosis.service import diagnosis
from backend.timestamps import parse_range

router = APIRouter(prefix="/api/v1/sites", tags=["diagnosis"])


@router.get("/{site_id}/diagnosis", responses={404: {}, 422: {}})
def get_diagnosis(
    site_id: str,
    ctx: ContextDep,
    start: RangeStart,
    end: RangeEnd,
) -> Response:
    """Per local day: sky, measured and expected energy, PR, gains and faults."""
    info = site_or_404(ctx, site_id)
    try:
        t0, t1 = parse_range(start, end, info.zone)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    return Response(orjson.dumps(diagnosis(ctx, info, t0, t1)), media_type="application/json")
