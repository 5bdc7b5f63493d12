"""``/api/v1/plants``: plants of dual-axis trackers and their position server (seed 004).

A plant controller polls ``/positions`` every minute; ``/sky-map`` is seed 004's
Fig. 6 (Lambert equal-area hemisphere of plane-of-array irradiance with the
shading region), JSON or PNG (``Accept: image/png``); ``/day`` feeds the
dashboard's Plant page.
"""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Any

import anyio
import orjson
import pandas as pd
from fastapi import APIRouter, Depends, HTTPException, Query, Request
from fastapi.responses import Response

from backend.api.deps import ContextDep, bearer_token, token_site
from backend.api.schemas.common import PNG_CONTENT
from backend.api.schemas.plants import (
    PlantDayRead,
    PlantRead,
    PlantSummaryRead,
    PositionsRead,
    SkyMapRead,
    SweepAcceptedRead,
    SweepCreate,
    SweepRunRead,
    SweepShadeRead,
)
from backend.limits import Busy
from backend.plants import STRATEGIES, PlantService, UnknownPlantError, sky_map_png
from backend.plants.sweep import SweepInputError, parse_size, prepare_sweep
from backend.plants.sweep_runner import SweepRunner, SweepState
from backend.timestamps import (
    FIRST_YEAR,
    LAST_YEAR,
    TimestampError,
    parse_day_or_instant,
    parse_instant,
)
from sim.plant.sweep import PLANT_LAYOUT, SweepCase, case_day_shade

router = APIRouter(prefix="/api/v1/plants", tags=["plants"])


def get_plant_service(request: Request) -> PlantService:
    """The app's :class:`PlantService`, made on first use (``Settings.sites.plants_dir`` if set)."""
    service = getattr(request.app.state, "plants", None)
    if service is None:
        settings = getattr(request.app.state, "settings", None)
        service = PlantService(None if settings is None else settings.sites.plants_dir)
        request.app.state.plants = service
    return service  # type: ignore[no-any-return]


PlantServiceDep = Annotated[PlantService, Depends(get_plant_service)]


def _time(text: str, field: str = "time") -> dt.datetime:
    """An instant by the service's one rule set (:mod:`backend.timestamps`); 422 otherwise."""
    try:
        return parse_instant(text, field)
    except TimestampError as exc:
        raise HTTPException(422, str(exc)) from None


def _plant_or_404(service: PlantService, plant_id: str) -> None:
    try:
        service.get(plant_id)
    except UnknownPlantError as exc:
        raise HTTPException(404, str(exc)) from None
    except ValueError as exc:
        raise HTTPException(500, f"plant {plant_id!r} has a bad config: {exc}") from None


def _strategy(strategy: str) -> str:
    if strategy not in STRATEGIES:
        raise HTTPException(422, f"strategy: must be one of {', '.join(STRATEGIES)}, "
                                 f"got {strategy!r}")
    return strategy


def get_sweep_runner(request: Request) -> SweepRunner:
    """The app's :class:`SweepRunner`, made on first use from ``Settings.plants``."""
    runner = getattr(request.app.state, "sweeps", None)
    if runner is None:
        settings = request.app.state.ctx.settings.plants
        runner = SweepRunner(settings.dask_scheduler, settings.sweep_queue)
        request.app.state.sweeps = runner
    return runner  # type: ignore[no-any-return]


SweepRunnerDep = Annotated[SweepRunner, Depends(get_sweep_runner)]


def _sweep_inputs(body: SweepCreate, service: PlantService) -> tuple[Any, list[Any]]:
    """The checked spec and cases of a sweep request; 404/422 naming the field."""
    plant = None
    if body.plant_id is not None:
        _plant_or_404(service, body.plant_id)
        plant = service.get(body.plant_id)
    zone = plant.timezone if plant is not None else "UTC"
    try:
        start = pd.Timestamp(parse_day_or_instant(body.start, zone, "start"))
        end = pd.Timestamp(parse_day_or_instant(body.end, zone, "end"))
        rows, columns = (int(v) for v in body.field_size.split("x"))
        custom = (None if body.aspect_ratio is None or body.offset is None
                  or body.rotation_deg is None
                  else (body.aspect_ratio, body.offset, body.rotation_deg))
        return prepare_sweep(
            layouts=body.layouts, gcr=body.gcr, strategies=body.strategies, start=start,
            end=end, step_s=body.step_s, latitude_deg=body.latitude_deg,
            longitude_deg=body.longitude_deg, altitude_m=body.altitude_m,
            collector_m=None if body.collector_m is None
            else parse_size(body.collector_m, "collector_m"),
            plant=plant, field_size=(rows, columns), custom=custom,
            slope_azimuth_deg=body.slope_azimuth_deg, slope_tilt_deg=body.slope_tilt_deg)
    except TimestampError as exc:
        raise HTTPException(422, str(exc)) from None
    except SweepInputError as exc:
        field = {"lat": "latitude_deg", "lon": "longitude_deg", "field": "field_size",
                 "strategy": "strategies"}.get(exc.field, exc.field)
        raise HTTPException(422, f"{field}: {exc.problem}") from None


