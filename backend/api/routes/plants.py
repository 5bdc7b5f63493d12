"""``/api/v1/plants``: plants of dual-axis trackers and their position server (seed 004).

A plant controller polls ``/positions`` every minute; ``/sky-map`` is seed 004's
Fig. 6 (Lambert equal-area hemisphere of plane-of-array irradiance with the
shading region), JSON or PNG (``Accept: image/png``); ``/day`` feeds the
dashboard's Plant page.

The computations on request (a day, a sky map, a sweep's shaded day) are priced in CPU
seconds before they run (:func:`backend.plants.day_cost_s`, :func:`sky_map_cost_s`): a
caller without a token pays the price from the hourly allowance the simulations use
(``HELIOTWIN_SIMULATION_ANONYMOUS_HOUR_MAX_S``, trued up to the CPU time taken; 429
with ``Retry-After`` when spent) and may not ask for more than one run's worth
(``HELIOTWIN_SIMULATION_ANONYMOUS_RUN_MAX_S``, 422). Whoever asks, they run one at a
time (``Limits.plants``: their memory peaks do not add up; 503 past its queue). A day
already computed is answered from the bounded day cache for free.
"""

from __future__ import annotations

import datetime as dt
import time
from collections.abc import Callable
from typing import Annotated, Any, TypeVar, cast

import anyio
import orjson
import pandas as pd
from fastapi import APIRouter, Depends, HTTPException, Query, Request
from fastapi.responses import Response

from backend.api.deps import CallerDep, ContextDep
from backend.api.forms import form_flag, form_model, form_text, read_form
from backend.api.routes.simulations import check_steps
from backend.api.routes.weather import WEATHER_FORM_FIELDS, read_weather_upload
from backend.api.schemas.common import PNG_CONTENT
from backend.api.schemas.plants import (
    PlantDayRead,
    PlantRead,
    PlantSkippedRead,
    PlantSummaryRead,
    PlantWeatherCreate,
    PlantWeatherRunRead,
    PositionsRead,
    SkyMapRead,
    SweepAcceptedRead,
    SweepCreate,
    SweepRunRead,
    SweepShadeRead,
)
from backend.limits import Busy, amount
from backend.plants import (
    STRATEGIES,
    PlantService,
    UnknownPlantError,
    cost_factor,
    day_cost_s,
    positions_cost_s,
    simulate_summary,
    sky_map_cost_s,
    sky_map_png,
)
from backend.plants.sweep import (
    MAX_CASE_STEPS,
    SweepInputError,
    case_steps,
    parse_gcr,
    parse_size,
    prepare_sweep,
    sweep_params,
    sweep_zone,
)
from backend.plants.sweep_runner import SweepRunner, SweepState
from backend.timestamps import (
    FIRST_YEAR,
    LAST_YEAR,
    TimestampError,
    parse_day_or_instant,
    parse_instant,
)
from backend.twin.scenario import StationTooFar, place_weather
from sim.energy import check_step
from sim.plant.layout import Plant
from sim.plant.strategies import check_strategy_collector, strategies_for
from sim.plant.sweep import SweepCase, case_day_shade, shade_day

router = APIRouter(prefix="/api/v1/plants", tags=["plants"])
T = TypeVar("T")
#: The answers of a priced computation (``_priced``), for the OpenAPI document.
_PRICED_DOC: dict[int | str, dict[str, Any]] = {
    401: {"description": "a token was sent but is unknown, expired or revoked"},
    404: {}, 422: {},
    429: {"description": "the caller's anonymous hourly allowance is spent (Retry-After)"},
    503: {"description": "too many plant computations are waiting (Retry-After)"}}
#: A token is optional on these routes (without one the work is priced).
_OPTIONAL_TOKEN: dict[str, Any] = {"security": [{}, {"bearerAuth": []}]}


async def get_plant_service(request: Request) -> PlantService:
    """The app's :class:`PlantService`, made on first use (``Settings.sites.plants_dir`` if set;
    on the event loop, so two first requests cannot make two)."""
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
    """404 for a plant the service does not serve: no such file, or a file it cannot load —
    left out of ``GET /plants`` as well (a tester's finding: that was a 500, and the 404's
    list of known plants named it)."""
    try:
        service.get(plant_id)
    except UnknownPlantError:
        known = ", ".join(p["plant_id"] for p in service.list()) or "none"
        raise HTTPException(404, f"plant_id: no plant {plant_id[:60]!r}; known plants: "
                                 f"{known}") from None
    except ValueError as exc:
        raise HTTPException(404, f"plant_id: plant {plant_id[:60]!r} is not served, its file is "
                                 f"invalid ({exc}); known plants are GET /api/v1/plants") from None


