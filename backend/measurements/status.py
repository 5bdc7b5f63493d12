"""A site's state now: what the overview's tiles show.

The sun and the tracker's joint angles from the twin's current minute
(``TwinService.sample``); at a site the twin cannot simulate (a camera-only
site, no PV arrays) the sun still comes from ``sim.sun.solar_position`` (NREL
SPA through pvlib: the sun needs no array). Each array's last reading and whether its logger is
reporting, the twin's power now, and today's measured and twin energy
(:func:`backend.measurements.energy.energy_rows`).
"""

from __future__ import annotations

import datetime as dt
from typing import TYPE_CHECKING, Any

import pandas as pd
from pvlib import atmosphere

from backend.alerts.rules import CADENCE_READINGS, FRESH_S, SILENT_CADENCES, cadence_s
from backend.alerts.service import silence_counter
from backend.measurements.energy import energy_rows
from backend.measurements.queries import iso_utc
from backend.sites import SiteInfo
from backend.storage.sqlraw import fetch
from sim.sun import solar_position

if TYPE_CHECKING:
    from backend.context import ServiceContext

#: the latest readings of a series, newest first: the last one and the logger's cadence
LATEST = ("SELECT ts_s, voltage_v, current_a, power_w FROM measurements "
          f"WHERE array_id = ? AND source = 0 ORDER BY ts_s DESC LIMIT {CADENCE_READINGS}")


def fresh_for(ts_desc_s: list[float], max_gap_s: int) -> int:
    """How old [s] a logger's last reading may be before it is stale: 2.5 of its own
    cadence (``SILENT_CADENCES``, :func:`cadence_s`), at least ``FRESH_S`` (the alert's
    rules, :mod:`backend.alerts.rules`) and at most the energy rule's
    ``max_gap_s`` (past it the next reading would not be bridged: :mod:`sim.energy`). A
    15-minute logger is not stale between two of its readings; a 1-minute one is after
    five silent minutes."""
    return int(min(max(FRESH_S, SILENT_CADENCES * cadence_s(ts_desc_s)),
                   max(FRESH_S, max_gap_s)))


def status(ctx: ServiceContext, info: SiteInfo, now: float) -> dict[str, Any]:
    """The overview tiles of ``info`` at Unix time ``now`` [s]."""
    site_id = info.site_id
    sample = ctx.twin.sample(site_id, now)
    v = sample.values
    if "solar_azimuth" not in v:  # nothing to simulate here, but the sun is still up there
        s = info.site
        when = pd.DatetimeIndex([pd.Timestamp(sample.ts_s, unit="s", tz="UTC")])
        pos = solar_position(when, s.latitude, s.longitude, s.altitude,  # as sim/twin.py does
                             float(atmosphere.alt2pres(s.altitude)), s.temp_air).iloc[0]
        v = {**v, "solar_azimuth": float(pos["azimuth"]),
             "apparent_elevation": float(pos["apparent_elevation"])}
    counted = silence_counter(ctx.settings, info)
    arrays: dict[str, Any] = {}
    with ctx.engine.connect() as conn:
        for name, arr in info.arrays.items():
            last = fetch(conn, LATEST, (arr.array_id,))
            entry: dict[str, Any] = {"kind": arr.kind, "last_ts": None, "power_w": None,
                                     "voltage_v": None, "current_a": None, "age_s": None,
                                     "logger": "never", "fresh_s": None, "silent_s": None,
                                     "twin_power_w": v.get(f"{name}_power_w")}
            if last:
                ts, volt, amp, pw = last[0]
                age = now - ts
                fresh = fresh_for([r[0] for r in last], ctx.settings.ingest.energy_max_gap_s)
                # the silence the alerts count: at night a sleeping logger is not late
                silent = age if age <= fresh or counted is None else counted(ts, now)
                entry.update(last_ts=iso_utc([int(ts)])[0], power_w=pw, voltage_v=volt,
                             current_a=amp, age_s=round(age, 1), fresh_s=fresh,
                             silent_s=round(silent, 1),
                             logger="reporting" if silent <= fresh else "stale")
            arrays[name] = entry
    local_now = dt.datetime.fromtimestamp(now, info.zone)
    today = local_now.replace(hour=0, minute=0, second=0, microsecond=0)
    tomorrow_d = today.date() + dt.timedelta(days=1)
    tomorrow = dt.datetime(tomorrow_d.year, tomorrow_d.month, tomorrow_d.day, tzinfo=info.zone)
    energy = energy_rows(ctx, info, today, tomorrow, "day")
    row = energy["rows"][0]
    for name in arrays:
        arrays[name]["energy_today_wh"] = row["arrays"][name]["measured_wh"]
        arrays[name]["twin_energy_today_wh"] = row["arrays"][name]["twin_wh"]
    return {
        "site_id": site_id,
        "time": local_now.isoformat(),
        "time_utc": iso_utc([int(now)])[0],
        "timezone": info.site.timezone,
        "sun": {"azimuth_deg": v.get("solar_azimuth"),
                "elevation_deg": v.get("apparent_elevation")},
        "tracker": {"azimuth_joint_deg": v.get("azimuth_joint_deg"),
                    "elevation_joint_deg": v.get("elevation_joint_deg")},
        "twin_minute": iso_utc([sample.ts_s])[0],
        "arrays": arrays,
        "gain_today_pct": row["gain_pct"],
        "twin_gain_today_pct": row["twin_gain_pct"],
        "twin_matched_gain_today_pct": row["twin_matched_gain_pct"],
        "partial_today": row["partial"],
        "fresh_s": FRESH_S,
    }
