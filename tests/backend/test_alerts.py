"""Alerts (``backend/alerts/``, issue 13 item 7): the rules, the webhook sender against a real
HTTP receiver, and the service over HTTP (in this process, ``live_service.InProcessServer``)
— a silent logger raised once and cleared once (across a restart), a fault and a low PR
from an injected diagnosis, and ingestion that never waits for a hanging webhook.

The receiver is a ``http.server.ThreadingHTTPServer`` on a free port in a thread of this
process; each test gives it a behaviour (answer 200, fail first, hang). The waits of the
sender are read from what it logs ("retry k of n in W s"), never from a clock, and "no
repeat" is checked over a number of the evaluator's rounds, not over a sleep.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import hashlib
import hmac
import http.server
import json
import logging
import re
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import get_args
from zoneinfo import ZoneInfo

import httpx
import orjson
import pandas as pd
import pytest
from live_service import Database, InProcessServer, free_port, new_database

from backend.alerts import rules
from backend.alerts.webhook import Event, WebhookSender, retry_after_s
from backend.diagnosis.faults import FAULT_WORDS, FaultKind

TZ = ZoneInfo("America/Mexico_City")  # tehuantepec's zone
SITE = "tehuantepec"
INGEST = f"/api/v1/sites/{SITE}/measurements"


# -- a real webhook receiver ------------------------------------------------------------------
class Receiver:
    """A local HTTP server recording every POST; ``behaviour(n)`` gives the n-th (0-based)
    request's status code, or None to hang until :meth:`release` (or the test ends)."""

    def __init__(self, behaviour: Callable[[int], int | None] = lambda n: 200) -> None:
        self.behaviour = behaviour
        self.requests: list[dict] = []
        self.lock = threading.Lock()
        self.released = threading.Event()
        receiver = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802 - http.server's name
                body = self.rfile.read(int(self.headers.get("Content-Length", "0")))
                with receiver.lock:
                    n = len(receiver.requests)
                    receiver.requests.append({"t": time.monotonic(), "headers": dict(
                        self.headers), "raw": body, "json": json.loads(body)})
                code = receiver.behaviour(n)
                if code is None:
                    receiver.released.wait(60)
                    return
                self.send_response(code)
                if code == 429:
                    self.send_header("Retry-After", "1")
                self.send_header("Content-Length", "0")
                self.end_headers()

            def log_message(self, *args: object) -> None:
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", free_port()), Handler)
        self.server.daemon_threads = True
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server.server_address[1]}/hook/secret-path"

    def __enter__(self) -> Receiver:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.released.set()
        self.server.shutdown()
        self.server.server_close()

    def events(self, kind: str | None = None) -> list[dict]:
        with self.lock:
            bodies = [r["json"] for r in self.requests]
        return [b for b in bodies if kind is None or b["alert"]["kind"] == kind]

    def wait_for(self, pred: Callable[[list[dict]], bool], timeout_s: float = 30.0) -> list[dict]:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            evs = self.events()
            if pred(evs):
                return evs
            time.sleep(0.05)
        raise AssertionError(f"webhook events not as expected in {timeout_s} s: {self.events()}")


# -- the rules, pure --------------------------------------------------------------------------
def test_silent_logger_rule_counts_from_the_start_and_ignores_never() -> None:
    now = 1_764_000_000.0
    last = {"tracker": int(now - 3600), "fixed": int(now - 60), "spare": None}
    ev = rules.silent_loggers(SITE, TZ, last, now, started_s=now - 7200, silent_min=30)
    assert [c.array for c in ev.conditions] == ["tracker"]
    c = ev.conditions[0]
    assert c.since_s == last["tracker"] and c.kind == "logger_silent"
    assert "60 min" in c.detail and "alert after 30 min" in c.detail
    assert c.data["silent_min"] == 60.0 and c.data["threshold_min"] == 30
    assert {s[1] for s in ev.scopes} == {"tracker", "fixed", "spare"}
    # just started: an hour of silence before the start cannot be vouched for — nothing is
    # raised, and nothing may be cleared either (the tracker's scope is not evaluated)
    ev = rules.silent_loggers(SITE, TZ, last, now, started_s=now - 60, silent_min=30)
    assert ev.conditions == [] and (SITE, "tracker", "logger_silent") not in ev.scopes


def test_a_slow_logger_is_silent_after_its_own_cadence_not_between_two_readings() -> None:
    """A 30-minute logger's next reading is due when the 30-minute threshold runs out: it
    was raised and cleared every half hour (an hourly one every hour) whenever the reading
    came a minute late. A logger slower than ``FRESH_S`` is given 2.5 of its cadence; a
    minute logger keeps the threshold alone."""
    now = 1_764_000_000.0
    last = {"tracker": int(now - 31 * 60), "fixed": int(now - 31 * 60)}
    cadence = {"tracker": 1800.0, "fixed": 60.0}
    ev = rules.silent_loggers(SITE, TZ, last, now, now - 86400, 30, cadence_s=cadence)
    assert [c.array for c in ev.conditions] == ["fixed"]
    assert (SITE, "tracker", "logger_silent") in ev.scopes  # evaluated: an alert clears
    ev = rules.silent_loggers(SITE, TZ, {"tracker": int(now - 76 * 60)}, now, now - 86400, 30,
                              cadence_s=cadence)
    c = ev.conditions[0]
    assert c.array == "tracker" and c.data["threshold_min"] == 75.0
    assert "alert after 75 min" in c.detail and "× its cadence 30 min" in c.detail
    # the service's start: the threshold's own minutes, whatever the cadence
    ev = rules.silent_loggers(SITE, TZ, {"tracker": int(now - 76 * 60)}, now, now - 31 * 60,
                              30, cadence_s=cadence)
    assert [c.array for c in ev.conditions] == ["tracker"]


