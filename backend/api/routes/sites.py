"""``/api/v1/sites``: the sites, their arrays' logger calibration, and live status."""

from __future__ import annotations

import asyncio
import dataclasses
import time
from typing import Any

from fastapi import APIRouter, HTTPException
from pydantic import BaseModel, ConfigDict, Field

from backend.api.deps import ContextDep, SiteTokenDep, site_or_404
from backend.measurements.parse import Calibration
from backend.measurements.status import status

router = APIRouter(prefix="/api/v1/sites", tags=["sites"])



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
    return status(ctx, site_or_404(ctx, site_id), time.time())
