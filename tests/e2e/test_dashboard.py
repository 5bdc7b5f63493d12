"""The dashboard in a real headless Chromium against a running ``heliotwin serve``.

Each test drives one page the way a person would and checks what is drawn:
charts that hold data points, a date change that changes them, an uploaded sky
image with the detected sun on it, a simulation run from the browser, and the
viser 3D twin rendering into its iframe. The ``page`` fixture fails a test on
any console error. Screenshots go to ``test-artifacts/``.
"""

from __future__ import annotations

import datetime as dt
import re
import urllib.parse
from pathlib import Path

import cv2
import pytest

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "test-artifacts"

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

REAL_SKY = ROOT / "tests" / "data" / "real-sky"  # copied from shared/, with licences
# A hand-labelled Wettermast frame: sun at row 1295, column 820 (see its README/metadata).
WETTERMAST = "Wettermast_20160615_112430UTCp1_sunrow1295_suncol820.jpg"


def _points(page, chart_id: str) -> int:
    return int(page.get_attribute(f"#{chart_id}", "data-points") or 0)


def _first_x(page, chart_id: str) -> str:
    return page.evaluate(
        "id => { const el = document.getElementById(id);"
        " return el && el.data && el.data.length ? String(el.data[0].x[0]) : ''; }",
        chart_id,
    )


def _open_overview(page, server, hash_: str = "#overview") -> None:
    page.goto(server.url + "/" + hash_)
    page.wait_for_selector("body[data-overview-loaded]")


def test_overview_shows_charts_with_data(page, server) -> None:
    _open_overview(page, server)
    yesterday = (server.today() - dt.timedelta(days=1)).isoformat()
    assert page.input_value("#day-input") == server.today().isoformat()
    # Today may be early morning in the site's zone: go to yesterday, a full back-filled day.
    page.click("#day-prev")
    page.wait_for_selector(f'body[data-overview-loaded="{server.site["site_id"]}/{yesterday}"]')
    # the twin under the measured sky is drawn when it arrives, after the page is loaded
    page.wait_for_selector(f'body[data-overview-weather="{server.site["site_id"]}/{yesterday}"]')
    assert _points(page, "chart-power") > 100, "power chart holds no points for a back-filled day"
    assert _points(page, "chart-daily") > 0
    assert _points(page, "chart-cumulative") > 0
    traces = page.evaluate("() => document.getElementById('chart-power').data.map(t => t.name)")
    assert "tracker measured" in traces and "fixed measured" in traces
    assert page.locator("#tiles [data-testid=tile]").count() >= 6
    # the gain of today is so far, and says so (at sunrise it reads several hundred percent)
    gain_tile = page.locator("#tiles [data-testid=tile]", has_text="Gain today")
    assert "so far" in (gain_tile.locator(".sub").text_content() or "")
    axis = page.evaluate(
        "() => document.getElementById('chart-power').layout.yaxis.title.text")
    assert "[W]" in axis
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "overview.png"), full_page=True)
    # Every chart's CSV button downloads what it draws.
    for chart in ("chart-power", "chart-daily", "chart-cumulative"):
        with page.expect_download() as dl:
            page.click(f'button.csv[data-chart="{chart}"]')
        lines = Path(dl.value.path()).read_text().splitlines()
        assert len(lines) > 1, f"{chart}: empty CSV"
        assert "_w" in lines[0], f"{chart}: no unit in the CSV header {lines[0]!r}"
        if chart == "chart-power":
            assert len(lines) - 1 == _points(page, chart), "CSV rows differ from the points drawn"


def test_overview_refreshes_itself(page, server) -> None:
    """Live: with the page left open, it polls the service and redraws without a reload."""
    page.clock.install()
    requests: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    _open_overview(page, server)
    navigations = page.evaluate("() => performance.getEntriesByType('navigation').length")
    before = sum("/status" in u for u in requests), sum("/measurements" in u for u in requests)
    with page.expect_request(lambda r: "/measurements" in r.url):
        page.clock.run_for(31_000)
    page.wait_for_timeout(500)
    after = sum("/status" in u for u in requests), sum("/measurements" in u for u in requests)
    assert after[0] > before[0], "the tiles were not refreshed"
    assert after[1] > before[1], "today's charts were not refreshed"
    assert page.evaluate("() => performance.getEntriesByType('navigation').length") == navigations


