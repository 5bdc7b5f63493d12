"""The tracker's pointing error measured from its own encoder angles (issue 13, item 4).

A logger that reports the tracker's joint angles (``azimuth_deg``, ``elevation_deg``
of the collector's normal, ``backend/measurements/fields.py``) shows its pointing
directly, without going through power: every minute the sun is up, the error is
the angle between the collector's normal and the sun — the angle of incidence of
the beam on a dual-axis collector, so a cos-loss of ``1 − cos(error)`` — computed
with ``pvlib.irradiance.aoi`` (tilt = 90° − elevation), and split into an azimuth
error (wrapped to ±180°) and an elevation error (measured − sun). The sun is the
SPA apparent position of :func:`sim.sun.solar_position`, as in the twin.

What this measures is the controller and the mechanism as the encoders see them (a
controller clock 30 min ahead shows as a 45° azimuth error at its 95th percentile).
Errors of the frame the encoders sit in are invisible here: a pedestal yaw or tilt, or
an encoder with a wrong zero, leave the joint angles equal to the sun's. The power-based
diagnosis (:mod:`backend.diagnosis.faults`) cannot see them either below about 25°
(docs/diagnosis.md, "Why the azimuth offset is not met").
"""

from __future__ import annotations

import datetime as dt
from typing import Any

import numpy as np
import pandas as pd
from pvlib import atmosphere
from sqlalchemy import Connection

from backend.measurements.fields import SENSOR_NAMES
from backend.measurements.queries import iso_utc, raw_rows
from backend.sites import SiteInfo
from sim.sky import angle_of_incidence
from sim.sun import solar_position

_AZ = 4 + SENSOR_NAMES.index("azimuth_deg")
_EL = 4 + SENSOR_NAMES.index("elevation_deg")


def _stats(err: np.ndarray) -> dict[str, float] | None:
    if err.size == 0:
        return None
    return {"rms_deg": float(np.sqrt(np.mean(err**2))), "median_deg": float(np.median(err)),
            "p95_deg": float(np.percentile(err, 95)), "max_deg": float(err.max())}


def pointing(conn: Connection, info: SiteInfo, t0: dt.datetime, t1: dt.datetime,
             max_points: int) -> dict[str, Any]:
    """Pointing error of the site's tracker over ``[t0, t1)`` from its encoder readings.

    Minutes with both angles and the sun above the horizon count. ``points`` holds
    every such minute, or every k-th (``points_step``) when there are more than
    ``max_points``; ``summary`` and ``days`` are over all of them.
    """
    tracker = info.array_of_kind("tracker")
    out: dict[str, Any] = {"site_id": info.site_id, "array": None, "start": t0.isoformat(),
                           "end": t1.isoformat(), "minutes": 0, "summary": None, "days": [],
                           "points": [], "points_step": 1}
    if tracker is None:
        return out
    out["array"] = tracker.name
    rows = raw_rows(conn, tracker.array_id, 0, int(t0.timestamp()), int(t1.timestamp()),
                    sensors=True)
    rows = rows[~np.isnan(rows[:, _AZ]) & ~np.isnan(rows[:, _EL])]
    if rows.size == 0:
        return out
    s = info.site
    when = pd.DatetimeIndex(pd.to_datetime(rows[:, 0], unit="s", utc=True))
    sun = solar_position(when, s.latitude, s.longitude, s.altitude,
                         float(atmosphere.alt2pres(s.altitude)), s.temp_air)
    sun_el = sun["apparent_elevation"].to_numpy()
    up = sun_el > 0.0
    rows, sun_el, sun_az = rows[up], sun_el[up], sun["azimuth"].to_numpy()[up]
    if rows.size == 0:
        return out
    az, el = rows[:, _AZ], rows[:, _EL]
    err = angle_of_incidence(90.0 - el, az, 90.0 - sun_el, sun_az)
    d_az = (az - sun_az + 180.0) % 360.0 - 180.0
    d_el = el - sun_el
    summary = _stats(err)
    assert summary is not None
    summary.update(mean_azimuth_error_deg=float(d_az.mean()),
                   mean_elevation_error_deg=float(d_el.mean()),
                   mean_cos_loss_pct=float(100.0 * np.mean(1.0 - np.cos(np.radians(err)))))
    out.update(minutes=int(err.size), summary=summary)
    local = when[up].tz_convert(info.zone)
    dates = np.asarray(local.strftime("%Y-%m-%d"))
    for date in np.unique(dates):
        sel = dates == date
        day = _stats(err[sel])
        assert day is not None
        out["days"].append({"date": str(date), "minutes": int(sel.sum()), **day})
    step = max(1, int(np.ceil(err.size / max(1, max_points))))
    k = slice(None, None, step)
    ts = iso_utc(rows[k, 0].astype(np.int64))
    cols = (ts, az[k].tolist(), el[k].tolist(), sun_az[k].tolist(), sun_el[k].tolist(),
            err[k].tolist(), d_az[k].tolist(), d_el[k].tolist())
    names = ("ts", "azimuth_deg", "elevation_deg", "sun_azimuth_deg", "sun_elevation_deg",
             "error_deg", "azimuth_error_deg", "elevation_error_deg")
    out["points"] = [dict(zip(names, vals, strict=True)) for vals in zip(*cols, strict=True)]
    out["points_step"] = step
    return out