def test_a_logger_that_sleeps_at_night_is_not_silent() -> None:
    """Daylight-only silence (the default): a logger quiet from sunset to 07:00 local is
    not silent; one quiet since 10:00 is, by the daylight seconds of the site's sun."""
    from backend.alerts.service import daylight_seconds
    from backend.sites import SiteInfo
    from sim.sites import load_site

    site = load_site("tehuantepec")
    info = SiteInfo(site, ZoneInfo(site.timezone), 0)
    zone = info.zone

    def at(h: int, m: int = 0) -> float:
        return dt.datetime(2024, 3, 20, h, m, tzinfo=zone).timestamp()
    night = daylight_seconds(info, at(0), at(5))
    assert night == 0.0
    # equinox at 16.4° N, 95.2° W, UTC−6: the sun rises near 06:25 local time
    assert daylight_seconds(info, at(5), at(7)) == pytest.approx(35 * 60, abs=6 * 60)
    # the tracker's logger slept from 18:50 yesterday (after sunset), the fixed one has been
    # quiet since 10:00 yesterday; at 06:40 only the fixed one has 30 min of daylight silence
    last: dict[str, int | None] = {"tracker": int(at(18, 50) - 86400),
                                   "fixed": int(at(10) - 86400)}
    ev = rules.silent_loggers(SITE, TZ, last, at(6, 40), at(6, 40) - 10 * 86400, 30,
                              lambda a, b: daylight_seconds(info, a, b))
    assert [c.array for c in ev.conditions] == ["fixed"]
    assert "of daylight" in ev.conditions[0].detail


def test_a_logger_silent_since_summer_is_silent_in_the_polar_night() -> None:
    """Tromsø (69.65° N) on 5 Dec, the sun down all day, a logger quiet since 23 Jun: all
    the daylight since counts (only the last three days did: none, so no alert, and an
    active one would clear as "reports again"; a tester's finding), to within 0.5 % of
    pvlib's sun every 10 minutes."""
    import pvlib

    from backend.alerts.service import daylight_seconds
    from backend.sites import SiteInfo
    from sim.sites import load_site

    site = dataclasses.replace(load_site("tehuantepec"), latitude=69.65, longitude=18.96,
                               altitude=10.0, timezone="Europe/Oslo")
    info = SiteInfo(site, ZoneInfo(site.timezone), 0)
    last = dt.datetime(2026, 6, 23, 21, 59, tzinfo=dt.UTC).timestamp()
    now = dt.datetime(2026, 12, 5, 12, 0, tzinfo=dt.UTC).timestamp()
    counted = daylight_seconds(info, last, now)
    when = pd.date_range(pd.Timestamp(last, unit="s", tz="UTC"),
                         pd.Timestamp(now, unit="s", tz="UTC"), freq="600s")
    up = pvlib.solarposition.get_solarposition(when, 69.65, 18.96, 10.0)["apparent_elevation"]
    assert counted == pytest.approx(float((up > 0).sum()) * 600.0, rel=0.005)
    assert daylight_seconds(info, now - 3 * 86400, now) == 0.0   # the polar night itself
    ev = rules.silent_loggers(SITE, TZ, {"tracker": int(last)}, now, now - 200 * 86400, 60,
                              lambda a, b: daylight_seconds(info, a, b))
    assert [c.array for c in ev.conditions] == ["tracker"]
    assert ev.conditions[0].data["silent_min"] > 100_000


def _day(date: str, pr: float | None, faults: list[dict], source: str = "fixed_array",
         fixed_wh: float | None = 3000.0) -> dict:
    return {"date": date, "sky": {"source": source},
            "tracker": {"measured_wh": None if pr is None else 4000.0 * pr,
                        "expected_wh": 4000.0, "performance_ratio": pr},
            "fixed": {"measured_wh": fixed_wh},
            "faults": faults}


def test_every_fault_kind_has_its_words() -> None:
    """The diagnosis' kinds and their words are one list: a new kind without words would
    be shown as its identifier on the dashboard."""
    assert set(FAULT_WORDS) == set(get_args(FaultKind))
    assert rules.title("fault", "sky_unusable") == f"Fault: {FAULT_WORDS['sky_unusable']}"
    assert rules.title("logger_silent", None) == "Logger silent"


def test_the_alert_window_holds_the_slowest_soiling_the_diagnosis_names() -> None:
    """A tester's 0.3 %/day soiling was found by the diagnosis over three weeks and never
    alerted: the alert diagnosed 7 days, where a decline must lose 2 % (0.33 %/day at the
    least). The default window reaches the diagnosis' own floor, 0.1 %/day."""
    from backend.diagnosis import faults
    from backend.settings import AlertSettings

    days = AlertSettings().diagnosis_days
    assert (days - 1) * faults.SOILING_MIN_PCT_PER_DAY >= 100 * faults.SOILING_MIN_TOTAL
    assert days - 1 >= faults.SOILING_MIN_DAYS


