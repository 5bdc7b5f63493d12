"""End-to-end fixtures: a real ``heliotwin serve`` with data, and Debian's Chromium.

The server runs as a subprocess on free ports (API and viser) with a temporary
SQLite file (``HELIOTWIN_DATABASE_URL``); the demo logger back-fills a few days
of minute readings over real HTTP, as at ``make run``. The browser is Debian's
``/usr/bin/chromium`` driven by Playwright (sync API); SwiftShader gives the
viser iframe a WebGL context without a GPU.

Without Chromium the tests skip with a message, unless
``HELIOTWIN_REQUIRE_SERVICES=1`` (CI), where they fail.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import os
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from zoneinfo import ZoneInfo

import httpx
import pytest

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "test-artifacts"
CHROMIUM = Path(os.environ.get("HELIOTWIN_CHROMIUM", "/usr/bin/chromium"))
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-background-networking",
    "--use-gl=swiftshader",
    "--enable-unsafe-swiftshader",
    # Debian's /etc/chromium.d/default-flags turns GPU rasterization on: under SwiftShader
    # every tile of every page was rasterized by an emulated GPU on the CPU; Skia's own
    # software rasterizer draws the same pages for less (WebGL still renders in SwiftShader)
    "--disable-gpu-rasterization",
]
SITE_ID = "tehuantepec"
BACKFILL_DAYS = 3
START_TIMEOUT_S = 90.0


def _require_or_skip(reason: str) -> None:
    if os.environ.get("HELIOTWIN_REQUIRE_SERVICES") == "1":
        pytest.fail(f"{reason} (HELIOTWIN_REQUIRE_SERVICES=1)")
    pytest.skip(reason)


def _need_chromium() -> None:
    if not CHROMIUM.exists():
        _require_or_skip(f"Chromium not found at {CHROMIUM}: browser tests skipped "
                         "(apt-get install chromium, or set HELIOTWIN_CHROMIUM)")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _heliotwin() -> list[str]:
    exe = Path(sys.executable).with_name("heliotwin")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "backend"]


@dataclass
class Server:
    """A running ``heliotwin serve`` and what the tests need to know about it."""

    url: str
    viser_url: str
    env: dict[str, str]
    site: dict = field(default_factory=dict)
    #: a write token of the site, stored before the server started (made while it runs, its
    #: SQLite write met the demo logger's: "database is locked", a fresh clone's run)
    write_token: str = ""

    @property
    def tz(self) -> ZoneInfo:
        return ZoneInfo(self.site.get("timezone", "UTC"))

    def today(self) -> dt.date:
        return dt.datetime.now(self.tz).date()


def _wait_healthy(client: httpx.Client, proc: subprocess.Popen, log: Path) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            tail = log.read_text()[-3000:]
            raise RuntimeError(f"heliotwin serve exited {proc.returncode}:\n{tail}")
        with contextlib.suppress(httpx.HTTPError):
            if client.get("/healthz", timeout=2).status_code == 200:
                return
        time.sleep(0.3)
    tail = log.read_text()[-3000:]
    raise RuntimeError(f"heliotwin serve not healthy after {START_TIMEOUT_S} s:\n{tail}")


def _wait_for_backfill(client: httpx.Client, server: Server) -> None:
    """Wait until the demo logger's back-fill reached the present for both arrays.

    Not merely "yesterday has readings": the back-fill posts its days oldest first, so
    tests that compare two reads of the past days (the API, then the page) would see them
    change in between while it is still running (both fixed and tracker: the last hour
    may be one of the logger's simulated outages)."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline:
        r = client.get(f"/api/v1/sites/{SITE_ID}/status")
        if r.status_code == 200:
            ages = [a.get("age_s") for a in r.json().get("arrays", {}).values()]
            if ages and all(age is not None and age < 3600 for age in ages):
                return
        time.sleep(0.5)
    raise RuntimeError("the demo logger's back-fill did not reach the present in time")


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Every test that drives Chromium (the ``browser`` fixture) carries the ``browser``
    marker, so ``-m "not browser"`` leaves them out and ``tests/conftest.py`` runs their
    modules first."""
    for item in items:
        if "browser" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.browser)


@pytest.fixture(scope="session")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    """``heliotwin serve`` on free ports with a temporary SQLite file and back-filled data,
    and a copy of the built-in plants folder (``HELIOTWIN_PLANTS_DIR``) that a test may add
    a plant file to, as a user would."""
    from sim.paths import default_plants_dir

    _need_chromium()
    tmp = tmp_path_factory.mktemp("e2e")
    port, viser_port = _free_port(), _free_port()
    shutil.copytree(default_plants_dir(), tmp / "plants")
    env = {
        **os.environ,
        "HELIOTWIN_DATABASE_URL": f"sqlite:///{tmp / 'heliotwin.sqlite'}",
        "HELIOTWIN_PLANTS_DIR": str(tmp / "plants"),
        "HELIOTWIN_DEMO_BACKFILL_DAYS": str(BACKFILL_DAYS),
        "PYTHONUNBUFFERED": "1",
    }
    from tests.backend.live_service import make_token

    token = make_token(env["HELIOTWIN_DATABASE_URL"], SITE_ID)
    log = tmp / "serve.log"
    cmd = [*_heliotwin(), "serve", "--host", "127.0.0.1", "--port", str(port),
           "--viser-port", str(viser_port)]
    with open(log, "wb") as out:
        proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=out, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    try:
        with httpx.Client(base_url=url, timeout=30) as client:
            _wait_healthy(client, proc, log)
            srv = Server(url=url, viser_url=f"http://127.0.0.1:{viser_port}/", env=env,
                         write_token=token)
            srv.site = client.get(f"/api/v1/sites/{SITE_ID}").raise_for_status().json()
            _wait_for_backfill(client, srv)
        yield srv
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)
        ARTIFACTS.mkdir(exist_ok=True)
        shutil.copy(log, ARTIFACTS / "e2e-serve.log")


@pytest.fixture(scope="session")
def browser() -> Iterator[object]:
    """Debian's Chromium under Playwright, shared by the session (without the session's
    server: the modules that start servers of their own need only the browser)."""
    _need_chromium()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> object:
    """Keep each phase's report on its test (``item.report_call``…) for :func:`call_failed`."""
    report = yield
    setattr(item, f"report_{report.when}", report)
    return report


