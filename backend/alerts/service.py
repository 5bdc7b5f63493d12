"""The alert evaluator and the read side of ``GET /api/v1/alerts``.

:class:`AlertService` runs on a thread of its own (``heliotwin-alerts``), started and
stopped by :class:`backend.context.ServiceContext` (``Settings.alerts.enabled``). Every
``Settings.alerts.interval_s`` (the first time one interval after start) it evaluates,
for every site with arrays (:mod:`backend.alerts.rules`):

- each array's last measured reading — one primary-key lookup per array, the same
  reading the overview's logger tiles show (``backend/measurements/status.py``);
- for a site with a tracker and a fixed array whose tracker reported within the last
  ``Settings.alerts.diagnosis_days`` complete local days: the diagnosis of those days
  (:func:`backend.diagnosis.service.diagnosis`; cached per day in ``diagnosis_days``, so
  a day is computed once, when it is complete, and again only if late readings of it
  arrive) → faults and the performance ratio; the window ends with the latest day the
  tracker's readings reached (a back-fill posted day by day is not judged on a day it has
  not reached yet).

A condition not yet active is inserted as an ``active`` alert (through the writer, the
one module that commits) and its ``raised`` event offered to the webhook sender; an
active alert whose rule was evaluated and no longer finds it is updated to ``cleared``
(``cleared_at``, ``cleared_detail``) and its ``cleared`` event offered. Nothing is sent
again while a condition lasts. Between the two an operator may acknowledge it, once
(:func:`acknowledge`, ``POST /api/v1/alerts/{alert_id}/acknowledge``): its ``acknowledged``
event goes out between the other two. The active alerts are read back from the database at
start, so a restart neither repeats nor forgets them. Ingestion never waits for any of
this: the evaluator only reads (its own pooled connections) and queues small writes,
and the webhook has a thread and a bounded queue of its own (:mod:`backend.alerts.webhook`).
"""

from __future__ import annotations

import contextlib
import datetime as dt
import logging
import threading
import time
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from typing import TYPE_CHECKING, Any, Literal

import orjson
from sqlalchemy import Connection, Engine, func, insert, select, update

from backend.alerts import rules
from backend.alerts.webhook import Event, WebhookSender
from backend.diagnosis.service import diagnosis
from backend.sites import SiteInfo
from backend.storage.tables import SOURCE_CODES, AlertRow, Measurement
from sim.sun import daylight_s

if TYPE_CHECKING:
    from backend.context import ServiceContext

logger = logging.getLogger(__name__)

MEASURED = SOURCE_CODES["measured"]
_COLUMNS = ("id", "site_id", "array_name", "kind", "fault_kind", "state", "since_s",
            "raised_at_s", "cleared_at_s", "detail", "cleared_detail", "data_json",
            "webhook_status", "webhook_attempts", "acknowledged_at_s", "acknowledged_by",
            "acknowledged_note")


def _version() -> str:
    try:
        return version("heliotwin")
    except PackageNotFoundError:
        return "0+unknown"


def iso(ts_s: int | float | None) -> str | None:
    """UTC ISO 8601 with ``Z``, or None."""
    if ts_s is None:
        return None
    return dt.datetime.fromtimestamp(int(ts_s), dt.UTC).isoformat().replace("+00:00", "Z")


def alert_dict(row: Any) -> dict[str, Any]:
    """An ``alerts`` row (a mapping of its columns) as the API and the webhook show it."""
    return {
        "id": row["id"], "site_id": row["site_id"], "array": row["array_name"],
        "kind": row["kind"], "fault_kind": row["fault_kind"],
        "title": rules.title(row["kind"], row["fault_kind"]), "state": row["state"],
        "since": iso(row["since_s"]), "raised_at": iso(row["raised_at_s"]),
        "cleared_at": iso(row["cleared_at_s"]), "detail": row["detail"],
        "cleared_detail": row["cleared_detail"], "data": orjson.loads(row["data_json"]),
        "webhook_status": row["webhook_status"], "webhook_attempts": row["webhook_attempts"],
        "acknowledged_at": iso(row["acknowledged_at_s"]),
        "acknowledged_by": row["acknowledged_by"], "acknowledged_note": row["acknowledged_note"],
    }


