"""Token scopes (issue 23, item 7; issue 22, item 11): an ``ingest`` token writes readings
and nothing else, a ``site`` token also edits its site and the shared 3D replay, the
admin token everything; a revoked token is told so; tokens stored before scopes become
``ingest`` (migration 0008). The service in this process on a real SQLite file.
"""

from __future__ import annotations

import argparse
import datetime as dt
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import httpx
import pandas as pd
import pytest
from live_service import OLD_SITE_SQL, InProcessServer, LiveServer, upgraded_from
from sqlalchemy import Connection, text

from backend.api.routes import twin3d
from backend.auth import TokenCache, create_token, list_tokens
from backend.cli.token import create, list_, revoke
from backend.settings import get_settings
from backend.sites import Registry, sync_sites
from backend.storage.engine import make_engine, run_migrations
from backend.twin.demo_logger import DEMO_TOKEN_LABEL, demo_token

SITE = "tehuantepec"


class _Scene:
    """What ``/api/v1/twin3d/replay`` needs of the viser scene: no viewer connected; and
    what every answer's security headers need: the port it serves on."""

    port = 8080

    def __init__(self) -> None:
        self.replays: dict[str, Any] = {}

    def site_views(self, viewer: str | None = None) -> list[Any]:
        return []

    def load_replay(self, replay: Any, viewer: str = "") -> list[Any]:
        self.replays[viewer] = replay
        return []

    def clear_replay(self, viewer: str = "") -> int:
        self.replays.pop(viewer, None)
        return 0


@pytest.fixture
def server(live_server: LiveServer, monkeypatch: pytest.MonkeyPatch) -> InProcessServer:
    """The shared service in this process, with a viser scene stand-in."""
    proc: InProcessServer = live_server.process
    monkeypatch.setattr(proc.app.state, "scene", _Scene(), raising=False)
    return proc


def _token(server: InProcessServer, site_id: str, scope: str) -> str:
    """A new token of ``site_id`` with ``scope``, stored through the service's writer."""
    return str(server.ctx.writer.call(
        lambda conn: create_token(conn, site_id, "tests", scope=scope)).result(60))


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def _reading(minute: int) -> dict[str, Any]:
    ts = dt.datetime(2026, 10, 1, tzinfo=dt.UTC) + dt.timedelta(minutes=minute)
    return {"readings": [{"ts": ts.isoformat(), "array": "tracker", "voltage_v": 30.0,
                          "current_a": 2.0}]}


def test_an_ingest_token_writes_readings_but_cannot_change_its_site(
        client: httpx.Client, server: InProcessServer) -> None:
    ingest = bearer(server.token(SITE))
    r = client.post(f"/api/v1/sites/{SITE}/measurements", headers=ingest, json=_reading(0))
    assert r.status_code == 200, r.text
    config = client.get(f"/api/v1/sites/{SITE}/config").json()
    moved = {**config, "latitude_deg": config["latitude_deg"] + 1.0}
    r = client.put(f"/api/v1/sites/{SITE}", headers=ingest, json=moved)
    assert r.status_code == 403 and "scope 'ingest'" in r.json()["detail"], r.text
    cal = f"/api/v1/sites/{SITE}/arrays/fixed/calibration"
    before = client.get(cal).json()
    r = client.put(cal, headers=ingest, json={**before, "adc_bits": 13})
    assert r.status_code == 403 and "scope 'ingest'" in r.json()["detail"], r.text
    assert client.get(cal).json() == before  # unchanged
    assert client.get(f"/api/v1/sites/{SITE}/config").json() == config

    site = bearer(_token(server, SITE, "site"))
    r = client.post(f"/api/v1/sites/{SITE}/measurements", headers=site, json=_reading(1))
    assert r.status_code == 200, r.text  # a site token also writes readings
    r = client.put(cal, headers=site, json={**before, "adc_bits": 13})
    assert r.status_code == 200 and client.get(cal).json()["adc_bits"] == 13
    other = bearer(_token(server, "guadalajara_fisheye", "site"))
    r = client.put(cal, headers=other, json=before)
    assert r.status_code == 403 and "guadalajara_fisheye" in r.json()["detail"]
    assert client.put(cal, headers=site, json=before).status_code == 200  # as it was


