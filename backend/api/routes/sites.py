"""``/api/v1/sites``: the sites, their arrays' logger calibration, and live status."""

from __future__ import annotations

import asyncio
import dataclasses
import datetime as dt
import time
from typing import Any

from fastapi import APIRouter, HTTPException
from pydantic import BaseModel, ConfigDict, Field

from backend.api.deps import ContextDep, SiteTokenDep, site_or_404
from backend.api.routes.energy import energy_rows
from backend.measurements.parse import Calibration
from backend.measurements.queries import iso_utc
from backend.storage.sqlraw import fetch

router = APIRouter(prefix="/api/v1/sites", tags=["sites"])

#: A logger whose last reading is older than this is "stale" [s].
FRESH_S = 300

_LAST = ("SELECT ts_s, voltage_v, current_a, power_w FROM measurements "
         "WHERE array_id = ? AND source = 0 ORDER BY ts_s DESC LIMIT 1")


class CalibrationModel(BaseModel):
    """Logger calibration of one array (seed 000, eqs. 16–19); NaN/Infinity are a 422."""

    model_config = ConfigDict(allow_inf_nan=False)

    adc_bits: int = Field(10, ge=8, le=24, description="ADC resolution [bit]")
    adc_vref_v: float = Field(5.0, gt=0, le=50, description="ADC reference voltage [V]")
    current_zero_v: float = Field(2.5, ge=0, le=50,
                                  description="ACS712 output at 0 A [V] (eq. 16)")
    current_sensitivity_mv_per_a: float = Field(
        100.0, gt=0, le=10_000, description="ACS712 sensitivity [mV/A] (eq. 16)")
    divider_ratio: float = Field(10.0, ge=1, le=10_000,
                                 description="(R1+R2+R3)/Rx of the divider (eq. 19)")


def _site_dict(info: Any) -> dict[str, Any]:
    d = info.site.to_dict()
    for name, arr in info.arrays.items():
        if name in d["arrays"]:
            d["arrays"][name]["kind"] = arr.kind
            d["arrays"][name]["calibration"] = dataclasses.asdict(arr.calibration)
    return d


@router.get("")
def list_sites(ctx: ContextDep) -> list[dict[str, Any]]:
    """Every site with its arrays."""
    return [_site_dict(info) for info in ctx.registry.sites.values()]


@router.get("/{site_id}", responses={404: {}})
def get_site(site_id: str, ctx: ContextDep) -> dict[str, Any]:
    """One site with its arrays (geometry, modules, logger calibration)."""
    return _site_dict(site_or_404(ctx, site_id))


@router.get("/{site_id}/arrays/{array}/calibration", responses={404: {}})
def get_calibration(site_id: str, array: str, ctx: ContextDep) -> CalibrationModel:
    """The calibration used to convert this array's raw ADC readings."""
    info = site_or_404(ctx, site_id)
    if array not in info.arrays:
        raise HTTPException(404, f"unknown array {array!r}; this site has "
                                 f"{', '.join(info.arrays)}")
    return CalibrationModel(**dataclasses.asdict(info.arrays[array].calibration))


@router.put("/{site_id}/arrays/{array}/calibration", responses={400: {}, 401: {}, 403: {},
                                                                      404: {}})
async def put_calibration(site_id: str, array: str, body: CalibrationModel, ctx: ContextDep,
                          _token_site: SiteTokenDep) -> CalibrationModel:
    """Store the calibration of an array's logger (needs the site's write token)."""
    info = site_or_404(ctx, site_id)
    if array not in info.arrays:
        raise HTTPException(404, f"unknown array {array!r}; this site has "
                                 f"{', '.join(info.arrays)}")
    cal = Calibration(**body.model_dump())
    await asyncio.wrap_future(ctx.writer.call(
        lambda conn: ctx.registry.set_calibration(conn, site_id, array, cal)))
    return body


@router.get("/{site_id}/status", responses={404: {}})
def site_status(site_id: str, ctx: ContextDep) -> dict[str, Any]:
    """The overview tiles: sun and tracker now, last readings, twin power, today's energy."""
    info = site_or_404(ctx, site_id)
    now = time.time()
    sample = ctx.twin.sample(site_id, now)
    v = sample.values
    arrays: dict[str, Any] = {}
    with ctx.engine.connect() as conn:
        for name, arr in info.arrays.items():
            last = fetch(conn, _LAST, (arr.array_id,))
            entry: dict[str, Any] = {"kind": arr.kind, "last_ts": None, "power_w": None,
                                     "voltage_v": None, "current_a": None, "age_s": None,
                                     "logger": "never",
                                     "twin_power_w": v.get(f"{name}_power_w")}
            if last:
                ts, volt, amp, pw = last[0]
                age = now - ts
                entry.update(last_ts=iso_utc([int(ts)])[0], power_w=pw, voltage_v=volt,
                             current_a=amp, age_s=round(age, 1),
                             logger="reporting" if age <= FRESH_S else "stale")
            arrays[name] = entry
    local_now = dt.datetime.fromtimestamp(now, info.zone)
    today = local_now.replace(hour=0, minute=0, second=0, microsecond=0)
    tomorrow_d = today.date() + dt.timedelta(days=1)
    tomorrow = dt.datetime(tomorrow_d.year, tomorrow_d.month, tomorrow_d.day, tzinfo=info.zone)
    energy = energy_rows(ctx, site_id, today, tomorrow, "day")
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
        "fresh_s": FRESH_S,
    }
