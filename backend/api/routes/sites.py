"""``/api/v1/sites``: the sites, their configs, their arrays' logger calibration, live status.

``PUT /api/v1/sites/{site_id}`` creates or edits a site from a config of
``docs/site.schema.json`` (``GET /api/v1/sites/schema.json``): it needs that
site's ``site``-scope token, or the admin token (``HELIOTWIN_ADMIN_TOKEN``) — a
new site has no token yet, so only the admin can create one. A field logger's
``ingest`` token writes readings only: it gets a 403 naming its scope here.
"""

from __future__ import annotations

import asyncio
import dataclasses
import time
from typing import Annotated, Any

import anyio
from fastapi import APIRouter, Body, Depends, Header, HTTPException
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field, model_validator

from backend.api.deps import (
    ContextDep,
    SiteAdminDep,
    check_site_admin,
    is_admin_token,
    parse_bearer,
    site_or_404,
)
from backend.api.schemas.sites import (
    CalibrationRead,
    JsonSchemaRead,
    SiteRead,
    SiteStatusRead,
    SiteWrittenRead,
)
from backend.measurements.parse import Calibration
from backend.measurements.status import status
from backend.sites import save_site
from sim.site_config import SiteConfig, site_json_schema, site_zone_warning
from sim.sites import builtin_site_ids, is_builtin, site_path

router = APIRouter(prefix="/api/v1/sites", tags=["sites"])

class CalibrationModel(BaseModel):
    """Logger calibration of one array (seed 000, eqs. 16–19); NaN/Infinity, unknown
    fields and numbers sent as strings or booleans are a 422."""

    model_config = ConfigDict(allow_inf_nan=False, extra="forbid", strict=True)

    adc_bits: int = Field(10, ge=8, le=24, description="ADC resolution [bit]")
    adc_vref_v: float = Field(5.0, gt=0, le=50, description="ADC reference voltage [V]")
    current_zero_v: float = Field(2.5, ge=0, le=50,
                                  description="ACS712 output at 0 A [V] (eq. 16)")
    current_sensitivity_mv_per_a: float = Field(
        100.0, gt=0, le=10_000, description="ACS712 sensitivity [mV/A] (eq. 16)")
    divider_ratio: float = Field(10.0, ge=1, le=10_000,
                                 description="(R1+R2+R3)/Rx of the divider (eq. 19)")

    @model_validator(mode="after")
    def _zero_within_the_reference(self) -> CalibrationModel:
        # the ADC reads 0 … adc_vref_v: a zero-current output above it makes every later
        # reading out of range (accepted before, a tester's finding)
        if self.current_zero_v >= self.adc_vref_v:
            raise ValueError(f"current_zero_v: {self.current_zero_v:g} V is not below "
                             f"adc_vref_v {self.adc_vref_v:g} V, the ADC's full scale")
        return self


def _origin(ctx: Any, site_id: str) -> dict[str, Any]:
    """Where the site's config lives: a built-in file, or the user's folder (which wins)."""
    try:
        path = site_path(site_id, ctx.settings.sites.user_dir)
    except ValueError:
        return {"origin": "unknown", "overrides_builtin": False}
    user = not is_builtin(path)
    return {"origin": "user" if user else "builtin",
            "overrides_builtin": user and site_id in builtin_site_ids()}


def _site_dict(info: Any, ctx: Any = None) -> dict[str, Any]:
    # the stamp convention always shown (the config leaves out its default)
    d = {**info.site.to_dict(), "readings_stamped": info.site.readings_stamped,
         "has_twin": info.has_twin()}
    if ctx is not None:
        d.update(_origin(ctx, info.site_id))
    for name, arr in info.arrays.items():
        if name in d["arrays"]:
            d["arrays"][name]["kind"] = arr.kind
            d["arrays"][name]["calibration"] = dataclasses.asdict(arr.calibration)
    return d


# response_model_exclude_unset: optional keys (a fixed mount's surface, an array's
# placement) stay absent, as the site's to_dict leaves them, instead of null
@router.get("", response_model=list[SiteRead], response_model_exclude_unset=True)
def list_sites(ctx: ContextDep) -> list[dict[str, Any]]:
    """Every site with its arrays (a site whose arrays have no database rows yet is left
    out: it answers 503 by its id)."""
    return [_site_dict(info, ctx) for info in ctx.registry.sites.values() if info.ready()]


