"""The webhook sender: alert events POSTed as JSON, on a thread of their own.

:class:`WebhookSender` owns a bounded queue (``Settings.alerts.webhook_queue``) and one
thread (``heliotwin-alert-webhook``). :meth:`WebhookSender.offer` never waits: an event
that finds the queue full is dropped and counted (its alert stays stored, its
``webhook_status`` says ``dropped``). The thread sends the events one at a time, in the
order they were offered — the order they were stored (a receiver sees an alert's ``raised``
before its ``acknowledged``, and both before its ``cleared``):

- a 2xx answer delivers it;
- no answer (refused, reset, ``Settings.alerts.webhook_timeout_s`` passed), a 5xx, 408,
  425 or 429 is retried after ``alert_webhook_backoff_s`` · 2^k (k = 0, 1, …), at most
  ``alert_webhook_backoff_max_s`` (:func:`backend.retry.backoff`, tenacity) — and never
  sooner than a 429/503's ``Retry-After``, itself capped at ``alert_webhook_backoff_max_s``
  — up to ``alert_webhook_retries`` times, then ``failed``;
- any other 4xx is ``failed`` at once (the receiver refuses this request; sending it
  again would change nothing).

Each POST carries ``Content-Type: application/json``, ``User-Agent: heliotwin/<version>``,
``X-Heliotwin-Event`` (``raised``/``acknowledged``/``cleared``), ``X-Heliotwin-Event-Id``
(the same on every retry, so a receiver can drop a repeat) and, with
``Settings.alerts.webhook_secret``, ``X-Heliotwin-Signature: sha256=<hex HMAC-SHA256 of
the body>``. Waits between retries end at once at shutdown; events still queued then are
logged and counted ``unsent`` (their alerts keep ``webhook_status = queued`` and are
offered again at the next start).
"""

from __future__ import annotations

import hashlib
import hmac
import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from email.utils import parsedate_to_datetime
from typing import Any
from urllib.parse import urlsplit

import httpx
from tenacity import RetryCallState, Retrying, retry_if_exception_type, stop_after_attempt

from backend.retry import Stopped, backoff, stoppable_sleep

logger = logging.getLogger(__name__)

RETRYABLE = {408, 425, 429, 500, 502, 503, 504}


class _Retryable(Exception):
    """An attempt worth repeating: no answer, or a status in :data:`RETRYABLE` (with the
    answer's ``Retry-After`` [s], if any)."""

    def __init__(self, why: str, after_s: float | None = None) -> None:
        super().__init__(why)
        self.after_s = after_s


@dataclass
class Event:
    """One event of one alert, its body ready to send."""

    alert_id: int
    event: str  # raised | acknowledged | cleared
    body: bytes

    @property
    def event_id(self) -> str:
        return f"{self.alert_id}:{self.event}"


#: ``on_result(event, status, attempts)``: status ``delivered``, ``failed`` or ``dropped``.
ResultHook = Callable[[Event, str, int], None]


def redact(url: str) -> str:
    """``https://hooks.example.com/…``: the scheme and host only (a path may hold a secret)."""
    parts = urlsplit(url)
    return f"{parts.scheme}://{parts.netloc.rsplit('@', 1)[-1]}/…"


def retry_after_s(value: str | None) -> float | None:
    """A ``Retry-After`` header in seconds (delta-seconds or an HTTP date), or None."""
    if not value:
        return None
    try:
        return max(0.0, float(value))
    except ValueError:
        pass
    try:
        return max(0.0, parsedate_to_datetime(value).timestamp() - time.time())
    except (TypeError, ValueError, IndexError):
        return None


