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
import datetime as dt
import io
from typing import Annotated, Any, Literal

import numpy as np
import orjson
from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import Response

from backend.api.deps import ContextDep, site_or_404
from backend.measurements.queries import energy_table, period_edges
from backend.timestamps import parse_range

router = APIRouter(prefix="/api/v1/sites", tags=["energy"])

MAX_PERIODS = 50_000
_SHORTEST_S = {"hour": 3600.0, "day": 82800.0, "month": 28 * 86400.0}  # DST days: 23 h


def _gain(tracker: float | None, fixed: float | None) -> float | None:
    if tracker is None or fixed is None or fixed <= 0:
        return None
    return 100.0 * (tracker / fixed - 1.0)


def energy_rows(ctx: Any, site_id: str, start: dt.datetime, end: dt.datetime,
                interval: str) -> dict[str, Any]:
    """The energy answer for a validated range (also used by the status tiles)."""
    info = site_or_404(ctx, site_id)
    at_least = (end - start).total_seconds() / _SHORTEST_S[interval]
    if at_least > MAX_PERIODS + 2:  # before building millions of period edges
        raise HTTPException(422, f"over {int(at_least)} periods of one {interval}; the limit is "
                                 f"{MAX_PERIODS}: use a longer interval or a shorter range")
    edges = period_edges(start, end, interval, info.zone)
    if len(edges) - 1 > MAX_PERIODS:
        raise HTTPException(422, f"{len(edges) - 1} periods of one {interval}; the limit is "
                                 f"{MAX_PERIODS}: use a longer interval or a shorter range")
    edges_s = np.array([int(e.timestamp()) for e in edges], np.int64)
    ctx.twin.ensure(site_id, int(edges_s[0]), int(edges_s[-1]))
    names = list(info.arrays)
    ids = [info.arrays[n].array_id for n in names]
    with ctx.engine.connect() as conn:
        table = energy_table(conn, ids, edges_s, info.phase_s, ctx.settings.energy_max_gap_s)
    tracker = info.array_of_kind("tracker")
    fixed = info.array_of_kind("fixed")
    rows = []
    totals: dict[str, dict[str, Any]] = {
        n: {"measured_wh": 0.0, "twin_wh": 0.0, "readings": 0} for n in names}
    for p in range(len(edges) - 1):
        arrays: dict[str, dict[str, Any]] = {}
        for n, aid in zip(names, ids, strict=True):
            m_n = int(table.readings[(aid, 0)][p])
            t_n = int(table.readings[(aid, 1)][p])
            m_wh = float(table.energy_wh[(aid, 0)][p])
            t_wh = float(table.energy_wh[(aid, 1)][p])
            arrays[n] = {"measured_wh": m_wh if m_n else None,
                         "twin_wh": t_wh if t_n else None, "readings": m_n}
            totals[n]["measured_wh"] += m_wh
            totals[n]["twin_wh"] += t_wh
            totals[n]["readings"] += m_n
        row: dict[str, Any] = {
            "period_start": edges[p].astimezone(info.zone).isoformat(),
            "period_end": edges[p + 1].astimezone(info.zone).isoformat(),
            "arrays": arrays,
            "gain_pct": None, "twin_gain_pct": None,
        }
        if tracker is not None and fixed is not None:
            tr, fx = arrays[tracker.name], arrays[fixed.name]
            row["gain_pct"] = _gain(tr["measured_wh"], fx["measured_wh"])
            row["twin_gain_pct"] = _gain(tr["twin_wh"], fx["twin_wh"])
        rows.append(row)
    for n in names:
        if not totals[n]["readings"]:
            totals[n]["measured_wh"] = None
    total_gain = None
    if tracker is not None and fixed is not None:
        tr_t, fx_t = totals[tracker.name], totals[fixed.name]
        total_gain = _gain(tr_t["measured_wh"], fx_t["measured_wh"])
    return {
        "site_id": site_id, "interval": interval, "timezone": info.site.timezone,
        "start": start.isoformat(), "end": end.isoformat(),
        "max_gap_s": ctx.settings.energy_max_gap_s,
        "rows": rows, "totals": {"arrays": totals, "gain_pct": total_gain},
    }


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
    data = energy_rows(ctx, site_id, t0, t1, interval)
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