def _strategy(strategy: str, plant: Plant | None = None) -> str:
    """A known strategy, that ``plant``'s collector takes (a polygon: ``sun`` only); 422."""
    if strategy not in STRATEGIES:
        raise HTTPException(422, f"strategy: must be one of {', '.join(STRATEGIES)}, "
                                 f"got {strategy!r}")
    if plant is not None:
        try:
            check_strategy_collector(strategy, plant)
        except ValueError as exc:
            raise HTTPException(422, f"strategy: {exc}") from None
    return strategy


async def get_sweep_runner(request: Request) -> SweepRunner:
    """The app's :class:`SweepRunner`, made on first use from ``Settings.plants`` (on the
    event loop: one runner; the app's lifespan closes it on shutdown)."""
    runner = getattr(request.app.state, "sweeps", None)
    if runner is None:
        settings = request.app.state.ctx.settings.plants
        runner = SweepRunner(settings.dask_scheduler, settings.sweep_queue)
        request.app.state.sweeps = runner
    return runner  # type: ignore[no-any-return]


SweepRunnerDep = Annotated[SweepRunner, Depends(get_sweep_runner)]


def _client(request: Request) -> str:
    """The anonymous allowance's key: the caller's address (as the simulations use)."""
    return f"addr:{request.client.host if request.client else '?'}"


async def _priced(request: Request, ctx: Any, caller: Any, cost_s: float,
                  work: Callable[[], T], one_at_a_time: bool = True,
                  fields: str = "step_s, resolution_deg") -> T:
    """Run a plant computation expected to take ``cost_s`` of CPU on a worker thread, one
    at a time (``Limits.plants``, 503 past its queue; not for the few milliseconds of an
    instant's positions, which a plant controller must not wait behind a day for).
    Without a token: 422 above one run's worth, the price taken from the hourly allowance
    (429) and trued up to the CPU time the work took (nothing when it never ran); the 422
    names ``fields``, what makes the work larger."""
    charge = None
    if caller is None:
        s = ctx.settings.simulations
        if cost_s > s.anonymous_run_max_s:
            raise HTTPException(422, f"{fields}: this computation is expected "
                                     f"to take {amount(cost_s)} s of CPU; without a write token "
                                     f"at most {s.anonymous_run_max_s:g} s "
                                     "(HELIOTWIN_SIMULATION_ANONYMOUS_RUN_MAX_S)")
        try:
            charge = ctx.simulations.anonymous_hours.take(_client(request), cost_s)
        except Busy as exc:
            raise HTTPException(exc.status_code, exc.message, headers=exc.headers) from None
    spent = [0.0]

    def timed() -> T:
        t0 = time.thread_time()
        try:
            return work()
        finally:
            spent[0] = time.thread_time() - t0

    try:
        if not one_at_a_time:
            return await anyio.to_thread.run_sync(timed)
        async with ctx.limits.plants.hold(1):
            return await anyio.to_thread.run_sync(timed)
    except Busy as exc:
        raise HTTPException(exc.status_code, exc.message, headers=exc.headers) from None
    finally:
        if charge is not None:
            ctx.simulations.anonymous_hours.settle(charge, spent[0])


def _gcr_read(body: SweepCreate) -> SweepCreate:
    """``gcr`` given as the CLI's text (``"0.15,0.25"``, ``"0.1:0.5:0.05"``) read by its rule
    (:func:`backend.plants.sweep.parse_gcr`; 422 naming ``gcr``), so the dashboard sends what
    was typed and a mistake is named, not changed (a copy of the rule in the page made
    ``0.1:0.3:0.000001`` 40 values from 0.1 to 0.100039 and dropped ``-0.1``)."""
    if not isinstance(body.gcr, str):
        return body
    try:
        return body.model_copy(update={"gcr": parse_gcr(body.gcr)})
    except SweepInputError as exc:
        raise HTTPException(422, exc.message()) from None


