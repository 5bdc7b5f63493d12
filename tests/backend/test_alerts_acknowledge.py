"""Acknowledging an alert (``POST /api/v1/alerts/{alert_id}/acknowledge``, docs/service.md
"Alerts"): who and when are stored once, a cleared alert is a 409, the scopes of the tokens,
the bad inputs, the ``acknowledged`` filter and the counts — over HTTP against the service in
this process, on SQLite and on PostgreSQL. The alerts are stored as the evaluator stores them
(an insert through the writer); its rounds are off here, so nothing else raises or clears
them. The webhook's ``acknowledged`` event, with the evaluator running, is in
``test_alerts.py``.
"""

from __future__ import annotations

import datetime as dt
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from live_service import BACKENDS, OLD_SITE_SQL, InProcessServer, new_database, upgraded_from
from sqlalchemy import Connection, insert, text, update

from backend.alerts.service import latest_event
from backend.storage.tables import ACK_NOTE_MAX_CHARS, AlertRow

SITE = "tehuantepec"
OTHER = "guadalajara_fisheye"
ADMIN = "admin-token-of-the-acknowledge-tests"


@pytest.fixture(scope="module", params=BACKENDS)
def server(request: pytest.FixtureRequest,
           tmp_path_factory: pytest.TempPathFactory) -> Iterator[InProcessServer]:
    """The service on a fresh database, its alert rounds off (``HELIOTWIN_ALERTS=false``)."""
    db = new_database(request.param, tmp_path_factory.mktemp(f"ack-{request.param}"))
    proc = InProcessServer(db.url, extra_env={"HELIOTWIN_ALERTS": "false",
                                              "HELIOTWIN_ADMIN_TOKEN": ADMIN}).start()
    try:
        yield proc
    finally:
        proc.stop()
        db.drop()


@pytest.fixture
def client(server: InProcessServer) -> Iterator[httpx.Client]:
    with server.client() as c:
        yield c


def _store(server: InProcessServer, site_id: str = SITE, state: str = "active",
           kind: str = "fault", fault_kind: str | None = "stuck") -> int:
    """An alert stored as the evaluator stores one (``AlertService._raise``); its id."""
    now = int(time.time())
    values: dict[str, Any] = {
        "site_id": site_id, "array_name": "tracker", "kind": kind, "fault_kind": fault_kind,
        "state": state, "since_s": now - 86400, "raised_at_s": now - 3600,
        "cleared_at_s": now - 60 if state == "cleared" else None,
        "detail": "stuck at azimuth 181°, elevation 35°",
        "cleared_detail": "not found in the diagnosis" if state == "cleared" else None,
        "data_json": "{}", "webhook_status": "off", "webhook_attempts": 0}

    def store(conn: Any) -> int:
        return int(conn.execute(insert(AlertRow).values(**values)).inserted_primary_key[0])
    return int(server.ctx.writer.call(store).result(60))


def _clear(server: InProcessServer, alert_id: int) -> None:
    """The evaluator's clearing of it (``AlertService._clear``)."""
    server.ctx.writer.call(lambda conn: conn.execute(
        update(AlertRow).where(AlertRow.id == alert_id).values(
            state="cleared", cleared_at_s=int(time.time()),
            cleared_detail="the condition no longer holds"))).result(60)


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def _ack(c: httpx.Client, alert_id: int | str, token: str | None = None,
         **kwargs: Any) -> httpx.Response:
    return c.post(f"/api/v1/alerts/{alert_id}/acknowledge",
                  headers=bearer(token) if token else {}, **kwargs)


def _listed(c: httpx.Client, alert_id: int, **params: str) -> dict | None:
    r = c.get("/api/v1/alerts", params={"limit": "1000", **params})
    assert r.status_code == 200, r.text
    return next((a for a in r.json()["alerts"] if a["id"] == alert_id), None)


def _counts(c: httpx.Client, site_id: str = SITE) -> dict[str, int]:
    return c.get("/api/v1/alerts", params={"site_id": site_id}).json()["counts"]  # type: ignore[no-any-return]


