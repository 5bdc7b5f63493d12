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
from fastapi import APIRouter, Depends, HTTPException, Query, Request
from fastapi.responses import Response

from backend.api.schemas.common import PNG_CONTENT
from backend.api.schemas.plants import (
    PlantDayRead,
    PlantRead,
    PlantSummaryRead,
    PositionsRead,
    SkyMapRead,
)
from backend.plants import STRATEGIES, PlantService, UnknownPlantError, sky_map_png
from backend.timestamps import FIRST_YEAR, LAST_YEAR, TimestampError, parse_instant

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
