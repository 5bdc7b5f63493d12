"""Sites far from where the product grew (a tester's "any site" round): a clock change that
skips local midnight (Santiago), and what a site's time zone may be.

The service runs in process with a user-sites folder and an admin token; each site is
"New site from the selected one" at another place (the Sites page's request)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import pandas as pd
import pytest
from live_service import InProcessServer, sites_service, tehuantepec_elsewhere

from sim.sites import Site
from sim.twin import simulate

ADMIN = "admin-secret-for-far-sites"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[InProcessServer]:
    """A service of its own on SQLite, with a user-sites folder and an admin token."""
    proc = sites_service(tmp_path_factory.mktemp("far-sites"), ADMIN)
    yield proc
    proc.stop()


@pytest.fixture()
def client(server: InProcessServer) -> Iterator[httpx.Client]:
    with server.client(timeout_s=120) as c:
        yield c


@pytest.fixture(scope="module")
def far(server: InProcessServer) -> None:
    """The module's sites: Santiago (its clocks skip midnight) and Lord Howe (30 minutes)."""
    with server.client(timeout_s=120) as c:
        _new_site(c, "santiago", latitude_deg=-33.45, longitude_deg=-70.66,
                  altitude_m=520.0, timezone="America/Santiago")
        _new_site(c, "lordhowe", latitude_deg=-31.55, longitude_deg=159.08,
                  timezone="Australia/Lord_Howe")


def _new_site(client: httpx.Client, site_id: str, **place: object) -> dict:
    """Tehuantepec's tracker and arrays at ``place``; the place decides the fixed plane."""
    r = client.put(f"/api/v1/sites/{site_id}", json=tehuantepec_elsewhere(client, site_id, **place),
                   headers={"Authorization": f"Bearer {ADMIN}"})
    assert r.status_code in (200, 201), r.text
    return r.json()


def _post_twin_days(client: httpx.Client, server: InProcessServer, site: Site,
                    start: pd.Timestamp, end: pd.Timestamp) -> None:
    """The site's own twin at 5-minute steps, both arrays, as a healthy logger posts it."""
    s = simulate(site, start, end, step_s=300).series
    token = server.token(site.site_id, "far sites")
    rows = [{"ts": t.isoformat(), "array": a, "power_w": round(float(s.at[t, f"{a}_power_w"]), 3)}
            for t in s.index for a in ("tracker", "fixed")]
    r = client.post(f"/api/v1/sites/{site.site_id}/measurements", json={"readings": rows},
                    headers={"Authorization": f"Bearer {token}"})
    assert r.status_code == 200, r.text


def test_a_clock_change_that_skips_midnight_is_an_ordinary_day(
        client: httpx.Client, server: InProcessServer, far: None) -> None:
    """Santiago's clocks go from 23:59:59 on 5 Sep 2026 to 01:00 on 6 Sep: the diagnosis
    and the weather twin's series and energy answered 500 ('nonexistent time', the days'
    grouping of the sky's minutes), on days with readings or without."""
    site = server.ctx.registry.sites["santiago"].site
    zone = "America/Santiago"
    _post_twin_days(client, server, site, pd.Timestamp("2026-09-05", tz=zone),
                    pd.Timestamp("2026-09-07", tz=zone))
    base = "/api/v1/sites/santiago"
    for start, end in (("2026-09-05", "2026-09-08"), ("2025-09-06", "2025-09-08")):
        r = client.get(f"{base}/diagnosis", params={"start": start, "end": end})
        assert r.status_code == 200, r.text
        assert [d["date"] for d in r.json()["days"]] == [
            str(d.date()) for d in pd.date_range(start, end, freq="D", inclusive="left")]
    days = client.get(f"{base}/diagnosis", params={"start": "2026-09-05", "end": "2026-09-07"}
                      ).json()["days"]
    assert [d["tracker"]["performance_ratio"] for d in days] == pytest.approx([1.0, 1.0],
                                                                               abs=0.05)
    r = client.get(f"{base}/energy", params={"start": "2026-09-05", "end": "2026-09-08",
                                             "source": "twin_weather"})
    assert r.status_code == 200, r.text
    r = client.get(f"{base}/measurements", params={
        "array": "tracker", "start": "2026-09-06", "end": "2026-09-07",
        "source": "twin_weather", "max_points": 10})
    assert r.status_code == 200, r.text