def test_diagnosis_rule_latest_day_faults_and_the_low_pr_run() -> None:
    stuck = {"kind": "stuck", "confidence": 0.9, "since": "2026-11-28", "magnitude": 35.0,
             "unit": "deg", "detail": "stuck at azimuth 181°, elevation 35°"}
    weak = {**stuck, "kind": "soiling", "confidence": 0.3}
    old = {**stuck, "kind": "clock_offset"}
    days = [_day("2026-11-26", 0.97, [old]), _day("2026-11-27", 0.95, []),
            _day("2026-11-28", 0.62, [stuck], source="sensor"),
            _day("2026-11-29", 0.9, [], source="clear_sky"),
            _day("2026-11-30", 0.61, [stuck, weak])]
    ev = rules.diagnosed(SITE, TZ, "tracker", days, pr_below=0.8, confidence_min=0.5)
    kinds = {(c.kind, c.fault_kind) for c in ev.conditions}
    # only the latest day's faults count, and only with enough confidence
    assert kinds == {("fault", "stuck"), ("low_performance_ratio", None)}
    fault = next(c for c in ev.conditions if c.kind == "fault")
    assert fault.since_s == int(dt.datetime(2026, 11, 28, tzinfo=TZ).timestamp())
    assert fault.detail.startswith("stuck at azimuth 181°, elevation 35° (since 2026-11-28, ")
    # the kind in words is said once: by the title (the webhook's text, the dashboard's head)
    text = rules.summary(SITE, "fault", "tracker", "stuck", "active", fault.detail)
    assert text.count(FAULT_WORDS["stuck"]) == 1, text
    low = next(c for c in ev.conditions if c.kind == "low_performance_ratio")
    # the clear-sky day is not judged, a sensor's is: the low run goes back to the 28th
    assert low.data["first_low_day"] == "2026-11-28" and low.data["performance_ratio"] == 0.61
    assert "61 %" in low.detail and "alert below 80 %" in low.detail
    healthy = rules.diagnosed(SITE, TZ, "tracker", days[:2], 0.8, 0.5)
    assert healthy.conditions == []
    assert {s[2] for s in healthy.scopes} == {"fault", "low_performance_ratio"}


def test_a_fixed_arrays_underperformance_is_raised_and_cleared_on_the_fixed_array() -> None:
    """Under a sensor's sky the fixed array is judged too (``fixed_underperformance``): its
    alert names that array, and a later day without it clears it there, even with no
    tracker readings (a site whose tracker logger is not there yet)."""
    snow = {"kind": "fixed_underperformance", "array": "fixed", "confidence": 1.0,
            "since": "2026-11-29", "magnitude": 71.3, "unit": "%",
            "detail": "the fixed array made 4.46 kWh …"}
    days = [_day("2026-11-29", None, [snow], source="sensor"),
            _day("2026-11-30", None, [snow], source="sensor")]
    ev = rules.diagnosed(SITE, TZ, "tracker", days, pr_below=0.8, confidence_min=0.5)
    (c,) = ev.conditions
    assert (c.array, c.kind, c.fault_kind) == ("fixed", "fault", "fixed_underperformance")
    assert c.since_s == int(dt.datetime(2026, 11, 29, tzinfo=TZ).timestamp())
    clean = rules.diagnosed(SITE, TZ, "tracker", [_day("2026-12-01", None, [], "sensor")],
                            0.8, 0.5)
    assert clean.conditions == [] and (SITE, "fixed", "fault") in clean.scopes
    silent = rules.diagnosed(SITE, TZ, "tracker", [_day("2026-12-01", None, [], "sensor",
                                                        fixed_wh=None)], 0.8, 0.5)
    assert (SITE, "fixed", "fault") not in silent.scopes  # no readings: unknown, not clear


# -- the webhook sender against a real receiver ----------------------------------------------
def _sender(url: str, **kw: object) -> tuple[WebhookSender, list[tuple[str, str, int]]]:
    results: list[tuple[str, str, int]] = []
    args = {"timeout_s": 2.0, "retries": 3, "backoff_s": 0.2, "backoff_max_s": 1.0,
            "queue_size": 10, **kw}
    sender = WebhookSender(url, on_result=lambda ev, st, n: results.append(
        (ev.event_id, st, n)), **args)  # type: ignore[arg-type]
    sender.start()
    return sender, results


def _event(i: int = 1, event: str = "raised") -> Event:
    body = orjson.dumps({"event": event, "event_id": f"{i}:{event}",
                         "alert": {"id": i, "kind": "logger_silent"}})
    return Event(i, event, body)