def latest_event(alert: dict[str, Any]) -> str:
    """An alert's latest webhook event: ``raised``, then ``acknowledged`` (at most once,
    while active), then ``cleared`` — the order they happen in, and are sent in."""
    if alert["state"] == "cleared":
        return "cleared"
    return "raised" if alert["acknowledged_at"] is None else "acknowledged"


def get_alert(conn: Connection, alert_id: int) -> dict[str, Any] | None:
    """One stored alert as the API shows it, or None."""
    cols = [getattr(AlertRow, c) for c in _COLUMNS]
    row = conn.execute(select(*cols).where(AlertRow.id == alert_id)).mappings().first()
    return None if row is None else alert_dict(row)


@dataclass(frozen=True)
class Acknowledgement:
    """What :func:`acknowledge` did: ``acknowledged`` (now), ``already`` (before: kept as it
    was), ``cleared`` (too late: nothing to take on) or ``unknown``; and the alert as stored."""

    outcome: Literal["acknowledged", "already", "cleared", "unknown"]
    alert: dict[str, Any] | None


def acknowledge(ctx: ServiceContext, alert_id: int, by: str, note: str | None,
                now_s: float | None = None) -> Acknowledgement:
    """Record that ``by`` has taken alert ``alert_id`` (with ``note``): once, and only while
    it is active — a second acknowledgement keeps the first's time, name and note. One
    transaction of the writer; then, with a webhook, its ``acknowledged`` event is offered
    (under :attr:`AlertService.events`, so events go out in the order they were stored).
    Waits for the writer: call it off the event loop."""
    alerts = ctx.alerts
    sender = alerts.sender if alerts is not None else None
    now = int(time.time() if now_s is None else now_s)

    def store(conn: Connection) -> Acknowledgement:
        alert = get_alert(conn, alert_id)
        if alert is None:
            return Acknowledgement("unknown", None)
        if alert["acknowledged_at"] is not None:
            return Acknowledgement("already", alert)
        if alert["state"] != "active":
            return Acknowledgement("cleared", alert)
        conn.execute(update(AlertRow).where(AlertRow.id == alert_id).values(
            acknowledged_at_s=now, acknowledged_by=by, acknowledged_note=note,
            webhook_status="off" if sender is None else "queued", webhook_attempts=0))
        return Acknowledgement("acknowledged", get_alert(conn, alert_id))

    with alerts.events if alerts is not None else contextlib.nullcontext():
        done: Acknowledgement = ctx.writer.call(store).result(timeout=60)
        if done.outcome == "acknowledged" and alerts is not None:
            assert done.alert is not None
            alerts.offer(done.alert, "acknowledged")
    if done.outcome == "acknowledged" and done.alert is not None:
        a = done.alert
        logger.info("%s", rules.summary(a["site_id"], a["kind"], a["array"], a["fault_kind"],
                                        "acknowledged", rules.acknowledged_text(a)))
    return done


def list_alerts(conn: Connection, site_id: str | None = None, state: str | None = None,
                kind: str | None = None, limit: int = 100,
                acknowledged: bool | None = None) -> dict[str, Any]:
    """Stored alerts, newest raised first, and how many of each state (and active ones not
    acknowledged) match the ``site_id`` and ``kind`` filter."""
    where = []
    if site_id is not None:
        where.append(AlertRow.site_id == site_id)
    if kind is not None:
        where.append(AlertRow.kind == kind)
    counts = {"active": 0, "cleared": 0, "active_unacknowledged": 0}
    for st, acked, n in conn.execute(
            select(AlertRow.state, AlertRow.acknowledged_at_s.is_not(None), func.count())
            .where(*where).group_by(AlertRow.state, AlertRow.acknowledged_at_s.is_not(None))):
        counts[st] += int(n)
        if st == "active" and not acked:
            counts["active_unacknowledged"] += int(n)
    if state is not None:
        where.append(AlertRow.state == state)
    if acknowledged is not None:
        where.append(AlertRow.acknowledged_at_s.is_not(None) if acknowledged
                     else AlertRow.acknowledged_at_s.is_(None))
    cols = [getattr(AlertRow, c) for c in _COLUMNS]
    rows = conn.execute(select(*cols).where(*where)
                        .order_by(AlertRow.raised_at_s.desc(), AlertRow.id.desc())
                        .limit(limit)).mappings().all()
    return {"alerts": [alert_dict(r) for r in rows], "counts": counts}


