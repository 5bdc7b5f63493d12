"""``/api/v1/simulations``: twin scenarios, now or in the background with progress."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Iterator
from typing import Annotated, Any, Literal

import anyio
import orjson
import pandas as pd
from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import Response, StreamingResponse
from pydantic import BaseModel, ConfigDict, Field, create_model

from backend.api.deps import ContextDep, caller_of, site_or_404
from backend.api.schemas.common import CSV_CONTENT
from backend.api.schemas.simulations import (
    SimulationAcceptedRead,
    SimulationEstimateRead,
    SimulationRunRead,
    SimulationSeriesRead,
    SimulationSummaryRead,
)
from backend.limits import Busy
from backend.measurements.queries import iso_utc
from backend.timestamps import TimestampError, parse_day_or_instant, parse_range
from backend.twin.export import export_frame, export_names
from backend.twin.parameters import MACHINE_PARAMETERS
from backend.twin.scenario import Scenario
from backend.twin.series_read import PackedSeries
from backend.twin.simulations import RunTooCostly
from sim.energy import MAX_STEP_S
from sim.twin import CONTROLLERS, RECEIVERS

router = APIRouter(prefix="/api/v1/simulations", tags=["simulations"])


class _SimulationBase(BaseModel):
    """A twin scenario (DESIGN.md ``heliotwin simulate``)."""

    # strict: unknown fields are a 422 (as unknown CSV columns are), "background": 0 is not
    # false and "60" or false is not a number
    model_config = ConfigDict(allow_inf_nan=False, extra="forbid", strict=True)

    site_id: str = Field("tehuantepec", min_length=1, max_length=64, examples=["tehuantepec"])
    start: str = Field(..., min_length=1, max_length=64,
                       description="date (site midnight) or ISO date-time with offset",
                       examples=["2024-03-15"])
    end: str = Field(..., min_length=1, max_length=64, description="exclusive",
                     examples=["2024-03-16"])
    step_s: float = Field(60.0, gt=0, le=MAX_STEP_S,
                          description="time step [s], at most an hour (sim.energy.MAX_STEP_S)")
    controller: Literal[CONTROLLERS] = Field(  # type: ignore[valid-type]
        "ideal", description="tracking controller",
        examples=["open_loop_model"])   # the example body's terms go with this controller
    receiver: Literal[RECEIVERS] = Field(  # type: ignore[valid-type]
        "flat", description="flat PV, or a CPV receiver with an acceptance angle")
    pointing_model_terms: dict[str, Any] | None = Field(
        None, max_length=32,
        description="open_loop_model only: the mount terms its commands go through — the "
                    "'terms' of GET /api/v1/sites/{site_id}/pointing-model as they come, "
                    "that whole answer, or {name: degrees}; default a perfect mount "
                    "(sim.pointing_model.PointingModel.from_terms checks them)",
        examples=[{"azimuth_zero_deg": {"value": 1.5, "std": 0.001}}])
    background: bool = Field(False, description="answer 202 at once and run in the background")


#: The request body: the base fields plus every machine parameter of the scenario table.
SimulationCreate = create_model(
    "SimulationCreate", __base__=_SimulationBase,
    **{p.name: (float, Field(p.default, ge=p.minimum, le=p.maximum, description=p.help))
       for p in MACHINE_PARAMETERS},  # type: ignore[call-overload]
)


def check_steps(ctx: Any, start: Any, end: Any, step_s: float) -> None:
    """A 422 naming ``step_s, end`` for a run of more steps than one request may ask
    (``HELIOTWIN_MAX_SIMULATION_STEPS``): the twin's runs and a plant's on weather."""
    steps = (end - start).total_seconds() / step_s
    if steps > ctx.settings.simulations.max_steps:
        raise HTTPException(422, f"step_s, end: {steps:,.0f} steps asked; the limit is "
                                 f"{ctx.settings.simulations.max_steps:,} "
                                 "(HELIOTWIN_MAX_SIMULATION_STEPS): use a larger step_s "
                                 "or a shorter range")


def _params(ctx: Any, body: _SimulationBase) -> Scenario:
    info = site_or_404(ctx, body.site_id, "site_id")
    try:
        t0, t1 = parse_range(body.start, body.end, info.zone)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    check_steps(ctx, t0, t1, body.step_s)
    machine = {p.name: float(getattr(body, p.name)) for p in MACHINE_PARAMETERS
               if getattr(body, p.name) != p.default}
    try:
        return Scenario(body.site_id, pd.Timestamp(t0), pd.Timestamp(t1), body.step_s,
                        body.controller, body.receiver, machine,
                        pointing_model_terms=body.pointing_model_terms)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None


#: The owner of a run sent with the admin token (no site id has a ':')
ADMIN_OWNER = ":admin"


async def _caller(request: Request) -> str | None:
    """The site of the caller's write token, :data:`ADMIN_OWNER` for the admin token (as
    every route that takes a token reads it, ``backend.api.deps.caller_of``: it had been
    answered "unknown, expired or revoked write token", a tester's finding); None without
    one; 401 for a bad one."""
    caller = await caller_of(request.app.state.ctx, request.headers.get("authorization"))
    if caller is None:
        return None
    return ADMIN_OWNER if caller == "admin" else caller.site_id


def client_key(request: Request, owner: str | None) -> str:
    """Who a run is queued for, for the queue's fairness and the anonymous bounds: a token's
    site, the admin, or the address of a caller without one."""
    if owner == ADMIN_OWNER:
        return "admin"
    if owner is not None:
        return f"site:{owner}"
    return f"addr:{request.client.host if request.client else '?'}"


def _busy(exc: Busy) -> HTTPException:
    return HTTPException(exc.status_code, exc.message, headers=exc.headers)


_BUSY_DOC: dict[int | str, dict[str, Any]] = {
    401: {"description": "a token was sent but is unknown, expired or revoked"},
    429: {"description": "rate limit of anonymous work (per client address: steps a minute, "
                         "worker time an hour); see Retry-After"},
    503: {"description": "the simulation queue is full; see Retry-After"},
}


#: the summary (200) or, for a background run, where to poll it (202)
SUBMIT_RESPONSES: dict[int | str, dict[str, Any]] = {
    202: {"model": SimulationAcceptedRead, "description": "accepted (background run)"}}


@router.post("", response_model=SimulationSummaryRead,
             responses={**SUBMIT_RESPONSES, 400: {}, 404: {}, 422: {}, **_BUSY_DOC},
             openapi_extra={"security": [{}, {"bearerAuth": []}]})
async def create_simulation(body: SimulationCreate,  # type: ignore[valid-type]
                            ctx: ContextDep, request: Request) -> Response:
    """Run a twin scenario; the summary, or 202 with a ``run_id`` to poll.

    Runs execute in worker processes, a bounded number at once, in a queue ordered
    fairly between callers (503 with ``Retry-After`` past the queue). Without a write
    token a run expected to take more than ``HELIOTWIN_SIMULATION_ANONYMOUS_RUN_MAX_S``
    of worker time is a 422 (and is stopped if it runs longer), the caller's address
    spends simulated steps a minute and worker time an hour (429 when spent), and only
    the newest anonymous runs stay stored (``docs/service.md``, "The simulation queue").
    """
    return await submit_scenario(ctx, request, _params(ctx, body),
                                 body.background)  # type: ignore[attr-defined]


@router.post("/estimate", response_model=SimulationEstimateRead,
             responses={400: {}, 401: {}, 404: {}, 422: {}},
             openapi_extra={"security": [{}, {"bearerAuth": []}]})
async def estimate_simulation(body: SimulationCreate,  # type: ignore[valid-type]
                              ctx: ContextDep, request: Request) -> SimulationEstimateRead:
    """What the run of this body would cost the worker and when it would start, without
    queueing it, and whether it would be accepted now (for "about 45 min: run anyway?")."""
    params = _params(ctx, body)
    owner = await _caller(request)
    est = ctx.simulations.estimate(params, client_key(request, owner), owner is None)
    return SimulationEstimateRead(
        site_id=params.site_id, controller=params.controller,
        steps=round((params.end - params.start).total_seconds() / params.step_s),
        estimated_run_s=round(est.estimated_run_s, 1),
        estimated_wait_s=round(est.estimated_wait_s, 1), runs_ahead=est.runs_ahead,
        anonymous_run_max_s=est.anonymous_run_max_s,
        anonymous_hour_left_s=None if est.anonymous_hour_left_s is None
        else round(est.anonymous_hour_left_s, 1),
        allowed=est.reason is None, reason=est.reason)


async def submit_scenario(ctx: Any, request: Request, params: Scenario,
                          background: bool) -> Response:
    """Queue a validated scenario for the caller: the anonymous allowance (429), the queue
    (503), then 202 with the ``run_id`` or, waiting for it, the summary."""
    owner = await _caller(request)
    anonymous = owner is None
    host = request.client.host if request.client else "?"
    steps = (params.end - params.start).total_seconds() / params.step_s
    try:
        if anonymous:
            ctx.limits.simulation_steps.take(host, steps)
    except Busy as exc:
        raise _busy(exc) from None
    try:
        state, done = await anyio.to_thread.run_sync(
            ctx.simulations.submit, params, anonymous, client_key(request, owner))
    except (Busy, RunTooCostly) as exc:
        if anonymous:  # refused: nothing ran, the allowance is given back
            ctx.limits.simulation_steps.refund(host, steps)
        if isinstance(exc, Busy):
            raise _busy(exc) from None
        raise HTTPException(422, str(exc)) from None
    if background:
        accepted = {k: v for k, v in state.to_dict().items()
                    if k in SimulationAcceptedRead.model_fields}
        return Response(orjson.dumps(accepted), status_code=202, media_type="application/json",
                        headers={"Location": f"/api/v1/simulations/{state.run_id}"})
    try:
        summary = await asyncio.wrap_future(done)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    except Exception as exc:  # the worker died or the service is stopping
        raise HTTPException(503, f"simulation {state.run_id} did not finish: {exc}",
                            headers={"Retry-After": "10"}) from None
    return Response(orjson.dumps(summary), media_type="application/json")


@router.get("/{run_id}", response_model=SimulationRunRead, responses={404: {}})
def get_simulation(run_id: str, ctx: ContextDep) -> Response:
    """Status, progress (0…1) and, when done, the summary of a run.

    Answered as stored (not filtered through the model): a run stored by an older version
    keeps the summary it had, without the keys added since."""
    state = ctx.simulations.get(run_id)
    if state is None:
        raise HTTPException(404, f"unknown simulation run {run_id!r}")
    return Response(orjson.dumps(state.to_dict()), media_type="application/json")


@router.delete("/{run_id}", response_model=SimulationRunRead, responses={404: {}})
async def cancel_simulation(run_id: str, ctx: ContextDep) -> Response:
    """Cancel a queued or running run; its state once it has ended (``failed`` with the
    error ``cancelled``, or as it was if it had already ended). Answered as stored, as
    :func:`get_simulation` is (a run stored by an older version keeps its summary).

    No token is needed, for a run made with one too: the ``run_id`` is the capability (a
    uuid4, 122 random bits, returned only to the caller that started the run and listed
    nowhere), as for ``GET``; share it as a private link (``docs/service.md``, "Limits")."""
    state = await anyio.to_thread.run_sync(ctx.simulations.cancel, run_id)
    if state is None:
        raise HTTPException(404, f"unknown simulation run {run_id!r}")
    return Response(orjson.dumps(state.to_dict()), media_type="application/json")


#: The series' JSON answer is written in these pieces (:class:`PackedSeries` blocks).
_JSON_OPTIONS = orjson.OPT_SERIALIZE_NUMPY


def _json_chunks(run_id: str, bucket_s: float, packed: PackedSeries, i0: int, i1: int,
                 per: int) -> Iterator[bytes]:
    """``SimulationSeriesRead`` written block by block: never the whole series at once."""
    names = export_names(packed.columns)
    keys = ["ts", *names]
    head = orjson.dumps({"run_id": run_id, "bucket_s": bucket_s, "columns": names})
    yield head[:-1] + b',"points":['
    first = True
    for ts, values in packed.blocks(i0, i1, per):
        points = [dict(zip(keys, [t, *row], strict=True))
                  for t, row in zip(iso_utc(ts), values.tolist(), strict=True)]
        if points:  # NaN is written as null (orjson)
            yield (b"" if first else b",") + orjson.dumps(points, option=_JSON_OPTIONS)[1:-1]
            first = False
    yield b"]}"


def _csv_chunks(packed: PackedSeries, i0: int, i1: int, per: int, timezone: str
                ) -> Iterator[bytes]:
    """The series as CSV (``backend.twin.export``: UTC and local time, units in the
    column names), written block by block."""
    header = True
    for ts, values in packed.blocks(i0, i1, per):
        frame = pd.DataFrame(values, index=pd.to_datetime(ts, unit="s", utc=True),
                             columns=packed.columns)
        yield export_frame(frame, timezone).to_csv(index=False, header=header,
                                                   lineterminator="\n").encode()
        header = False
    if header:  # no rows: the header alone
        yield (",".join(["time_utc", "time_local", *export_names(packed.columns)])
               + "\n").encode()


def _instant_s(text: str | None, zone: str, name: str) -> int | None:
    if text is None:
        return None
    try:
        return int(parse_day_or_instant(text, zone, name).timestamp())
    except TimestampError as exc:
        raise HTTPException(422, str(exc)) from None


@router.get("/{run_id}/series", response_model=SimulationSeriesRead,
            responses={200: {"content": CSV_CONTENT}, 401: {}, 404: {}, 409: {}, 422: {},
                       429: {"description": "rate limit of anonymous series reads (values a "
                                            "minute per client address); see Retry-After"}},
            openapi_extra={"security": [{}, {"bearerAuth": []}]})
async def get_simulation_series(
    run_id: str,
    ctx: ContextDep,
    request: Request,
    start: Annotated[str | None, Query(max_length=64, description=(
        "first time (inclusive): a date (site midnight) or ISO date-time with offset"))] = None,
    end: Annotated[str | None, Query(max_length=64, description="exclusive")] = None,
    step_s: Annotated[float | None, Query(gt=0, le=31 * 86400, allow_inf_nan=False, description=(
        "resolution [s]: means over this span, a whole multiple of the run's step"))] = None,
    max_points: Annotated[int | None, Query(ge=1, le=2_000_000)] = None,
    format: Literal["json", "csv"] = "json",
) -> Response:
    """A finished run's series, streamed as it is written (JSON or CSV), within
    ``start``/``end`` when given, averaged into buckets of ``step_s`` or into at most
    ``max_points`` buckets when asked (the coarser of the two). Without a token a client
    address reads at most ``HELIOTWIN_ANONYMOUS_SERIES_CELLS_PER_MIN`` values a minute."""
    # a run no longer in memory is read from the database: off the event loop
    state = await anyio.to_thread.run_sync(ctx.simulations.get, run_id)
    if state is None:
        raise HTTPException(404, f"unknown simulation run {run_id!r}")
    owner = await _caller(request)
    blob = await anyio.to_thread.run_sync(ctx.simulations.series_blob, run_id)
    if blob is None:
        raise HTTPException(409, f"run {run_id} is {state.status}; its series is not ready")
    info = ctx.registry.get(state.site_id)
    zone = info.site.timezone if info else "UTC"
    start_s, end_s = _instant_s(start, zone, "start"), _instant_s(end, zone, "end")
    if start_s is not None and end_s is not None and end_s <= start_s:
        raise HTTPException(422, f"end ({end}) must be after start ({start}); end is exclusive")
    # concurrent readers share the bytes; unpacking the time column is off the loop too
    packed = await anyio.to_thread.run_sync(lambda: PackedSeries(blob.data, keep=blob))
    i0, i1 = packed.index_range(start_s, end_s)
    run_step_s = float(state.params.get("step_s", 60.0))
    per = 1
    if step_s is not None:
        ratio = step_s / run_step_s
        if ratio < 1 - 1e-9 or abs(ratio - round(ratio)) > 1e-6:
            raise HTTPException(422, f"step_s: {step_s:g} s is not a whole multiple of the "
                                     f"run's step ({run_step_s:g} s)")
        per = round(ratio)
    if max_points is not None and i1 - i0 > max_points * per:
        per = math.ceil((i1 - i0) / max_points)
    cells = math.ceil((i1 - i0) / per) * (len(packed.columns) + 1)
    if owner is None:
        try:
            ctx.limits.series_cells.take(request.client.host if request.client else "?",
                                         cells)
        except Busy as exc:
            raise _busy(exc) from None
    bucket_s = per * run_step_s if per > 1 else 0.0
    if format == "csv":
        return StreamingResponse(_csv_chunks(packed, i0, i1, per, zone), media_type="text/csv",
                                 headers={"Content-Disposition":
                                          f'attachment; filename="simulation_{run_id}.csv"'})
    return StreamingResponse(_json_chunks(run_id, bucket_s, packed, i0, i1, per),
                             media_type="application/json")
