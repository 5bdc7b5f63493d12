"""The Simulation page with a controller and a disturbance, in a real Chromium: the machine's
fields come from the service, the run's pointing error is shown and charted."""

from __future__ import annotations

import datetime as dt
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "test-artifacts"

pytestmark = [pytest.mark.browser, pytest.mark.timeout(180)]


def _points(page, chart_id: str) -> int:
    return int(page.get_attribute(f"#{chart_id}", "data-points") or 0)


def _run_open_loop(page, server, yaw_deg: str) -> str:
    """Yesterday at 5 min with ``open_loop_spa`` and a pedestal yaw, run from the page."""
    page.goto(server.url + "/#simulation")
    page.wait_for_selector("#sim-machine-fields input[name=pedestal_yaw_deg]", state="attached")
    day = (server.today() - dt.timedelta(days=1)).isoformat()
    page.fill("#sim-start", day)
    page.fill("#sim-end", server.today().isoformat())
    page.select_option("#sim-step", "300")
    page.select_option("#sim-controller", "open_loop_spa")
    page.click("#sim-machine summary")
    page.fill("#sim-pedestal_yaw_deg", yaw_deg)
    page.click("#sim-run")
    page.wait_for_selector("body[data-simulation-done]", timeout=90_000)
    return day


def test_open_loop_with_a_pedestal_yaw_points_off_and_says_so(page, server) -> None:
    _run_open_loop(page, server, "2")
    tiles = page.text_content("#sim-summary") or ""
    rms = re.search(r"Pointing error\s*([\d.]+) mrad", tiles)
    assert rms, tiles
    # 2° of yaw is 34.9 mrad of azimuth; seen along the normal it shrinks with the sun's
    # elevation (× cos el): tens of mrad over the day
    assert 10.0 < float(rms.group(1)) < 40.0
    assert "Net gain" in tiles and "moves" in tiles
    assert _points(page, "chart-sim-pointing") > 50
    names = page.evaluate("() => document.getElementById('chart-sim-angles').data"
                          ".map(t => t.name)")
    assert "azimuth commanded" in names and "tracker azimuth (actual)" in names
    page.screenshot(path=str(ARTIFACTS / "simulation-control.png"), full_page=True)


def test_a_run_shown_in_the_3d_twin(page, server) -> None:
    import httpx

    day = _run_open_loop(page, server, "3")
    run_id = page.get_attribute("#sim-3d", "data-run-id")
    with page.expect_response("**/api/v1/twin3d/replay") as answer:
        page.click("#sim-3d")
    assert answer.value.status == 200
    replay = answer.value.json()
    assert replay["run_id"] == run_id and replay["start"].startswith(day[:4])
    page.wait_for_url("**/#twin")
    page.wait_for_selector("#twin-frame[src]")
    bad = httpx.put(server.url + "/api/v1/twin3d/replay", json={"run_id": "nope"}, timeout=10)
    assert bad.status_code == 404 and "run_id" in bad.json()["detail"]
    # the scene now replays the run; the service says so and goes back to live on DELETE
    r = httpx.delete(server.url + "/api/v1/twin3d/replay", timeout=10)
    assert r.status_code == 200 and r.json() == {"replay": None}


def test_a_run_that_has_not_reported_says_no_percentage(page, server) -> None:
    """A run reports its progress at the end of each 65,536 steps: a 4-day run at 1 min said
    "0 % of about 1 s" until it was done. Before its first report the page gives the
    expected time and the elapsed one, no percentage (the run's state here is held at
    running, progress 0, by the test; the run itself goes on in the service)."""
    import json

    def held(route) -> None:  # type: ignore[no-untyped-def]
        if route.request.method != "GET" or route.request.url.endswith("/estimate"):
            route.continue_()
            return
        run_id = route.request.url.rsplit("/", 1)[1].split("?")[0]
        route.fulfill(status=200, content_type="application/json", body=json.dumps({
            "run_id": run_id, "site_id": "tehuantepec", "status": "running", "progress": 0.0,
            "summary": None, "error": None, "estimated_run_s": 600.0, "estimated_wait_s": 0.0,
            "queue_position": None}))

    page.goto(server.url + "/#simulation")
    page.wait_for_selector("#sim-form")
    page.route("**/api/v1/simulations/*", held)
    day = (server.today() - dt.timedelta(days=1)).isoformat()
    page.fill("#sim-start", day)
    page.fill("#sim-end", server.today().isoformat())
    page.select_option("#sim-step", "300")
    page.click("#sim-run")
    page.wait_for_function("() => document.getElementById('sim-progress-text').textContent"
                           ".startsWith('running · about 10 min expected · ')")
    assert "%" not in page.text_content("#sim-progress-text")
    page.unroute("**/api/v1/simulations/*")
    page.click("#sim-cancel")