def _sweep_inputs(body: SweepCreate, service: PlantService,
                  anonymous_bound: float | None = None) -> tuple[Any, list[Any]]:
    """The checked spec and cases of a sweep request; 404/422 naming the field.
    ``anonymous_bound``: the cases × steps of a caller without a token (the message quotes
    it, not the bound of a token's sweep)."""
    plant = None
    if body.plant_id is not None:
        _plant_or_404(service, body.plant_id)
        plant = service.get(body.plant_id)
    try:
        zone = sweep_zone(plant, body.timezone)
        start = pd.Timestamp(parse_day_or_instant(body.start, zone, "start"))
        end = pd.Timestamp(parse_day_or_instant(body.end, zone, "end"))
        size = None if body.field_size is None else tuple(
            int(v) for v in parse_size(body.field_size, "field_size"))
        custom = (body.aspect_ratio, body.offset, body.rotation_deg)
        return prepare_sweep(
            layouts=body.layouts, strategies=body.strategies, start=start,
            gcr=cast(list[float], body.gcr),  # the text read to a list by _gcr_read
            end=end, step_s=body.step_s, latitude_deg=body.latitude_deg,
            longitude_deg=body.longitude_deg, altitude_m=body.altitude_m,
            collector_m=None if body.collector_m is None
            else parse_size(body.collector_m, "collector_m"),
            collector_polygon_m=body.collector_polygon_m, plant=plant,
            field_size=cast(tuple[int, int] | None, size),
            custom=None if custom == (None, None, None) else custom,
            slope_azimuth_deg=body.slope_azimuth_deg, slope_tilt_deg=body.slope_tilt_deg,
            timezone=body.timezone,
            max_case_steps=MAX_CASE_STEPS if anonymous_bound is None else anonymous_bound,
            bound_note="" if anonymous_bound is None else " without a write token")
    except TimestampError as exc:
        raise HTTPException(422, str(exc)) from None
    except SweepInputError as exc:     # names the request's keys (the CLI maps them to flags)
        raise HTTPException(422, exc.message()) from None


@router.post("/sweeps", status_code=202, response_model=SweepAcceptedRead,
             responses={401: {}, 404: {}, 422: {}, 429: {}, 503: {}},
             openapi_extra={"security": [{}, {"bearerAuth": []}]})
async def create_sweep(body: SweepCreate, request: Request, ctx: ContextDep,
                       caller: CallerDep, service: PlantServiceDep,
                       runner: SweepRunnerDep) -> Response:
    """Queue a plant-design sweep (layouts × GCRs × strategies, each case a Dask task);
    202 with the ``sweep_id`` to poll. Without a write token a sweep may hold at most
    ``HELIOTWIN_PLANTS_ANONYMOUS_SWEEP_CASE_STEPS`` cases × steps (a polygon collector's
    steps weighing 100×, ``backend.plants.sweep.case_steps``; 422 beyond), spent from
    the address's anonymous simulation allowance (429 when spent); one sweep runs at a time
    (503 past the queue)."""
    anonymous = caller is None
    body = _gcr_read(body)
    spec, cases = await anyio.to_thread.run_sync(
        _sweep_inputs, body, service,
        ctx.settings.plants.anonymous_sweep_case_steps if anonymous else None)
    cost = case_steps(spec, len(cases))  # within the caller's bound (prepare_sweep)
    host = request.client.host if request.client else "?"
    try:
        if anonymous:
            ctx.limits.simulation_steps.take(host, cost)
    except Busy as exc:
        raise HTTPException(exc.status_code, exc.message, headers=exc.headers) from None
    try:
        state = runner.submit(spec, cases, sweep_params(spec, cases, body.model_dump()))
    except Busy as exc:  # the queue is full: nothing runs, the allowance is given back
        if anonymous:
            ctx.limits.simulation_steps.refund(host, cost)
        raise HTTPException(exc.status_code, exc.message, headers=exc.headers) from None
    state.spec, state.cases = spec, tuple(cases)
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
    """Cancel a queued or running sweep (a running one at once, its running cases dropped).

    No token is needed: the ``sweep_id`` (64 random bits, returned only to the caller
    who started the sweep) is the capability, as a simulation's ``run_id``."""
    _sweep_or_404(runner, sweep_id)
    state = runner.cancel(sweep_id)
    assert state is not None
    return state.to_dict()