def test_an_alert_is_acknowledged_once_and_listed_so(client: httpx.Client,
                                                     server: InProcessServer) -> None:
    alert_id = _store(server)
    fresh = _listed(client, alert_id, acknowledged="false")
    assert fresh is not None and (fresh["acknowledged_at"], fresh["acknowledged_by"],
                                  fresh["acknowledged_note"]) == (None, None, None)
    before = _counts(client)
    ana = server.token(SITE, label="Ana (night shift)", scope="site")
    t0 = int(time.time())
    r = _ack(client, alert_id, ana, json={"note": "  sent Luis to check the azimuth drive "})
    assert r.status_code == 200, r.text
    got = r.json()
    assert (got["id"], got["state"], got["acknowledged_by"], got["acknowledged_note"]) == (
        alert_id, "active", "Ana (night shift)", "sent Luis to check the azimuth drive")
    at = dt.datetime.fromisoformat(got["acknowledged_at"])
    assert at.tzinfo is not None and t0 <= at.timestamp() <= time.time() + 1
    # the list shows it so, the filter finds it on its side only, the counts follow
    assert _listed(client, alert_id) == got
    assert _listed(client, alert_id, acknowledged="true") == got
    assert _listed(client, alert_id, acknowledged="false") is None
    after = _counts(client)
    assert after == {**before, "active_unacknowledged": before["active_unacknowledged"] - 1}
    # a colleague acknowledging it again changes nothing: the first time, name and note stay
    time.sleep(1.1)  # a later second, were it stored again
    r = _ack(client, alert_id, server.token(SITE, label="Bea", scope="site"),
             json={"note": "on my way"})
    assert r.status_code == 200 and r.json() == got
    assert _listed(client, alert_id) == got
    # once cleared by the evaluator it keeps who took it
    _clear(server, alert_id)
    cleared = _listed(client, alert_id, state="cleared", acknowledged="true")
    assert cleared is not None and cleared["acknowledged_by"] == "Ana (night shift)"
    assert _ack(client, alert_id, ana).json() == cleared  # still idempotent: 200, as stored


def test_no_note_an_empty_body_and_who_a_token_without_a_label_or_the_admin_is(
        client: httpx.Client, server: InProcessServer) -> None:
    unlabelled = server.token(SITE, label="", scope="site")
    token_id = server.ctx.tokens.grant(unlabelled).token_id
    first, second, third = _store(server), _store(server), _store(server)
    r = _ack(client, first, unlabelled)  # no body at all
    assert r.status_code == 200, r.text
    assert (r.json()["acknowledged_by"], r.json()["acknowledged_note"]) == (
        f"token #{token_id}", None)
    r = _ack(client, second, ADMIN, json={"note": "   "})  # blank: no note
    assert r.status_code == 200, r.text
    assert (r.json()["acknowledged_by"], r.json()["acknowledged_note"]) == ("admin", None)
    r = _ack(client, third, ADMIN, json={})
    assert r.status_code == 200 and r.json()["acknowledged_note"] is None


def test_a_cleared_alert_is_a_409_and_stays_unacknowledged(client: httpx.Client,
                                                           server: InProcessServer) -> None:
    alert_id = _store(server, state="cleared")
    r = _ack(client, alert_id, ADMIN, json={"note": "too late"})
    assert r.status_code == 409, r.text
    assert r.json()["detail"].startswith(f"alert_id: alert {alert_id} was cleared at ")
    assert "nothing to take on" in r.json()["detail"]
    listed = _listed(client, alert_id)
    assert listed is not None and listed["acknowledged_at"] is None


def test_who_may_acknowledge(client: httpx.Client, server: InProcessServer) -> None:
    """A ``site``-scope token of the alert's site or the admin token; no token or a bad one
    is a 401, another site's token or a logger's ``ingest`` token a 403 naming why."""
    alert_id, other_id = _store(server), _store(server, site_id=OTHER, kind="logger_silent",
                                                fault_kind=None)
    r = _ack(client, alert_id)
    assert r.status_code == 401 and r.headers["www-authenticate"] == "Bearer"
    assert "write token required" in r.json()["detail"]
    r = _ack(client, alert_id, "ht_not-a-token")
    assert r.status_code == 401 and r.json()["detail"] == "unknown write token"
    r = _ack(client, alert_id, server.token(OTHER, scope="site"))
    assert r.status_code == 403, r.text
    assert r.json()["detail"] == f"this token writes to site {OTHER!r}, not {SITE!r}"
    r = _ack(client, alert_id, server.token(SITE))  # the logger's ingest token
    assert r.status_code == 403 and "scope 'ingest'" in r.json()["detail"]
    assert "acknowledging alerts of site 'tehuantepec'" in r.json()["detail"]
    assert _listed(client, alert_id)["acknowledged_at"] is None  # type: ignore[index]
    # each site's operator takes its own site's alerts
    r = _ack(client, other_id, server.token(OTHER, label="Guadalajara ops", scope="site"))
    assert r.status_code == 200 and r.json()["acknowledged_by"] == "Guadalajara ops"
    assert _counts(client, OTHER)["active_unacknowledged"] == 0


