"""``HELIOTWIN_READ_REQUIRE_TOKEN``: every read of the service's data needs a token.

The reads are enumerated from the app's routes (every GET), so a route added later is
checked without anyone remembering to: without a token each answers 401 naming the
setting, except the public ones listed here (:data:`PUBLIC`, which must be the service's
own ``backend.api.deps.PUBLIC_READS``); with the admin token each is served. A logger's
``ingest`` token reads too (any valid token does); a bad token is the usual 401.
"""

from __future__ import annotations

import datetime as dt
import re
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.routing import APIRoute
from live_service import InProcessServer, new_database

ADMIN = "admin-token-read-tests"
SITE = "tehuantepec"
SETTING = "HELIOTWIN_READ_REQUIRE_TOKEN"

#: The reads open to anyone with the setting on: they hold none of the sites' data.
PUBLIC = {"/healthz", "/api/v1/meta", "/", "/vendor/plotly.min.js", "/docs",
          "/api/v1/sites/schema.json", "/api/v1/vision/frame-times"}

_DAY = (dt.date.today() - dt.timedelta(days=2)).isoformat()
_NEXT = (dt.date.today() - dt.timedelta(days=1)).isoformat()
#: A value for each path or required query parameter of a read (a new one: add it here).
SAMPLES: dict[str, str] = {
    "site_id": SITE, "array": "tracker", "plant_id": "", "run_id": "no-such-run",
    "sweep_id": "no-such-sweep", "calibration_id": "999999", "start": _DAY, "end": _NEXT,
    "date": _DAY, "time": f"{_DAY}T12:00:00Z", "filename": "sky_20240601T120000Z.jpg",
    "layout": "grid", "gcr": "0.3", "strategy": "astronomical"}
#: Reads of ids the test has not made: served, but 404 (the token was accepted first).
ABSENT_IDS = {"run_id", "sweep_id", "calibration_id"}
#: What a read may answer with a token other than 200, and why.
NOT_200 = {"/api/v1/twin3d": 503,  # the tests' service runs without viser
           # no observations stored: the fit says it needs 10 (after the token was taken)
           "/api/v1/sites/{site_id}/pointing-model": 422,
           "/api/v1/sites/{site_id}/pointing-model/command": 422}


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[InProcessServer]:
    db = new_database("sqlite", tmp_path_factory.mktemp("read-token"))
    proc = InProcessServer(db.url, extra_env={
        SETTING: "true", "HELIOTWIN_ADMIN_TOKEN": ADMIN, "HELIOTWIN_ALERTS": "false"}).start()
    try:
        yield proc
    finally:
        proc.stop()
        db.drop()


def _routes(routes: list[Any]) -> Iterator[APIRoute]:
    """Every API route, those of the included routers too (FastAPI ≥ 0.16x keeps an included
    router as one entry of ``app.routes``, its ``original_router`` holding its routes)."""
    for route in routes:
        if isinstance(route, APIRoute):
            yield route
        elif hasattr(route, "original_router"):
            # included without a prefix: a route's ``path`` is its whole path, which is
            # what ``deps.read_token`` compares with PUBLIC_READS
            assert getattr(route.include_context, "prefix", "") == ""
            yield from _routes(route.original_router.routes)


def _reads(server: InProcessServer) -> list[APIRoute]:
    return [r for r in _routes(server.app.routes) if "GET" in r.methods]


def _request(server: InProcessServer, route: APIRoute) -> tuple[str, dict[str, str]]:
    """The route's URL with its path parameters filled in, and its required query."""
    samples = {**SAMPLES, "plant_id": _first_plant(server)}
    names = re.findall(r"{(\w+)}", route.path)
    missing = [n for n in names if n not in samples]
    assert not missing, f"{route.path}: add a sample value of {missing} to SAMPLES"
    url = route.path
    for name in names:
        url = url.replace("{" + name + "}", samples[name])
    query = {}
    for param in route.dependant.query_params:
        if param.field_info.is_required():
            assert param.alias in samples, (
                f"{route.path}: add a sample value of the query's {param.alias!r} to SAMPLES")
            query[param.alias] = samples[param.alias]
    return url, query


def _first_plant(server: InProcessServer) -> str:
    return sorted(p.stem for p in server.settings.sites.plants_dir.glob("*.json"))[0]


