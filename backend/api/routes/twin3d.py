"""``/api/v1/twin3d``: what the viser 3D twin shows — live ideal tracking, or a simulation run.

``PUT /replay`` poses the tracker as a finished run did (its actual joint angles on
its disturbed pedestal) with a translucent ghost of the ideal pose where the two
differ; ``DELETE /replay`` goes back to live. The scene is one for all viewers.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, HTTPException, Request
from pydantic import BaseModel, Field

from backend.api.deps import ContextDep
from backend.twin.scenario import disturbances_of
from backend.twin.scene_pose import Replay

router = APIRouter(prefix="/api/v1/twin3d", tags=["twin3d"])


class ReplayRequest(BaseModel):
    run_id: str = Field(..., min_length=1, max_length=64, description="a finished simulation run")


def _scene(request: Request) -> Any:
    scene = getattr(request.app.state, "scene", None)
    if scene is None:
        raise HTTPException(503, "the 3D twin is not running on this service (HELIOTWIN_VISER)")
    return scene


@router.put("/replay", responses={404: {}, 409: {}, 422: {}, 503: {}})
def put_replay(body: ReplayRequest, request: Request, ctx: ContextDep) -> dict[str, Any]:
    """Show a finished simulation run in the 3D twin (its first instant)."""
    scene = _scene(request)
    state = ctx.simulations.get(body.run_id)
    if state is None:
        raise HTTPException(404, f"run_id: unknown simulation run {body.run_id!r}")
    if state.site_id != scene.site.site_id:
        raise HTTPException(422, f"run_id: the run is for site {state.site_id!r}; the 3D twin "
                                 f"shows {scene.site.site_id!r}")
    series = ctx.simulations.series(body.run_id)
    if series is None:
        raise HTTPException(409, f"run_id: run {body.run_id} is {state.status}; not finished")
    try:
        replay = Replay.from_series(body.run_id, series, disturbances_of(state.params),
                                    float(state.params.get("step_s", 60.0)))
    except ValueError as exc:
        raise HTTPException(422, f"run_id: {exc}") from None
    pose = scene.load_replay(replay)
    return {"run_id": body.run_id, "start": replay.start.isoformat(),
            "end": replay.end.isoformat(),
            "pointing_error_mrad": None if pose is None else pose.pointing_error_mrad}


@router.delete("/replay", responses={503: {}})
def delete_replay(request: Request) -> dict[str, Any]:
    """Back to live ideal tracking."""
    _scene(request).clear_replay()
    return {"replay": None}
