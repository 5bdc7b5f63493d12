"""``/api/v1/sites/{site_id}/energy``: energy per hour, day or month, measured beside the twin.

Periods are local calendar hours/days/months of the site, clipped to
``[start, end)``. ``measured_wh`` is null for a period without readings;
``twin_wh`` comes from the twin series, computed and stored on demand for past
days (``TwinService.ensure``). ``gain_pct`` is the tracking gain
``100·(tracker/fixed − 1)`` from measured energy, null when either is missing;
``twin_gain_pct`` the same from the twin. Energy does not bridge gaps longer
than ``HELIOTWIN_ENERGY_MAX_GAP_S`` (see ``docs/service.md``).
"""

from __future__ import annotations

import csv
import io
from typing import Annotated, Literal

import orjson
from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import Response

from backend.api.deps import ContextDep, site_or_404
from backend.measurements.energy import energy_rows
from backend.timestamps import parse_range

router = APIRouter(prefix="/api/v1/sites", tags=["energy"])

@router.get("/{site_id}/energy", responses={404: {}, 422: {}})
def get_energy(
    site_id: str,
    ctx: ContextDep,
    start: Annotated[str, Query(description="date (site midnight) or ISO date-time, inclusive")],
    end: Annotated[str, Query(description="date or ISO date-time, exclusive")],
    interval: Literal["hour", "day", "month"] = "day",
    format: Literal["json", "csv"] = "json",
) -> Response:
    """Energy per period for every array, measured and twin, with the tracking gain."""
    info = site_or_404(ctx, site_id)
    try:
        t0, t1 = parse_range(start, end, info.zone)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    data = energy_rows(ctx, info, t0, t1, interval)
    if format == "csv":
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        names = list(info.arrays)
        w.writerow(["period_start", "period_end",
                    *[f"{n}_{k}" for n in names for k in ("measured_wh", "twin_wh")],
                    "gain_pct", "twin_gain_pct"])
        for r in data["rows"]:
            w.writerow([r["period_start"], r["period_end"],
                        *[r["arrays"][n][k] for n in names for k in ("measured_wh", "twin_wh")],
                        r["gain_pct"], r["twin_gain_pct"]])
        return Response(buf.getvalue(), media_type="text/csv", headers={
            "Content-Disposition": f'attachment; filename="{site_id}_energy_{interval}.csv"'})
    return Response(orjson.dumps(data), media_type="application/json")
