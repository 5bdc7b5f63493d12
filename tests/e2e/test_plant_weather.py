"""The Plant page's run on a weather file (``POST /api/v1/plants/{plant_id}/weather``) in a
real headless Chromium against the session's ``heliotwin serve`` (``conftest.py``): the
summary's energy, wind stow and weather warning as tiles, and a refusal in the service's
words. The plants are files written into the server's folder while the test runs."""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from sim.plant import default_plants_dir
from sim.sky import pvlib_tmy3_path

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "test-artifacts"
SAND_POINT_TMY3 = pvlib_tmy3_path().parent / "703165TY.csv"

pytestmark = [pytest.mark.browser, pytest.mark.timeout(180)]


@contextlib.contextmanager
def _plants(server, **places: dict) -> Iterator[None]:  # type: ignore[no-untyped-def]
    """Peñarroya's layout at each of ``places`` (plant id → keys to set), as files of the
    server's plants folder; removed after."""
    paths = []
    for plant_id, keys in places.items():
        plant = json.loads((default_plants_dir() / "penarroya.json").read_text())
        plant.update(plant_id=plant_id, **keys)
        path = Path(server.env["HELIOTWIN_PLANTS_DIR"]) / f"{plant_id}.json"
        path.write_text(json.dumps(plant))
        paths.append(path)
    try:
        yield
    finally:
        for path in paths:
            path.unlink()


def _run(page, plant_id: str, path: Path, start: str, end: str, step_s: str,  # type: ignore[no-untyped-def]
         force: bool = False, name: str | None = None) -> None:
    page.select_option("#plant-select", plant_id)
    page.wait_for_selector(f'body[data-plant-loaded^="{plant_id}/"]', state="attached",
                           timeout=60_000)
    page.set_input_files("#plant-weather-file", files=[{
        "name": name or path.name, "mimeType": "text/csv", "buffer": path.read_bytes()}])
    page.fill("#plant-weather-start", start)
    page.fill("#plant-weather-end", end)
    page.fill("#plant-weather-step", step_s)
    page.set_checked("#plant-weather-force", force)
    page.click("#plant-weather-run")
    page.wait_for_function("() => !document.getElementById('plant-weather-run').disabled"
                           " && !document.getElementById('plant-weather-status').textContent"
                           ".startsWith('Running')", timeout=60_000)


