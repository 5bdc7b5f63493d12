"""``/api/v1/alerts``: the stored alerts — silent loggers, diagnosis faults, low performance
ratio — and the state of their evaluator and webhook (``backend/alerts/``,
``docs/service.md`` "Alerts"). Readable without a token, like the dashboard's other reads;
acknowledging one needs a ``site``-scope token of its site or the admin token."""

from __future__ import annotations

from typing import Annotated, Any

import anyio
import orjson
from fastapi import APIRouter, Body, HTTPException, Path, Query
from fastapi.responses import Response

from backend.alerts.service import acknowledge, get_alert, list_alerts
from backend.api.deps import CallerDep, ContextDep, authorize, caller_name
from backend.api.schemas.alerts import (
    AcknowledgeCreate,
    AlertKind,
    AlertRead,
    AlertsRead,
    AlertState,
)

router = APIRouter(prefix="/api/v1/alerts", tags=["alerts"])

@router.get("", response_model=AlertsRead,
            responses={404: {"description": "unknown site_id"}, 422: {}})
async def get_alerts(
    ctx: ContextDep,
    site_id: Annotated[str | None, Query(min_length=1, max_length=64,
                                         description="only this site's alerts")] = None,
    state: Annotated[AlertState | None, Query(description="only active or only cleared")] = None,
    kind: Annotated[AlertKind | None, Query(description="only this kind")] = None,
    acknowledged: Annotated[bool | None, Query(
        description="true: only alerts an operator acknowledged; false: only the others")]
        = None,
    limit: Annotated[int, Query(ge=1, le=1000, description="most alerts answered")] = 100,
) -> Response:
    """Stored alerts (newest raised first), their counts, and the evaluator's state."""
    if site_id is not None and ctx.registry.get(site_id) is None:
        known = ", ".join(ctx.registry.sites) or "none"
        raise HTTPException(404, f"site_id: unknown site {site_id!r}; known sites: {known}")

    def read() -> dict[str, Any]:
        with ctx.engine.connect() as conn:
            return list_alerts(conn, site_id, state, kind, limit, acknowledged)

    body = await anyio.to_thread.run_sync(read)
    body["evaluator"] = ctx.alerts.status() if ctx.alerts is not None else {"enabled": False}
    return Response(orjson.dumps(body), media_type="application/json")


@router.post("/{alert_id}/acknowledge", response_model=AlertRead, responses={
    401: {"description": "no token, or an unknown, revoked or expired one"},
    403: {"description": "a token of another site, or an `ingest` (logger) token"},
    404: {"description": "unknown alert_id"},
    409: {"description": "the alert was cleared before anyone acknowledged it"},
    422: {}})
async def acknowledge_alert(
    alert_id: Annotated[int, Path(ge=1, le=2**31 - 1, description="the alert's `id`")],
    ctx: ContextDep, caller: CallerDep,
    body: Annotated[AcknowledgeCreate | None, Body()] = None,
) -> Response:
    """Say an active alert is seen and taken (who: the token's label; an optional note).

    Once: acknowledging it again changes nothing and answers it as stored (the first time,
    name and note). A cleared alert is a 409: nobody needs to take it on any more. Needs a
    ``site``-scope token of the alert's site, or the admin token."""
    def read() -> dict[str, Any] | None:
        with ctx.engine.connect() as conn:
            return get_alert(conn, alert_id)

    alert = await anyio.to_thread.run_sync(read)
    if alert is None:
        raise HTTPException(404, f"alert_id: no alert {alert_id}")
    site = alert["site_id"]
    authorize(caller, site, "site", f"acknowledging alerts of site {site!r}")
    note = (body.note or "").strip() or None if body is not None else None
    done = await anyio.to_thread.run_sync(acknowledge, ctx, alert_id, caller_name(caller), note)
    if done.outcome == "unknown":  # its site was deleted meanwhile
        raise HTTPException(404, f"alert_id: no alert {alert_id}")
    assert done.alert is not None
    if done.outcome == "cleared":
        raise HTTPException(409, f"alert_id: alert {alert_id} was cleared at "
                                 f"{done.alert['cleared_at']} ({done.alert['cleared_detail']}) "
                                 "before anyone acknowledged it: nothing to take on")
    return Response(orjson.dumps(done.alert), media_type="application/json")
