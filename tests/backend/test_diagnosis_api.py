"""The diagnosis endpoint over real HTTP: realistic logger days (tests/sim/realistic_sky.py:
a cloud process independent of the inversion, both arrays through the twin) with one module
of four lost from the fourth day, posted like a logger would; then the cache is invalidated
by back-filled readings. Seeds here (21) are held out from the tuning seeds (1–3)."""

from __future__ import annotations

import datetime as dt

import httpx
import numpy as np
import pandas as pd
import pytest

from sim.sites import load_site
from tests.sim.realistic_sky import logger_days

BASE = "/api/v1/sites/tehuantepec"
FIRST = "2025-04-07"
DAYS = 6
FAULT_DAY = 3
GAP = slice(1 * 1440 + 11 * 60, 1 * 1440 + 12 * 60 + 30)  # day 2, 11:00–12:30 local


def _readings(times: pd.DatetimeIndex, power: np.ndarray, array: str) -> list[dict]:
    out = []
    for t, p in zip(times, power, strict=True):
        if not np.isfinite(p):
            continue
        v = 26.0 if p > 0 else 0.0
        out.append({"ts": t.isoformat(), "array": array, "voltage_v": v,
                    "current_a": float(p) / v if v else 0.0, "power_w": float(p)})
    return out


def _post(client: httpx.Client, token: str, readings: list[dict]) -> None:
    for k in range(0, len(readings), 5000):
        r = client.post(f"{BASE}/measurements", json={"readings": readings[k:k + 5000]},
                        headers={"Authorization": f"Bearer {token}"})
        assert r.status_code == 200, r.text


@pytest.fixture(scope="module")
def logged():
    site = load_site("tehuantepec")
    first = pd.Timestamp(FIRST, tz=site.timezone)
    return logger_days(site, first, DAYS, seed=21, fault="module_loss", fault_day=FAULT_DAY)


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # fits; PG: tests below
def test_diagnosis_finds_module_loss_and_expects_the_healthy_energy(client, live_server,
                                                                    logged) -> None:
    tracker = logged.tracker_power_w.copy()
    tracker[GAP] = np.nan  # the logger lost 90 daylight minutes of the tracker
    _post(client, live_server.write_token, _readings(logged.times, logged.fixed_power_w, "fixed")
          + _readings(logged.times, tracker, "tracker"))
    end = (dt.date.fromisoformat(FIRST) + dt.timedelta(days=DAYS)).isoformat()
    r = client.get(f"{BASE}/diagnosis", params={"start": FIRST, "end": end}, timeout=120)
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["site_id"] == "tehuantepec" and len(body["days"]) == DAYS
    for k, day in enumerate(body["days"]):
        assert day["sky"]["source"] == "fixed_array"
        truth_wh = logged.healthy_tracker_power_w[k * 1440:(k + 1) * 1440].sum() / 60.0
        expected = day["tracker"]["expected_wh"]
        limit = 0.03 if logged.kinds[k] == "clear" else 0.08
        assert abs(expected / truth_wh - 1) < limit, (k, logged.kinds[k], expected, truth_wh)
        assert day["tracker"]["expected_wh_low"] <= truth_wh <= day["tracker"]["expected_wh_high"]
        kinds = {f["kind"]: f for f in day["faults"]}
        if k < FAULT_DAY:
            assert not [f for f in day["faults"] if f["confidence"] >= 0.5
                        and f["kind"] != "dropout"], day["faults"]
            assert 0.95 < day["tracker"]["performance_ratio"] < 1.05
        else:
            loss = kinds["module_loss"]
            assert abs(loss["magnitude"] - 25.0) < 5.0 and loss["unit"] == "%"
            since = dt.date.fromisoformat(loss["since"])
            assert abs((since - dt.date.fromisoformat(FIRST)).days - FAULT_DAY) <= 1
            assert 0.70 < day["tracker"]["performance_ratio"] < 0.80
    assert [f["kind"] for f in body["days"][1]["faults"]] == ["dropout"]
    assert body["days"][1]["faults"][0]["title"] == "logger dropout"  # the words shown
    assert body["days"][1]["faults"][0]["magnitude"] == 90.0

    # cached: the same answer; back-filled readings of day 2 drop that day from the cache
    again = client.get(f"{BASE}/diagnosis", params={"start": FIRST, "end": end}).json()
    assert again == body
    fill = np.full(tracker.size, np.nan)
    fill[GAP] = logged.tracker_power_w[GAP]
    _post(client, live_server.write_token, _readings(logged.times, fill, "tracker"))
    after = client.get(f"{BASE}/diagnosis", params={"start": FIRST, "end": end}).json()
    assert after["days"][1]["faults"] == []
    assert after["days"][0] == body["days"][0]


