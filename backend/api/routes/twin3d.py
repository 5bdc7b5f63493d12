"""``/api/v1/twin3d``: the viser 3D twin's viewers and what they replay.

Every viewer (a browser tab on the viser page) has its own time, play state and
site (``backend.twin.scene``). ``GET`` lists them; ``PUT /replay`` poses the
tracker as a finished run did (its actual joint angles on its disturbed
pedestal, with a translucent ghost of the ideal pose where they differ) in the
viewers of one dashboard tab — the ``viewer`` key the dashboard puts in the
viser page's URL — or, without a key, in every viewer of the run's site that
has no replay of its own; ``DELETE /replay`` takes it back to live. A tab's own
viewer key changes that tab alone, so it needs no token; the shared replay (no
key) changes what every viewer of the site sees, so setting or clearing it needs
a ``site``-scope token of the run's site, or the admin token.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Query, Request
from pydantic import BaseModel, ConfigDict, Field

from backend.api.deps import CallerDep, ContextDep, authorize
from backend.api.schemas.twin3d import ReplayClearedRead, ReplayRead, ViewersRead
from backend.twin.scenario import disturbances_of
from backend.twin.scene_pose import Replay

router = APIRouter(prefix="/api/v1/twin3d", tags=["twin3d"])

VIEWER_PATTERN = r"^[A-Za-z0-9_-]{1,64}$"


class ReplayRequest(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)

    run_id: str = Field(..., min_length=1, max_length=64, description="a finished simulation run")
    viewer: str | None = Field(None, pattern=VIEWER_PATTERN,
                               description="the dashboard tab's viewer key (in the viser "
                                           "page's URL); omitted: every viewer of the site")


def _scene(request: Request) -> Any:
    scene = getattr(request.app.state, "scene", None)
    if scene is None:
        raise HTTPException(503, "the 3D twin is not running on this service (HELIOTWIN_VISER)")
    return scene


@router.get("", response_model=ViewersRead, responses={503: {}})
def viewers(request: Request) -> dict[str, Any]:
    """The viser port actually bound, the default site and every connected site viewer: its
    key, site, mode, shown time, replay, the tracker's shade on the fixed array [-] and the
    tracker collector's ground shadow (east, north) [m]."""
    scene = _scene(request)
    rows = []
    for view in scene.site_views():
        pose = view.pose
        rows.append({"viewer": view.viewer, "site_id": view.site.site_id,
                     "mode": "live" if view.live else "playing" if view.playing else "scrubbing",
                     "time": None if pose is None else pose.ts.isoformat(),
                     "replay_run_id": None if view.replay is None else view.replay.run_id,
                     "fixed_shaded_fraction": None if pose is None else pose.fixed_shaded_fraction,
                     "tracker_shadow_m": [[round(float(x), 3) for x in p] for p in
                                          view.shadows.get("/shadows/tracker_panels", [])]})
    return {"viser_port": scene.port, "default_site": scene.site.site_id, "viewers": rows}


#: a token only for the shared replay (no viewer key)
_OPTIONAL_TOKEN: dict[str, Any] = {"security": [{}, {"bearerAuth": []}]}


@router.put("/replay", response_model=ReplayRead, openapi_extra=_OPTIONAL_TOKEN,
            responses={401: {}, 403: {}, 404: {}, 409: {}, 422: {}, 503: {}})
def put_replay(body: ReplayRequest, request: Request, ctx: ContextDep,
               caller: CallerDep) -> dict[str, Any]:
    """Show a finished simulation run in the 3D twin (its first instant): in one viewer,
    or (a ``site`` token of the run's site, or the admin token) in all of the site's."""
    scene = _scene(request)
    state = ctx.simulations.get(body.run_id)
    if state is None:
        raise HTTPException(404, f"run_id: unknown simulation run {body.run_id!r}")
    viewer = body.viewer or ""
    if not viewer:
        authorize(caller, state.site_id, "site", "the shared replay (every viewer of site "
                                                 f"{state.site_id!r}; a viewer key of your "
                                                 "own replays in that tab alone, no token "
                                                 "needed)")
    other = sorted({v.site.site_id for v in scene.site_views(viewer or None)} - {state.site_id})
    if viewer and other:
        raise HTTPException(422, f"viewer: the viewer shows site {other[0]!r}; run "
                                 f"{body.run_id} is for site {state.site_id!r}")
    series = ctx.simulations.series(body.run_id)
    if series is None:
        raise HTTPException(409, f"run_id: run {body.run_id} is {state.status}; not finished")
    try:
        replay = Replay.from_series(body.run_id, series, disturbances_of(state.params),
                                    float(state.params.get("step_s", 60.0)), state.site_id)
    except ValueError as exc:
        raise HTTPException(422, f"run_id: {exc}") from None
    poses = scene.load_replay(replay, viewer)
    return {"run_id": body.run_id, "site_id": state.site_id, "viewer": body.viewer,
            "viewers": len(poses), "start": replay.start.isoformat(),
            "end": replay.end.isoformat(),
            "pointing_error_mrad": poses[0].pointing_error_mrad if poses else None}


@router.delete("/replay", response_model=ReplayClearedRead, openapi_extra=_OPTIONAL_TOKEN,
               responses={401: {}, 403: {}, 422: {}, 503: {}})
def delete_replay(request: Request, caller: CallerDep, viewer: Annotated[str | None, Query(
        pattern=VIEWER_PATTERN, description="the viewer key; omitted: the shared replay")]
        = None) -> dict[str, Any]:
    """Back to live ideal tracking: one viewer, or (a ``site`` token of a site whose
    viewers show it, or the admin token) the shared replay."""
    scene = _scene(request)
    if not viewer:
        shared = scene.replays.get("")
        if shared is not None:  # clearing nothing changes nothing: no token needed
            authorize(caller, shared.site_id, "site",
                      f"clearing the shared replay of site {shared.site_id!r}")
    scene.clear_replay(viewer or "")
    return {"replay": None}