def _swept_case(cases: tuple[SweepCase, ...], layout: str, gcr: float,
                strategy: str) -> SweepCase:
    """The sweep's case of that layout, GCR (to 1e-9) and strategy; else a 422 naming the
    first of the three the sweep did not run, with the values it ran."""
    for name, value, ran in (("layout", layout, {c.layout for c in cases}),
                             ("strategy", strategy, {c.strategy for c in cases})):
        if value not in ran:
            raise HTTPException(422, f"{name}: this sweep ran no case of {value[:60]!r}; its "
                                     f"{name}s: {', '.join(sorted(ran))}")
    for c in cases:
        if (c.layout, c.strategy) == (layout, strategy) and abs(c.gcr - gcr) <= 1e-9:
            return c
    gcrs = sorted({c.gcr for c in cases if (c.layout, c.strategy) == (layout, strategy)})
    raise HTTPException(422, f"gcr: this sweep ran no {layout} · {strategy} case at GCR {gcr:g}; "
                             f"its GCRs there: {', '.join(f'{g:g}' for g in gcrs)}")


@router.get("/sweeps/{sweep_id}/shade", response_model=SweepShadeRead,
            responses=_PRICED_DOC, openapi_extra=_OPTIONAL_TOKEN)
async def sweep_shade(sweep_id: str, request: Request, ctx: ContextDep, caller: CallerDep,
                      runner: SweepRunnerDep,
                      layout: Annotated[str, Query(max_length=100)],
                      gcr: Annotated[float, Query(gt=0, lt=1, allow_inf_nan=False)],
                      strategy: Annotated[str, Query()] = "sun",
                      date: Annotated[str | None, Query(
                          pattern=r"^\d{4}-\d{2}-\d{2}$",
                          description="default: the winter solstice of the sweep's "
                                      "hemisphere in the year it starts, or the day nearest "
                                      "to it with daylight")] = None,
                      step_s: Annotated[float, Query(ge=300, le=3600, allow_inf_nan=False)] = 900
                      ) -> dict[str, Any]:
    """One case the sweep ran (its layout — ``plant`` for a plant's —, GCR and strategy)
    through a clear-sky day: every collector's shaded fraction (priced as a plant day of its
    field; see the module docstring). A case it did not run is a 422 naming what differs (a
    tester's finding: any GCR or strategy was computed, and a plant sweep's ``layout=square``
    answered as the plant's)."""
    state = _sweep_or_404(runner, sweep_id)
    spec = getattr(state, "spec", None)
    if spec is None:
        raise HTTPException(404, f"sweep {sweep_id!r} has no field to show")
    try:
        if date is not None:
            dt.date.fromisoformat(date)
    except ValueError:
        raise HTTPException(422, f"date: {date!r} is not a calendar date") from None
    if strategy in STRATEGIES and strategy not in strategies_for(spec.collector):
        raise HTTPException(422, f"strategy: {strategy!r} needs a rectangular collector; this "
                                 "sweep's polygon takes 'sun'")
    case = _swept_case(state.cases, layout, gcr, _strategy(strategy))
    cost_s = day_cost_s(spec.rows * spec.columns if spec.plant is None
                        else spec.plant.n_trackers, step_s, cost_factor(spec.collector))
    try:
        return await _priced(request, ctx, caller, cost_s,
                             lambda: case_day_shade(spec, case, date or shade_day(spec, step_s),
                                                    step_s))
    except ValueError as exc:  # the case's field: an unknown layout or a GCR it cannot take
        raise HTTPException(422, f"layout, gcr: {exc}") from None


@router.get("", response_model=list[PlantSummaryRead])
def list_plants(service: PlantServiceDep) -> list[dict[str, Any]]:
    """Every plant (id, name, number of trackers, place)."""
    return service.list()


@router.get("/skipped", response_model=list[PlantSkippedRead])
def skipped_plants(service: PlantServiceDep) -> list[dict[str, str]]:
    """The plant files of the folder that are not served, each with its problem (left out of
    ``GET /api/v1/plants``, which said nothing of them)."""
    return service.skipped()


