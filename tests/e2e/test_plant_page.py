"""The Plant page in a real headless Chromium against a running ``heliotwin serve``
(the e2e fixtures of ``conftest.py``); any console error fails the test."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "test-artifacts"

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