@router.get("/schema.json", response_model=JsonSchemaRead)
def get_site_schema() -> dict[str, Any]:
    """The JSON Schema of a site config (``docs/site.schema.json``): every field's unit,
    default and source."""
    return site_json_schema()


@router.get("/{site_id}", response_model=SiteRead, response_model_exclude_unset=True,
            responses={404: {}})
def get_site(site_id: str, ctx: ContextDep) -> dict[str, Any]:
    """One site with its arrays (geometry, modules, logger calibration) and its origin."""
    return _site_dict(site_or_404(ctx, site_id), ctx)


@router.get("/{site_id}/config", response_model=SiteConfig, responses={404: {}})
def get_site_config(site_id: str, ctx: ContextDep) -> JSONResponse:
    """The site as a config of ``docs/site.schema.json`` (what ``PUT`` takes back), as
    written: the model documents it, without filling in defaults."""
    return JSONResponse(site_or_404(ctx, site_id).site.to_config())


async def site_writer(site_id: str, ctx: ContextDep,
                      authorization: Annotated[str | None, Header()] = None) -> str:
    """``"admin"`` for the admin token, else a ``site``-scope token of the site."""
    if ctx.registry.get(site_id) is None and not is_admin_token(
            ctx.settings, token := parse_bearer(authorization)):
        if token is None:
            raise HTTPException(401, "creating a site needs the admin token "
                                     "(HELIOTWIN_ADMIN_TOKEN): send 'Authorization: Bearer "
                                     "<token>'", headers={"WWW-Authenticate": "Bearer"})
        raise HTTPException(403, f"site {site_id!r} does not exist: only the admin token "
                                 "(HELIOTWIN_ADMIN_TOKEN) can create a site")
    return await check_site_admin(ctx, site_id, authorization, f"editing site {site_id!r}")


@router.put("/{site_id}", response_model=SiteWrittenRead,
            responses={201: {"model": SiteWrittenRead, "description": "created"}, 401: {}, 403: {},
                       409: {}, 422: {}})
async def put_site(site_id: str, ctx: ContextDep,
                   config: Annotated[dict[str, Any], Body(description=(
                       "a site config, docs/site.schema.json"))],
                   who: Annotated[str, Depends(site_writer)]) -> JSONResponse:
    """Create or edit a site (a ``site``-scope token, or the admin token for a new site).

    The config is validated (422 names the field), written to ``HELIOTWIN_SITES_DIR``,
    and the twin series cached for the site are dropped, to be simulated again.
    """
    info, created, dropped = await anyio.to_thread.run_sync(save_site, ctx, site_id, config)
    warning = site_zone_warning(info.site.to_config())
    body = {**_site_dict(info, ctx), "created": created, "twin_readings_dropped": dropped,
            "written_by": who, "warnings": [] if warning is None else [warning]}
    return JSONResponse(body, status_code=201 if created else 200)


@router.get("/{site_id}/arrays/{array}/calibration", response_model=CalibrationRead,
            responses={404: {}})
def get_calibration(site_id: str, array: str, ctx: ContextDep) -> CalibrationRead:
    """The calibration used to convert this array's raw ADC readings."""
    info = site_or_404(ctx, site_id)
    if array not in info.arrays:
        raise HTTPException(404, f"unknown array {array!r}; this site has "
                                 f"{', '.join(info.arrays)}")
    return CalibrationRead(**dataclasses.asdict(info.arrays[array].calibration))


@router.put("/{site_id}/arrays/{array}/calibration", response_model=CalibrationRead,
            responses={400: {}, 401: {}, 403: {}, 404: {}})
async def put_calibration(site_id: str, array: str, body: CalibrationModel, ctx: ContextDep,
                          _who: SiteAdminDep) -> CalibrationRead:
    """Store the calibration of an array's logger (a ``site``-scope token or the admin's)."""
    info = site_or_404(ctx, site_id)
    if array not in info.arrays:
        raise HTTPException(404, f"unknown array {array!r}; this site has "
                                 f"{', '.join(info.arrays)}")
    cal = Calibration(**body.model_dump())
    await asyncio.wrap_future(ctx.writer.call(
        lambda conn: ctx.registry.set_calibration(conn, site_id, array, cal)))
    return CalibrationRead(**body.model_dump())


@router.get("/{site_id}/status", response_model=SiteStatusRead, responses={404: {}})
def site_status(site_id: str, ctx: ContextDep) -> dict[str, Any]:
    """The overview tiles: sun and tracker now, last readings, twin power, today's energy."""
    return status(ctx, site_or_404(ctx, site_id), time.time())