@router.post("/sweeps", status_code=202, response_model=SweepAcceptedRead,
             responses={401: {}, 404: {}, 422: {}, 429: {}, 503: {}},
             openapi_extra={"security": [{}, {"bearerAuth": []}]})
async def create_sweep(body: SweepCreate, request: Request, ctx: ContextDep,
                       service: PlantServiceDep, runner: SweepRunnerDep) -> Response:
    """Queue a plant-design sweep (layouts × GCRs × strategies, each case a Dask task);
    202 with the ``sweep_id`` to poll. Without a write token a sweep may hold at most
    ``HELIOTWIN_PLANTS_ANONYMOUS_SWEEP_CASE_STEPS`` cases × steps (422 beyond), spent from
    the address's anonymous simulation allowance (429 when spent); one sweep runs at a time
    (503 past the queue)."""
    spec, cases = await anyio.to_thread.run_sync(_sweep_inputs, body, service)
    case_steps = len(cases) * (spec.end - spec.start).total_seconds() / spec.step_s
    token = bearer_token(request)
    host = request.client.host if request.client else "?"
    if token is not None and await token_site(request, token) is None:
        raise HTTPException(401, "unknown, expired or revoked write token",
                            headers={"WWW-Authenticate": "Bearer"})
    try:
        if token is None:
            bound = ctx.settings.plants.anonymous_sweep_case_steps
            if case_steps > bound:
                raise HTTPException(422, f"step_s: {len(cases)} cases × "
                                         f"{case_steps / len(cases):.0f} steps is more than "
                                         f"{bound:,} without a write token: use a larger "
                                         "step_s, a shorter range or fewer cases")
            ctx.limits.simulation_steps.take(host, case_steps)
    except Busy as exc:
        raise HTTPException(exc.status_code, exc.message, headers=exc.headers) from None
    try:
        state = runner.submit(spec, cases, body.model_dump())
    except Busy as exc:  # the queue is full: nothing runs, the allowance is given back
        if token is None:
            ctx.limits.simulation_steps.refund(host, case_steps)
        raise HTTPException(exc.status_code, exc.message, headers=exc.headers) from None
    state.spec = spec
    return Response(orjson.dumps({"sweep_id": state.sweep_id, "status": state.status,
                                  "progress": 0.0, "cases": state.total}),
                    status_code=202, media_type="application/json",
                    headers={"Location": f"/api/v1/plants/sweeps/{state.sweep_id}"})


def _sweep_or_404(runner: SweepRunner, sweep_id: str) -> SweepState:
    state = runner.get(sweep_id)
    if state is None:
        raise HTTPException(404, f"unknown sweep {sweep_id!r}")
    return state


@router.get("/sweeps/{sweep_id}", response_model=SweepRunRead, responses={404: {}})
def get_sweep(sweep_id: str, runner: SweepRunnerDep) -> dict[str, Any]:
    """A sweep's status, progress (cases done over cases) and, when done, its rows."""
    return _sweep_or_404(runner, sweep_id).to_dict()


@router.delete("/sweeps/{sweep_id}", response_model=SweepRunRead, responses={404: {}})
def cancel_sweep(sweep_id: str, runner: SweepRunnerDep) -> dict[str, Any]:
    """Cancel a queued or running sweep (a running one stops after its current cases)."""
    _sweep_or_404(runner, sweep_id)
    state = runner.cancel(sweep_id)
    assert state is not None
    return state.to_dict()


@router.get("/sweeps/{sweep_id}/shade", response_model=SweepShadeRead,
            responses={404: {}, 422: {}})