def test_a_revoked_token_is_answered_revoked(client: httpx.Client, server: InProcessServer,
                                             monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    token = server.token(SITE)
    monkeypatch.setenv("HELIOTWIN_DATABASE_URL", server.database_url)
    revoke(argparse.Namespace(token_or_id=token))  # `heliotwin token revoke`
    assert "revoked token" in capsys.readouterr().out
    r = client.post(f"/api/v1/sites/{SITE}/measurements", headers=bearer(token),
                    json=_reading(2))
    assert r.status_code == 401 and r.json()["detail"] == "revoked write token"
    r = client.post(f"/api/v1/sites/{SITE}/measurements", headers=bearer("ht_no-such-token"),
                    json=_reading(2))
    assert r.status_code == 401 and r.json()["detail"] == "unknown write token"


def test_the_shared_replay_needs_a_site_token(client: httpx.Client, server: InProcessServer,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    # a finished run of SITE, without simulating one (the route's checks are the subject)
    run = SimpleNamespace(site_id=SITE, params={}, status="done")
    monkeypatch.setattr(server.ctx.simulations, "get", lambda run_id: run)
    monkeypatch.setattr(server.ctx.simulations, "series", lambda run_id: pd.DataFrame())
    start = pd.Timestamp("2024-03-15", tz="UTC")
    monkeypatch.setattr(twin3d.Replay, "from_series", lambda run_id, *a, **k: SimpleNamespace(
        run_id=run_id, site_id=SITE, start=start, end=start + pd.Timedelta(days=1)))
    body = {"run_id": "r1"}
    r = client.put("/api/v1/twin3d/replay", json=body)
    assert r.status_code == 401
    r = client.put("/api/v1/twin3d/replay", json=body, headers=bearer(server.token(SITE)))
    assert r.status_code == 403 and "scope 'ingest'" in r.json()["detail"]
    other = bearer(_token(server, "guadalajara_fisheye", "site"))
    assert client.put("/api/v1/twin3d/replay", json=body, headers=other).status_code == 403
    assert server.app.state.scene.replays == {}  # nobody's view changed
    # a tab's own viewer key changes that tab alone: no token needed
    r = client.put("/api/v1/twin3d/replay", json={**body, "viewer": "tab1"})
    assert r.status_code == 200, r.text
    site = bearer(_token(server, SITE, "site"))
    r = client.put("/api/v1/twin3d/replay", json=body, headers=site)
    assert r.status_code == 200 and "" in server.app.state.scene.replays
    assert client.delete("/api/v1/twin3d/replay").status_code == 401
    assert client.delete("/api/v1/twin3d/replay", headers=site).status_code == 200
    assert "" not in server.app.state.scene.replays


def test_the_cli_makes_and_lists_scoped_tokens(server: InProcessServer,
                                               monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("HELIOTWIN_DATABASE_URL", server.database_url)
    create(argparse.Namespace(site=SITE, label="operator", scope="site",
                              expires_in_days=None, expires=None))
    made = capsys.readouterr()
    assert made.err.startswith("site token for site tehuantepec")
    assert made.out.startswith("ht_") and made.out.count("\n") == 1  # the token alone
    list_(argparse.Namespace(site=SITE, json=False))
    table = capsys.readouterr().out.splitlines()
    assert table[0].split()[:3] == ["id", "site_id", "scope"]
    operator = [row.split() for row in table if row.rstrip().endswith("operator")]
    assert operator and operator[0][2] == "site"


def test_tokens_stored_before_scopes_become_ingest(tmp_path: Path) -> None:
    def rows(conn: Connection) -> None:
        conn.execute(text(OLD_SITE_SQL))
        conn.execute(text("INSERT INTO logger_tokens (site_id, token_sha256, token_prefix, "
                          "label, created_at) VALUES ('s', 'h', 'ht_x', 'old', "
                          "'2026-01-01')"))

    with upgraded_from(f"sqlite:///{tmp_path / 'old.sqlite'}", "0007_alerts", rows) as conn:
        assert conn.execute(text("SELECT scope FROM logger_tokens")).scalars().all() == [
            "ingest"]


def test_restarts_leave_one_demo_logger_token(tmp_path: Path) -> None:
    """Issue 22, item 11: each ``heliotwin serve`` start made another active demo token."""
    engine = make_engine(get_settings(database_url=f"sqlite:///{tmp_path / 'demo.sqlite'}"))
    run_migrations(engine)
    try:
        with engine.begin() as conn:
            sync_sites(conn, [Registry.load_files(tmp_path / "sites").sites[SITE].site])
            other = create_token(conn, SITE, "a field logger")
        tokens = []
        for _ in range(3):  # three starts
            with engine.begin() as conn:
                tokens.append(demo_token(conn, SITE))
        with engine.connect() as conn:
            labels = sorted(t.label for t in list_tokens(conn, SITE) if t.status() == "active")
        assert labels == ["a field logger", DEMO_TOKEN_LABEL]
        cache = TokenCache(engine)
        assert cache.site_of(tokens[-1]) == SITE and cache.site_of(other) == SITE
        assert cache.site_of(tokens[0]) is None
    finally:
        engine.dispose()
