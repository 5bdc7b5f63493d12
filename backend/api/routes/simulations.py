"""``/api/v1/simulations``: twin scenarios, now or in the background with progress."""

from __future__ import annotations

import asyncio
import math
from typing import Annotated, Any, Literal

import anyio
import numpy as np
import orjson
import pandas as pd
from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import Response
from pydantic import BaseModel, ConfigDict, Field, create_model

from backend.api.deps import ContextDep, bearer_token, site_or_404, token_site
from backend.api.schemas.common import CSV_CONTENT
from backend.api.schemas.simulations import (
    SimulationAcceptedRead,
    SimulationRunRead,
    SimulationSeriesRead,
    SimulationSummaryRead,
)
from backend.limits import Busy
from backend.measurements.queries import iso_utc
from backend.timestamps import parse_range
from backend.twin.export import export_names, series_csv
from backend.twin.parameters import MACHINE_PARAMETERS
from backend.twin.scenario import Scenario
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
    step_s: float = Field(60.0, gt=0, le=86400, description="time step [s]")
    controller: Literal[CONTROLLERS] = Field(  # type: ignore[valid-type]
        "ideal", description="tracking controller")
    receiver: Literal[RECEIVERS] = Field(  # type: ignore[valid-type]
        "flat", description="flat PV, or a CPV receiver with an acceptance angle")
    background: bool = Field(False, description="answer 202 at once and run in the background")


#: The request body: the base fields plus every machine parameter of the scenario table.
SimulationCreate = create_model(
    "SimulationCreate", __base__=_SimulationBase,
    **{p.name: (float, Field(p.default, ge=p.minimum, le=p.maximum, description=p.help))
       for p in MACHINE_PARAMETERS},  # type: ignore[call-overload]
)


def _params(ctx: Any, body: _SimulationBase) -> Scenario:
    info = site_or_404(ctx, body.site_id)
    try:
        t0, t1 = parse_range(body.start, body.end, info.zone)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    steps = (t1 - t0).total_seconds() / body.step_s
    if steps > ctx.settings.simulations.max_steps:
        raise HTTPException(422, f"{steps:.4g} steps asked; the limit is "
                                 f"{ctx.settings.simulations.max_steps}: use a larger step_s "
                                 "or a shorter range")
    machine = {p.name: float(getattr(body, p.name)) for p in MACHINE_PARAMETERS
               if getattr(body, p.name) != p.default}
    try:
        return Scenario(body.site_id, pd.Timestamp(t0), pd.Timestamp(t1), body.step_s,
                        body.controller, body.receiver, machine)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None


async def _caller(request: Request) -> str | None:
    """The site of the caller's write token; None without one; 401 for a bad one."""
    token = bearer_token(request)
    if token is None:
        return None
    owner = await token_site(request, token)
    if owner is None:
        raise HTTPException(401, "unknown, expired or revoked write token",
                            headers={"WWW-Authenticate": "Bearer"})
    return owner


def _busy(exc: Busy) -> HTTPException:
    return HTTPException(exc.status_code, exc.message, headers=exc.headers)


_BUSY_DOC: dict[int | str, dict[str, Any]] = {
    401: {"description": "a token was sent but is unknown, expired or revoked"},
    429: {"description": "rate limit of anonymous work (per client address); see Retry-After"},
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

    Runs execute in worker processes, a bounded number at once (503 with
    ``Retry-After`` past the queue). Without a write token the caller's address
    spends simulated steps from a per-minute allowance (429 when spent), and
    only the newest anonymous runs stay stored (``docs/service.md``, Limits).
    """
    return await submit_scenario(ctx, request, _params(ctx, body),
                                 body.background)  # type: ignore[attr-defined]


async def submit_scenario(ctx: Any, request: Request, params: Scenario,
                          background: bool) -> Response:
    """Queue a validated scenario for the caller: the anonymous allowance (429), the queue
    (503), then 202 with the ``run_id`` or, waiting for it, the summary."""
    owner = await _caller(request)
    anonymous = owner is None
    try:
        if anonymous:
            steps = (params.end - params.start).total_seconds() / params.step_s
            ctx.limits.simulation_steps.take(request.client.host if request.client else "?",
                                             steps)
        state, done = await anyio.to_thread.run_sync(ctx.simulations.submit, params, anonymous)
    except Busy as exc:
        raise _busy(exc) from None
    if background:
        return Response(orjson.dumps({"run_id": state.run_id, "status": state.status,
                                      "progress": state.progress}),
                        status_code=202, media_type="application/json",
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
    :func:`get_simulation` is (a run stored by an older version keeps its summary)."""
    state = await anyio.to_thread.run_sync(ctx.simulations.cancel, run_id)
    if state is None:
        raise HTTPException(404, f"unknown simulation run {run_id!r}")
    return Response(orjson.dumps(state.to_dict()), media_type="application/json")


@router.get("/{run_id}/series", response_model=SimulationSeriesRead,
            responses={200: {"content": CSV_CONTENT}, 404: {}, 409: {}})
def get_simulation_series(
    run_id: str,
    ctx: ContextDep,
    max_points: Annotated[int | None, Query(ge=1, le=2_000_000)] = None,
    format: Literal["json", "csv"] = "json",
) -> Response:
    """A finished run's series; averaged into at most ``max_points`` buckets when asked."""
    state = ctx.simulations.get(run_id)
    if state is None:
        raise HTTPException(404, f"unknown simulation run {run_id!r}")
    series = ctx.simulations.series(run_id)
    if series is None:
        raise HTTPException(409, f"run {run_id} is {state.status}; its series is not ready")
    ts = series.index.as_unit("s").asi8
    data = series.to_numpy(np.float64)
    bucket_s = 0.0
    if max_points is not None and len(series) > max_points:
        per = math.ceil(len(series) / max_points)
        m = math.ceil(len(series) / per)
        pad = m * per - len(series)
        padded = np.vstack([data, np.full((pad, data.shape[1]), np.nan)])
        data = np.nanmean(padded.reshape(m, per, -1), axis=1)
        ts = ts[::per]
        bucket_s = per * float(state.params.get("step_s", 60.0))
    cols = list(series.columns)
    times = iso_utc(ts)
    if format == "csv":  # units in the column names, UTC and local time (backend.twin.export)
        info = ctx.registry.sites.get(state.site_id)
        frame = pd.DataFrame(data, index=pd.to_datetime(ts, unit="s", utc=True), columns=cols)
        text = series_csv(frame, info.site.timezone if info else "UTC")
        return Response(text, media_type="text/csv", headers={
            "Content-Disposition": f'attachment; filename="simulation_{run_id}.csv"'})
    names = export_names(cols)
    points = [dict(zip(["ts", *names], [t, *row], strict=True))
              for t, row in zip(times, data.tolist(), strict=True)]
    return Response(orjson.dumps({"run_id": run_id, "bucket_s": bucket_s, "columns": names,
                                  "points": points}, option=orjson.OPT_SERIALIZE_NUMPY),
                    media_type="application/json")