def test_a_range_that_cuts_a_day_makes_it_partial(client, live_server, logged) -> None:
    """A range from noon to noon: its first and last days are cut — ``partial``, without the
    shape and energy fits a whole day needs, and not cached over the whole days (before,
    they were answered as whole days: ``partial`` false, a fault fitted on half a day)."""
    sl = slice(3 * 1440, 6 * 1440)
    _post(client, live_server.write_token,
          _readings(logged.times[sl], logged.fixed_power_w[sl], "fixed")
          + _readings(logged.times[sl], logged.tracker_power_w[sl], "tracker"))
    day3 = dt.date.fromisoformat(FIRST) + dt.timedelta(days=3)
    whole = {"start": day3.isoformat(), "end": (day3 + dt.timedelta(days=3)).isoformat()}
    before = client.get(f"{BASE}/diagnosis", params=whole, timeout=120).json()["days"]
    assert [d["partial"] for d in before] == [False] * 3
    noon = {"start": f"{day3}T12:00:00-06:00",
            "end": f"{day3 + dt.timedelta(days=2)}T12:00:00-06:00"}
    cut = client.get(f"{BASE}/diagnosis", params=noon, timeout=120).json()["days"]
    assert [d["partial"] for d in cut] == [True, False, True]
    assert [d["status"] for d in cut] == ["complete"] * 3
    assert cut[0]["faults"] == [] and cut[2]["faults"] == []
    # the whole day between is the same day (a fault's ``since`` is within the range asked)
    assert {**cut[1], "faults": None} == {**before[1], "faults": None}
    assert [f["kind"] for f in cut[1]["faults"]] == [f["kind"] for f in before[1]["faults"]]
    assert client.get(f"{BASE}/diagnosis", params=whole).json()["days"] == before


def test_diagnosis_bad_input(client) -> None:
    r = client.get(f"{BASE}/diagnosis", params={"start": "2025-01-01T00:00:00",
                                                 "end": "2025-01-02"})
    assert r.status_code == 422 and "start" in r.text
    r = client.get(f"{BASE}/diagnosis", params={"start": "2025-01-03", "end": "2025-01-02"})
    assert r.status_code == 422 and "end" in r.text
    r = client.get(f"{BASE}/diagnosis", params={"start": "2024-01-01", "end": "2026-01-02"})
    assert r.status_code == 422 and "400 days" in r.text
    r = client.get("/api/v1/sites/nowhere/diagnosis", params={"start": "2025-01-01",
                                                               "end": "2025-01-02"})
    assert r.status_code == 404


def test_a_day_without_readings_expects_the_clear_sky_twin(client, live_server,
                                                             logged) -> None:
    """A day without one fixed-array reading, right after a measured one, is expected under
    the clear-sky twin's own weather (Ineichen GHI/DNI/DHI): neither a decomposition of a
    clear-sky POA (its gain ran 13 points low) nor the measured neighbour's sky."""
    last = dt.date.fromisoformat(FIRST) + dt.timedelta(days=DAYS - 1)
    sl = slice((DAYS - 1) * 1440, DAYS * 1440)
    _post(client, live_server.write_token,
          _readings(logged.times[sl], logged.fixed_power_w[sl], "fixed"))
    params = {"start": last.isoformat(), "end": (last + dt.timedelta(days=2)).isoformat()}
    measured, empty = client.get(f"{BASE}/diagnosis", params=params, timeout=120).json()["days"]
    assert measured["sky"]["source"] == "fixed_array" and empty["sky"]["source"] == "clear_sky"
    assert empty["fixed"]["measured_wh"] is None
    r = client.get(f"{BASE}/energy", params={**params, "interval": "day"})
    assert r.status_code == 200, r.text
    twin = r.json()["rows"][1]
    for kind in ("tracker", "fixed"):
        assert empty[kind]["expected_wh"] == pytest.approx(twin["arrays"][kind]["twin_wh"],
                                                           rel=1e-3), kind
    assert empty["gain_expected_pct"] == pytest.approx(twin["twin_gain_pct"], abs=0.1)


