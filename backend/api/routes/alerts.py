"""``/api/v1/alerts``: the stored alerts — silent loggers, diagnosis faults, low performance
ratio — and the state of their evaluator and webhook (``backend/alerts/``,
``docs/service.md`` "Alerts"). Readable without a token, like the dashboard's other reads."""

from __future__ import annotations

from typing import Annotated, Any

import anyio
import orjson
from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import Response

from backend.alerts.service import list_alerts
from backend.api.deps import ContextDep
from backend.api.schemas.alerts import AlertKind, AlertsRead, AlertState

router = APIRouter(prefix="/api/v1/alerts", tags=["alerts"])

@router.get("", response_model=AlertsRead,
            responses={404: {"description": "unknown site_id"}, 422: {}})
async def get_alerts(
    ctx: ContextDep,
    site_id: Annotated[str | None, Query(min_length=1, max_length=64,
                                         description="only this site's alerts")] = None,
    state: Annotated[AlertState | None, Query(description="only active or only cleared")] = None,
    kind: Annotated[AlertKind | None, Query(description="only this kind")] = None,
    limit: Annotated[int, Query(ge=1, le=1000, description="most alerts answered")] = 100,
) -> Response:
    """Stored alerts (newest raised first), their counts, and the evaluator's state."""
    if site_id is not None and ctx.registry.get(site_id) is None:
        known = ", ".join(ctx.registry.sites) or "none"
        raise HTTPException(404, f"site_id: unknown site {site_id!r}; known sites: {known}")

    def read() -> dict[str, Any]:
        with ctx.engine.connect() as conn:
            return list_alerts(conn, site_id, state, kind, limit)

    body = await anyio.to_thread.run_sync(read)
    body["evaluator"] = ctx.alerts.status() if ctx.alerts is not None else {"enabled": False}
    return Response(orjson.dumps(body), media_type="application/json")