def _until(pred: Callable[[], bool], timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not pred():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


def test_webhook_delivers_signed_json() -> None:
    with Receiver() as rx:
        sender, results = _sender(rx.url, secret="s3cret")
        try:
            assert sender.offer(_event())
            _until(lambda: results == [("1:raised", "delivered", 1)])
        finally:
            sender.stop()
        req = rx.requests[0]
        assert req["json"]["event_id"] == "1:raised"
        assert req["headers"]["Content-Type"] == "application/json"
        assert req["headers"]["X-Heliotwin-Event-Id"] == "1:raised"
        want = hmac.new(b"s3cret", req["raw"], hashlib.sha256).hexdigest()
        assert req["headers"]["X-Heliotwin-Signature"] == f"sha256={want}"
        assert sender.status()["url"] == f"http://127.0.0.1:{rx.server.server_address[1]}/…"


def _waits(caplog: pytest.LogCaptureFixture) -> list[tuple[int, int, float]]:
    """The sender's retries as it logs them: ``(k, of n, wait [s])`` in order."""
    found = [re.search(r"retry (\d+) of (\d+) in ([\d.]+) s", r.getMessage())
             for r in caplog.records if r.name == "backend.alerts.webhook"]
    return [(int(m[1]), int(m[2]), float(m[3])) for m in found if m]


def test_webhook_retries_with_backoff_then_delivers(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, logger="backend.alerts.webhook")
    with Receiver(lambda n: 503 if n < 2 else 200) as rx:
        sender, results = _sender(rx.url, backoff_s=0.3)
        try:
            sender.offer(_event())
            _until(lambda: bool(results))
        finally:
            sender.stop()
        assert results == [("1:raised", "delivered", 3)]
        assert _waits(caplog) == [(1, 3, 0.3), (2, 3, 0.6)]  # 0.3 s, then doubled
        assert {r["headers"]["X-Heliotwin-Event-Id"] for r in rx.requests} == {"1:raised"}
        st = sender.status()
        assert (st["delivered"], st["retries"], st["failed"]) == (1, 2, 0)


def test_webhook_429_waits_for_retry_after_and_400_is_not_retried(
        caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, logger="backend.alerts.webhook")
    assert retry_after_s("2") == 2.0 and retry_after_s("soon") is None
    with Receiver(lambda n: 429 if n == 0 else 400) as rx:
        sender, results = _sender(rx.url, backoff_s=0.05)
        try:
            sender.offer(_event())
            _until(lambda: bool(results))
        finally:
            sender.stop()
        assert results == [("1:raised", "failed", 2)]
        assert _waits(caplog) == [(1, 3, 1.0)]  # Retry-After: 1, not the 0.05 s backoff
        assert "HTTP 400" in sender.status()["last_error"]


def test_webhook_gives_up_after_the_retries() -> None:
    with Receiver(lambda n: 500) as rx:
        sender, results = _sender(rx.url, retries=2, backoff_s=0.05)
        try:
            sender.offer(_event())
            _until(lambda: bool(results))
        finally:
            sender.stop()
        assert results == [("1:raised", "failed", 3)] and len(rx.requests) == 3


def test_a_hanging_webhook_never_blocks_offer_and_drops_beyond_the_queue() -> None:
    with Receiver(lambda n: None) as rx:
        sender, results = _sender(rx.url, queue_size=2, timeout_s=3.0)
        try:
            sender.offer(_event(1))
            _until(lambda: len(rx.requests) == 1)  # the first is in flight, hanging
            # a blocking offer would wait for the queue to drain and accept them all
            accepted = [sender.offer(_event(i)) for i in range(2, 7)]
            assert accepted == [True, True, False, False, False]
            assert sender.status()["dropped"] == 3 and sender.status()["queued"] == 3
            assert [r for r in results if r[1] == "dropped"] == [
                (f"{i}:raised", "dropped", 0) for i in (4, 5, 6)]
        finally:
            sender.stop()
        # the POST in flight ended at its timeout, not at the hanging receiver's release;
        # it and the two queued events are counted unsent (logged, offered at the next start)
        st = sender.status()
        assert "ReadTimeout" in st["last_error"] and st["unsent"] == 3, st
        assert len(rx.requests) == 1 and not rx.released.is_set()


# -- the service over HTTP, in this process --------------------------------------------------
def _server(db: Database, **env: str) -> InProcessServer:
    base = {"HELIOTWIN_ALERT_INTERVAL_S": "0.3", "HELIOTWIN_ALERT_WEBHOOK_BACKOFF_S": "0.2",
            "HELIOTWIN_ALERT_SILENT_DAYLIGHT_ONLY": "false",  # the tests run at any hour
            "HELIOTWIN_ALERT_DIAGNOSIS_DAYS": "0"}
    return InProcessServer(db.url, extra_env={**base, **env})


def _reading(ts: float, array: str = "tracker") -> dict:
    stamp = dt.datetime.fromtimestamp(int(ts), dt.UTC).isoformat()
    return {"ts": stamp, "array": array, "voltage_v": 26.0, "current_a": 5.0}


def _post(c: httpx.Client, token: str, readings: list[dict]) -> httpx.Response:
    r = c.post(INGEST, json={"readings": readings}, headers={"Authorization": f"Bearer {token}"})
    assert r.status_code == 200, r.text
    return r


def _alerts(c: httpx.Client, **params: str) -> dict:
    r = c.get("/api/v1/alerts", params=params)
    assert r.status_code == 200, r.text
    return r.json()


def _rounds(c: httpx.Client, n: int, timeout_s: float = 60.0) -> dict:
    """Wait until the evaluator has run ``n`` more rounds; its status then."""
    want = _alerts(c)["evaluator"]["evaluations"] + n
    deadline = time.monotonic() + timeout_s
    while (ev := _alerts(c)["evaluator"])["evaluations"] < want:
        assert time.monotonic() < deadline, f"the evaluator ran no {n} rounds: {ev}"
        time.sleep(0.05)
    return ev  # type: ignore[no-any-return]


@pytest.fixture
def sqlite_database(tmp_path: Path) -> Iterator[Database]:
    """One backend for the tests whose subject is not the database (the webhook, the
    endpoint's errors, the diagnosis rules in the service); the alert rows themselves are
    checked on both by the silent-logger test. CI time is part of the budget."""
    db = new_database("sqlite", tmp_path)
    yield db
    db.drop()


@pytest.fixture
def rx() -> Iterator[Receiver]:
    with Receiver() as receiver:
        yield receiver


#: the silence threshold of the silent-logger tests [min] (1.2 s) and the evaluator's rounds
#: that cover it from a start (0.3 s each, HELIOTWIN_ALERT_INTERVAL_S) with two to spare
SILENT_MIN = 0.02
ROUNDS_PAST_SILENCE = 6


def test_silent_logger_raised_once_kept_over_a_restart_and_cleared_once(
        database: Database, rx: Receiver, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="backend.app")
    server = _server(database, HELIOTWIN_ALERT_SILENT_MIN=str(SILENT_MIN),
                     HELIOTWIN_ALERT_WEBHOOK_URL=rx.url).start()
    try:
        token = server.token()
        with server.client(timeout_s=30) as c:
            last = time.time() - 1
            _post(c, token, [_reading(last)])  # the fixed array never reports: no alert
            evs = rx.wait_for(lambda e: len(e) >= 1)
            # more rounds with the logger still silent raise nothing more
            assert _rounds(c, ROUNDS_PAST_SILENCE)["webhook"]["offered"] == 1
            evs = rx.events()
            assert [(e["event"], e["alert"]["array"]) for e in evs] == [("raised", "tracker")]
            alert = evs[0]["alert"]
            assert (alert["kind"], alert["state"], alert["site_id"]) == \
                ("logger_silent", "active", SITE)
            assert alert["since"] == dt.datetime.fromtimestamp(int(last), dt.UTC).isoformat(
                ).replace("+00:00", "Z")
            assert "no reading from the tracker logger" in alert["detail"]
            assert "tracker" in evs[0]["text"] and evs[0]["event_id"] == f"{alert['id']}:raised"
            body = _alerts(c, site_id=SITE, state="active")
            assert [a["id"] for a in body["alerts"]] == [alert["id"]]
            assert body["alerts"][0]["webhook_status"] == "delivered"
            assert body["counts"] == {"active": 1, "cleared": 0, "active_unacknowledged": 1}
            assert body["evaluator"]["webhook"]["delivered"] == 1
            assert "secret-path" not in json.dumps(body)  # the URL's path is never shown
        server.stop()  # graceful: the lifespan's shutdown ran to its end
        assert "service stopped" in caplog.messages
        server.start()  # the same database: the active alert is read back, not raised again
        with server.client(timeout_s=30) as c:
            # past the silence threshold counted from the new start: nothing offered
            assert _rounds(c, ROUNDS_PAST_SILENCE)["webhook"]["offered"] == 0
            assert len(rx.events()) == 1
            assert [a["id"] for a in _alerts(c, state="active")["alerts"]] == [alert["id"]]
            # the logger reports again (stamped a minute ahead: it stays fresh for the test)
            _post(c, token, [_reading(time.time() + 60)])
            evs = rx.wait_for(lambda e: len(e) >= 2)
            assert _rounds(c, 3)["webhook"]["offered"] == 1  # cleared once
            evs = rx.events()
            assert [e["event"] for e in evs] == ["raised", "cleared"]
            cleared = evs[1]["alert"]
            assert (cleared["id"], cleared["state"]) == (alert["id"], "cleared")
            assert cleared["cleared_detail"].startswith("the tracker logger reports again")
            body = _alerts(c, site_id=SITE)
            assert body["counts"] == {"active": 0, "cleared": 1, "active_unacknowledged": 0}
            assert body["alerts"][0]["cleared_at"] is not None
            assert _alerts(c, state="active")["alerts"] == []
    finally:
        server.stop()


def test_acknowledged_goes_out_between_raised_and_cleared_and_a_new_alert_is_not(
        sqlite_database: Database, rx: Receiver) -> None:
    """An operator acknowledges a silent logger's alert (``POST …/acknowledge``): the webhook
    gets an ``acknowledged`` event after the ``raised`` one, saying who and their note; the
    ``cleared`` event then carries who took it; the logger falling silent again is a new
    alert, not acknowledged."""
    server = _server(sqlite_database, HELIOTWIN_ALERT_SILENT_MIN=str(SILENT_MIN),
                     HELIOTWIN_ALERT_WEBHOOK_URL=rx.url).start()
    try:
        token = server.token()
        operator = server.token(label="Ana", scope="site")
        with server.client(timeout_s=30) as c:
            _post(c, token, [_reading(time.time() - 1)])
            first = rx.wait_for(lambda e: len(e) >= 1)[0]["alert"]
            r = c.post(f"/api/v1/alerts/{first['id']}/acknowledge",
                       json={"note": "sent Luis to the logger"},
                       headers={"Authorization": f"Bearer {operator}"})
            assert r.status_code == 200, r.text
            evs = rx.wait_for(lambda e: len(e) >= 2)
            ack = evs[1]
            assert (ack["event"], ack["event_id"]) == ("acknowledged",
                                                       f"{first['id']}:acknowledged")
            assert ack["alert"]["acknowledged_by"] == "Ana" and ack["alert"]["state"] == "active"
            assert ack["text"] == ("heliotwin tehuantepec / tracker: acknowledged — Logger silent: "
                                   "by Ana: sent Luis to the logger")
            assert rx.requests[1]["headers"]["X-Heliotwin-Event"] == "acknowledged"
            _until(lambda: _alerts(c, state="active")["alerts"][0]["webhook_status"]
                   == "delivered")
            # the logger reports (cleared), then falls silent again (a new alert)
            _post(c, token, [_reading(time.time())])
            evs = rx.wait_for(lambda e: len(e) >= 4)
            assert [e["event"] for e in evs] == ["raised", "acknowledged", "cleared", "raised"]
            cleared, again = evs[2]["alert"], evs[3]["alert"]
            assert cleared["id"] == first["id"]
            assert (cleared["acknowledged_by"], cleared["acknowledged_note"]) == (
                "Ana", "sent Luis to the logger")
            assert again["id"] != first["id"] and again["acknowledged_at"] is None
            body = _alerts(c, site_id=SITE)
            assert body["counts"] == {"active": 1, "cleared": 1, "active_unacknowledged": 1}
            assert [a["id"] for a in _alerts(c, acknowledged="false")["alerts"]] == [again["id"]]
            assert [a["id"] for a in _alerts(c, acknowledged="true")["alerts"]] == [first["id"]]
    finally:
        server.stop()


def test_a_newer_reading_still_old_ends_one_silence_and_starts_another(
        sqlite_database: Database, rx: Receiver) -> None:
    """A reading stored late (a back-fill) that is newer than the alert's last one but
    itself older than the threshold: that silence ended — the alert is cleared — and the
    logger is silent again since the new reading. Before, the alert stayed active with its
    old ``since`` and detail, beside a ``/status`` showing the newer reading."""
    server = _server(sqlite_database, HELIOTWIN_ALERT_SILENT_MIN=str(SILENT_MIN),
                     HELIOTWIN_ALERT_WEBHOOK_URL=rx.url).start()
    try:
        token = server.token()
        with server.client(timeout_s=30) as c:
            first = time.time() - 30
            _post(c, token, [_reading(first)])
            rx.wait_for(lambda e: len(e) >= 1)
            newer = time.time() - 10
            _post(c, token, [_reading(newer)])
            evs = rx.wait_for(lambda e: len(e) >= 3)
            assert [e["event"] for e in evs] == ["raised", "cleared", "raised"]
            assert evs[1]["alert"]["cleared_detail"].startswith("a newer reading was stored")
            stamp = [dt.datetime.fromtimestamp(int(t), dt.UTC).isoformat().replace(
                "+00:00", "Z") for t in (first, newer)]
            assert [evs[0]["alert"]["since"], evs[2]["alert"]["since"]] == stamp
            assert _rounds(c, 3)["webhook"]["offered"] == 3  # and no more
            active = _alerts(c, state="active")["alerts"]
            assert [a["since"] for a in active] == [stamp[1]]
    finally:
        server.stop()


def test_the_service_gives_a_30_minute_logger_its_cadence(sqlite_database: Database) -> None:
    """Both loggers last read 40 minutes ago, past the threshold: the minute logger is
    silent, the 30-minute one (next reading 10 minutes late, within 2.5 of its cadence) is
    not — before, both were raised."""
    server = _server(sqlite_database, HELIOTWIN_ALERT_SILENT_MIN=str(SILENT_MIN)).start()
    try:
        with server.client(timeout_s=30) as c:
            last = int(time.time()) // 60 * 60 - 2400
            _post(c, server.token(), [_reading(last - 1800 * k) for k in range(11)]
                  + [_reading(last - 60 * k, "fixed") for k in range(11)])
            _rounds(c, ROUNDS_PAST_SILENCE)
            active = _alerts(c, site_id=SITE, state="active")["alerts"]
            assert [(a["array"], a["kind"]) for a in active] == [("fixed", "logger_silent")]
    finally:
        server.stop()


def test_alerts_endpoint_names_the_bad_field(sqlite_database: Database) -> None:
    with _server(sqlite_database, HELIOTWIN_ALERTS="false") as server, \
            server.client(timeout_s=30) as c:
        r = c.get("/api/v1/alerts", params={"site_id": "atlantis"})
        assert r.status_code == 404 and r.json()["detail"].startswith(
            "site_id: unknown site 'atlantis'")
        r = c.get("/api/v1/alerts", params={"state": "open"})
        assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "state"]
        r = c.get("/api/v1/alerts", params={"limit": "0"})
        assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "limit"]
        body = _alerts(c)
        assert body == {"alerts": [], "counts": {"active": 0, "cleared": 0,
                                                 "active_unacknowledged": 0},
                        "evaluator": {"enabled": False}}
        doc = c.get("/openapi.json").json()
        op = doc["paths"]["/api/v1/alerts"]["get"]
        assert {p["name"] for p in op["parameters"]} == {"site_id", "state", "kind",
                                                          "acknowledged", "limit"}
        assert "AlertRead" in doc["components"]["schemas"]