def _with_pyranometer(readings: list[dict], d) -> list[dict]:
    """``readings`` (one logger's) carrying the GHI pyranometer and the air thermometer of
    the logged days ``d`` at their times."""
    by_ts = {r["ts"]: r for r in readings}
    for t, g, temp in zip(d.times, d.ghi_w_m2, d.temp_air_c, strict=True):
        if t.isoformat() in by_ts:
            by_ts[t.isoformat()].update(ghi_w_m2=float(g), temp_air_c=float(temp))
    return readings


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # the sky, not storage
def test_a_pyranometer_on_the_logger_is_the_days_sky(client, live_server) -> None:
    """Readings that carry a GHI pyranometer and an air thermometer on the tracker's logger,
    no fixed array reading (a site without a reference array) over HTTP: those days' sky is
    the sensor's, named in the answer, on the diagnosis and on ``source=twin_weather``
    alike; held-out seed 23."""
    site = load_site("tehuantepec")
    first = "2025-08-04"
    d = logger_days(site, pd.Timestamp(first, tz=site.timezone), 3, seed=23)
    _post(client, live_server.write_token,
          _with_pyranometer(_readings(d.times, d.tracker_power_w, "tracker"), d))
    end = (dt.date.fromisoformat(first) + dt.timedelta(days=3)).isoformat()
    body = client.get(f"{BASE}/diagnosis", params={"start": first, "end": end},
                      timeout=120).json()
    for k, day in enumerate(body["days"]):
        assert day["sky"]["source"] == "sensor" and day["sky"]["sensor"] == "ghi_w_m2"
        truth_wh = d.healthy_tracker_power_w[k * 1440:(k + 1) * 1440].sum() / 60.0
        assert abs(day["tracker"]["expected_wh"] / truth_wh - 1) < 0.03, (k, d.kinds[k])
        assert not [f for f in day["faults"] if f["confidence"] >= 0.5], day["faults"]
    r = client.get(f"{BASE}/measurements", params={"start": first, "end": end,
                                                    "source": "twin_weather",
                                                    "array": "tracker"}, timeout=120)
    assert r.status_code == 200, r.text
    assert r.json()["sky"]["source"] == "sensor" and r.json()["sky"]["sensor"] == "ghi_w_m2"


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # the sky, not storage
def test_a_pyranometer_beside_the_fixed_array_does_not_hide_a_loss(client, live_server
                                                                     ) -> None:
    """A tester's finding: a tracker making 85 % of a healthy one's, with the fixed array's
    power, was found underperforming on 7 of 7 days — and on none once the fixed array's
    logger also sent a GHI pyranometer, whose sky (DIRINT on the horizontal plane) then
    replaced the fixed array's and whose 16 % band held the loss. The fixed array's power
    comes first now: every day's sky is the fixed array's and the loss is found (seed 24,
    held out; the measured gain below the expected one)."""
    site = load_site("tehuantepec")
    first = "2025-08-11"
    d = logger_days(site, pd.Timestamp(first, tz=site.timezone), 3, seed=24)
    _post(client, live_server.write_token,
          _with_pyranometer(_readings(d.times, d.fixed_power_w, "fixed"), d)
          + _readings(d.times, 0.85 * d.tracker_power_w, "tracker"))
    end = (dt.date.fromisoformat(first) + dt.timedelta(days=3)).isoformat()
    body = client.get(f"{BASE}/diagnosis", params={"start": first, "end": end},
                      timeout=120).json()
    for k, day in enumerate(body["days"]):
        assert day["sky"]["source"] == "fixed_array", day["sky"]
        found = {f["kind"]: f["confidence"] for f in day["faults"]}
        assert found.get("underperformance", 0.0) >= 0.5, (k, d.kinds[k], day["faults"])
        assert day["tracker"]["measured_wh"] < day["tracker"]["expected_wh_low"], k


