"""The diagnosis on a real sky, as posted (issue 27 item 4): NREL RMIS's 5-minute files
(tests/data/rmis; tests/backend/rmis_sky.py) made into what a healthy tracker (the measured
GNI through the PV model) and the fixed array (the measured POA) would log, posted at
their 5-minute cadence with one sky instrument — the fixed plane's POA sensor, or a GHI
pyranometer alone — the air temperature and the wind speed to a site created at the
station over the API, then diagnosed in process over HTTP.

The expected tracker energy must hold the measured truth (the tracker's own readings)
within what the day-by-day table of docs/diagnosis.md measured for that path, inside the
band, and a healthy day must carry no finding. Nothing was tuned on these days but the
bands' widths (backend/diagnosis/faults.py: in-sample).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import rmis_sky
from live_service import InProcessServer, new_database

ADMIN = "admin-for-real-sky-tests"
SITE = "rmis_golden"
BASE = f"/api/v1/sites/{SITE}"
#: partly cloudy, and the windiest clear day (4.3 m s⁻¹ in daylight: two days, the test's cost)
DAYS = ("2022-01-03", "2022-01-04")
#: |expected / truth − 1| per day and sky instrument: the day-by-day table of
#: docs/diagnosis.md measured +0.5 % and −1.5 % from the POA sensor (air temperature and
#: wind speed posted; without the wind 4 Jan ran −4.2 %, outside its limit), +18.3 % and
#: −3.2 % from the GHI pyranometer (a broken-cloud sky that GHI cannot tell from beam; +23.4
#: and −0.0 % before the horizontal plane's beam at a winter sun under 17.5° was the one its
#: seen minutes make likely, sim.sky_sensor._unseen_beam)
LIMITS = {"poa_irradiance_w_m2": (0.015, 0.025), "ghi_w_m2": (0.19, 0.035)}


def _readings(lg: rmis_sky.Logged, sensor: str) -> list[dict]:
    """What the loggers post of a logged day: the tracker's power; the sky instrument
    ``sensor`` (the reading's field: the fixed plane's POA or the GHI), the air temperature
    and, where the file has one, the station's wind speed; and, beside a POA sensor, the
    fixed array's power on the same logger. A GHI pyranometer is posted on the tracker's
    logger with no fixed array (a site without a reference array): beside the fixed
    array's power it would not be the sky (sim.sky_sensor.weather_from_fixed)."""
    column = "poa" if sensor == "poa_irradiance_w_m2" else "ghi"
    wind = lg.data["wind_speed"].to_numpy()
    out = []
    for k, t in enumerate(lg.times):
        out.append({"ts": t.isoformat(), "array": "tracker",
                    "power_w": round(float(lg.tracker_power_w[k]), 2)})
        if column == "poa":
            out.append({"ts": t.isoformat(), "array": "fixed",
                        "power_w": round(float(lg.fixed_power_w[k]), 2)})
        out[-1].update({sensor: round(float(lg.data[column].iloc[k]), 2),
                        "temp_air_c": round(float(lg.temp_air[k]), 2)})
        if np.isfinite(wind[k]):  # the station's anemometer, where the file has it
            out[-1]["wind_speed_m_s"] = round(float(wind[k]), 2)
    return out


@pytest.fixture(scope="module", params=sorted(LIMITS))
def diagnosed(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
              ) -> Iterator[tuple[dict, dict, str]]:
    """The diagnosis answer of :data:`DAYS` with the sky from one instrument (the param: the
    reading's field), the truth (the tracker's logged energy) per day [Wh], the field."""
    sensor = request.param
    tmp = tmp_path_factory.mktemp("real-sky")
    db = new_database("sqlite", tmp)
    site = rmis_sky.station_site()
    df = rmis_sky.load()
    with InProcessServer(db.url, extra_env={"HELIOTWIN_SITES_DIR": str(tmp / "sites"),
                                            "HELIOTWIN_ADMIN_TOKEN": ADMIN}) as server, \
            server.client(timeout_s=300) as client:
        config = json.loads((rmis_sky.DATA / "rmis_golden.json").read_text())
        r = client.put(BASE, json=config, headers={"Authorization": f"Bearer {ADMIN}"})
        assert r.status_code == 201, r.text
        token = server.token(SITE)
        readings = [reading for date in DAYS for reading in _readings(
            rmis_sky.logged_day(site, df, pd.Timestamp(date, tz=site.timezone)), sensor)]
        r = client.post(f"{BASE}/measurements", json={"readings": readings},
                        headers={"Authorization": f"Bearer {token}"})
        assert r.status_code == 200, r.text
        end = (pd.Timestamp(DAYS[-1]) + pd.Timedelta(days=1)).date().isoformat()
        r = client.get(f"{BASE}/diagnosis", params={"start": DAYS[0], "end": end})
        assert r.status_code == 200, r.text
        energy = client.get(f"{BASE}/energy", params={"start": DAYS[0], "end": end,
                                                      "interval": "day"}).json()
    db.drop()
    truth = {row["period_start"][:10]: row["arrays"]["tracker"]["measured_wh"]
             for row in energy["rows"]}
    yield r.json(), truth, sensor