def _inject(db_url: str, day: dt.date, payload: dict) -> None:
    """Store a diagnosis of ``day`` in the cache as the service would (diagnosis_days)."""
    from sqlalchemy import delete, insert

    from backend.diagnosis.service import CACHE_VERSION, site_key
    from backend.settings import get_settings
    from backend.storage.engine import make_engine
    from backend.storage.tables import DiagnosisDay
    from sim.sites import load_site

    start = dt.datetime(day.year, day.month, day.day, tzinfo=TZ)
    nxt = day + dt.timedelta(days=1)
    end = dt.datetime(nxt.year, nxt.month, nxt.day, tzinfo=TZ)
    engine = make_engine(get_settings(database_url=db_url))
    try:
        with engine.begin() as conn:
            conn.execute(delete(DiagnosisDay).where(DiagnosisDay.site_id == SITE))
            conn.execute(insert(DiagnosisDay).values(
                site_id=SITE, day_start_s=int(start.timestamp()), day_end_s=int(end.timestamp()),
                payload_json=orjson.dumps({**payload, "cache_version": CACHE_VERSION,
                                           "site_key": site_key(load_site(SITE))}).decode()))
    finally:
        engine.dispose()


def _payload(day: dt.date, pr: float, stuck: bool, stopped_at: str | None = None) -> dict:
    features: dict = {"missing_daylight_min": 0}
    if stuck:  # the fit features of a stuck tracker (backend/diagnosis/faults.py)
        features.update(residual=0.30, stuck={"residual": 0.05, "tilt_deg": 55.0,
                                              "azimuth_deg": 181.0, "stopped_at": stopped_at},
                        azimuth_offset={"residual": 0.25, "offset_deg": 10.0},
                        clock_offset={"residual": 0.28, "offset_s": 0.0, "scale": 1.0})
    else:
        features.update(residual=0.02)
    return {"date": day.isoformat(),
            "sky": {"clearness_index": 0.72, "source": "fixed_array", "valid_minutes_pct": 97.0},
            "tracker": {"measured_wh": 5000.0 * pr, "expected_wh": 5000.0,
                        "expected_wh_low": 4800.0, "expected_wh_high": 5200.0,
                        "performance_ratio": pr},
            "fixed": {"measured_wh": 4000.0, "expected_wh": 4000.0, "performance_ratio": 1.0},
            "gain_measured_pct": 25.0 * pr, "gain_expected_pct": 25.0, "features": features}