def test_a_cached_day_of_another_version_is_computed_again(client, live_server) -> None:
    """A day cached by another version of the computation (``CACHE_VERSION``) is not
    served; one of this version is, as stored."""
    import orjson
    import sqlalchemy as sa

    from backend.diagnosis.service import CACHE_VERSION, site_key

    site = load_site("tehuantepec")
    first = "2025-09-15"
    d = logger_days(site, pd.Timestamp(first, tz=site.timezone), 1, seed=24)
    _post(client, live_server.write_token, _readings(d.times, d.fixed_power_w, "fixed")
          + _readings(d.times, d.tracker_power_w, "tracker"))
    params = {"start": first, "end": "2025-09-16"}
    body = client.get(f"{BASE}/diagnosis", params=params, timeout=120).json()
    engine = sa.create_engine(live_server.database_url)
    table = sa.table("diagnosis_days", sa.column("site_id"), sa.column("payload_json"),
                     sa.column("day_start_s"))
    start_s = int(pd.Timestamp(first, tz=site.timezone).timestamp())
    where = (table.c.site_id == "tehuantepec") & (table.c.day_start_s == start_s)

    def cache(version: int) -> None:
        day = {**body["days"][0], "features": {}, "cache_version": version,
               "site_key": site_key(site)}
        day["tracker"] = {**day["tracker"], "expected_wh": -1.0}  # a marker
        with engine.begin() as conn:
            conn.execute(sa.update(table).where(where).values(
                payload_json=orjson.dumps(day).decode()))

    try:
        cache(CACHE_VERSION - 1)
        assert client.get(f"{BASE}/diagnosis", params=params).json() == body
        cache(CACHE_VERSION)
        again = client.get(f"{BASE}/diagnosis", params=params).json()
        assert again["days"][0]["tracker"]["expected_wh"] == -1.0
    finally:
        engine.dispose()


def test_a_tracker_reading_0_w_all_day_is_an_underperformance(client, live_server) -> None:
    """A tripped breaker, the logger still reading 0 W: the day is an underperformance of
    its whole expected energy, with no shape fault (there is no shape to fit: its residual
    divided by a mean of 0 was inf, a NaN confidence, then a JSON null in the cache that
    made every later request of the day a 500)."""
    site = load_site("tehuantepec")
    first = "2025-06-10"
    d = logger_days(site, pd.Timestamp(first, tz=site.timezone), 1, seed=26, kinds=["clear"])
    _post(client, live_server.write_token, _readings(d.times, d.fixed_power_w, "fixed")
          + _readings(d.times, np.zeros(d.times.size), "tracker"))
    params = {"start": first, "end": "2025-06-11"}
    for _ in range(2):  # computed, then from the cache
        r = client.get(f"{BASE}/diagnosis", params=params, timeout=120)
        assert r.status_code == 200, r.text
        day = r.json()["days"][0]
        assert [f["kind"] for f in day["faults"]] == ["underperformance"], day["faults"]
        assert day["tracker"]["performance_ratio"] == 0.0
        assert day["faults"][0]["confidence"] is not None