class WebhookSender:
    """POSTs alert events to one URL (see the module docstring)."""

    def __init__(self, url: str, *, timeout_s: float = 5.0, retries: int = 5,
                 backoff_s: float = 2.0, backoff_max_s: float = 300.0, queue_size: int = 1000,
                 secret: str | None = None, user_agent: str = "heliotwin",
                 on_result: ResultHook | None = None) -> None:
        self.url = url
        self.where = redact(url)
        self.timeout_s = timeout_s
        self.retries = retries
        self.backoff_s = backoff_s
        self.backoff_max_s = backoff_max_s
        self.secret = secret.encode() if secret else None
        self.user_agent = user_agent
        self.on_result = on_result
        self._queue: queue.Queue[Event] = queue.Queue(maxsize=queue_size)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self.counts = {"offered": 0, "delivered": 0, "failed": 0, "dropped": 0, "retries": 0,
                       "unsent": 0}
        self.last_error: str | None = None
        self.last_delivered_s: float | None = None
        self.sending = False

    # -- lifecycle -----------------------------------------------------------
    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="heliotwin-alert-webhook",
                                        daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float | None = None) -> None:
        """Stop after the attempt in flight (at most the POST timeout); log what is left."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(self.timeout_s + 2.0 if timeout_s is None else timeout_s)
            self._thread = None
        while True:
            try:
                ev = self._queue.get_nowait()
            except queue.Empty:
                break
            self._count("unsent")
            logger.warning("alert webhook: event %s not sent at shutdown (offered again at the "
                           "next start): %s", ev.event_id, ev.body[:300].decode(errors="replace"))

    # -- the producer side: never blocks -------------------------------------
    def offer(self, ev: Event) -> bool:
        """Queue ``ev``; False (and counted ``dropped``) when the queue is full."""
        self._count("offered")
        try:
            self._queue.put_nowait(ev)
        except queue.Full:
            self._count("dropped")
            logger.warning("alert webhook queue full (%d events): event %s dropped",
                           self._queue.maxsize, ev.event_id)
            self._report(ev, "dropped", 0)
            return False
        return True

    def status(self) -> dict[str, Any]:
        with self._lock:
            counts = dict(self.counts)
        return {"url": self.where, "queued": self._queue.qsize() + (1 if self.sending else 0),
                "queue_size": self._queue.maxsize, **counts, "last_error": self.last_error,
                "last_delivered_at": None if self.last_delivered_s is None else
                time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(self.last_delivered_s))}

    # -- the thread ------------------------------------------------------------
    def _count(self, name: str, n: int = 1) -> None:
        with self._lock:
            self.counts[name] += n

    def _report(self, ev: Event, status: str, attempts: int) -> None:
        if self.on_result is not None:
            try:
                self.on_result(ev, status, attempts)
            except Exception:  # noqa: BLE001 - bookkeeping must not stop the sender
                logger.exception("alert webhook: recording the outcome of %s failed",
                                 ev.event_id)

    def _run(self) -> None:
        with httpx.Client(timeout=self.timeout_s, follow_redirects=False) as client:
            while not self._stop.is_set():
                try:
                    ev = self._queue.get(timeout=0.25)
                except queue.Empty:
                    continue
                self.sending = True
                try:
                    self._deliver(client, ev)
                finally:
                    self.sending = False

    def _headers(self, ev: Event) -> dict[str, str]:
        headers = {"Content-Type": "application/json", "User-Agent": self.user_agent,
                   "X-Heliotwin-Event": ev.event, "X-Heliotwin-Event-Id": ev.event_id}
        if self.secret is not None:
            digest = hmac.new(self.secret, ev.body, hashlib.sha256).hexdigest()
            headers["X-Heliotwin-Signature"] = f"sha256={digest}"
        return headers

    def _deliver(self, client: httpx.Client, ev: Event) -> None:
        """POST ``ev`` until delivered, refused, out of retries or stopped (module docstring);
        the waits are :func:`backend.retry.backoff`'s, never sooner than a Retry-After."""
        policy = backoff(self.backoff_s, self.backoff_max_s)
        attempts = 0
        last_why = ""

        def attempt() -> httpx.Response:
            nonlocal attempts, last_why
            attempts += 1
            try:
                r = client.post(self.url, content=ev.body, headers=self._headers(ev))
            except httpx.HTTPError as exc:
                last_why = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
                raise _Retryable(last_why) from exc
            if r.status_code in RETRYABLE:
                last_why = f"HTTP {r.status_code}"
                raise _Retryable(last_why, retry_after_s(r.headers.get("retry-after")))
            return r

        def wait(state: RetryCallState) -> float:
            exc = state.outcome.exception() if state.outcome is not None else None
            after = exc.after_s if isinstance(exc, _Retryable) else None
            return min(max(policy(state), after or 0.0), self.backoff_max_s)

        def before_sleep(state: RetryCallState) -> None:
            wait_s = state.next_action.sleep if state.next_action is not None else 0.0
            self.last_error = f"{last_why} (event {ev.event_id}, attempt {attempts})"
            logger.warning("alert webhook %s: %s; retry %d of %d in %.1f s", self.where,
                           last_why, attempts, self.retries, wait_s)
            self._count("retries")

        retrying = Retrying(stop=stop_after_attempt(self.retries + 1), wait=wait,
                            retry=retry_if_exception_type(_Retryable),
                            sleep=stoppable_sleep(self._stop), before_sleep=before_sleep,
                            reraise=True)
        try:
            r = retrying(attempt)
        except _Retryable:
            self._fail(ev, attempts, f"{last_why}; gave up after {attempts} attempts")
            return
        except Stopped:
            self._count("unsent")
            logger.warning("alert webhook: event %s not sent at shutdown (%s)", ev.event_id,
                           last_why)
            return
        if 200 <= r.status_code < 300:
            self._count("delivered")
            self.last_delivered_s = time.time()
            self._report(ev, "delivered", attempts)
            return
        self._fail(ev, attempts, f"HTTP {r.status_code}: refused, not retried")

    def _fail(self, ev: Event, attempts: int, why: str) -> None:
        self._count("failed")
        self.last_error = f"{why} (event {ev.event_id})"
        logger.error("alert webhook %s: event %s failed: %s", self.where, ev.event_id, why)
        self._report(ev, "failed", attempts)