def test_fault_and_low_pr_from_an_injected_diagnosis_raised_then_cleared(
        sqlite_database: Database, rx: Receiver) -> None:
    yesterday = dt.datetime.now(TZ).date() - dt.timedelta(days=1)
    noon = dt.datetime(yesterday.year, yesterday.month, yesterday.day, 12, tzinfo=TZ)
    env = {"HELIOTWIN_ALERT_DIAGNOSIS_DAYS": "7", "HELIOTWIN_ALERT_WEBHOOK_URL": rx.url}
    # a logger day to diagnose (its readings would drop a cached diagnosis of the day)
    with _server(sqlite_database, HELIOTWIN_ALERTS="false") as server, \
            server.client(timeout_s=30) as c:
        _post(c, server.token(), [_reading(noon.timestamp() + 60 * k, a)
                                  for k in range(10) for a in ("tracker", "fixed")])
    _inject(sqlite_database.url, yesterday, _payload(yesterday, 0.62, stuck=True))
    with _server(sqlite_database, **env) as server, server.client(timeout_s=30) as c:
        evs = rx.wait_for(lambda e: len(e) >= 2)
        assert _rounds(c, 3)["webhook"]["offered"] == 2  # nothing more in later rounds
        evs = rx.events()
        got = {(e["event"], e["alert"]["kind"], e["alert"]["fault_kind"]) for e in evs}
        assert got == {("raised", "fault", "stuck"), ("raised", "low_performance_ratio", None)}
        assert len(evs) == 2
        fault = next(e["alert"] for e in evs if e["alert"]["kind"] == "fault")
        assert fault["array"] == "tracker"
        # the kind in words comes from the service (the dashboard shows it as it is)
        assert fault["title"] == "Fault: tracker stuck"
        assert _alerts(c, kind="fault")["alerts"][0]["title"] == "Fault: tracker stuck"
        assert fault["detail"].startswith("stuck at azimuth 181°, elevation 35° (since "
                                          f"{yesterday.isoformat()}, ")
        midnight = dt.datetime(yesterday.year, yesterday.month, yesterday.day, tzinfo=TZ)
        assert dt.datetime.fromisoformat(fault["since"]) == midnight
        assert fault["data"]["confidence"] == pytest.approx(0.833, abs=1e-3)
        low = next(e["alert"] for e in evs if e["alert"]["kind"] == "low_performance_ratio")
        assert low["data"]["performance_ratio"] == 0.62 and "62 %" in low["detail"]
    _inject(sqlite_database.url, yesterday, _payload(yesterday, 0.97, stuck=False))  # repaired
    with _server(sqlite_database, **env) as server, server.client(timeout_s=30) as c:
        evs = rx.wait_for(lambda e: len(e) >= 4)
        assert _rounds(c, 3)["webhook"]["offered"] == 2  # each cleared once
        evs = rx.events()
        cleared = {e["alert"]["kind"]: e["alert"] for e in evs if e["event"] == "cleared"}
        assert set(cleared) == {"fault", "low_performance_ratio"} and len(evs) == 4
        assert cleared["fault"]["cleared_detail"] == \
            f"not found in the diagnosis of {yesterday.isoformat()}"
        assert cleared["low_performance_ratio"]["cleared_detail"].startswith(
            "performance ratio 0.97")
        assert _alerts(c, site_id=SITE, kind="fault")["counts"] == {
            "active": 0, "cleared": 1, "active_unacknowledged": 0}