async def sweep_shade(sweep_id: str, runner: SweepRunnerDep,
                      layout: Annotated[str, Query(max_length=100)],
                      gcr: Annotated[float, Query(gt=0, lt=1)],
                      strategy: Annotated[str, Query()] = "sun",
                      date: Annotated[str, Query(pattern=r"^\d{4}-\d{2}-\d{2}$")] = "2021-12-21",
                      step_s: Annotated[float, Query(ge=300, le=3600)] = 900) -> dict[str, Any]:
    """One case of a sweep through a clear-sky day: every collector's shaded fraction."""
    state = _sweep_or_404(runner, sweep_id)
    spec = getattr(state, "spec", None)
    if spec is None:
        raise HTTPException(404, f"sweep {sweep_id!r} has no field to show")
    try:
        dt.date.fromisoformat(date)
    except ValueError:
        raise HTTPException(422, f"date: {date!r} is not a calendar date") from None
    name = layout if spec.plant is None else PLANT_LAYOUT
    case = SweepCase(name, gcr, _strategy(strategy))
    try:
        return await anyio.to_thread.run_sync(case_day_shade, spec, case, date, step_s)
    except ValueError as exc:
        raise HTTPException(422, f"layout/gcr: {exc}") from None


@router.get("", response_model=list[PlantSummaryRead])
def list_plants(service: PlantServiceDep) -> list[dict[str, Any]]:
    """Every plant (id, name, number of trackers, place)."""
    return service.list()


@router.get("/{plant_id}", response_model=PlantRead, responses={404: {}})
def get_plant(plant_id: str, service: PlantServiceDep) -> dict[str, Any]:
    """One plant: place, collector and electrical layout, trackers in ENU metres."""
    _plant_or_404(service, plant_id)
    return service.get(plant_id).to_dict()


@router.get("/{plant_id}/positions", response_model=PositionsRead, responses={404: {}, 422: {}})
def positions(plant_id: str, service: PlantServiceDep,
              time: Annotated[str, Query(description="ISO 8601 with offset")],
              strategy: Annotated[str, Query(description="sun | backtrack | sky_scan")] = "sun",
              ) -> dict[str, Any]:
    """Every tracker's orientation under a strategy, its shaded fraction and who shades it."""
    when = _time(time)
    _plant_or_404(service, plant_id)
    return service.positions(plant_id, when, _strategy(strategy))


@router.get("/{plant_id}/sky-map", response_model=SkyMapRead,
            responses={404: {}, 422: {}, 200: {"content": PNG_CONTENT}})
async def sky_map(plant_id: str, request: Request, service: PlantServiceDep,
                  time: Annotated[str, Query(description="ISO 8601 with offset")],
                  resolution_deg: Annotated[float, Query(ge=1.0, le=15.0)] = 3.0,
                  strategy: Annotated[str, Query()] = "sky_scan",
                  format: Annotated[str | None, Query(pattern="^(json|png)$")] = None,
                  ) -> Any:
    """Seed 004 Fig. 6: POA over the hemisphere of orientations (clear sky, Perez), grey where
    an orientation would shade a collector; ``Accept: image/png`` (or ``format=png``) for PNG."""
    when = _time(time)
    _plant_or_404(service, plant_id)
    m = await anyio.to_thread.run_sync(
        lambda: service.sky_map(plant_id, when, resolution_deg, _strategy(strategy)))
    want_png = format == "png" or (format is None and
                                   "image/png" in request.headers.get("accept", ""))
    if want_png:
        return Response(await anyio.to_thread.run_sync(sky_map_png, m), media_type="image/png")
    return m


@router.get("/{plant_id}/day", response_model=PlantDayRead, response_model_exclude_unset=True,
            responses={404: {}, 422: {}})
async def day(plant_id: str, service: PlantServiceDep,
              date: Annotated[str, Query(pattern=r"^\d{4}-\d{2}-\d{2}$",
                                         description="local date, YYYY-MM-DD "
                                                     f"({FIRST_YEAR}–{LAST_YEAR})")],
              step_s: Annotated[float, Query(ge=300, le=3600)] = 900) -> dict[str, Any]:
    """A clear-sky day (local date): each tracker's shade under sun tracking, and the plant
    energy of every strategy and of the fixed plant."""
    try:
        day_ = dt.date.fromisoformat(date)
    except ValueError:
        raise HTTPException(422, f"date: {date!r} is not a calendar date") from None
    if not FIRST_YEAR <= day_.year <= LAST_YEAR:
        raise HTTPException(422, f"date: {date!r} is outside the years {FIRST_YEAR}–{LAST_YEAR}")
    _plant_or_404(service, plant_id)
    return await anyio.to_thread.run_sync(lambda: service.day(plant_id, day_, step_s))
