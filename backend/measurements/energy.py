"""Energy per local hour, day or month of a site, measured beside the twin.

Periods are the site's local calendar hours/days/months clipped to ``[start, end)``;
energy comes from the hourly rollups (:mod:`backend.measurements.queries`, the
rule of :mod:`backend.measurements.rollups`), the twin's from series stored on
demand (``TwinService.ensure``). ``gain_pct`` is ``100·(tracker/fixed − 1)`` from
measured energy, null when either is missing; ``twin_gain_pct`` the same from the twin.
"""

from __future__ import annotations

import datetime as dt
from typing import TYPE_CHECKING, Any

import numpy as np

from backend.errors import InputError
from backend.measurements.queries import energy_table, period_edges
from backend.sites import SiteInfo

if TYPE_CHECKING:
    from backend.context import ServiceContext

MAX_PERIODS = 50_000
_SHORTEST_S = {"hour": 3600.0, "day": 82800.0, "month": 28 * 86400.0}  # DST days: 23 h


def _gain(tracker: float | None, fixed: float | None) -> float | None:
    if tracker is None or fixed is None or fixed <= 0:
        return None
    return 100.0 * (tracker / fixed - 1.0)


def energy_rows(ctx: ServiceContext, info: SiteInfo, start: dt.datetime, end: dt.datetime,
                interval: str) -> dict[str, Any]:
    """The energy answer for a validated range (the energy endpoint and the status tiles)."""
    site_id = info.site_id
    at_least = (end - start).total_seconds() / _SHORTEST_S[interval]
    if at_least > MAX_PERIODS + 2:  # before building millions of period edges
        raise InputError(422, f"over {int(at_least)} periods of one {interval}; the limit is "
                                 f"{MAX_PERIODS}: use a longer interval or a shorter range")
    edges = period_edges(start, end, interval, info.zone)
    if len(edges) - 1 > MAX_PERIODS:
        raise InputError(422, f"{len(edges) - 1} periods of one {interval}; the limit is "
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