def test_a_tracker_stopped_part_way_through_yesterday_raises_a_fault_since_its_stop(
        sqlite_database: Database, rx: Receiver) -> None:
    """A tracker that stopped at 13:00 yesterday, its PR 0.93 above the alert's 0.8 (and
    inside its band: no underperformance): the diagnosis' ``stuck`` with its stop minute
    (features.stuck.stopped_at, faults._stopped) raises a ``fault`` alert like a whole-day
    stuck one, its ``since`` the stop minute, not the day's midnight."""
    yesterday = dt.datetime.now(TZ).date() - dt.timedelta(days=1)
    noon = dt.datetime(yesterday.year, yesterday.month, yesterday.day, 12, tzinfo=TZ)
    stop = noon + dt.timedelta(hours=1)
    env = {"HELIOTWIN_ALERT_DIAGNOSIS_DAYS": "7", "HELIOTWIN_ALERT_WEBHOOK_URL": rx.url}
    with _server(sqlite_database, HELIOTWIN_ALERTS="false") as server, \
            server.client(timeout_s=30) as c:
        _post(c, server.token(), [_reading(noon.timestamp() + 60 * k, a)
                                  for k in range(10) for a in ("tracker", "fixed")])
    _inject(sqlite_database.url, yesterday,
            _payload(yesterday, 0.93, stuck=True, stopped_at=stop.isoformat()))
    with _server(sqlite_database, **env) as server, server.client(timeout_s=30) as c:
        rx.wait_for(lambda e: len(e) >= 1)
        assert _rounds(c, 3)["webhook"]["offered"] == 1
        (ev,) = rx.events()
        fault = ev["alert"]
        assert (ev["event"], fault["kind"], fault["fault_kind"]) == ("raised", "fault", "stuck")
        assert dt.datetime.fromisoformat(fault["since"]) == stop
        assert fault["detail"].startswith("stuck at azimuth 181°, elevation 35° from 13:00 "
                                          f"(tracking until then) (since {yesterday}, ")
        assert fault["data"]["since_time"] == stop.isoformat()


