"""Sites far from where the product grew (a tester's "any site" round): a clock change that
skips local midnight (Santiago), and what a site's time zone may be.

The service runs in process with a user-sites folder and an admin token; each site is
"New site from the selected one" at another place (the Sites page's request)."""

from __future__ import annotations

from collections.abc import Iterator

import httpx
import pandas as pd
import pytest
from live_service import InProcessServer

from sim.sites import Site
from sim.twin import simulate

ADMIN = "admin-secret-for-far-sites"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[InProcessServer]:
    tmp = tmp_path_factory.mktemp("far-sites")
    env = {"HELIOTWIN_SITES_DIR": str(tmp / "user-sites"), "HELIOTWIN_ADMIN_TOKEN": ADMIN}
    proc = InProcessServer(f"sqlite:///{tmp / 'far.sqlite'}", extra_env=env).start()
    yield proc
    proc.stop()


@pytest.fixture()
def client(server: InProcessServer) -> Iterator[httpx.Client]:
    with server.client(timeout_s=120) as c:
        yield c


def _new_site(client: httpx.Client, site_id: str, **place: object) -> dict:
    """Tehuantepec's tracker and arrays at ``place``; the place decides the fixed plane."""
    config = client.get("/api/v1/sites/tehuantepec/config").json()
    for key in ("temp_air_c", "wind_speed_m_s", "assumed"):
        config.pop(key, None)
    for arr in config["arrays"].values():
        if arr["mount"] == "fixed":
            arr.pop("surface_tilt_deg"), arr.pop("surface_azimuth_deg")
    body = {**config, **place, "site_id": site_id, "name": site_id, "source": "", "notes": ""}
    r = client.put(f"/api/v1/sites/{site_id}", json=body,
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
        client: httpx.Client, server: InProcessServer) -> None:
    """Santiago's clocks go from 23:59:59 on 5 Sep 2026 to 01:00 on 6 Sep: the diagnosis
    and the weather twin's series and energy answered 500 ('nonexistent time', the days'
    grouping of the sky's minutes), on days with readings or without."""
    _new_site(client, "santiago", latitude_deg=-33.45, longitude_deg=-70.66,
              altitude_m=520.0, timezone="America/Santiago")
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
