"""The running service: live twin loop, demo logger, status tiles, meta, clean shutdown (a
``heliotwin serve`` process: its signals and exit are the subject), and the 3D twin's port."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import httpx
import pytest
from live_service import InProcessServer, ServerProcess, new_database

if TYPE_CHECKING:
    from live_service import Database

BASE = "/api/v1/sites/tehuantepec"


def _wait(predicate, timeout_s: float = 60.0) -> bool:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.3)
    return False


@pytest.mark.slow
def test_serve_with_live_twin_and_demo_logger(database: Database, tmp_path: Path) -> None:
    server = ServerProcess(database.url, tmp_path / "server.log", demo=True, extra_env={
        "HELIOTWIN_LIVE_TWIN": "true", "HELIOTWIN_LIVE_TWIN_INTERVAL_S": "1",
        "HELIOTWIN_DEMO_BACKFILL_DAYS": "1"}).start()
    try:
        with httpx.Client(base_url=server.base_url, timeout=60) as c:
            meta = c.get("/api/v1/meta").json()
            assert {"version", "viser_port", "vision_require_token"} <= set(meta)

            def demo_backfilled() -> bool:
                """The back-fill reached the present (its last minutes may be an outage).

                Not merely "a reading arrived": the back-fill posts the day oldest first,
                in batches, so the first batch alone leaves the last reading hours old."""
                age_s = c.get(f"{BASE}/status").json()["arrays"]["tracker"]["age_s"]
                return age_s is not None and age_s < 3600

            assert _wait(demo_backfilled, timeout_s=120), server.log_tail()
            status = c.get(f"{BASE}/status").json()
            for key in ("time", "sun", "tracker", "arrays", "gain_today_pct"):
                assert key in status
            assert -90 <= status["sun"]["elevation_deg"] <= 90
            assert 0 <= status["sun"]["azimuth_deg"] < 360
            tr = status["arrays"]["tracker"]
            assert tr["age_s"] < 3600 and tr["twin_power_w"] is not None
            assert tr["logger"] in ("reporting", "stale")
            # the demo logger back-filled a day of minutes for both arrays over HTTP
            now = time.time()
            q = {"start": time.strftime("%Y-%m-%dT%H:%M:%S+00:00", time.gmtime(now - 86400)),
                 "end": time.strftime("%Y-%m-%dT%H:%M:%S+00:00", time.gmtime(now + 60))}
            n = c.get(f"{BASE}/measurements", params={**q, "array": "fixed",
                                                       "max_points": 10}).json()
            assert 1300 < sum(p["n"] for p in n["points"]) <= 1442
            # the live twin loop writes source=twin rows each interval
            live = {"start": time.strftime("%Y-%m-%dT%H:%M:00+00:00", time.gmtime(now - 120)),
                    "end": q["end"]}
            twin = c.get(f"{BASE}/measurements", params={**live, "array": "tracker",
                                                          "source": "twin"}).json()
            assert len(twin["points"]) >= 2
    finally:
        code = server.stop()
    # uvicorn shuts down gracefully, then re-raises SIGTERM (exit status -15)
    assert code in (0, -15), server.log_tail()
    assert "service stopped" in server.log_path.read_text()


def test_meta_reports_the_port_the_3d_twin_really_uses(database: Database) -> None:
    """With the configured viser port taken, the scene moves to a free one and
    /api/v1/meta says which, so the dashboard's iframe finds it. The service runs in this
    process (the port is the subject, not the process); viser answers on a real socket."""
    import socket

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        taken = busy.getsockname()[1]
        with InProcessServer(database.url, extra_env={
                "HELIOTWIN_VISER": "true", "HELIOTWIN_VISER_PORT": str(taken)}) as server, \
                server.client(timeout_s=30) as c:
            r = c.get("/api/v1/meta")
            meta = r.json()
            assert meta["viser_enabled"] is True
            assert meta["viser_port"] != taken
            assert meta["viser_public_port"] == meta["viser_port"]
            page = httpx.get(f"http://127.0.0.1:{meta['viser_port']}/", timeout=30)
            assert page.status_code == 200, page.text[:200]
            # the CSP lets the dashboard frame the port the scene moved to (it named the
            # configured, busy one: the 3D tab was blocked)
            csp = r.headers["content-security-policy"]
            assert f"frame-src http://testserver:{meta['viser_port']} " in csp, csp


def test_the_public_viser_port_is_the_one_meta_and_the_csp_give(database: Database) -> None:
    """Published on another port than it listens on (Docker Compose's 8081 for the
    container's 8080, a proxy), the 3D twin is framed at ``HELIOTWIN_VISER_PUBLIC_PORT``:
    /api/v1/meta says it beside the port listened on, and every page's CSP allows it
    (and not the inside port)."""
    with InProcessServer(database.url, extra_env={
            "HELIOTWIN_VISER": "false", "HELIOTWIN_VISER_PORT": "8080",
            "HELIOTWIN_VISER_PUBLIC_PORT": "8081"}) as server, \
            server.client(timeout_s=30) as c:
        r = c.get("/api/v1/meta", headers={"Host": "dash.example:8001"})
        assert (r.json()["viser_port"], r.json()["viser_public_port"]) == (8080, 8081)
        for path in ("/api/v1/meta", "/"):
            csp = c.get(path, headers={"Host": "dash.example:8001"}).headers[
                "content-security-policy"]
            directives = dict(d.split(" ", 1) for d in csp.split("; "))
            assert directives["frame-src"] == \
                "http://dash.example:8081 https://dash.example:8081", (path, csp)
            assert ":8080" not in csp, (path, csp)


@pytest.mark.slow
@pytest.mark.parametrize(("args", "env", "seen"), [
    ((), {}, "203.0.113.7"),  # a proxy on the same host is trusted (uvicorn's 127.0.0.1,::1)
    # only the proxy named, the flag over uvicorn's variable (which alone is uvicorn's own
    # rule: serve passes no value then)
    (("--forwarded-allow-ips", "10.0.0.5"), {"FORWARDED_ALLOW_IPS": "127.0.0.1"},
     "127.0.0.1"),
])
def test_serve_trusts_x_forwarded_for_from_the_proxies_named(
        tmp_path: Path, args: tuple[str, ...], env: dict[str, str], seen: str,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``heliotwin serve --forwarded-allow-ips`` (or FORWARDED_ALLOW_IPS) names the proxies
    whose X-Forwarded-For is the client's address (the one the anonymous allowances count
    by), as docs/service.md says; the access log shows the address the service saw."""
    monkeypatch.delenv("FORWARDED_ALLOW_IPS", raising=False)
    server = ServerProcess(new_database("sqlite", tmp_path).url, tmp_path / "server.log",
                           args=args, extra_env={"HELIOTWIN_ACCESS_LOG": "true", **env}).start()
    try:
        r = httpx.get(f"{server.base_url}/api/v1/meta", timeout=30,
                      headers={"X-Forwarded-For": "203.0.113.7"})
        assert r.status_code == 200
        assert _wait(lambda: '"GET /api/v1/meta HTTP/1.1" 200' in server.log_path.read_text(),
                     timeout_s=10)
    finally:
        server.stop()
    line = next(x for x in server.log_path.read_text().splitlines()
                if '"GET /api/v1/meta HTTP/1.1"' in x)
    assert f"{seen}:" in line, line


@pytest.mark.slow
def test_the_serve_banner_names_the_viser_port_really_taken(tmp_path: Path) -> None:
    """With the viser port taken, ``heliotwin serve`` says the port the scene moved to (its
    banner, printed before the scene started, named the busy one: a user opening the 3D
    twin alone went to another program's port)."""
    import socket

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        taken = busy.getsockname()[1]
        server = ServerProcess(new_database("sqlite", tmp_path).url, tmp_path / "server.log",
                               viser_port=taken, extra_env={"HELIOTWIN_VISER": "true"}).start()
        try:
            meta = httpx.get(f"{server.base_url}/api/v1/meta", timeout=30).json()
        finally:
            server.stop()
    assert meta["viser_port"] != taken
    (banner,) = [x for x in server.log_path.read_text().splitlines()
                 if x.startswith("heliotwin: dashboard and API on")]
    assert banner.endswith(f"3D twin on :{meta['viser_port']} (:{taken} was busy)"), banner
