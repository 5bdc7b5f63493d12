"""The Plant page in a real headless Chromium against the real service app.

The server is ``backend.app.create_app`` (temporary SQLite, no viser, no live twin, no
demo logger) served by uvicorn; the plants router is included when ``backend/app.py``
does not register it yet. Any console error fails the test.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "test-artifacts"
CHROMIUM = Path(os.environ.get("HELIOTWIN_CHROMIUM", "/usr/bin/chromium"))
CHROMIUM_ARGS = ["--no-sandbox", "--disable-background-networking"]

pytestmark = [pytest.mark.browser, pytest.mark.timeout(180)]


class _PlantServer:
    def __init__(self, url: str) -> None:
        self.url = url


@pytest.fixture(scope="module")
def plant_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[_PlantServer]:
    import socket

    import uvicorn

    from backend.api.routes import plants
    from backend.app import create_app
    from backend.settings import Settings

    tmp = tmp_path_factory.mktemp("plant-e2e")
    settings = Settings(database_url=f"sqlite:///{tmp / 'heliotwin.sqlite'}", viser=False,
                        live_twin=False, demo_logger=False)
    app = create_app(settings)
    if not any(getattr(r, "path", "").startswith("/api/v1/plants") for r in app.routes):
        app.include_router(plants.router)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 60
    while not server.started:
        if time.monotonic() > deadline or not thread.is_alive():
            raise RuntimeError("the service did not start")
        time.sleep(0.1)
    yield _PlantServer(f"http://127.0.0.1:{port}")
    server.should_exit = True
    thread.join(timeout=15)


@pytest.fixture(scope="module")
def plant_page(plant_server: _PlantServer, request: pytest.FixtureRequest) -> Iterator[object]:
    """Debian's Chromium under Playwright; console errors and page errors fail the test."""
    if not CHROMIUM.exists():
        if os.environ.get("HELIOTWIN_REQUIRE_SERVICES") == "1":
            pytest.fail(f"Chromium not found at {CHROMIUM} (HELIOTWIN_REQUIRE_SERVICES=1)")
        pytest.skip(f"Chromium not found at {CHROMIUM}: browser tests skipped")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        context = browser.new_context(viewport={"width": 1400, "height": 1000})
        pg = context.new_page()
        errors: list[str] = []
        pg.on("console", lambda m: errors.append(f"console.error: {m.text}")
              if m.type == "error" else None)
        pg.on("pageerror", lambda e: errors.append(f"pageerror: {e}"))
        pg.set_default_timeout(30_000)
        yield pg
        context.close()
        browser.close()
    assert not errors, "errors in the browser console:\n" + "\n".join(errors)


def test_plant_page_shows_layout_shade_strategies_and_sky_map(plant_page, plant_server) -> None:  # type: ignore[no-untyped-def]
    import cv2

    page = plant_page

    page.goto(plant_server.url + "/#plant?day=2021-12-21")
    page.wait_for_selector('body[data-plant-loaded="penarroya/2021-12-21"]', timeout=60_000)
    assert page.input_value("#plant-day") == "2021-12-21"
    # the layout holds all 29 collectors, some shaded at the first shaded step
    colors = page.evaluate(
        "() => document.getElementById('chart-plant-layout').data[0].marker.color")
    assert len(colors) == 29
    assert 0 < sum(c > 0 for c in colors) <= 29
    assert int(page.get_attribute("#chart-plant-shade", "data-points")) > 20
    bars = page.evaluate("() => document.getElementById('chart-plant-strategies').data[0].x")
    assert bars == ["sun", "backtrack", "sky_scan", "fixed"]
    # the sky map image loads for the selected time and shows the grey shading region
    page.wait_for_function(
        "() => { const i = document.getElementById('plant-sky-map');"
        " return i.complete && i.naturalWidth > 0 && i.dataset.loaded === i.dataset.time; }")
    page.wait_for_function("() => document.getElementById('plant-chosen').textContent.length > 0")
    assert "collectors shaded" in page.text_content("#plant-chosen")
    shot = page.locator("#plant-sky-map").screenshot()
    img = cv2.imdecode(np.frombuffer(shot, np.uint8), cv2.IMREAD_COLOR)
    assert (np.abs(img.astype(int) - 150).max(axis=-1) <= 3).mean() > 0.01
    # moving the time slider to noon clears the shade of the layout
    n = int(page.get_attribute("#plant-time", "max"))
    page.fill("#plant-time", str(n // 2))
    page.dispatch_event("#plant-time", "input")
    page.wait_for_function(
        "() => document.getElementById('chart-plant-layout').data[0].marker.color"
        ".every(c => c === 0)")
    page.wait_for_function(
        "() => { const i = document.getElementById('plant-sky-map');"
        " return i.complete && i.dataset.loaded === i.dataset.time; }")
    page.wait_for_function("() => document.getElementById('plant-chosen').textContent"
                           ".includes('0 collectors shaded')")
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "plant.png"), full_page=True)
