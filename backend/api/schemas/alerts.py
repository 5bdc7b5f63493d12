"""``/api/v1/alerts``: stored alerts and the state of their evaluator and webhook."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, StringConstraints

from backend.alerts.rules import AlertKind
from backend.storage.tables import ACK_NOTE_MAX_CHARS
from backend.text import one_line

AlertState = Literal["active", "cleared"]


class AlertRead(BaseModel):
    """One alert: raised once when its condition starts, cleared once when it ends."""

    id: int
    site_id: str
    array: str = Field(description="the array the alert is about (`tracker`, `fixed`, …)")
    kind: AlertKind
    fault_kind: str | None = Field(description="for `fault`: the diagnosis' kind (`stuck`, "
                                               "`module_loss`, `dropout`, …); else null")
    title: str = Field(description="the kind (and the fault's) in words, e.g. `Fault: tracker "
                                   "stuck`: what the dashboard and the webhook's text say")
    state: AlertState
    since: str = Field(description="when the condition began (UTC): the last reading, the "
                                   "fault's first day, the first low-PR day")
    raised_at: str = Field(description="when the service raised it (UTC)")
    cleared_at: str | None = Field(description="when it was cleared (UTC); null while active")
    detail: str = Field(description="what was found, in plain words")
    cleared_detail: str | None = Field(description="why it was cleared, in plain words")
    data: dict[str, Any] = Field(description="the numbers behind it, units in the names")
    webhook_status: Literal["off", "queued", "delivered", "failed", "dropped"] = Field(
        description="delivery of its latest event (raised, acknowledged or cleared) to the "
                    "webhook")
    webhook_attempts: int
    acknowledged_at: str | None = Field(description="when an operator acknowledged it (UTC); "
                                                    "null while nobody has")
    acknowledged_by: str | None = Field(description="who: the label of the token used, "
                                                    "`token #<id>` for a token without one, "
                                                    "or `admin`")
    acknowledged_note: str | None = Field(description="what they said (optional)")


class AcknowledgeCreate(BaseModel):
    """An operator's acknowledgement of an alert: seen, someone is on it."""

    model_config = ConfigDict(extra="forbid", strict=True)

    note: Annotated[str, StringConstraints(max_length=ACK_NOTE_MAX_CHARS),
                    AfterValidator(one_line)] | None = Field(
                             None,
                             examples=["sent Luis to check the azimuth drive"],
                             description="a short note for colleagues (one line, no control "
                                         "characters); blank is no note")


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
    counts: dict[str, int] = Field(description="`active`, `cleared` and "
                                               "`active_unacknowledged` alerts matching "
                                               "`site_id` and `kind` (whatever `state` and "
                                               "`acknowledged`)")
    evaluator: EvaluatorRead