def call_failed(request: pytest.FixtureRequest) -> bool:
    """Whether the test of this fixture failed (or never ran its body), for teardowns that
    keep evidence (screenshots) only then."""
    call = getattr(request.node, "report_call", None)
    return call is None or bool(call.failed)


@contextlib.contextmanager
def open_page(browser, request: pytest.FixtureRequest, timeout_ms: float = 20_000,  # type: ignore[no-untyped-def]
              ignore: Callable[[str], bool] = lambda text: False) -> Iterator[object]:
    """A fresh page that records console errors (but those ``ignore`` accepts) and uncaught
    exceptions in ``page.console_errors``; none may occur. A test that failed leaves a
    full-page screenshot in ``test-artifacts/`` (a passing one costs no screenshot)."""
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    pg = context.new_page()
    errors: list[str] = []

    def on_console(msg) -> None:  # type: ignore[no-untyped-def]
        if msg.type == "error" and not ignore(msg.text):
            errors.append(f"console.error: {msg.text} ({msg.location.get('url', '')})")

    pg.on("console", on_console)
    pg.on("pageerror", lambda e: errors.append(f"pageerror: {e}"))
    pg.set_default_timeout(timeout_ms)
    pg.console_errors = errors  # type: ignore[attr-defined]
    try:
        yield pg
    finally:
        if call_failed(request):
            ARTIFACTS.mkdir(exist_ok=True)
            with contextlib.suppress(Exception):
                pg.screenshot(path=str(ARTIFACTS / f"e2e-{request.node.name}-final.png"),
                              full_page=True)
        context.close()
    assert not errors, "errors in the browser console:\n" + "\n".join(errors)


@pytest.fixture()
def page(browser, server: Server, request: pytest.FixtureRequest) -> Iterator[object]:
    """A fresh page on the session's server (:func:`open_page`)."""
    with open_page(browser, request) as pg:
        yield pg