def test_local_hours_and_days_across_half_hour_and_midnight_clock_changes(
        client: httpx.Client, far: None) -> None:
    """Lord Howe moves its clocks by 30 minutes: every hour after the change fell on :30,
    one across local midnight, and the same hour had other edges when asked alone (a
    tester's finding); the local o'clock hours add up to the days. Santiago's 6 Sep 2026
    begins at 01:00−03:00, and says so (it read 00:00−04:00, a time that did not exist)."""
    base = "/api/v1/sites/lordhowe/energy"
    rng = {"start": "2026-10-03", "end": "2026-10-06"}
    hours = client.get(base, params={**rng, "interval": "hour"}).json()["rows"]
    days = client.get(base, params={**rng, "interval": "day"}).json()["rows"]
    starts = [pd.Timestamp(r["period_start"]) for r in hours]
    lengths = [(pd.Timestamp(r["period_end"]) - pd.Timestamp(r["period_start"])).seconds
               for r in hours]
    assert len(hours) == 72 and sum(t.minute != 0 for t in starts) == 1
    assert sum(lengths) == 71.5 * 3600 and sorted(set(lengths)) == [1800, 3600]
    assert [r["period_start"][11:16] for r in hours if r["period_start"][11:13] == "02"] == [
        "02:00", "02:30", "02:00"]                   # 02:00–02:30 on the 4th does not exist
    for d in days:
        own = [r for r in hours if r["period_start"][:10] == d["period_start"][:10]]
        assert own[0]["period_start"] == d["period_start"]
        assert own[-1]["period_end"] == d["period_end"]               # none across midnight
        assert sum(r["arrays"]["tracker"]["twin_wh"] for r in own) == pytest.approx(
            d["arrays"]["tracker"]["twin_wh"], rel=1e-9)
    alone = client.get(base, params={"start": "2026-10-05", "end": "2026-10-06",
                                     "interval": "hour"}).json()["rows"]
    assert [r["period_start"] for r in alone] == [r["period_start"] for r in hours[-24:]]
    santiago = client.get("/api/v1/sites/santiago/energy", params={
        "start": "2026-09-05", "end": "2026-09-08", "interval": "day"}).json()["rows"]
    assert [r["period_start"] for r in santiago] == [
        "2026-09-05T00:00:00-04:00", "2026-09-06T01:00:00-03:00", "2026-09-07T00:00:00-03:00"]


def test_a_pvgis_year_uploaded_runs_on_the_suns_time(client: httpx.Client) -> None:
    """A PVGIS TMY (JSON, as the tool downloads it) uploaded for a site at its place (45° N,
    8° E) is read as a typical year in UTC, its irradiance at PVGIS's instants: the run's
    clock check finds 0 min. Its EPW (header UTC+1) had been read as hour-start means at
    UTC+1: 40 min early, a warning (``tests/sim/test_pvgis_weather.py``)."""
    from tests.sim.test_pvgis_weather import TMY, pvgis_text

    _new_site(client, "piedmont", latitude_deg=45.0, longitude_deg=8.0, altitude_m=250.0,
              timezone="Europe/Rome")
    week = {"site_id": "piedmont", "start": "2024-06-01", "end": "2024-06-15", "step_s": "600"}
    for kind in ("json", "epw"):
        r = client.post("/api/v1/simulations/weather", data=week,
                        files={"file": (f"{TMY}.{kind}", pvgis_text(kind).encode(),
                                        "application/octet-stream")})
        assert r.status_code == 200, r.text
        run = r.json()
        assert run["sky"] == "weather" and run["timezone"] == "Europe/Rome"
        assert abs(run["weather_shift_min"]) <= 2.5 and run["weather_warning"] is None, run
    r = client.post("/api/v1/simulations/weather", data=week,
                    files={"file": ("hourly.csv", (Path(__file__).parents[1] / "data" / "pvgis"
                                    / "pvgis_hourly_Timeseries_45.000_8.000_SA_30deg_0deg_"
                                    "2016_2016.csv").read_bytes(), "text/csv")})
    assert r.status_code == 422
    assert r.json()["detail"].startswith("file: hourly.csv is not a readable TMY3, EPW, "
                                         "PVGIS or NSRDB typical year: a PVGIS file that is "
                                         "not a typical year (TMY)")


def test_an_nsrdb_year_uploaded_runs_at_its_stamps(client: httpx.Client) -> None:
    """An NSRDB PSM4 download (30-min values of 2023 at Craig, Colorado), uploaded as it is
    for a site at its place, is measured weather at its stamps: 0 min from the sun, where
    the same values in a CSV read as interval-end means run 15 min early; its typical year
    is a typical year, on the sun's time too (``tests/sim/test_nsrdb_weather.py``)."""
    from tests.sim.test_nsrdb_weather import FILES, nsrdb_text

    _new_site(client, "craig", latitude_deg=40.53, longitude_deg=-108.54, altitude_m=2168.0,
              timezone="America/Denver")
    for kind, start, end in (("psm4", "2023-09-01", "2023-10-01"),
                             ("tmy", "2026-09-01", "2026-10-01")):  # a typical year: any
        r = client.post("/api/v1/simulations/weather",
                        data={"site_id": "craig", "start": start, "end": end, "step_s": "600"},
                        files={"file": (FILES[kind], nsrdb_text(kind).encode(), "text/csv")})
        assert r.status_code == 200, r.text
        run = r.json()
        assert run["sky"] == "weather" and run["timezone"] == "America/Denver"
        assert abs(run["weather_shift_min"]) <= 5.0 and run["weather_warning"] is None, run