@pytest.mark.parametrize("zone", ["America/Mexico_City", "Europe/Berlin", "Australia/Lord_Howe"])
def test_site_time_matches_zoneinfo(page, server, zone: str) -> None:
    """frontend/js/time.js (Intl in the browser) against Python's zoneinfo, DST days included."""
    from zoneinfo import ZoneInfo

    page.goto(server.url + "/#overview")
    days = ["2026-03-08", "2026-03-29", "2026-04-05", "2026-10-04", "2026-10-25", "2026-11-01",
            "2026-12-31"]
    got = page.evaluate(
        """async ([zone, days]) => {
          const t = await import('/static/js/time.js');
          return days.map((d) => {
            const ms = t.localMidnightMs(zone, d);
            const wall = t.toLocalWall(zone, ms + 13.5 * 3600e3);
            return [ms, wall, t.addDays(d, 1), t.localDate(zone, ms)];
          });
        }""", [zone, days])
    tz = ZoneInfo(zone)
    for d, (ms, wall, next_day, local) in zip(days, got, strict=True):
        midnight = dt.datetime.fromisoformat(d).replace(tzinfo=tz)
        assert ms == midnight.timestamp() * 1000, (zone, d)
        later = (midnight.astimezone(dt.UTC) + dt.timedelta(hours=13.5)).astimezone(tz)
        assert wall == later.strftime("%Y-%m-%d %H:%M:%S"), (zone, d)
        assert next_day == (dt.date.fromisoformat(d) + dt.timedelta(days=1)).isoformat()
        assert local == d


def test_changing_the_date_changes_the_charts(page, server) -> None:
    _open_overview(page, server)
    today = server.today()
    site = server.site["site_id"]
    day1 = (today - dt.timedelta(days=1)).isoformat()
    day2 = (today - dt.timedelta(days=2)).isoformat()
    page.fill("#day-input", day1)
    page.dispatch_event("#day-input", "change")
    page.wait_for_selector(f'body[data-overview-loaded="{site}/{day1}"]')
    x1 = _first_x(page, "chart-power")
    power1 = page.evaluate("() => document.getElementById('chart-power').data[0].y.slice(0, 2000)")
    page.click("#day-prev")
    page.wait_for_selector(f'body[data-overview-loaded="{site}/{day2}"]')
    x2 = _first_x(page, "chart-power")
    power2 = page.evaluate("() => document.getElementById('chart-power').data[0].y.slice(0, 2000)")
    assert x1.startswith(day1) and x2.startswith(day2), (x1, x2)
    assert power1 != power2
    assert _points(page, "chart-power") > 100
    assert "Energy of" in page.text_content("#day-energy-title")
    # The day lives in the address: a reload shows the same day; → steps forward again.
    assert f"day={day2}" in page.evaluate("() => location.hash")
    page.reload()
    page.wait_for_selector(f'body[data-overview-loaded="{site}/{day2}"]')
    assert page.input_value("#day-input") == day2
    page.locator("body").press("ArrowRight")
    page.wait_for_selector(f'body[data-overview-loaded="{site}/{day1}"]')


def _synthetic_sky(path: Path) -> tuple[float, float]:
    """A 640×480 all-sky frame (vision.synth) with the sun where SPA puts it at Tehuantepec
    on 2024-06-21 18:00 UTC; returns that sun's pixel (column, row)."""
    import pandas as pd
    import pvlib

    from vision.cameras import FisheyeCamera
    from vision.synth import fisheye_frame

    sun = pvlib.solarposition.get_solarposition(
        pd.DatetimeIndex([pd.Timestamp("2024-06-21T18:00:00Z")]), 16.28875, -95.240871, 50.0)
    az, el = float(sun["azimuth"].iloc[0]), float(sun["apparent_elevation"].iloc[0])
    cam = FisheyeCamera(cx_px=319.5, cy_px=239.5, px_per_deg=2.6)
    frame = fisheye_frame(az, el, camera=cam, seed=3)
    cv2.imwrite(str(path), frame.image)
    x, y = cam.sky_to_pixel(az, el)
    return float(x), float(y)