def test_the_posted_5_minute_days_are_diagnosed_from_their_sky_sensor(diagnosed) -> None:
    body, truth, sensor = diagnosed
    assert [d["date"] for d in body["days"]] == list(DAYS)
    for d in body["days"]:
        assert d["sky"]["source"] == "sensor" and d["sky"]["sensor"] == sensor
        assert d["complete"] and not d["partial"]
        # the measured energy is the 5-minute readings' by the energy rule, as /energy says
        assert d["tracker"]["measured_wh"] == pytest.approx(truth[d["date"]], rel=1e-9)


@pytest.mark.parametrize("k", range(len(DAYS)))
def test_the_expected_energy_holds_the_measured_truth(diagnosed, k: int) -> None:
    """Within the path's measured error, inside the band — for the GHI pyranometer its own
    band (faults.GHI_UNCERTAINTY: 3 Jan's truth lay under the POA sensor's 4.5 % band, a
    healthy day read as an underperformance) — and no finding on a healthy day."""
    body, _, sensor = diagnosed
    limit = LIMITS[sensor][k]
    t = body["days"][k]["tracker"]
    err = t["expected_wh"] / t["measured_wh"] - 1
    assert abs(err) < limit, (body["days"][k]["date"], err)
    assert t["expected_wh_low"] <= t["measured_wh"] <= t["expected_wh_high"]
    # a healthy day: no finding, its PR near 1
    assert body["days"][k]["faults"] == []
    assert abs(1 / t["performance_ratio"] - 1) < limit


def test_the_data_are_the_ones_documented() -> None:
    """The copies are pvanalytics' files, with the notice (tests/data/rmis/README.md)."""
    readme = (rmis_sky.DATA / "README.md").read_text()
    assert "MIT License" in readme and "pvanalytics" in readme
    for name in rmis_sky.FILES:
        assert Path(rmis_sky.DATA / name).stat().st_size > 100_000
    assert np.isclose(rmis_sky.station_site().latitude, 39.742)


def test_the_stamps_are_mst_at_the_end_of_each_mean() -> None:
    """On the clearest day (1 Feb 2019) the GHI-weighted mean time, less the 2.5 min of a
    5-minute mean's end stamp, is solar noon (SPA transit, pvlib) to within a minute: the
    stamps need no shift (docs/diagnosis.md, "Real skies")."""
    from pvlib import solarposition

    day = "2019-02-01"
    d = rmis_sky.load().tz_convert(rmis_sky.MST).loc[day]
    t_min = (d.index - d.index.normalize()).total_seconds().to_numpy() / 60.0
    mean_min = float((t_min * d["ghi"].to_numpy()).sum() / d["ghi"].sum()) - 2.5
    transit = solarposition.sun_rise_set_transit_spa(
        pd.DatetimeIndex([pd.Timestamp(day, tz=rmis_sky.MST)]), 39.742, -105.18)["transit"].iloc[0]
    assert abs(mean_min - (transit.hour * 60 + transit.minute + transit.second / 60)) < 1.0


def test_the_wind_is_what_puts_4_jan_2022_below_its_irradiation() -> None:
    """On the windiest day (4 Jan 2022, 4.3 m s⁻¹ in daylight against the site's default 1)
    the expected tracker energy from the POA sensor ran 2.5 points below its tracker-plane
    irradiation (−4.2 % against −1.7 %): the truth's cells are cooled by the measured wind,
    the expectation's are not (the service ingests no wind). With the station's wind in the
    expectation the energy's error comes back to the irradiation's (docs/diagnosis.md, "Real
    skies": −1.5 %)."""
    from sim.energy import energy_wh

    site = rmis_sky.station_site()
    day = pd.Timestamp("2022-01-04", tz=site.timezone)
    lg = rmis_sky.logged_day(site, rmis_sky.load(), day)
    grid = rmis_sky.minutes(day).as_unit("s").asi8
    ts = lg.times.as_unit("s").asi8
    truth = rmis_sky.day_energy_wh(lg.times, lg.tracker_power_w, rmis_sky.STEP_S)
    gni = rmis_sky.day_energy_wh(lg.times, lg.data["gni"].to_numpy(), rmis_sky.STEP_S)
    inside = (grid >= ts[0]) & (grid <= ts[-1])
    err, g_err = {}, 0.0
    for wind in (False, True):
        e = rmis_sky.expectation(site, lg, day, "poa_sensor", anemometer=wind,
                                 second_sky=False)
        err[wind] = energy_wh(grid, np.where(inside, e["tracker_power_w"], np.nan), 60) / truth - 1
        if not wind:  # the irradiation does not depend on the wind
            g_err = energy_wh(grid, np.where(inside, e["tracker_poa"], np.nan), 60) / gni - 1
    assert err[False] < g_err - 0.02  # the default wind: 2.5 points below the irradiation
    assert abs(err[True] - g_err) < 0.005  # the measured wind: within 0.5 point of it