@pytest.mark.parametrize(("first", "tracker_kw"), [("2025-06-11", True), ("2025-06-12", False)])
def test_a_tracker_logger_posting_kw_is_told_so(client, live_server, first: str,
                                                tracker_kw: bool) -> None:
    """A tester's finding: the tracker's power posted in kW (the fixed array's in W) read
    "underperformance 99.9 %" with no word of the unit (the fixed array's is named, by
    ``sky_unusable``). The readings are the expected day at a thousandth: the finding now
    asks whether they are kW. A tracker at 1/1000 of the expected that does not follow its
    curve (a dead array with a trickle) is not told so."""
    site = load_site("tehuantepec")
    d = logger_days(site, pd.Timestamp(first, tz=site.timezone), 1, seed=28, kinds=["clear"])
    tracker = d.tracker_power_w / 1000.0
    if not tracker_kw:  # the same energy, a flat trickle through daylight
        tracker = np.where(tracker > 0, tracker.mean() * 2.0, 0.0)
    _post(client, live_server.write_token, _readings(d.times, d.fixed_power_w, "fixed")
          + _readings(d.times, np.round(tracker, 3), "tracker"))  # a logger's 3 decimals
    end = (dt.date.fromisoformat(first) + dt.timedelta(days=1)).isoformat()
    day = client.get(f"{BASE}/diagnosis", params={"start": first, "end": end},
                     timeout=120).json()["days"][0]
    assert [f["kind"] for f in day["faults"]] == ["underperformance"], day["faults"]
    said = "power sent in kW where W are asked?" in day["faults"][0]["detail"]
    assert said is tracker_kw, day["faults"][0]["detail"]


@pytest.mark.parametrize(("first", "case"), [("2025-06-17", "breaker"), ("2025-06-18", "kw"),
                                             ("2025-06-19", "local_as_utc")])
def test_a_day_whose_fixed_array_readings_are_refused_says_why(client, live_server,
                                                               first: str, case: str) -> None:
    """A tester's finding: a day whose sky fell back to the clear sky because the fixed
    array's readings were refused had no finding at PR 0.000–0.98 — both arrays reading
    0 W all day (a tripped site breaker), power posted in kW, local wall-clock time stamped
    as UTC (here 6 h late: Tehuantepec's offset). Now a ``sky_unusable`` names the share
    refused and its likely causes; and a healthy day with a measured sky has none (the
    other tests here)."""
    site = load_site("tehuantepec")
    d = logger_days(site, pd.Timestamp(first, tz=site.timezone), 1, seed=27, kinds=["clear"])
    times, fixed, tracker = d.times, d.fixed_power_w, d.tracker_power_w
    if case == "breaker":
        fixed, tracker = np.zeros(times.size), np.zeros(times.size)
    elif case == "kw":
        fixed, tracker = fixed / 1000.0, tracker / 1000.0
    else:  # the wall clock's digits with +00:00
        times = times.tz_convert(site.timezone).tz_localize(None).tz_localize("UTC")
    _post(client, live_server.write_token,
          _readings(times, fixed, "fixed") + _readings(times, tracker, "tracker"))
    end = (dt.date.fromisoformat(first) + dt.timedelta(days=1)).isoformat()
    day = client.get(f"{BASE}/diagnosis", params={"start": first, "end": end},
                     timeout=120).json()["days"][0]
    assert day["sky"]["source"] == "clear_sky", day["sky"]
    found = [f for f in day["faults"] if f["kind"] == "sky_unusable"]
    assert len(found) == 1, day["faults"]
    assert found[0]["confidence"] == 1.0 and found[0]["magnitude"] > 50.0, found
    assert "0 W or nearly" in found[0]["detail"] and "kW" in found[0]["detail"], found