@pytest.mark.parametrize("kind", ["real", "synthetic"])
def test_sky_upload_shows_the_detected_sun(page, server, tmp_path: Path, kind: str) -> None:
    page.goto(server.url + "/#sky")
    page.wait_for_selector("#sky-form")
    if kind == "real":
        image = REAL_SKY / WETTERMAST
        label = (820.0, 1295.0)
        params = {"px_per_deg": "11.7", "cx_px": "972", "cy_px": "956"}
        page.select_option("#sky-place", "coords")
        page.fill('#sky-coords [name="latitude_deg"]', "53.519917")
        page.fill('#sky-coords [name="longitude_deg"]', "10.105139")
        tolerance_px = 15.0  # the glare biases the centroid on a real frame
    else:
        image = tmp_path / "synthetic_sky_20240621_180000.png"
        label = _synthetic_sky(image)
        params = {"px_per_deg": "2.6"}
        page.select_option("#sky-place", "site")  # the built-in site, Tehuantepec
        tolerance_px = 3.0
    page.select_option("#sky-camera", "fisheye")
    for name, value in params.items():
        page.fill(f'.cam-params[data-camera="fisheye"] [name="{name}"]', value)
    page.set_input_files("#sky-files", str(image))
    page.click("#sky-detect")
    result = page.wait_for_selector("[data-testid=sky-result]", timeout=30_000)
    assert result.get_attribute("data-sun-found") == "true", result.text_content()
    text = result.text_content()
    # The file name carries the time, the place was given: the ephemeris sun is shown too.
    assert "Centroid [px]" in text and "Ephemeris az / el" in text, text
    cell = page.locator("[data-testid=sky-result] tr:has-text('Centroid') td").text_content()
    cx, cy = [float(v.replace(",", "")) for v in cell.split(", ")]
    assert abs(cx - label[0]) < tolerance_px and abs(cy - label[1]) < tolerance_px, (cx, cy, label)
    # the frame's time formatted in the sky map's zone, named: typed coordinates' in UTC
    # (it was the raw ISO instant there, formatted only for a site)
    legend = page.locator("[data-testid=sky-result] .legend").text_content()
    zone = "UTC" if kind == "real" else "America/Mexico_City"
    assert legend.endswith(f"({zone})"), legend
    assert not re.search(r"\d{4}-\d{2}-\d{2}T\d", legend), legend
    # The orange detection marker is drawn on the canvas.
    orange = page.evaluate(
        """() => { const c = document.querySelector('[data-testid=sky-canvas]');
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data; let n = 0;
        for (let i = 0; i < d.length; i += 4)
          if (d[i] > 230 && d[i+1] > 90 && d[i+1] < 130 && d[i+2] < 30) n++;
        return n; }""")
    assert orange > 20, "no detection marker drawn on the image"
    # The stored detection appears on the day's sky map.
    page.wait_for_function("() => +document.getElementById('chart-sky-track').dataset.points > 0")
    page.screenshot(path=str(ARTIFACTS / f"sky-{kind}.png"), full_page=True)


def test_sky_calibration_from_timestamped_frames(page, server) -> None:
    """The six labelled Wettermast frames → a fitted fisheye, then used for detection."""
    frames = sorted(REAL_SKY.glob("Wettermast_*.jpg"))
    assert len(frames) == 6, f"the six Wettermast frames belong in {REAL_SKY}"
    page.goto(server.url + "/#sky")
    page.wait_for_selector("#sky-form")
    page.select_option("#sky-place", "coords")
    page.fill('#sky-coords [name="latitude_deg"]', "53.519917")
    page.fill('#sky-coords [name="longitude_deg"]', "10.105139")
    page.set_input_files("#sky-files", [str(f) for f in frames])
    page.click("#sky-calibrate")
    card = page.wait_for_selector("[data-testid=calibration-result]", timeout=60_000)
    rms = card.query_selector("tr:has-text('Residual RMS [px]') td").text_content()
    assert float(rms) < 4.0, f"calibration residual {rms} px"
    assert page.input_value("#sky-calibration") != "", "the new calibration is not selected"
    page.click("#sky-detect")
    page.wait_for_selector(f"[data-testid=sky-result] >> nth={len(frames) - 1}", timeout=60_000)
    found = page.locator("[data-testid=sky-result][data-sun-found=true]").count()
    assert found == len(frames)
    page.screenshot(path=str(ARTIFACTS / "sky-calibration.png"), full_page=True)