def _ids(route: APIRoute) -> set[str]:
    return set(re.findall(r"{(\w+)}", route.path))


def test_the_public_reads_are_the_services() -> None:
    from backend.api.deps import PUBLIC_READS

    assert set(PUBLIC_READS) == PUBLIC


def test_meta_says_reads_need_a_token(server: InProcessServer) -> None:
    with server.client() as c:
        r = c.get("/api/v1/meta")
    assert r.status_code == 200 and r.json()["read_require_token"] is True


def test_every_read_needs_a_token(server: InProcessServer) -> None:
    reads = _reads(server)
    assert len(reads) > 30, "the app's GET routes were not found"
    refused, served = [], []
    with server.client() as anon, server.client(
            headers={"Authorization": f"Bearer {ADMIN}"}) as admin:
        for route in reads:
            url, query = _request(server, route)
            r = anon.get(url, params=query)
            if route.path in PUBLIC:
                if r.status_code == 401:
                    refused.append(f"{route.path}: public, but {r.status_code} {r.text[:120]}")
                continue
            if r.status_code != 401 or SETTING not in r.json()["detail"]:
                refused.append(f"{route.path} without a token: {r.status_code} {r.text[:120]}")
            assert r.headers.get("www-authenticate") == "Bearer" or r.status_code != 401
            r = admin.get(url, params=query)
            expected = 404 if _ids(route) & ABSENT_IDS else NOT_200.get(route.path, 200)
            if r.status_code != expected:
                served.append(f"{route.path} with a token: {r.status_code} (expected "
                              f"{expected}) {r.text[:160]}")
    assert not refused, "\n".join(refused)
    assert not served, "\n".join(served)


@pytest.mark.parametrize("scope", ["ingest", "site"])
def test_a_site_token_of_any_scope_reads(server: InProcessServer, scope: str) -> None:
    """Any valid token reads: a logger's ``ingest`` token too, and another site's data."""
    token = server.token(SITE, scope=scope)
    with server.client(headers={"Authorization": f"Bearer {token}"}) as c:
        day = {"start": _DAY, "end": _NEXT}
        for path, query in ((f"/api/v1/sites/{SITE}/measurements", {**day, "array": "tracker"}),
                            (f"/api/v1/sites/{SITE}/energy", day),
                            ("/api/v1/sites", {}), (f"/api/v1/sites/{SITE}/config", {}),
                            ("/api/v1/alerts", {}),
                            ("/api/v1/sites/guadalajara_fisheye/status", {})):
            r = c.get(path, params=query)
            assert r.status_code == 200, (path, r.status_code, r.text[:200])


def test_a_bad_token_is_refused_as_everywhere(server: InProcessServer) -> None:
    with server.client(headers={"Authorization": "Bearer not-a-token"}) as c:
        r = c.get("/api/v1/sites")
        assert r.status_code == 401 and r.json()["detail"] == "unknown write token"
        # a public read does not look at the token
        assert c.get("/healthz").status_code == 200
    with server.client(headers={"Authorization": "Basic eDp5"}) as c:
        r = c.get("/api/v1/sites")
        assert r.status_code == 401 and "Bearer" in r.json()["detail"]


def test_writes_and_compute_keep_their_own_rules(server: InProcessServer) -> None:
    """The setting is about reads: a write without a token is refused by its route as
    before (its own message), an estimate stays open to the anonymous allowance."""
    with server.client() as c:
        r = c.put(f"/api/v1/sites/{SITE}", json={})
        assert r.status_code == 401 and SETTING not in r.text
        r = c.post("/api/v1/simulations/estimate", json={
            "site_id": SITE, "start": f"{_DAY}T00:00:00Z", "end": f"{_NEXT}T00:00:00Z"})
        assert r.status_code == 200, r.text


def test_reads_are_open_by_default(tmp_path: Any) -> None:
    db = new_database("sqlite", tmp_path)
    with InProcessServer(db.url) as server, server.client() as c:
        assert c.get("/api/v1/meta").json()["read_require_token"] is False
        assert c.get("/api/v1/sites").status_code == 200
        assert c.get(f"/api/v1/sites/{SITE}/config").status_code == 200