@pytest.mark.parametrize(("path", "body", "status", "where"), [
    ("0", None, 422, ["path", "alert_id"]),
    ("abc", None, 422, ["path", "alert_id"]),
    (str(2**31), None, 422, ["path", "alert_id"]),
    ("ALERT", {"note": "x" * (ACK_NOTE_MAX_CHARS + 1)}, 422, ["body", "note"]),
    ("ALERT", {"note": "two\nlines"}, 422, ["body", "note"]),
    ("ALERT", {"note": "two\u2028lines"}, 422, ["body", "note"]),
    ("ALERT", {"note": "a C1 \u0085 control"}, 422, ["body", "note"]),
    ("ALERT", {"note": "seen \u202eoj\u202c"}, 422, ["body", "note"]),
    ("ALERT", {"note": 5}, 422, ["body", "note"]),
    ("ALERT", {"note": "ok", "by": "someone else"}, 422, ["body", "by"]),
    ("ALERT", ["not", "an", "object"], 422, ["body"]),
], ids=["zero", "not-a-number", "past-32-bit", "note-too-long", "note-with-a-newline",
         "note-with-a-line-separator", "note-with-a-c1-control", "note-with-a-bidi-override",
        "note-not-a-string", "unknown-field", "not-an-object"])
def test_bad_input_names_the_field(client: httpx.Client, server: InProcessServer, path: str,
                                   body: Any, status: int, where: list[str]) -> None:
    alert_id = _store(server)
    r = _ack(client, str(alert_id) if path == "ALERT" else path, ADMIN,
             **({} if body is None else {"json": body}))
    assert r.status_code == status, r.text
    assert r.json()["detail"][0]["loc"] == where
    assert _listed(client, alert_id)["acknowledged_at"] is None  # type: ignore[index]


def test_a_lone_surrogate_is_a_422_not_a_500(client: httpx.Client,
                                            server: InProcessServer) -> None:
    """JSON may escape a lone surrogate; it is no UTF-8, and the driver failed on it (500)."""
    alert_id = _store(server)
    r = client.post(f"/api/v1/alerts/{alert_id}/acknowledge", content=b'{"note": "\\ud800"}',
                    headers={**bearer(ADMIN), "Content-Type": "application/json"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "note"], r.text
    assert any(w in r.json()["detail"][0]["msg"] for w in ("surrogate", "unicode string"))
    assert _listed(client, alert_id)["acknowledged_at"] is None  # type: ignore[index]


def test_unknown_alert_and_bad_filter(client: httpx.Client, server: InProcessServer) -> None:
    r = _ack(client, 2**31 - 1, ADMIN)
    assert r.status_code == 404 and r.json()["detail"] == f"alert_id: no alert {2**31 - 1}"
    # a note of exactly the bound is kept whole
    alert_id = _store(server)
    note = "é" * ACK_NOTE_MAX_CHARS
    r = _ack(client, alert_id, ADMIN, json={"note": note})
    assert r.status_code == 200 and r.json()["acknowledged_note"] == note
    r = client.get("/api/v1/alerts", params={"acknowledged": "maybe"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "acknowledged"]


def test_the_latest_event_of_an_alert() -> None:
    """What a restart offers again for an alert whose event was still queued."""
    active = {"state": "active", "acknowledged_at": None}
    assert latest_event(active) == "raised"
    assert latest_event({**active, "acknowledged_at": "2026-12-05T09:00:00Z"}) == "acknowledged"
    assert latest_event({"state": "cleared", "acknowledged_at": None}) == "cleared"
    assert latest_event({"state": "cleared", "acknowledged_at": "2026-12-05T09:00:00Z"}) \
        == "cleared"


def test_alerts_stored_before_0014_are_not_acknowledged(tmp_path: Path) -> None:
    def rows(conn: Connection) -> None:
        conn.execute(text(OLD_SITE_SQL))
        conn.execute(text("INSERT INTO alerts (site_id, array_name, kind, state, since_s, "
                          "raised_at_s, detail, data_json, webhook_status) VALUES ('s', "
                          "'tracker', 'logger_silent', 'active', 1, 2, 'silent', '{}', "
                          "'off')"))

    with upgraded_from(f"sqlite:///{tmp_path / 'old.sqlite'}", "0013_service_state",
                       rows) as conn:
        row = conn.execute(text("SELECT acknowledged_at_s, acknowledged_by, "
                                "acknowledged_note FROM alerts")).one()
        assert tuple(row) == (None, None, None)
