"""``/api/v1/alerts``: the stored alerts — silent loggers, diagnosis faults, low performance
ratio — and the state of their evaluator and webhook (``backend/alerts/``,
``docs/service.md`` "Alerts"). Readable without a token, like the dashboard's other reads."""

from __future__ import annotations

import asyncio
from typing import Annotated, Any, Literal

import orjson
from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import Response
from pydantic import BaseModel, Field

from backend.alerts.service import list_alerts
from backend.api.deps import ContextDep

router = APIRouter(prefix="/api/v1/alerts", tags=["alerts"])

AlertKind = Literal["logger_silent", "fault", "low_performance_ratio"]
AlertState = Literal["active", "cleared"]


class AlertRead(BaseModel):
    """One alert: raised once when its condition starts, cleared once when it ends."""

    id: int
    site_id: str
    array: str = Field(description="the array the alert is about (`tracker`, `fixed`, …)")
    kind: AlertKind
    fault_kind: str | None = Field(description="for `fault`: the diagnosis' kind (`stuck`, "
                                               "`module_loss`, `dropout`, …); else null")
    state: AlertState
    since: str = Field(description="when the condition began (UTC): the last reading, the "
                                   "fault's first day, the first low-PR day")
    raised_at: str = Field(description="when the service raised it (UTC)")
    cleared_at: str | None = Field(description="when it was cleared (UTC); null while active")
    detail: str = Field(description="what was found, in plain words")
    cleared_detail: str | None = Field(description="why it was cleared, in plain words")
    data: dict[str, Any] = Field(description="the numbers behind it, units in the names")
    webhook_status: Literal["off", "queued", "delivered", "failed", "dropped"] = Field(
        description="delivery of its latest event (raised or cleared) to the webhook")
    webhook_attempts: int


class WebhookRead(BaseModel):
    """The webhook sender: where (scheme and host only) and its counters."""

    url: str
    queued: int
    queue_size: int
    offered: int
    delivered: int
    failed: int
    dropped: int = Field(description="events refused because the queue was full")
    retries: int
    unsent: int = Field(description="events still waiting at a shutdown (sent at the next start)")
    last_error: str | None
    last_delivered_at: str | None


class EvaluatorRead(BaseModel):
    """The alert evaluator and its thresholds (the `HELIOTWIN_ALERT_*` settings)."""

    enabled: bool
    interval_s: float | None = None
    last_evaluated_at: str | None = None
    last_evaluation_ms: float | None = None
    max_evaluation_ms: float | None = Field(None, description="the slowest round so far (the "
                                                              "first of a day diagnoses it)")
    evaluations: int = 0
    active: int = 0
    errors: list[str] = []
    silent_min: float | None = None
    pr_below: float | None = None
    fault_confidence_min: float | None = None
    diagnosis_days: int | None = None
    webhook: WebhookRead | None = None


class AlertsRead(BaseModel):
    """The alerts matching the query, newest raised first."""

    alerts: list[AlertRead]
    counts: dict[str, int] = Field(description="`active` and `cleared` alerts matching "
                                               "`site_id` and `kind` (whatever `state`)")
    evaluator: EvaluatorRead


@router.get("", responses={200: {"model": AlertsRead},
                           404: {"description": "unknown site_id"}, 422: {}})
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

    body = await asyncio.to_thread(read)
    body["evaluator"] = ctx.alerts.status() if ctx.alerts is not None else {"enabled": False}
    return Response(orjson.dumps(body), media_type="application/json")
