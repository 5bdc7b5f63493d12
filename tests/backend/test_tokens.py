"""Write tokens: ``heliotwin token create|list|revoke`` and ``/api/v1/tokens`` on a running
service (in this process, ``live_service.InProcessServer``); the CLI runs as ``backend.cli.main``
in this process (``heliotwin_cli``) with its own database connection, and once as a real
process, where what the process prints is the subject.

A token revoked by the CLI (another connection, outside the server's token cache) is refused
within the cache TTL (``HELIOTWIN_TOKEN_CACHE_TTL_S`` ≤ 1 s); one revoked over HTTP at once; an
expired one from its expiry. Real database (SQLite and PostgreSQL).
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest
from live_service import BACKENDS, HELIOTWIN, ROOT, InProcessServer, new_database

ADMIN = "admin-secret-for-tests"


@pytest.fixture(scope="module", params=BACKENDS)
def server(request: pytest.FixtureRequest,
           tmp_path_factory: pytest.TempPathFactory) -> Iterator[InProcessServer]:
    tmp = tmp_path_factory.mktemp(f"tokens-{request.param}")
    db = new_database(request.param, tmp)
    proc = InProcessServer(db.url, extra_env={"HELIOTWIN_ADMIN_TOKEN": ADMIN}).start()
    try:
        yield proc
    finally:
        proc.stop()
        db.drop()


@pytest.fixture
def client(server: InProcessServer) -> Iterator[httpx.Client]:
    with server.client(timeout_s=30) as c:
        yield c


def _cli(server: InProcessServer, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*HELIOTWIN, "token", *args], cwd=ROOT, env=server.env,
                          capture_output=True, text=True, timeout=120)


def _post(client: httpx.Client, token: str, minute: int) -> httpx.Response:
    """One reading of the tracker, ``minute`` minutes after 2026-11-01 00:00 UTC."""
    ts = dt.datetime(2026, 11, 1, tzinfo=dt.UTC) + dt.timedelta(minutes=minute)
    return client.post("/api/v1/sites/tehuantepec/measurements",
                       headers={"Authorization": f"Bearer {token}"},
                       json={"readings": [{"ts": ts.isoformat(), "array": "tracker",
                                           "voltage_v": 30.0, "current_a": 2.0}]})


def test_create_prints_only_the_token(server: InProcessServer) -> None:
    out = _cli(server, "create", "--site", "tehuantepec", "--label", "quiet")
    assert out.returncode == 0, out.stderr
    # TOKEN=$(heliotwin token create …) holds the token alone; the sentence is on stderr
    assert out.stdout.startswith("ht_") and out.stdout.count("\n") == 1, out.stdout
    assert out.stderr.startswith("ingest token for site tehuantepec (shown once;"), out.stderr
    assert out.stderr.count("\n") == 1  # no INFO lines about migrations or sites


def test_cli_revocation_is_refused_within_a_second(server: InProcessServer,
                                                   client: httpx.Client,
                                                   heliotwin_cli: Callable) -> None:
    token = server.token("tehuantepec", "to-revoke")  # the CLI's revoke is the subject
    assert _post(client, token, 0).status_code == 200
    assert _post(client, token, 1).status_code == 200  # now cached by the server
    listed = json.loads(heliotwin_cli("token", "list", "--site", "tehuantepec", "--json",
                                     env=server.env).stdout)
    mine = [t for t in listed if token.startswith(t["token_prefix"]) and
            t["label"] == "to-revoke"]
    assert len(mine) == 1 and mine[0]["status"] == "active"
    assert token not in json.dumps(listed)  # list never shows a token

    revoked = heliotwin_cli("token", "revoke", str(mine[0]["id"]), env=server.env)
    assert revoked.returncode == 0, revoked.stderr
    time.sleep(1.0)
    r = _post(client, token, 2)
    assert r.status_code == 401, r.text
    after = json.loads(heliotwin_cli("token", "list", "--json", env=server.env).stdout)
    assert [t["status"] for t in after if t["id"] == mine[0]["id"]] == ["revoked"]


def test_cli_revoke_by_token_and_unknown(server: InProcessServer, client: httpx.Client,
                                         heliotwin_cli: Callable) -> None:
    token = server.token("tehuantepec")
    assert heliotwin_cli("token", "revoke", token, env=server.env).returncode == 0
    time.sleep(1.0)
    assert _post(client, token, 3).status_code == 401
    missing = heliotwin_cli("token", "revoke", "999999", env=server.env)
    assert missing.returncode == 2 and "no write token with id 999999" in missing.stderr
    bad = heliotwin_cli("token", "create", "--site", "tehuantepec", "--expires",
                        "2020-01-01T00:00Z", env=server.env)
    assert bad.returncode == 2 and "--expires" in bad.stderr


def test_admin_endpoints(server: InProcessServer, client: httpx.Client,
                         caplog: pytest.LogCaptureFixture) -> None:
    url = "/api/v1/tokens"
    admin = {"Authorization": f"Bearer {ADMIN}"}
    assert client.get(url).status_code == 401
    assert client.get(url, headers={"Authorization": "Bearer wrong"}).status_code == 401
    for scope in ("ingest", "site"):  # a valid token is authenticated, not allowed: 403
        site_token = server.token("tehuantepec", scope=scope)
        r = client.get(url, headers={"Authorization": f"Bearer {site_token}"})
        assert r.status_code == 403 and "admin token" in r.json()["detail"], r.text
        assert r.json()["detail"].startswith(
            f"{'an' if scope == 'ingest' else 'a'} {scope}-scope token of site "), r.text

    r = client.post(url, headers=admin, json={"site_id": "tehuantepec", "label": "http"})
    assert r.status_code == 201, r.text
    made = r.json()
    assert made["status"] == "active" and made["token"].startswith(made["token_prefix"])
    assert _post(client, made["token"], 10).status_code == 200
    refused = _post(client, ADMIN, 12)  # the admin token is not a logger's: said so, 403
    assert refused.status_code == 403 and "ingest" in refused.json()["detail"], refused.text
    listed = client.get(url, headers=admin, params={"site_id": "tehuantepec"}).json()["tokens"]
    assert made["id"] in [t["id"] for t in listed]
    assert all("token" not in t for t in listed)

    gone = client.delete(f"{url}/{made['id']}", headers=admin)
    assert gone.status_code == 200 and gone.json()["status"] == "revoked"
    assert _post(client, made["token"], 11).status_code == 401  # at once: cache forgotten
    with caplog.at_level(logging.INFO):  # an ordinary 404 is not a failed write
        assert client.delete(f"{url}/999999", headers=admin).status_code == 404
    assert [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING] == []

    bad = client.post(url, headers=admin, json={"site_id": "mars"})
    assert bad.status_code == 404 and "mars" in bad.text
    assert bad.json()["detail"].startswith("site_id: unknown site")  # the body's field
    bad = client.get(url, headers=admin, params={"site_id": "mars"})  # was an empty list
    assert bad.status_code == 404 and "mars" in bad.text
    bad = client.post(url, headers=admin, json={"site_id": "tehuantepec",
                                                "expires_at": "2020-01-01T00:00:00Z"})
    assert bad.status_code == 422 and "expires_at" in bad.text
    bad = client.post(url, headers=admin, json={"site_id": "tehuantepec",
                                                "expires_in_days": -1})
    assert bad.status_code == 422 and "expires_in_days" in bad.text
    for days in (True, "30"):  # strict: true had made a token expiring in one day
        bad = client.post(url, headers=admin, json={"site_id": "tehuantepec",
                                                    "expires_in_days": days})
        assert bad.status_code == 422 and "expires_in_days" in bad.text, bad.text
    # a NUL: PostgreSQL answered 500
    bad = client.post(url, headers=admin, json={"site_id": "tehuantepec", "label": "a\u0000b"})
    assert bad.status_code == 422 and "label" in bad.text, bad.text
    # a lone surrogate (JSON may escape one) is no UTF-8: the driver failed on it with a 500
    bad = client.post(url, headers={**admin, "Content-Type": "application/json"},
                      content=b'{"site_id": "tehuantepec", "label": "a\\ud800"}')
    assert bad.status_code == 422 and bad.json()["detail"][0]["loc"] == ["body", "label"], bad.text


def test_expired_token_is_refused(client: httpx.Client) -> None:
    admin = {"Authorization": f"Bearer {ADMIN}"}
    expires = dt.datetime.now(dt.UTC) + dt.timedelta(seconds=4)
    r = client.post("/api/v1/tokens", headers=admin,
                    json={"site_id": "tehuantepec", "expires_at": expires.isoformat()})
    assert r.status_code == 201, r.text
    token = r.json()["token"]
    assert _post(client, token, 20).status_code == 200  # cached with its expiry
    time.sleep(max(0.0, (expires - dt.datetime.now(dt.UTC)).total_seconds()) + 0.2)
    assert _post(client, token, 21).status_code == 401
    listed = client.get("/api/v1/tokens", headers=admin).json()["tokens"]
    assert [t["status"] for t in listed if t["id"] == r.json()["id"]] == ["expired"]


def test_admin_disabled_without_setting(tmp_path: Path) -> None:
    db = new_database("sqlite", tmp_path)
    with InProcessServer(db.url) as proc, proc.client() as c:
        r = c.get("/api/v1/tokens", headers={"Authorization": "Bearer anything"})
        assert r.status_code == 403 and "HELIOTWIN_ADMIN_TOKEN" in r.text


def test_the_admin_token_runs_simulations_as_site_edits_take_it(client: httpx.Client) -> None:
    """``POST /api/v1/simulations`` answered the admin token "unknown, expired or revoked
    write token" while ``PUT /api/v1/sites/{id}`` took it (a tester's finding): it is taken,
    as every route that reads a caller takes it (``backend.api.deps.caller_of``)."""
    body = {"site_id": "tehuantepec", "start": "2024-03-15", "end": "2024-03-16",
            "step_s": 3600}
    r = client.post("/api/v1/simulations", json=body,
                    headers={"Authorization": f"Bearer {ADMIN}"})
    assert r.status_code == 200, r.text
    r = client.post("/api/v1/simulations", json=body,
                    headers={"Authorization": "Bearer not-a-token-at-all"})
    assert r.status_code == 401 and "unknown" in r.json()["detail"]


def test_cli_refuses_a_site_without_a_config(tmp_path: Path, heliotwin_cli: Callable) -> None:
    """``token create`` for a site no config gives is refused naming it and the known sites,
    also when the database still holds the site after its file went (a token had been made
    there, exit 0, though the service answers "unknown site" to its every reading, and
    ``POST /api/v1/tokens`` 404s). ``list`` takes a built-in site the database does not
    hold yet (it answered "unknown site 'tehuantepec'; known sites: none") and one the
    database holds without a config (its tokens can be revoked)."""
    env = {"HELIOTWIN_DATABASE_URL": f"sqlite:///{tmp_path / 'db.sqlite'}",
           "HELIOTWIN_SITES_DIR": str(tmp_path / "sites")}
    fresh = heliotwin_cli("token", "list", "--site", "tehuantepec", "--json", env=env)
    assert (fresh.returncode, fresh.stdout.strip()) == (0, "[]"), fresh
    made = heliotwin_cli("site", "create", "--id", "gone", "--latitude-deg", "53.5",
                         "--longitude-deg", "10", "--altitude-m", "10", "--timezone",
                         "Europe/Berlin", env=env)
    assert made.returncode == 0, made.stderr
    (tmp_path / "sites" / "gone.json").unlink()  # the database keeps the site's row
    for command, site in (("create", "gone"), ("create", "nowhere"), ("list", "nowhere")):
        out = heliotwin_cli("token", command, "--site", site, env=env)
        assert (out.returncode, out.stdout) == (2, ""), out
        assert out.stderr.startswith(
            f"heliotwin token {command}: error: --site: unknown site {site!r}: no site "
            "config gives it"), out.stderr
        assert "known sites: guadalajara_fisheye, tehuantepec" in out.stderr  # was "none"
    listed = heliotwin_cli("token", "list", "--site", "gone", "--json", env=env)
    assert (listed.returncode, json.loads(listed.stdout)) == (0, [])  # nothing was stored
