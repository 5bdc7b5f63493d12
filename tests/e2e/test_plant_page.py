"""The Plant page in a real headless Chromium against a running ``heliotwin serve``
(the e2e fixtures of ``conftest.py``); any console error fails the test.

A plant is a file of the service's plants folder (no route writes one). For a polygon
plant the page comes from the session's server, and its ``/api/v1/plants`` requests are
answered by the service in this process (``InProcessServer``: 0.3 s to start where a
second ``heliotwin serve`` takes 3-6 s) whose ``HELIOTWIN_PLANTS_DIR`` holds the plant."""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest

from sim.plant import default_plants_dir

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "backend"))
from live_service import InProcessServer, new_database  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "test-artifacts"
# Peñarroya's pivots with an L-shaped collector, [u, v] m about the pivot (u right, v up)
L_SHAPE = [[-6, -2.5], [6, -2.5], [6, 0], [0, 0], [0, 2.5], [-6, 2.5]]

pytestmark = [pytest.mark.browser, pytest.mark.timeout(180)]


def test_plant_page_shows_layout_shade_strategies_and_sky_map(page, server) -> None:
    import cv2

    page.goto(server.url + "/#plant?day=2021-12-21")
    page.wait_for_selector('body[data-plant-loaded="penarroya/2021-12-21"]', timeout=60_000)
    assert page.input_value("#plant-day") == "2021-12-21"
    # the layout holds all 29 collectors, some shaded at the first shaded step
    colors = page.evaluate(
        "() => document.getElementById('chart-plant-layout').data[0].marker.color")
    assert len(colors) == 29
    assert 0 < sum(c > 0 for c in colors) <= 29
    # a rectangular collector: a square marker each, no outlines
    layout = page.evaluate("() => { const c = document.getElementById('chart-plant-layout');"
                           " return [c.data[0].marker.symbol, c.layout.shapes || []]; }")
    assert layout == ["square", []]
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


@pytest.fixture(scope="module")
def polygon_plants(browser, tmp_path_factory: pytest.TempPathFactory) -> Iterator[httpx.Client]:
    """A client of the service in this process whose only plant is Peñarroya with the L."""
    tmp = tmp_path_factory.mktemp("plant-polygon")
    plant = json.loads((default_plants_dir() / "penarroya.json").read_text())
    del plant["collector"]["width_m"], plant["collector"]["height_m"]
    plant["plant_id"], plant["collector"]["outline_m"] = "penarroya-l", L_SHAPE
    (tmp / "plants").mkdir()
    (tmp / "plants" / "penarroya-l.json").write_text(json.dumps(plant))
    with InProcessServer(new_database("sqlite", tmp).url,
                         {"HELIOTWIN_PLANTS_DIR": str(tmp / "plants")}) as service, \
            service.client(timeout_s=60) as client:
        yield client


def test_plant_page_draws_a_polygon_collector_outline(page, server,  # type: ignore[no-untyped-def]
                                                      polygon_plants: httpx.Client) -> None:
    """Each collector's outline is drawn to scale at its pivot (u east, v north), filled
    with its shade's colour; the strategies offered are ``sun`` alone, no sky map."""

    def answer(route) -> None:  # type: ignore[no-untyped-def]
        req = route.request
        r = polygon_plants.request(req.method, req.url.removeprefix(server.url),
                                   headers={"accept": req.headers.get("accept", "*/*")})
        route.fulfill(status=r.status_code, body=r.content,
                      headers={"content-type": r.headers["content-type"]})

    page.route(server.url + "/api/v1/plants**", answer)
    page.goto(server.url + "/#plant?day=2021-12-21")
    page.wait_for_selector('body[data-plant-loaded="penarroya-l/2021-12-21"]')
    trackers = polygon_plants.get("/api/v1/plants/penarroya-l").json()["trackers"]
    # the drawn SVG paths, in pixels: one per collector, the L at its pivot under one
    # scale for east and north (px = a·east + b, py = −a·north + c)
    paths = page.eval_on_selector_all(
        "#chart-plant-layout .shapelayer path", "ps => ps.map(p => p.getAttribute('d'))")
    assert len(paths) == len(trackers) == 29
    px = np.array([[float(v) for v in pt.split(",")] for d in paths
                   for pt in d.strip("MZ").split("L")])
    metres = np.array([[t["east_m"] + u, t["north_m"] + v] for t in trackers
                       for u, v in L_SHAPE])
    assert px.shape == metres.shape
    ones, zeros = np.ones((len(px), 1)), np.zeros((len(px), 1))
    design = np.block([[metres[:, :1], ones, zeros], [-metres[:, 1:], zeros, ones]])
    drawn = np.concatenate([px[:, 0], px[:, 1]])
    coef, *_ = np.linalg.lstsq(design, drawn, rcond=None)
    assert coef[0] > 1.0  # px per metre
    off = np.abs(design @ coef - drawn).max()
    assert off < 0.5, f"the outlines are {off:.1f} px off the L at its pivots"
    # filled with the colour of each shaded fraction (#d3f9d8 → #343a40 up to cmax)
    f = np.array(page.evaluate(
        "() => document.getElementById('chart-plant-layout').data[0].marker.color"))
    assert 0 < (f > 0).sum() < 29
    fills = page.eval_on_selector_all("#chart-plant-layout .shapelayer path",
                                      "ps => ps.map(p => p.style.fill)")
    light, dark = np.array([211, 249, 216]), np.array([52, 58, 64])
    want = light + f[:, None] / max(0.05, f.max()) * (dark - light)
    got = np.array([[float(c) for c in fill[4:-1].split(",")] for fill in fills])
    assert np.abs(got - want).max() <= 0.5 + 1e-9
    # sun tracking alone: the strategies offered, the energies, no sky map
    options = page.eval_on_selector_all("#plant-strategy option", "os => os.map(o => o.value)")
    assert options == ["sun"]
    bars = page.evaluate("() => document.getElementById('chart-plant-strategies').data[0].x")
    assert bars == ["sun", "fixed"]
    assert page.is_hidden("#plant-sky-map")
    page.wait_for_function(
        "() => document.getElementById('plant-chosen').textContent.includes('no sky map')")
    ARTIFACTS.mkdir(exist_ok=True)
    page.locator("#page-plant .grid").first.screenshot(path=str(ARTIFACTS / "plant-polygon.png"))