def test_an_hourly_loggers_end_stamped_means_with_the_sites_stamp_convention(
        tmp_path: Path) -> None:
    """A logger that stores hourly means stamped at the end of each hour (the 5-minute
    files averaged, rmis_sky.coarser), posted to a site at the station whose
    ``readings_stamped`` is then changed, the service bridging an hour
    (``energy_max_gap_s`` 3600 s):
    taken as instants, the clear 1 Feb 2019 ran −5.3 % (the morning's sky matched to the
    sun half an hour later, docs/diagnosis.md, "Cadence"); as ``interval_end`` means, each
    reading at its hour's middle, −1.0 % (its 5-minute error: −0.7 %). The default
    ``instant`` of an hourly logger is now read from its readings
    (sim.sky_sensor.inferred_stamped): the same −1.0 % (−5.3 % before)."""
    db = new_database("sqlite", tmp_path)
    site = rmis_sky.station_site()
    day = pd.Timestamp("2019-02-01", tz=site.timezone)
    lg = rmis_sky.coarser(rmis_sky.logged_day(site, rmis_sky.load(), day), 3600)
    readings = _readings(lg, "poa_irradiance_w_m2")  # the 2019 file has no wind
    config = json.loads((rmis_sky.DATA / "rmis_golden.json").read_text())
    err = {}
    with InProcessServer(db.url, extra_env={"HELIOTWIN_SITES_DIR": str(tmp_path / "sites"),
                                            "HELIOTWIN_ADMIN_TOKEN": ADMIN,
                                            "HELIOTWIN_ENERGY_MAX_GAP_S": "3600"}) as server, \
            server.client(timeout_s=300) as client:
        # one site, its convention changed in between: the day cached under the first
        # config is computed again under the second (backend.sites.drop_twin_cache)
        for stamped in ("instant", "interval_end"):
            r = client.put(BASE, headers={"Authorization": f"Bearer {ADMIN}"},
                           json={**config, "readings_stamped": stamped})
            assert r.status_code in (200, 201), r.text
            assert r.json()["readings_stamped"] == stamped
            if stamped == "instant":
                r = client.post(f"{BASE}/measurements", json={"readings": readings},
                                headers={"Authorization": f"Bearer {server.token(SITE)}"})
                assert r.status_code == 200, r.text
            r = client.get(f"{BASE}/diagnosis", params={"start": "2019-02-01",
                                                        "end": "2019-02-02"})
            assert r.status_code == 200, r.text
            # as the bench's cadence table: the expectation over the minutes the readings
            # cover (1 / performance ratio) against the measured energy
            err[stamped] = 1 / r.json()["days"][0]["tracker"]["performance_ratio"] - 1
    db.drop()
    assert err["instant"] == pytest.approx(err["interval_end"], abs=1e-9), err
    assert abs(err["interval_end"]) < 0.015, err


def test_the_share_of_the_expectation_the_sky_instrument_was_blind_to(diagnosed) -> None:
    """``sky.beam_unseen_expected_pct``: the day's expected tracker energy from minutes its
    sky instrument did not see the beam in. The 39° plane facing south sees a January sun
    all day (pvlib: cos AOI ≥ 0.3 from sunrise to sunset), so its share is the minutes
    without a usable reading (3 Jan 2022: 4.7 % of the daylight minutes, 5.0 % of the
    energy). A horizontal pyranometer does not see the beam below 17.5° of sun (cos z <
    sim.sky_sensor.BEAM_SEEN_COS), where a January sun at Golden spends hours: the share is
    the truth's (the healthy tracker's logged energy) in those minutes by pvlib's sun, 17.2
    and 19.7 %, measured 17.5 and 15.5 % — on the clear 4 Jan the beam guessed at a low sun
    falls short of the measured one (docs/diagnosis.md: Ineichen's beam at 5-12° of sun)."""
    from pvlib import irradiance, solarposition

    from sim.sky_sensor import BEAM_SEEN_COS

    body, _, sensor = diagnosed
    site, df = rmis_sky.station_site(), rmis_sky.load()
    fixed = site.arrays["fixed"]
    for d in body["days"]:
        got = d["sky"]["beam_unseen_expected_pct"]
        lg = rmis_sky.logged_day(site, df, pd.Timestamp(d["date"], tz=site.timezone))
        sp = solarposition.get_solarposition(lg.times, site.latitude, site.longitude,
                                             site.altitude)
        up = sp["apparent_elevation"].to_numpy() > 0
        if sensor == "poa_irradiance_w_m2":
            cos_aoi = np.cos(np.radians(irradiance.aoi(
                fixed.surface_tilt, fixed.surface_azimuth, sp["apparent_zenith"],
                sp["azimuth"]).to_numpy()))
            assert cos_aoi[up].min() >= BEAM_SEEN_COS
            unread = 100.0 - d["sky"]["valid_minutes_pct"]
            assert got <= unread + 0.5, (d["date"], got, unread)
            continue
        low = up & (np.cos(np.radians(sp["apparent_zenith"].to_numpy())) < BEAM_SEEN_COS)
        share = 100 * lg.tracker_power_w[low].sum() / lg.tracker_power_w.sum()
        assert share > 15.0 and got == pytest.approx(share, abs=5.0), (d["date"], got, share)