def test_images_chosen_before_the_sky_page_is_ready_are_detected(page, server) -> None:  # type: ignore[no-untyped-def]
    """A file chosen while the page still waits for the site list (its module starts after it)
    raised a change no one heard: "Detect the sun" said "Choose one or more images first"
    over the chosen file (a CI run under load). The page takes the files already chosen."""
    frame = sorted(REAL_SKY.glob("Wettermast_*.jpg"))[0]
    held: list = []
    page.route("**/api/v1/sites", lambda route: held.append(route))
    page.goto(server.url + "/#sky", wait_until="domcontentloaded")
    while not held:          # the site list asked for, and held: the Sky page not yet started
        page.wait_for_timeout(20)
    page.set_input_files("#sky-files", str(frame))
    for route in held:
        route.continue_()
    page.unroute("**/api/v1/sites")
    page.wait_for_selector("#chart-sky-error[data-points]", state="attached")
    page.select_option("#sky-place", "coords")
    page.fill('#sky-coords [name="latitude_deg"]', "53.519917")
    page.fill('#sky-coords [name="longitude_deg"]', "10.105139")
    page.click("#sky-detect")
    page.wait_for_selector("[data-testid=sky-result][data-sun-found=true]", timeout=60_000)


def test_simulation_runs_from_the_browser(page, server) -> None:
    page.goto(server.url + "/#simulation")
    page.wait_for_selector("#sim-form")
    day = (server.today() - dt.timedelta(days=1)).isoformat()
    page.fill("#sim-start", day)
    page.fill("#sim-end", server.today().isoformat())
    page.select_option("#sim-step", "300")
    page.click("#sim-run")
    page.wait_for_selector("body[data-simulation-done]", timeout=60_000)
    assert _points(page, "chart-sim-power") > 100
    assert _points(page, "chart-sim-angles") > 100
    assert "kWh" in page.text_content("#sim-summary") or "Wh" in page.text_content("#sim-summary")
    assert page.get_attribute("#sim-csv", "href").endswith("format=csv")
    page.screenshot(path=str(ARTIFACTS / "simulation.png"), full_page=True)


def test_twin_iframe_is_a_viser_canvas_of_its_own_viewer(page, server) -> None:
    """The iframe's address and viser's canvas in it; that the canvas draws the scene (not
    blank, and moving with the sun) is tests/e2e/test_twin3d_page.py's ``_drawn``."""
    page.goto(server.url + "/#twin")
    frame_el = page.wait_for_selector("#twin-frame[src]")
    # each viewer connects with its own address: /site/<id>/viewer/<key> (docs/twin3d.md)
    assert frame_el.get_attribute("src").startswith(server.viser_url + "?websocket=")
    assert "/site/tehuantepec/viewer/" in urllib.parse.unquote(frame_el.get_attribute("src"))
    assert page.get_attribute("#twin-open", "href").startswith(server.viser_url)
    frame_el.content_frame().wait_for_selector("canvas", timeout=30_000)


def test_the_address_follows_the_site_picker_on_every_page(page, server) -> None:  # type: ignore[no-untyped-def]
    """Picking a site on the Sky page puts it in the address, so a reload stays on it (only
    the Overview wrote it: a reload of #sky?site=old went back to the old site)."""
    page.goto(server.url + "/#sky?site=tehuantepec")
    page.wait_for_selector("#sky-form")
    page.select_option("#site-select", "guadalajara_fisheye")
    page.wait_for_function("() => location.hash.includes('site=guadalajara_fisheye')")
    assert page.evaluate("() => location.hash").startswith("#sky?")
    page.reload()
    page.wait_for_selector("#sky-form")
    assert page.input_value("#site-select") == "guadalajara_fisheye"
    # the header's offset is today's, and says so (a June day under a winter offset was
    # read as the day's; a researcher's finding)
    assert re.fullmatch(r"America/Mexico_City \(UTC−06:00 now\)",
                        page.text_content("#site-tz") or ""), page.text_content("#site-tz")