def test_a_back_fill_not_yet_at_yesterday_raises_no_dropout(sqlite_database: Database) -> None:
    """A logger back-filled day by day, the day before yesterday posted, yesterday not yet:
    yesterday is not judged — its diagnosis was a whole-day dropout, raised and cleared
    seconds later when the back-fill reached it (a tester's finding)."""
    before = dt.datetime.now(TZ).date() - dt.timedelta(days=2)
    midnight = dt.datetime(before.year, before.month, before.day, tzinfo=TZ).timestamp()
    env = {"HELIOTWIN_ALERT_DIAGNOSIS_DAYS": "7"}
    with _server(sqlite_database, **env) as server, server.client(timeout_s=60) as c:
        _post(c, server.token(), [_reading(midnight + 60 * k, a)
                                  for k in range(24 * 60) for a in ("tracker", "fixed")])
        _rounds(c, 3, timeout_s=180.0)
        faults = _alerts(c, site_id=SITE, kind="fault")["alerts"]
        assert [a for a in faults if a["fault_kind"] == "dropout"] == [], faults


POSTED = 60  # readings posted while the webhook hangs


def test_ingestion_never_waits_for_a_hanging_webhook(
        sqlite_database: Database, caplog: pytest.LogCaptureFixture) -> None:
    """The webhook's receiver takes every POST and never answers; the sender's timeout is
    longer than the whole test's ingestion. Every reading posted meanwhile is acknowledged
    and stored, the evaluator keeps its rounds and its events beyond the queue are dropped,
    all while the webhook's first POST is still in flight; then the service stops."""
    caplog.set_level(logging.INFO, logger="backend.app")
    with Receiver(lambda n: None) as hang:
        server = _server(sqlite_database, HELIOTWIN_ALERT_SILENT_MIN=str(SILENT_MIN),
                         HELIOTWIN_ALERT_INTERVAL_S="0.2", HELIOTWIN_ALERT_WEBHOOK_URL=hang.url,
                         HELIOTWIN_ALERT_WEBHOOK_TIMEOUT_S="120",
                         HELIOTWIN_ALERT_WEBHOOK_RETRIES="10",
                         HELIOTWIN_ALERT_WEBHOOK_QUEUE="1").start()
        try:
            token = server.token()
            with server.client(timeout_s=30) as c:
                # the tracker logger falls silent: its alert goes to the hanging webhook
                _post(c, token, [_reading(time.time() - 1)])
                _until(lambda: len(hang.requests) == 1)
                start_s = int(time.time()) // 60 * 60 - 86400
                for k in range(POSTED):  # one minute a request, as a field logger posts
                    _post(c, token, [_reading(start_s + 60 * k, "fixed")])
                # flap the tracker (fresh, silent, fresh, …): more events for the webhook, until
                # one is dropped. The reading is stamped in the next whole second (stamps are
                # whole seconds: time.time() - 0.5 was 0.5–1.5 s old, often past the 1.2 s
                # silence already); a flap the evaluator still misses (a round late on a
                # loaded machine) offers nothing, and the next one tries again.
                before = _alerts(c)["evaluator"]["evaluations"]
                flaps = 0
                while flaps < 10:
                    flaps += 1
                    _post(c, token, [_reading(time.time() + 1)])
                    ev = _rounds(c, ROUNDS_PAST_SILENCE)
                    if ev["webhook"]["dropped"] >= 1:
                        break
                r = c.get(f"/api/v1/sites/{SITE}/measurements", params={
                    "array": "fixed", "start": dt.datetime.fromtimestamp(start_s, dt.UTC)
                    .isoformat(), "end": dt.datetime.fromtimestamp(start_s + 60 * POSTED, dt.UTC)
                    .isoformat(), "max_points": "1000"})
            assert r.status_code == 200 and len(r.json()["points"]) == POSTED
            assert ev["evaluations"] >= before + flaps * ROUNDS_PAST_SILENCE
            webhook = ev["webhook"]
            assert (webhook["delivered"], webhook["retries"], webhook["failed"]) == (0, 0, 0)
            # one in flight, one queued, the rest dropped: never waited for
            assert webhook["queued"] == 2 and webhook["dropped"] >= 1, webhook
            assert webhook["offered"] == webhook["queued"] + webhook["dropped"], webhook
            assert len(hang.requests) == 1  # the first POST, still unanswered
            hang.released.set()  # its connection now closes unanswered: the sender waits
        finally:
            server.stop()  # and the shutdown ends that wait
    assert "service stopped" in caplog.messages