@router.get("/{plant_id}", response_model=PlantRead, responses={404: {}})
def get_plant(plant_id: str, service: PlantServiceDep) -> dict[str, Any]:
    """One plant: place, collector and electrical layout, trackers in ENU metres, and the
    strategies its collector can take (``sun`` alone for a polygon)."""
    _plant_or_404(service, plant_id)
    plant = service.get(plant_id)
    return {**plant.to_dict(), "strategies": list(strategies_for(plant.collector))}


@router.get("/{plant_id}/positions", response_model=PositionsRead, responses=_PRICED_DOC,
            openapi_extra=_OPTIONAL_TOKEN)
async def positions(plant_id: str, request: Request, ctx: ContextDep, caller: CallerDep,
                    service: PlantServiceDep,
                    time: Annotated[str, Query(description="ISO 8601 with offset")],
                    strategy: Annotated[str, Query(
                        description="sun | backtrack | sky_scan")] = "sun",
                    ) -> dict[str, Any]:
    """Every tracker's orientation under a strategy, its shaded fraction and who shades it
    (priced, without waiting for other plant computations: see the module docstring)."""
    when = _time(time)
    _plant_or_404(service, plant_id)
    plant = service.get(plant_id)
    strategy = _strategy(strategy, plant)
    cost_s = positions_cost_s(plant.n_trackers, cost_factor(plant.collector))
    return await _priced(request, ctx, caller, cost_s,
                         lambda: service.positions(plant_id, when, strategy),
                         one_at_a_time=False)


@router.get("/{plant_id}/sky-map", response_model=SkyMapRead,
            responses={**_PRICED_DOC, 200: {"content": PNG_CONTENT}}, openapi_extra=_OPTIONAL_TOKEN)
async def sky_map(plant_id: str, request: Request, ctx: ContextDep, caller: CallerDep,
                  service: PlantServiceDep,
                  time: Annotated[str, Query(description="ISO 8601 with offset")],
                  resolution_deg: Annotated[float, Query(ge=1.0, le=15.0,
                                                         allow_inf_nan=False)] = 3.0,
                  strategy: Annotated[str, Query()] = "sky_scan",
                  format: Annotated[str | None, Query(pattern="^(json|png)$")] = None,
                  ) -> Any:
    """Seed 004 Fig. 6: POA over the hemisphere of orientations (clear sky, Perez), grey where
    an orientation would shade a collector; ``Accept: image/png`` (or ``format=png``) for PNG."""
    when = _time(time)
    _plant_or_404(service, plant_id)
    strategy = _strategy(strategy)
    if "sky_scan" not in strategies_for(service.get(plant_id).collector):
        raise HTTPException(422, f"plant_id: {plant_id}'s collector is a polygon; the sky "
                                 "map's shaded region is the rectangle's shade-free test")
    m = await _priced(request, ctx, caller, sky_map_cost_s(resolution_deg),
                      lambda: service.sky_map(plant_id, when, resolution_deg, strategy))
    want_png = format == "png" or (format is None and
                                   "image/png" in request.headers.get("accept", ""))
    if want_png:
        return Response(await anyio.to_thread.run_sync(sky_map_png, m), media_type="image/png")
    return m


@router.get("/{plant_id}/day", response_model=PlantDayRead, response_model_exclude_unset=True,
            responses=_PRICED_DOC, openapi_extra=_OPTIONAL_TOKEN)
async def day(plant_id: str, request: Request, ctx: ContextDep, caller: CallerDep,
              service: PlantServiceDep,
              date: Annotated[str, Query(pattern=r"^\d{4}-\d{2}-\d{2}$",
                                         description="local date, YYYY-MM-DD "
                                                     f"({FIRST_YEAR}–{LAST_YEAR})")],
              step_s: Annotated[float, Query(ge=300, le=3600, allow_inf_nan=False)] = 900
              ) -> dict[str, Any]:
    """A clear-sky day (local date): each tracker's shade under sun tracking, and the plant
    energy of every strategy and of the fixed plant (priced: see the module docstring)."""
    try:
        day_ = dt.date.fromisoformat(date)
    except ValueError:
        raise HTTPException(422, f"date: {date!r} is not a calendar date") from None
    if not FIRST_YEAR <= day_.year <= LAST_YEAR:
        raise HTTPException(422, f"date: {date!r} is outside the years {FIRST_YEAR}–{LAST_YEAR}")
    _plant_or_404(service, plant_id)
    hit = service.cached_day(plant_id, day_, step_s)
    if hit is not None:
        return hit
    plant = service.get(plant_id)
    cost_s = day_cost_s(plant.n_trackers, step_s, cost_factor(plant.collector))
    return await _priced(request, ctx, caller, cost_s,
                         lambda: service.day(plant_id, day_, step_s))