def test_a_day_not_yet_over_is_judged_up_to_now(client, live_server) -> None:
    """At noon of a day (``now_s``), with the tracker's logger silent since 10:00 and the
    fixed one reporting: a dropout of exactly the 120 daylight minutes 10:00–12:00 — the
    afternoon still to come is not missing — the day marked not complete and not cached;
    at 10:00 its sky is measured (the minutes to come are not missing readings either).
    The same day asked once it is over counts the whole silent afternoon."""
    import sqlalchemy as sa

    from backend.context import open_context
    from backend.diagnosis.service import diagnosis
    from backend.settings import get_settings

    site = load_site("tehuantepec")
    first = "2025-10-06"
    day0 = pd.Timestamp(first, tz=site.timezone)
    d = logger_days(site, day0, 1, seed=25)
    noon, ten = day0 + pd.Timedelta(hours=12), day0 + pd.Timedelta(hours=10)
    before_noon, before_ten = d.times < noon, d.times < ten
    _post(client, live_server.write_token,
          _readings(d.times[before_noon], d.fixed_power_w[before_noon], "fixed")
          + _readings(d.times[before_ten], d.tracker_power_w[before_ten], "tracker"))
    # in process, beside the live server on its database: only the clock is set by the test
    ctx = open_context(get_settings(database_url=live_server.database_url,
                                    sites_dir=get_settings().sites.user_dir, alerts=False))
    try:
        info = ctx.registry.sites["tehuantepec"]
        end = (day0 + pd.Timedelta(days=1)).to_pydatetime()
        body = diagnosis(ctx, info, day0.to_pydatetime(), end, now_s=noon.timestamp())
        day = body["days"][0]
        assert day["complete"] is False
        assert [(f["kind"], f["magnitude"]) for f in day["faults"]] == [("dropout", 120.0)]
        with ctx.engine.connect() as conn:
            cached = conn.execute(sa.text(
                "SELECT count(*) FROM diagnosis_days WHERE site_id = 'tehuantepec' "
                "AND day_start_s = :s"), {"s": int(day0.timestamp())}).scalar_one()
        assert cached == 0
        # at 10:00 the day's sky is the fixed array's: the minutes still to come are not
        # missing readings (they were: 29 % of the daylight valid, the clear sky taken)
        early = diagnosis(ctx, info, day0.to_pydatetime(), end,
                          now_s=ten.timestamp())["days"][0]
        assert early["sky"]["source"] == "fixed_array", early["sky"]
        assert early["sky"]["valid_minutes_pct"] > 90.0, early["sky"]
        # nor as minutes whose beam the fixed array did not see (they did: 54.3 % at 10:00);
        # what it did not see is the dawn grazing its plane (cos AOI < 0.3, pvlib's sun), the
        # healthy tracker's share of the morning there
        from pvlib import irradiance, solarposition

        from sim.sky_sensor import BEAM_SEEN_COS

        sp = solarposition.get_solarposition(d.times, site.latitude, site.longitude,
                                             site.altitude)
        fixed = site.arrays["fixed"]
        grazing = np.cos(np.radians(irradiance.aoi(
            fixed.surface_tilt, fixed.surface_azimuth, sp["apparent_zenith"],
            sp["azimuth"]).to_numpy())) < BEAM_SEEN_COS
        p = np.where(before_ten, d.healthy_tracker_power_w, 0.0)
        share = 100 * p[grazing].sum() / p.sum()
        assert early["sky"]["beam_unseen_expected_pct"] == pytest.approx(share, abs=1.0), share
    finally:
        ctx.close()
    over = client.get(f"{BASE}/diagnosis", params={"start": first, "end": "2025-10-07"},
                      timeout=120).json()["days"][0]
    daylight_after_ten = int(((d.times >= ten) & (d.healthy_tracker_power_w > 0)).sum())
    assert over["complete"] is True
    silent = [f["magnitude"] for f in over["faults"] if f["kind"] == "dropout"]
    assert silent and silent[0] > 300 and abs(silent[0] - daylight_after_ten) < 40, (
        silent, daylight_after_ten)