def test_the_plant_page_runs_a_plant_on_a_weather_file(  # type: ignore[no-untyped-def]
        browser, server, request, tmp_path: Path) -> None:
    """Peñarroya's layout at Sand Point stowing at 12 m/s on pvlib's 703165TY, 30–31 March
    at 5 min: the service's 1.45 MWh and 194.0 kWh lost in 715 stowed minutes
    (docs/plants.md) as tiles; the file at Peñarroya, 9,000 km away, refused naming
    ``force`` with no tile left; Greensboro's TMY3 with its header's offset −4 for −5 at a
    plant on the station warned as a file 65 min off the sun's time; a PVGIS TMY (JSON) at
    a plant at its place run as a typical year with no warning, and an NSRDB one too."""
    sand_point = {"latitude_deg": 55.317, "longitude_deg": -160.517, "altitude_m": 7,
                  "timezone": "America/Anchorage",
                  "tracker": {"stow_wind_speed_m_s": 12}}
    greensboro = {"latitude_deg": 36.1, "longitude_deg": -79.95, "altitude_m": 273,
                  "timezone": "America/New_York"}
    piedmont = {"latitude_deg": 45.0, "longitude_deg": 8.0, "altitude_m": 250,
                "timezone": "Europe/Rome"}
    craig = {"latitude_deg": 40.53, "longitude_deg": -108.54, "altitude_m": 2168,
             "timezone": "America/Denver"}
    from tests.e2e.conftest import open_page
    from tests.sim.test_nsrdb_weather import nsrdb_file
    from tests.sim.test_pvgis_weather import pvgis_file

    with _plants(server, sandpoint=sand_point, greensboro=greensboro, piedmont=piedmont,
                 craig=craig), \
            open_page(browser, request, ignore=lambda text: "422" in text) as page:
        page.goto(server.url + "/#plant?day=2026-03-30")
        page.wait_for_selector('body[data-plant-loaded$="/2026-03-30"]', state="attached",
                               timeout=60_000)
        _run(page, "sandpoint", SAND_POINT_TMY3, "2026-03-30", "2026-04-01", "300")
        tiles = page.locator("#plant-weather-summary").inner_text()
        assert page.is_hidden("#plant-weather-message"), page.text_content(
            "#plant-weather-message")
        assert "1.45 MWh" in tiles, tiles
        stow = page.inner_text('#plant-weather-summary [data-testid="stow-tile"]')
        assert "194.0 kWh" in stow and "lost in 715 daylight minutes" in stow, stow
        assert "SAND POINT" in tiles and "0 km from the plant" in tiles, tiles
        page.locator("#plant-weather-form").scroll_into_view_if_needed()
        page.screenshot(path=str(ARTIFACTS / "plant-weather.png"), full_page=True,
                        clip=_clip(page, "#plant-weather-form", "#plant-weather-summary"))

        _run(page, "penarroya", SAND_POINT_TMY3, "2026-03-30", "2026-04-01", "300")
        message = page.text_content("#plant-weather-message")
        assert "422 Unprocessable Entity: force: the weather station SAND POINT" in message \
            and "km from plant penarroya" in message, message
        assert page.locator("#plant-weather-summary [data-testid=tile]").count() == 0

        lines = pvlib_tmy3_path().read_text().splitlines(keepends=True)
        head = lines[0].split(",")
        lines[0] = ",".join([*head[:3], "-4.0", *head[4:]])
        shifted = tmp_path / "shifted.csv"
        shifted.write_text("".join(lines))
        _run(page, "greensboro", shifted, "2021-06-01", "2021-06-11", "900")
        warning = page.inner_text('#plant-weather-summary [data-testid="weather-warning"]')
        assert "-65 min" in warning or "−65 min" in warning, warning
        assert "stow-tile" not in page.inner_html("#plant-weather-summary")  # never stows
        page.screenshot(path=str(ARTIFACTS / "plant-weather-warning.png"), full_page=True,
                        clip=_clip(page, "#plant-weather-form", "#plant-weather-summary"))

        # typical years as PVGIS and the NSRDB write them, and an NSRDB actual year (measured
        # weather of its own dates): each at a plant at its place, on the sun's time
        for plant_id, path, start, end, labels in (
                ("piedmont", pvgis_file("json", tmp_path), "2021-06-01", "2021-06-11",
                 ("PVGIS typical year", "TMY, PVGIS-SARAH3")),
                ("craig", nsrdb_file("tmy", tmp_path), "2021-06-01", "2021-06-11",
                 ("NSRDB typical year", "location 401182")),
                ("craig", nsrdb_file("psm4", tmp_path), "2023-09-01", "2023-09-11",
                 ("measured weather", "NSRDB location 401182"))):
            _run(page, plant_id, path, start, end, "900")
            tiles = page.locator("#plant-weather-summary").inner_text()
            assert all(label in tiles for label in labels), tiles
            assert "0 km from the plant" in tiles and "weather-warning" not in page.inner_html(
                "#plant-weather-summary"), tiles
            if plant_id == "piedmont":
                page.screenshot(path=str(ARTIFACTS / "plant-weather-pvgis.png"),
                                full_page=True, clip=_clip(page, "#plant-weather-form",
                                                           "#plant-weather-summary"))


def _clip(page, first: str, last: str) -> dict:  # type: ignore[no-untyped-def]
    """The page region from ``first``'s top to ``last``'s bottom, full width."""
    a = page.locator(first).bounding_box()
    b = page.locator(last).bounding_box()
    top = a["y"] + page.evaluate("() => window.scrollY")
    return {"x": 0, "y": top, "width": page.viewport_size["width"],
            "height": b["y"] + b["height"] - a["y"] + 8}
