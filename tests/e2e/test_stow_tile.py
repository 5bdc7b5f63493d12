"""The Simulation page's "Wind stow" tile, in a real Chromium against ``heliotwin serve``: a
site whose tracker stows (a file in its own ``HELIOTWIN_SITES_DIR``) run on a gusty day's
measured weather shows the energy lost and the daylight minutes beside the gain, as the
API says (tests/backend/test_stow_api.py: 85 minutes, 70.3 Wh); a site without the setting
on the same weather shows no such tile."""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.e2e.conftest import open_page

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "backend"))
from live_service import ServerProcess, new_database  # noqa: E402
from test_stow_api import _gusty_day  # noqa: E402


@pytest.fixture(scope="module")
def windy_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    from sim.sites import load_site

    tmp = tmp_path_factory.mktemp("stow-e2e")
    config = load_site("tehuantepec").to_config()
    config.update(site_id="windy", name="Windy")
    config["tracker"].update(stow_wind_speed_m_s=15.0, stow_release_min=30.0)
    (tmp / "user-sites").mkdir()
    (tmp / "user-sites" / "windy.json").write_text(json.dumps(config))
    db = new_database("sqlite", tmp)
    proc = ServerProcess(db.url, tmp / "server.log", extra_env={
        "HELIOTWIN_SITES_DIR": str(tmp / "user-sites"), "HELIOTWIN_VISER": "false"})
    proc.start()
    try:
        yield proc
    finally:
        proc.stop()
        db.drop()


def _run(page, base_url: str, site_id: str, weather: Path,  # type: ignore[no-untyped-def]
         end: str = "2024-03-16") -> None:
    """Run ``site_id`` on ``weather`` from 15 March to ``end`` at 5 min and wait for this
    run's summary tiles."""
    page.goto(f"{base_url}/#simulation")
    page.wait_for_selector(f"#site-select option[value={site_id}]", state="attached")
    page.select_option("#site-select", site_id)
    page.fill("#sim-start", "2024-03-15")
    page.fill("#sim-end", end)
    page.select_option("#sim-step", "300")
    page.set_input_files("#sim-weather", str(weather))
    page.select_option("#sim-weather-stamped", "instant")
    page.eval_on_selector("#sim-summary", "box => { box.innerHTML = ''; }")  # not the last run's
    page.click("#sim-run")
    page.wait_for_selector("#sim-summary .tile", timeout=120_000)


def test_the_stow_tile_shows_the_loss_beside_the_gain(browser, windy_server: ServerProcess,  # type: ignore[no-untyped-def]
                                                      request: pytest.FixtureRequest,
                                                      tmp_path: Path) -> None:
    path = _gusty_day(tmp_path / "gusty.csv")
    with open_page(browser, request, timeout_ms=60_000) as page:
        _run(page, windy_server.base_url, "windy", path)
        text = page.text_content("[data-testid=stow-tile]") or ""
        assert "70 Wh" in text and "85 daylight minutes" in text and "15.0 m/s" in text, text
        # beside the gain: the tile right after "Tracking gain"
        titles = page.eval_on_selector_all("#sim-summary .tile", "ts => ts.map(t => t.innerText)")
        gain = next(i for i, t in enumerate(titles) if t.upper().startswith("TRACKING GAIN"))
        assert titles[gain + 1].upper().startswith("WIND STOW"), titles
        # the same windy day at a site without the setting: no tile
        _run(page, windy_server.base_url, "tehuantepec", path)
        assert page.locator("[data-testid=stow-tile]").count() == 0


def _overcast_windy_day(path: Path) -> Path:
    """Two of the gusty day's days under an overcast sky (no beam: DHI = GHI, a half sine up
    to 300 W m⁻²) with 18 m/s all day: stowed all day, and flat beats facing the sun (the
    daily chart draws two days or more)."""
    times = pd.date_range("2024-03-15 00:00", "2024-03-17 00:00", freq="5min", tz="Etc/GMT+6")
    hours = (times.hour + times.minute / 60).to_numpy()
    ghi = np.clip(300 * np.sin(np.pi * (hours - 6.5) / 12), 0, None).round(1)
    pd.DataFrame({"time": [t.isoformat() for t in times], "ghi": ghi, "dni": 0.0, "dhi": ghi,
                  "temp_air_c": 28.0, "wind_speed_m_s": 18.0}).to_csv(path, index=False)
    return path


def test_a_cloudy_days_stow_gain_is_said_and_drawn(browser, windy_server: ServerProcess,  # type: ignore[no-untyped-def]
                                                    request: pytest.FixtureRequest,
                                                    tmp_path: Path) -> None:
    """Under an overcast sky the flat stowed panel sees more of the sky than one facing a low
    sun: the stow's 'loss' is negative (a review: Sand Point, pvlib's 703165TY, 30 March 2026
    at 12 m/s, -109.54 Wh against pvlib's -109.54). The tile said "-… Wh lost" and the daily
    chart's axis began at 0, hiding the day's bar; now "gained" and an axis below 0."""
    path = _overcast_windy_day(tmp_path / "overcast.csv")
    with open_page(browser, request, timeout_ms=60_000) as page:
        _run(page, windy_server.base_url, "windy", path, end="2024-03-17")
        text = page.text_content("[data-testid=stow-tile]") or ""
        assert "gained, not lost" in text and "-" not in text.split("gained")[0], text
        chart = "document.getElementById('chart-sim-daily')"
        page.wait_for_function(f"() => {chart}?.layout?.yaxis")
        low = page.evaluate(f"() => {chart}.layout.yaxis.range[0]")
        assert low < 0, low