#: The longest plant run on a weather file [days]: a typical year holds one year (a longer
#: range only repeats it), and a year at 1 min is what ``heliotwin plant simulate`` runs in a
#: few seconds; the twin's bound on steps (``HELIOTWIN_MAX_SIMULATION_STEPS``) holds too.
MAX_WEATHER_RUN_DAYS = 366


@router.post("/{plant_id}/weather", response_model=PlantWeatherRunRead,
             response_model_exclude_unset=True,
             responses={**_PRICED_DOC, 400: {}, 413: {}, 415: {}},
             openapi_extra=_OPTIONAL_TOKEN)
async def run_on_weather(plant_id: str, request: Request, ctx: ContextDep, caller: CallerDep,
                         service: PlantServiceDep) -> dict[str, Any]:
    """The plant over ``[start, end)`` on an uploaded weather file: ``heliotwin plant
    simulate --json``'s summary (one ``strategy``; the fixed plant beside it), its wind stow
    (``stow_min``, ``stow_loss_wh``) and the file's clock check (``weather_shift_min``,
    ``weather_warning``).

    Multipart, read as ``POST /api/v1/simulations/weather`` reads it (one reading: the body
    bounded by ``HELIOTWIN_MAX_UPLOAD_BYTES``, a TMY3/EPW/PVGIS typical year laid on the range's
    calendar or measured weather of its own dates; ``force`` for a station more than 100 km
    away or a header's UTC offset off its longitude) with the fields ``start``, ``end``,
    ``step_s`` and ``strategy``. At most :data:`MAX_WEATHER_RUN_DAYS` days and
    ``HELIOTWIN_MAX_SIMULATION_STEPS`` steps. A token is optional, as for the twin's run on
    weather: without one the run is priced as that many clear-sky days of the plant
    (:func:`backend.plants.day_cost_s`, which holds three strategies: an upper bound) from
    the address's hourly allowance (see the module docstring)."""
    form = await read_form(request, ctx.settings.server.max_upload_bytes,
                           "the weather file in 'file'", max_files=1, max_fields=16)
    force = form_flag(form_text(form, "force"), "force")
    body = form_model(PlantWeatherCreate, form, WEATHER_FORM_FIELDS)
    _plant_or_404(service, plant_id)
    plant = service.get(plant_id)
    strategy = _strategy(body.strategy, plant)
    try:
        start = pd.Timestamp(parse_day_or_instant(body.start, plant.timezone, "start"))
        end = pd.Timestamp(parse_day_or_instant(body.end, plant.timezone, "end"))
        check_step(start, end, body.step_s)  # its refusals name end or step_s
    except (TimestampError, ValueError) as exc:
        raise HTTPException(422, str(exc)) from None
    days = (end - start).total_seconds() / 86400.0
    if days > MAX_WEATHER_RUN_DAYS:
        raise HTTPException(422, f"end: the run is {days:,.1f} days; at most "
                                 f"{MAX_WEATHER_RUN_DAYS} on a weather file (a typical year "
                                 "holds one year)")
    check_steps(ctx, start, end, body.step_s)
    typical, meta = await read_weather_upload(form)
    try:
        weather, station, clock = await anyio.to_thread.run_sync(
            place_weather, typical, meta, plant, start, end, force, "force")
    except StationTooFar as exc:
        raise HTTPException(422, f"force: {exc}") from None
    except ValueError as exc:  # a run outside measured weather's dates
        raise HTTPException(422, f"file: {exc}") from None
    cost_s = days * day_cost_s(plant.n_trackers, body.step_s, cost_factor(plant.collector))
    return await _priced(request, ctx, caller, cost_s,
                         lambda: simulate_summary(plant, start, end, body.step_s, strategy,
                                                  weather, station, clock),
                         fields="step_s, end")