def test_a_measured_wind_cools_the_expected_cells() -> None:
    """``wind_speed_m_s`` of either logger (the fixed one's first, as ``temp_air_c``) goes
    into the weather-aware twin in place of the site's default wind (issue 27): the
    weather frame carries it minute by minute, and where neither logger reads it the site's
    default stays. A day-long 6 m s⁻¹ instead of the default 1 (cells about 7 °C cooler at
    900 W m⁻², SAPM open rack) raises the expected tracker energy of a clear day by 3.7 %
    (measured) when a POA sensor gives the sky; from the fixed array's power only by
    0.7 %: the same cooling of the fixed modules lowers the irradiance inverted from them."""
    from backend.diagnosis.weather_twin import sky_sensors
    from backend.measurements.fields import SENSOR_NAMES
    from sim import sky_sensor, twin

    site = load_site("tehuantepec")
    start = pd.Timestamp("2025-03-10 06:00", tz=site.timezone)  # the daylight hours only
    end = start + pd.Timedelta(hours=13)
    clear = twin.simulate(site, start, end).series
    fixed_w = clear["fixed_power_w"].to_numpy()
    n, w = fixed_w.size, SENSOR_NAMES.index("wind_speed_m_s")
    fixed_s, tracker_s = (np.full((n, len(SENSOR_NAMES)), np.nan) for _ in range(2))
    fixed_s[: n // 2, w] = 6.0
    tracker_s[:, w] = 2.0  # read only where the fixed logger has none
    sensors = sky_sensors(fixed_s, tracker_s)
    assert sensors is not None
    assert np.array_equal(sensors["wind_speed_m_s"].to_numpy(),
                          np.r_[np.full(n // 2, 6.0), np.full(n - n // 2, 2.0)])
    weather, _ = sky_sensor.weather_from_fixed(site, clear.index, fixed_w, sensors=sensors)
    for frame in weather.values():
        assert np.array_equal(frame["wind_speed"].to_numpy(), sensors["wind_speed_m_s"].to_numpy())
    gains = {}
    for sky in ("fixed_array", "sensor_poa"):
        still, windy = (pd.DataFrame({"wind_speed_m_s": np.full(n, v)}) for v in (np.nan, 6.0))
        if sky == "sensor_poa":
            for frame in (still, windy):
                frame["fixed_poa_w_m2"] = clear["fixed_poa_global"].to_numpy()
        default = sky_sensor.weather_aware_twin(site, start, end, fixed_w, sensors=still)
        assert (default["wind_speed"] == site.wind_speed).all() and site.wind_speed == 1.0
        assert (default["sky_source"][default["poa_clear"] > 20] == sky).all()
        e = sky_sensor.weather_aware_twin(site, start, end, fixed_w, sensors=windy)
        gains[sky] = e["tracker_power_w"].sum() / default["tracker_power_w"].sum() - 1
    assert 0.032 < gains["sensor_poa"] < 0.042, gains
    assert 0.004 < gains["fixed_array"] < 0.011, gains


def test_a_tracker_that_stops_part_way_through_a_day_is_stuck_from_then(client,
                                                                        live_server) -> None:
    """A clear day (seed 27, held out) on which the tracker stops at 13:00 and holds its
    orientation, posted like a logger would: the answer names ``stuck`` that day with the
    stop minute in ``since_time`` (the site's offset), computed and then from the cache
    (measured in process: confidence 0.88, 13:00; PR 0.93, an underperformance too)."""
    site = load_site("tehuantepec")
    first = "2025-08-20"
    d = logger_days(site, pd.Timestamp(first, tz=site.timezone), 1, seed=27, kinds=["clear"],
                    fault="stuck", stop_local="13:00")
    _post(client, live_server.write_token, _readings(d.times, d.fixed_power_w, "fixed")
          + _readings(d.times, d.tracker_power_w, "tracker"))
    params = {"start": first, "end": "2025-08-21"}
    for _ in range(2):  # computed, then from the cache
        r = client.get(f"{BASE}/diagnosis", params=params, timeout=120)
        assert r.status_code == 200, r.text
        day = r.json()["days"][0]
        stuck = [f for f in day["faults"] if f["kind"] == "stuck"]
        assert len(stuck) == 1 and stuck[0]["confidence"] >= 0.8, day["faults"]
        got = dt.datetime.fromisoformat(stuck[0]["since_time"])
        assert got.utcoffset() == dt.timedelta(hours=-6), stuck[0]
        stop = dt.datetime.fromisoformat(f"{first}T13:00:00-06:00")
        assert abs((got - stop).total_seconds()) <= 5 * 60, stuck[0]
        assert all(f.get("since_time") is None for f in day["faults"] if f["kind"] != "stuck")
