"""``/api/v1/simulations``: twin scenarios, now or in the background with progress."""

from __future__ import annotations

import asyncio
import csv
import io
import math
from typing import Annotated, Any, Literal

import numpy as np
import orjson
import pandas as pd
from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import Response
from pydantic import BaseModel, ConfigDict, Field, create_model

from backend.api.deps import ContextDep, site_or_404
from backend.measurements.queries import iso_utc
from backend.timestamps import parse_range
from backend.twin.parameters import MACHINE_PARAMETERS
from backend.twin.scenario import Scenario
from sim.twin import CONTROLLERS, RECEIVERS

router = APIRouter(prefix="/api/v1/simulations", tags=["simulations"])


class _SimulationBase(BaseModel):
    """A twin scenario (DESIGN.md ``heliotwin simulate``)."""

    model_config = ConfigDict(allow_inf_nan=False)

    site_id: str = Field("tehuantepec", examples=["tehuantepec"])
    start: str = Field(..., description="date (site midnight) or ISO date-time with offset",
                       examples=["2024-03-15"])
    end: str = Field(..., description="exclusive", examples=["2024-03-16"])
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
    if steps > ctx.settings.max_simulation_steps:
        raise HTTPException(422, f"{steps:.4g} steps asked; the limit is "
                                 f"{ctx.settings.max_simulation_steps}: use a larger step_s "
                                 "or a shorter range")
    machine = {p.name: float(getattr(body, p.name)) for p in MACHINE_PARAMETERS
               if getattr(body, p.name) != p.default}
    try:
        return Scenario(body.site_id, pd.Timestamp(t0), pd.Timestamp(t1), body.step_s,
                        body.controller, body.receiver, machine)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None


@router.post("", responses={202: {"description": "accepted (background run)"}, 400: {},
                                 404: {}, 422: {}})
async def create_simulation(body: SimulationCreate,  # type: ignore[valid-type]
                            ctx: ContextDep) -> Response:
    """Run a twin scenario; the summary, or 202 with a ``run_id`` to poll."""
    params = _params(ctx, body)
    if body.background:  # type: ignore[attr-defined]
        state = await asyncio.to_thread(ctx.simulations.start_background, params)
        return Response(orjson.dumps({"run_id": state.run_id, "status": state.status,
                                      "progress": state.progress}),
                        status_code=202, media_type="application/json",
                        headers={"Location": f"/api/v1/simulations/{state.run_id}"})
    try:
        summary = await asyncio.to_thread(ctx.simulations.run_sync, params)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    return Response(orjson.dumps(summary), media_type="application/json")


@router.get("/{run_id}", responses={404: {}})
def get_simulation(run_id: str, ctx: ContextDep) -> dict[str, Any]:
    """Status, progress (0…1) and, when done, the summary of a run."""
    state = ctx.simulations.get(run_id)
    if state is None:
        raise HTTPException(404, f"unknown simulation run {run_id!r}")
    return state.to_dict()


@router.get("/{run_id}/series", responses={404: {}, 409: {}})
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
    if format == "csv":
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["ts", *cols])
        w.writerows([t, *row] for t, row in zip(times, data.tolist(), strict=True))
        return Response(buf.getvalue(), media_type="text/csv", headers={
            "Content-Disposition": f'attachment; filename="simulation_{run_id}.csv"'})
    points = [dict(zip(["ts", *cols], [t, *row], strict=True))
              for t, row in zip(times, data.tolist(), strict=True)]
    return Response(orjson.dumps({"run_id": run_id, "bucket_s": bucket_s, "columns": cols,
                                  "points": points}, option=orjson.OPT_SERIALIZE_NUMPY),
                    media_type="application/json")