#: Daylight is sampled at this step [s] over the last ``DAYLIGHT_SPAN_S`` of a span, and at
#: most ``DAYLIGHT_SAMPLES`` times over what lies before it.
DAYLIGHT_STEP_S = 300
DAYLIGHT_SPAN_S = 3 * 86400
DAYLIGHT_SAMPLES = 3000


def _daylight_in(info: SiteInfo, t0_s: float, t1_s: float, step_s: float) -> float:
    s = info.site
    return daylight_s(t0_s, t1_s, step_s, s.latitude, s.longitude, s.altitude, s.temp_air)


def daylight_seconds(info: SiteInfo, t0_s: float, t1_s: float) -> float:
    """Seconds of ``[t0, t1]`` with the sun's apparent elevation above 0° at the site: the
    last ``DAYLIGHT_SPAN_S`` sampled every ``DAYLIGHT_STEP_S``, what lies before at most
    ``DAYLIGHT_SAMPLES`` times (their middles drift through the day: a month's daylight
    to a few tenths of a percent). The whole span counts: taking its last three days only,
    a polar night held the silence of a logger quiet since summer at zero (no alert, and
    an active one cleared as "reports again"; a tester's finding at Tromsø)."""
    if t1_s <= t0_s:
        return 0.0
    recent = max(t0_s, t1_s - DAYLIGHT_SPAN_S)
    earlier = recent - t0_s
    return (_daylight_in(info, recent, t1_s, DAYLIGHT_STEP_S)
            + _daylight_in(info, t0_s, recent, max(DAYLIGHT_STEP_S, earlier / DAYLIGHT_SAMPLES)))


def silence_counter(settings: Any, info: SiteInfo) -> Any:
    """The seconds of ``[a, b]`` that count as a logger's silence at ``info``'s site, as a
    function of (a, b): the daylight seconds (:func:`daylight_seconds`) while
    ``Settings.alerts.silent_daylight_only``, else None (all of them). The one rule of the
    ``logger_silent`` alert and of the overview's stale logger (``SiteStatusRead``): a logger
    silent through the night was red "4.0 h ago" there while the alerts said nothing."""
    if settings.alerts.silent_daylight_only:
        return lambda a, b: daylight_seconds(info, a, b)
    return None


def _local_midnight(day: dt.date, zone: Any) -> dt.datetime:
    return dt.datetime(day.year, day.month, day.day, tzinfo=zone)


class AlertService:
    """The evaluator thread and the webhook sender (see the module docstring)."""

    def __init__(self, ctx: ServiceContext, now_s: float | None = None) -> None:
        s = ctx.settings
        self.ctx = ctx
        self.engine: Engine = ctx.engine
        self.interval_s = s.alerts.interval_s
        self.started_s = time.time() if now_s is None else now_s
        self.sender: WebhookSender | None = None
        a = s.alerts
        if a.webhook_url:
            self.sender = WebhookSender(
                str(a.webhook_url), timeout_s=a.webhook_timeout_s, retries=a.webhook_retries,
                backoff_s=a.webhook_backoff_s, backoff_max_s=a.webhook_backoff_max_s,
                queue_size=a.webhook_queue,
                secret=None if a.webhook_secret is None else a.webhook_secret.get_secret_value(),
                user_agent=f"heliotwin/{_version()}", on_result=self._delivered)
        self._active: dict[rules.Key, dict[str, Any]] = {}
        #: held from the write of an alert's change to the offer of its event (raise, clear,
        #: :func:`acknowledge`): events are offered in the order they were stored
        self.events = threading.Lock()
        self._errors: dict[tuple[str, str], str] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.last_evaluated_s: float | None = None
        self.last_evaluation_ms: float | None = None
        self.max_evaluation_ms: float | None = None
        self.evaluations = 0

    # -- lifecycle -----------------------------------------------------------
    def start(self) -> None:
        """Read the active alerts back, re-offer unsent events, start the threads."""
        with self.engine.connect() as conn:
            cols = [getattr(AlertRow, c) for c in _COLUMNS]
            active = conn.execute(select(*cols).where(AlertRow.state == "active")
                                  .order_by(AlertRow.id)).mappings().all()
            queued = conn.execute(select(*cols).where(AlertRow.webhook_status == "queued")
                                  .order_by(AlertRow.id)).mappings().all()
        for row in active:
            a = alert_dict(row)
            self._active[self._key(a)] = a
        if self.sender is not None:
            self.sender.start()
            for row in queued:
                a = alert_dict(row)
                self.offer(a, latest_event(a))
        self._thread = threading.Thread(target=self._run, name="heliotwin-alerts", daemon=True)
        self._thread.start()
        logger.info("alerts: %d active; evaluated every %.3g s; webhook %s", len(self._active),
                    self.interval_s, "off" if self.sender is None else self.sender.where)

    def stop(self, timeout_s: float = 30.0) -> None:
        """End the evaluator (after its current evaluation), then the sender."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None
        if self.sender is not None:
            self.sender.stop()

    def _run(self) -> None:
        while not self._stop.wait(self.interval_s):
            try:
                self.evaluate()
            except Exception:  # noqa: BLE001 - the next round tries again
                logger.exception("alert evaluation failed")

    def status(self) -> dict[str, Any]:
        """For ``GET /api/v1/alerts``: the evaluator, its thresholds and the webhook."""
        s = self.ctx.settings
        return {
            "enabled": True, "interval_s": self.interval_s,
            "last_evaluated_at": iso(self.last_evaluated_s),
            "last_evaluation_ms": self.last_evaluation_ms,
            "max_evaluation_ms": self.max_evaluation_ms, "evaluations": self.evaluations,
            "active": len(self._active), "errors": sorted(self._errors.values()),
            "silent_min": s.alerts.silent_min, "pr_below": s.alerts.pr_below,
            "fault_confidence_min": s.alerts.fault_confidence_min,
            "diagnosis_days": s.alerts.diagnosis_days,
            "webhook": None if self.sender is None else self.sender.status(),
        }

    # -- evaluation ----------------------------------------------------------
    def evaluate(self, now_s: float | None = None) -> None:
        """One round: evaluate every rule of every site, raise and clear."""
        t0 = time.perf_counter()
        now = time.time() if now_s is None else now_s
        found = rules.Evaluation()
        for info in list(self.ctx.registry.sites.values()):
            if not info.arrays:
                continue
            found.extend(self._guard("logger_silent", info, lambda i=info: self._silent(i, now)))
            if self.ctx.settings.alerts.diagnosis_days > 0 and info.has_twin():
                found.extend(self._guard("diagnosis", info,
                                         lambda i=info: self._diagnosed(i, now)))
        self._reconcile(found, now)
        self.evaluations += 1
        self.last_evaluated_s = now
        self.last_evaluation_ms = round(1000 * (time.perf_counter() - t0), 1)
        self.max_evaluation_ms = max(self.max_evaluation_ms or 0.0, self.last_evaluation_ms)

    def _guard(self, rule: str, info: SiteInfo, fn: Any) -> rules.Evaluation:
        """A rule's evaluation, or an empty one (nothing cleared) when it fails; logged
        once per distinct failure."""
        key = (rule, info.site_id)
        try:
            out: rules.Evaluation = fn()
        except Exception as exc:  # noqa: BLE001 - one site's failure must not stop the rest
            msg = f"{rule} of {info.site_id}: {type(exc).__name__}: {exc}"
            if self._errors.get(key) != msg:
                logger.exception("alerts: %s", msg)
            self._errors[key] = msg
            return rules.Evaluation()
        self._errors.pop(key, None)
        return out

    def _silent(self, info: SiteInfo, now: float) -> rules.Evaluation:
        last: dict[str, int | None] = {}
        cadence: dict[str, float] = {}
        with self.engine.connect() as conn:
            for name, arr in info.arrays.items():
                # the latest readings (the overview's): the last one and the logger's cadence
                ts = conn.execute(select(Measurement.ts_s).where(
                    Measurement.array_id == arr.array_id, Measurement.source == MEASURED)
                    .order_by(Measurement.ts_s.desc()).limit(rules.CADENCE_READINGS)).scalars().all()
                last[name] = int(ts[0]) if ts else None
                cadence[name] = rules.cadence_s(list(ts))
        return rules.silent_loggers(info.site_id, info.zone, last, now, self.started_s,
                                    self.ctx.settings.alerts.silent_min,
                                    silence_counter(self.ctx.settings, info), cadence)

    def _diagnosed(self, info: SiteInfo, now: float) -> rules.Evaluation:
        s = self.ctx.settings
        tracker, fixed = info.array_of_kind("tracker"), info.array_of_kind("fixed")
        assert tracker is not None and fixed is not None
        today = dt.datetime.fromtimestamp(now, info.zone).date()
        end = _local_midnight(today, info.zone)
        start = _local_midnight(today - dt.timedelta(days=s.alerts.diagnosis_days), info.zone)
        # the tracker logger's readings set the days judged; without any, the fixed array's
        # (under a sensor's sky it is judged itself: fixed_underperformance — a site whose
        # tracker logger is not there yet had its snowed-in reference array never alerted)
        with self.engine.connect() as conn:
            for array in (tracker, fixed):
                first, last = conn.execute(select(
                    func.min(Measurement.ts_s), func.max(Measurement.ts_s)).where(
                    Measurement.array_id == array.array_id, Measurement.source == MEASURED,
                    Measurement.ts_s >= int(start.timestamp()),
                    Measurement.ts_s < int(end.timestamp()))).one()
                if first is not None:
                    break
        if first is None:  # no readings in the window: nothing to tell
            return rules.Evaluation()
        first_day = dt.datetime.fromtimestamp(int(first), info.zone).date()
        start = max(start, _local_midnight(first_day, info.zone))
        # the latest day judged is the latest the logger's readings reached: the days after
        # it are not in yet (a back-fill day by day, a logger offline — that one is
        # logger_silent's to tell), and diagnosed they would be whole-day dropouts
        last_day = dt.datetime.fromtimestamp(int(last), info.zone).date()
        end = min(end, _local_midnight(last_day + dt.timedelta(days=1), info.zone))
        answer = diagnosis(self.ctx, info, start, end)
        return rules.diagnosed(info.site_id, info.zone, tracker.name, answer["days"],
                               s.alerts.pr_below, s.alerts.fault_confidence_min)

    @staticmethod
    def _key(a: dict[str, Any]) -> rules.Key:
        return (a["site_id"], a["array"], a["kind"], a["fault_kind"] or "")

    def _reconcile(self, found: rules.Evaluation, now: float) -> None:
        holding = {c.key: c for c in found.conditions}
        for key, cond in holding.items():
            old = self._active.get(key)
            if old is not None and cond.kind == "logger_silent" \
                    and old["since"] != iso(cond.since_s):
                # a newer reading was stored (late, or back-filled) and the logger is silent
                # again since it: that silence ended, this one is new (docs/service.md)
                self._clear(key, old, f"a newer reading was stored (last one "
                                      f"{cond.data['last_reading_ts']})", now)
            if key not in self._active:
                self._raise(cond, now)
        for key, alert in list(self._active.items()):
            if key in holding or key[:3] not in found.scopes:
                continue
            note = found.clear_notes.get(key) or found.clear_notes.get(key[:3]) \
                or "the condition no longer holds"
            self._clear(key, alert, note, now)

    def _raise(self, cond: rules.Condition, now: float) -> None:
        values = {
            "site_id": cond.site_id, "array_name": cond.array, "kind": cond.kind,
            "fault_kind": cond.fault_kind, "state": "active", "since_s": cond.since_s,
            "raised_at_s": int(now), "cleared_at_s": None, "detail": cond.detail,
            "cleared_detail": None, "data_json": orjson.dumps(cond.data).decode(),
            "webhook_status": "off" if self.sender is None else "queued",
            "webhook_attempts": 0,
        }

        def store(conn: Connection) -> int:
            key = conn.execute(insert(AlertRow).values(**values)).inserted_primary_key
            assert key is not None
            return int(key[0])

        with self.events:
            try:
                alert_id = self.ctx.writer.call(store).result(timeout=60)
            except Exception:  # noqa: BLE001 - not raised now: the next round tries again
                logger.exception("alerts: could not store %s", cond.key)
                return
            alert = alert_dict({**values, "id": alert_id, "acknowledged_at_s": None,
                                "acknowledged_by": None, "acknowledged_note": None})
            self._active[cond.key] = alert
            self.offer(alert, "raised")
        logger.warning("%s", rules.summary(cond.site_id, cond.kind, cond.array, cond.fault_kind,
                                           "active", cond.detail))

    def _clear(self, key: rules.Key, alert: dict[str, Any], note: str, now: float) -> None:
        changes = {"state": "cleared", "cleared_at_s": int(now), "cleared_detail": note,
                   "webhook_status": "off" if self.sender is None else "queued",
                   "webhook_attempts": 0}

        def store(conn: Connection) -> dict[str, Any] | None:
            conn.execute(update(AlertRow).where(AlertRow.id == alert["id"]).values(**changes))
            return get_alert(conn, alert["id"])  # as stored: with an acknowledgement, if any

        with self.events:
            try:
                cleared = self.ctx.writer.call(store).result(timeout=60)
            except Exception:  # noqa: BLE001 - still active: the next round tries again
                logger.exception("alerts: could not clear alert %s", alert["id"])
                return
            del self._active[key]
            if cleared is not None:  # None: its site was deleted meanwhile
                self.offer(cleared, "cleared")
        logger.info("%s", rules.summary(alert["site_id"], alert["kind"], alert["array"],
                                        alert["fault_kind"], "cleared", note))

    # -- the webhook -----------------------------------------------------------
    def offer(self, alert: dict[str, Any], event: str) -> None:
        """Hand ``alert``'s ``event`` (``raised``, ``acknowledged``, ``cleared``) to the
        webhook sender, if there is one (never waits)."""
        if self.sender is None:
            return
        words = {"raised": alert["detail"], "cleared": alert["cleared_detail"],
                 "acknowledged": rules.acknowledged_text(alert)}[event]
        text = rules.summary(alert["site_id"], alert["kind"], alert["array"],
                             alert["fault_kind"], "active" if event == "raised" else event,
                             words)
        body = orjson.dumps({"event": event, "event_id": f"{alert['id']}:{event}",
                             "text": text, "alert": alert, "service": "heliotwin"})
        self.sender.offer(Event(alert["id"], event, body))

    def _delivered(self, ev: Event, status: str, attempts: int) -> None:
        """The sender's outcome of ``ev`` → the alert's ``webhook_status`` (unless the alert
        has moved on to its next event meanwhile: :func:`latest_event`)."""
        def store(conn: Connection) -> None:
            alert = get_alert(conn, ev.alert_id)  # in the writer's transaction: as it is now
            if alert is not None and latest_event(alert) == ev.event:
                conn.execute(update(AlertRow).where(AlertRow.id == ev.alert_id)
                             .values(webhook_status=status, webhook_attempts=attempts))

        try:
            self.ctx.writer.call(store)  # not waited for: the sender goes on at once
        except RuntimeError:  # the writer has stopped (shutdown): the status stays queued
            pass
