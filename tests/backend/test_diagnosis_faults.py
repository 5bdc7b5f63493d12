"""Fault signatures (backend/diagnosis/faults.py) on faults injected into realistic days
(tests/sim/realistic_sky.py: an independent cloud process, the twin's arrays, the fault
from sim's site wiring / a frozen orientation / a shifted logger clock). Seed 31 is held
out from the tuning seed (3)."""

from __future__ import annotations

import datetime as dt
import functools
import re
from dataclasses import replace
from typing import Any

import numpy as np
import pandas as pd
import pytest

from backend.diagnosis.faults import (
    GHI_UNCERTAINTY,
    INVERSION_UNCERTAINTY,
    band_uncertainty,
    blind_beam_sd_wh,
    faults_over_days,
    features_by_day,
)
from sim import sky_sensor
from sim.sites import load_site
from tests.sim.realistic_sky import logger_days

SITE = load_site("tehuantepec")
FIRST = pd.Timestamp("2026-02-02", tz=SITE.timezone)
DAYS, FAULT_DAY, SEED = 6, 3, 31
#: Far sites of these tests: latitude, longitude, zone, altitude [m], fixed tilt and azimuth [°]
GOLDEN = (39.74, -105.18, "America/Denver", 1828.0, 39.0, 180.0)  # the RMIS station
TROMSO = (69.65, 18.96, "Europe/Oslo", 100.0, 50.0, 180.0)


def _elsewhere(place: tuple[float, float, str, float, float, float], first_day: str, seed: int
               ) -> tuple[Any, pd.DataFrame, list[dict[str, Any]]]:
    """Tehuantepec's arrays at ``place`` with its own fixed plane: six healthy generated days
    from ``first_day`` (seed ``seed``) → (logged days, expectation, days' features)."""
    lat, lon, zone, altitude, tilt, azimuth = place
    site = replace(SITE, latitude=lat, longitude=lon, timezone=zone, altitude=altitude,
                   arrays={**SITE.arrays, "fixed": replace(
                       SITE.arrays["fixed"], surface_tilt=tilt, surface_azimuth=azimuth)})
    first = pd.Timestamp(first_day, tz=zone)
    d = logger_days(site, first, 6, seed)
    e = sky_sensor.weather_aware_twin(site, first, first + pd.Timedelta(days=6), d.fixed_power_w)
    return d, e, features_by_day(site, first, e, d.tracker_power_w)


@functools.cache
def _expected(fixed_power_w: bytes) -> pd.DataFrame:
    """The weather-aware twin of the fixed array's readings (raw bytes of the float64
    array): a tracker fault leaves the fixed array's readings as they are, so the tests of
    one seed share it (about 0.7 s of CPU each)."""
    return sky_sensor.weather_aware_twin(SITE, FIRST, FIRST + pd.Timedelta(days=DAYS),
                                         np.frombuffer(fixed_power_w))


def _diagnose(fault: str | None) -> list[list[dict]]:
    d = logger_days(SITE, FIRST, DAYS, SEED, fault=fault, fault_day=FAULT_DAY)
    e = _expected(np.ascontiguousarray(d.fixed_power_w, np.float64).tobytes())
    return faults_over_days(features_by_day(SITE, FIRST, e, d.tracker_power_w))


def _since_ok(f: dict) -> bool:
    since = dt.date.fromisoformat(f["since"])
    return abs((since - FIRST.date()).days - FAULT_DAY) <= 1


@pytest.mark.parametrize("fault,check", [
    ("stuck", lambda f: abs(f["magnitude"] - 35.0) <= 5.0 and "azimuth 18" in f["detail"]),
    ("clock_offset", lambda f: abs(f["magnitude"] - 1800.0) <= 300.0),
    ("module_loss", lambda f: abs(f["magnitude"] - 25.0) <= 5.0),
])
def test_injected_fault_found_with_kind_magnitude_and_start(fault, check) -> None:
    found = _diagnose(fault)
    for k in range(DAYS):
        strong = [f for f in found[k] if f["confidence"] >= 0.5]
        if k < FAULT_DAY - 1:
            assert strong == [], (k, strong)
        elif k >= FAULT_DAY + 1:
            mine = [f for f in strong if f["kind"] == fault]
            assert len(mine) == 1, (k, found[k])
            assert check(mine[0]) and _since_ok(mine[0]), mine[0]


def test_healthy_days_get_no_fault() -> None:
    assert all(f["confidence"] < 0.5 for day in _diagnose(None) for f in day)


def test_soiling_found_as_a_slow_decline() -> None:
    """0.5 %/day of transmittance lost on the tracker's glass from day 4 of 14 (seed 41;
    the soiling thresholds were set on seeds 3 and 4: 0.42 and 0.71 %/day found)."""
    first, days, start = pd.Timestamp("2026-03-20", tz=SITE.timezone), 14, 4
    d = logger_days(SITE, first, days, 41, fault="soiling", fault_day=start)
    e = sky_sensor.weather_aware_twin(SITE, first, first + pd.Timedelta(days=days),
                                      d.fixed_power_w)
    found = faults_over_days(features_by_day(SITE, first, e, d.tracker_power_w))
    soil = [f for f in found[-1] if f["kind"] == "soiling"]
    assert len(soil) == 1 and soil[0]["unit"] == "%/day", found[-1]
    assert abs(soil[0]["magnitude"] - 0.5) <= 0.25
    since = (dt.date.fromisoformat(soil[0]["since"]) - first.date()).days
    assert abs(since - start) <= 3
    assert all(f["kind"] != "module_loss" for day in found for f in day)


def test_six_days_are_no_soiling_trend() -> None:
    """SOILING_MIN_DAYS says a decline needs a week of days to be told from noise, but the
    rule let six through: a healthy 6-day run at Golden in June (development seed 1) whose
    partly cloudy first and last days read −4.4 % and +5.1 % was named ``soiling`` on all
    six days (and the same seed at Madrid and Freiburg). Now a week or more of days."""
    _, _, days = _elsewhere(GOLDEN, "2026-06-10", 1)
    found = faults_over_days(days)
    assert not [f for day in found for f in day if f["kind"] == "soiling"], found


@pytest.mark.parametrize("shift_min", [0, 60, -30])
def test_a_sky_an_hour_late_is_named(shift_min: int) -> None:
    """A logger that stamps summer-time wall clocks with the winter offset: both arrays'
    readings an hour late (and a clock half an hour behind). The sky comes from the same
    readings, so the tracker's own clock fit cannot see it; the fixed plane against its
    clear sky does. Held out: seed 34 in July (the 25-min threshold was read off seeds 31
    and 32 in April: 1–3 min on healthy clear days, 30 and 60 min found within 7; a plane
    mis-set 30° in azimuth shifts by 23)."""
    first = pd.Timestamp("2026-07-10", tz=SITE.timezone)
    d = logger_days(SITE, first, 5, 34)
    fixed, tracker = (np.roll(a, shift_min) for a in (d.fixed_power_w, d.tracker_power_w))
    e = sky_sensor.weather_aware_twin(SITE, first, first + pd.Timedelta(days=5), fixed)
    days = features_by_day(SITE, first, e, tracker)
    found = faults_over_days(days)
    clear = [k for k, day in enumerate(days)
             if (c := day["features"]["sky_clock"]) and c["residual"] < 0.05]
    assert len(clear) >= 2, [day["features"]["sky_clock"] for day in days]
    for k, day in enumerate(found):
        mine = [f for f in day if f["kind"] == "sky_clock_offset"]
        if shift_min == 0 or k < clear[0]:
            assert mine == [], (k, mine)
        elif k not in clear:  # a cloudy day in the run carries it
            assert len(mine) == 1 and mine[0]["detail"].endswith("cannot show it)"), (k, day)
        else:
            # the tracker is not judged under the shifted sky (its own clock fit read the
            # shift with the other sign, -67 min)
            assert [f["kind"] for f in day] == ["sky_clock_offset"], (k, day)
            assert mine[0]["confidence"] >= 0.5, (k, day)
            assert abs(mine[0]["magnitude"] - 60 * shift_min) <= 8 * 60, mine[0]
            # the cloudy days between do not break the run
            assert mine[0]["since"] == days[clear[0]]["date"], mine[0]


@pytest.mark.parametrize(("fixed_lag_min", "tracker_lag_min"),
                         [(0, 0), (7, 0), (-10, 0), (0, 15), (0, -10), (7, -30)])
def test_a_fixed_logger_late_is_not_the_trackers_clock(fixed_lag_min: int,
                                                       tracker_lag_min: int) -> None:
    """The fixed array's logger alone runs late (or early) beside a right tracker: the sky
    comes from its readings, so the tracker's clock fit reads the shift with the other sign
    (7 min late: a tracker ``clock_offset`` of −12 min on the twin's clear days, a tester's
    finding; here −7 min on the cloudy days, where the clouds pass the two loggers 7 min
    apart). The fixed plane's shape against the clear sky says whose clock it is: a
    ``sky_clock_offset``, never the tracker's. A tracker whose own clock is off keeps its
    ``clock_offset``, beside a right fixed logger or one 7 min late (two clocks off: the
    sizes disagree). Held out: seed 34 in July (the repro was Tehuantepec in March, the
    twin's own clear days)."""
    first = pd.Timestamp("2026-07-10", tz=SITE.timezone)
    d = logger_days(SITE, first, 5, 34)
    e = sky_sensor.weather_aware_twin(SITE, first, first + pd.Timedelta(days=5),
                                      np.roll(d.fixed_power_w, fixed_lag_min))
    found = faults_over_days(features_by_day(SITE, first, e,
                                             np.roll(d.tracker_power_w, tracker_lag_min)))
    named = [f for day in found for f in day]
    clock = [f for f in named if f["kind"] == "clock_offset" and f["confidence"] >= 0.5]
    sky = [f for f in named if f["kind"] == "sky_clock_offset"]
    if tracker_lag_min:
        assert not [f for f in named if f["kind"] == "sky_clock_offset"], named
        assert len(clock) >= 2, named
        # the clouds time the tracker against the sky's logger: its clock less the sky's
        want = 60 * (tracker_lag_min - fixed_lag_min)
        assert all(abs(f["magnitude"] - want) <= 3 * 60 for f in clock), clock
        return
    assert not [f for f in named if f["kind"] == "clock_offset"], named
    if fixed_lag_min == 0:
        assert not named, named
        return
    # (7 min late: only on the cloudy days, at 0.44, the clear days' own sky fits' 1 - ratio)
    assert len(sky) >= 2, found
    # the sky's shape reads 5-7 min for 7 min late, 10-14 min for 10 min early
    assert all(abs(f["magnitude"] - 60 * fixed_lag_min) <= 5 * 60 for f in sky), sky


def test_azimuth_offset_is_not_named_as_another_fault() -> None:
    """A 10° pedestal yaw (open-loop SPA) from day 3 is not found from power (its 1.5 % ×
    cos²h of the beam is inside the sky's error at low sun, docs/diagnosis.md), but it must
    not be called something else either: no fault of another kind with confidence ≥ 0.5
    (on development seed 5 a 20–30° yaw was called soiling)."""
    found = _diagnose("azimuth_offset")
    wrong = [f for day in found for f in day
             if f["confidence"] >= 0.5 and f["kind"] != "azimuth_offset"]
    assert wrong == [], wrong


@pytest.mark.parametrize("model", ["haydavies", "perez"])
def test_the_stuck_fit_prices_orientations_with_the_sites_sky_model(model: str) -> None:
    """The stuck fit's power at an orientation (faults._power_at) is the expected twin's at
    the tracker's own orientation (the sun's), whichever transposition model the site
    names: with Hay-Davies hard-coded a Perez site's fit was 1.5 % low on a clear day."""
    import dataclasses

    from backend.diagnosis.faults import _power_at
    from sim import twin

    site = dataclasses.replace(SITE, transposition_model=model)
    first = pd.Timestamp("2026-02-03", tz=site.timezone)
    end = first + pd.Timedelta(days=1)
    fixed = twin.simulate(site, first, end).series["fixed_power_w"].fillna(0.0).to_numpy()
    e = sky_sensor.weather_aware_twin(site, first, end, fixed)
    day = e[e["apparent_elevation"] > 10.0]
    tilt = (90.0 - day["apparent_elevation"].to_numpy())[None]
    power = _power_at(site, day, tilt, day["solar_azimuth"].to_numpy()[None])[0]
    np.testing.assert_allclose(power, day["tracker_power_w"].to_numpy(), rtol=1e-6)


def test_the_band_widens_by_the_instrument_the_days_sky_rests_on() -> None:
    """faults.band_uncertainty: a day whose daylight sky rests mostly on a GHI pyranometer
    gets GHI_UNCERTAINTY, any other day INVERSION_UNCERTAINTY — by the same rule the
    diagnosis reports the day's source with (sim.sky_sensor.main_sky_source), so the two
    never disagree; the night's minutes do not count."""
    def day(sources: list[str], night: int = 0) -> pd.DataFrame:
        return pd.DataFrame({"poa_clear": [0.0] * night + [500.0] * len(sources),
                             "flag": [sky_sensor.FLAGS["night"]] * night + [0] * len(sources),
                             "sky_source": ["sensor_ghi"] * night + sources})

    assert band_uncertainty(day(["sensor_ghi"] * 6 + ["fixed_array"] * 4)) == GHI_UNCERTAINTY
    assert band_uncertainty(day(["sensor_poa"] * 6 + ["sensor_ghi"] * 4)) \
        == INVERSION_UNCERTAINTY
    # three sources: the most common one, as the reported source
    mixed = day(["sensor_ghi"] * 4 + ["fixed_array"] * 3 + ["clear_sky"] * 3)
    assert sky_sensor.main_sky_source(mixed) == "sensor_ghi"
    assert band_uncertainty(mixed) == GHI_UNCERTAINTY
    # a GHI night before a POA-sensor day
    assert band_uncertainty(day(["sensor_poa"] * 5, night=20)) == INVERSION_UNCERTAINTY
    assert GHI_UNCERTAINTY > INVERSION_UNCERTAINTY


def test_a_summer_dawn_behind_the_fixed_plane_is_not_read_as_a_beam() -> None:
    """The RMIS station's site (Golden, Colorado) in June, tehuantepec's arrays with the
    fixed plane at the station's 39° facing south, generated held-out skies (seed 11): the
    sun rises and sets behind the plane, whose POA is then diffuse only, and an overcast
    deck's diffuse there is as bright as the clear sky's. Read as a beam
    (sky_sensor._clear_beam's k ≥ 0.85, GTI-DIRINT), its two partly cloudy days and its
    overcast one ran +11.4, +11.1 and +21.9 %, each an underperformance of a healthy
    tracker at confidence 1.0; capped by the minutes around that see the beam, measured
    +4.1, +1.6 and +3.3 %; since the beam there is the one the seen minutes make likely
    (sky_sensor._unseen_beam), +1.2, +2.9 and +3.0 % (the clear days −0.6 … +0.3 %), no
    finding."""
    d, e, days = _elsewhere(GOLDEN, "2026-06-10", 11)
    found = faults_over_days(days)
    assert d.kinds.count("clear") < 6  # the cloudy days this is about
    for k in range(6):
        sl = slice(k * 1440, (k + 1) * 1440)
        ratio = e["tracker_power_w"].to_numpy()[sl].sum() / d.healthy_tracker_power_w[sl].sum()
        limit = 0.01 if d.kinds[k] == "clear" else 0.05
        assert abs(ratio - 1) < limit, (k, d.kinds[k], ratio)
        assert not [f for f in found[k] if f["confidence"] >= 0.5], (k, found[k])


@pytest.mark.parametrize(("latitude", "longitude", "zone", "altitude", "tilt", "cloudy_limit"), [
    (-42.88, 147.33, "Australia/Hobart", 50.0, 35.7, 0.04),  # Hobart
    (-64.77, -64.05, "Antarctica/Palmer", 10.0, 40.0, 0.19)])  # Palmer Station
def test_a_december_day_behind_a_plane_facing_north_is_no_underperformance(
        latitude: float, longitude: float, zone: str, altitude: float, tilt: float,
        cloudy_limit: float) -> None:
    """A tester's finding: at Hobart and at Palmer Station in December, the fixed plane
    facing north (35.7° and 40°, as the tester's sites), the sun rises and sets behind it and grazes
    it for hours, and an overcast deck's diffuse there reads as bright as a clear sky's. The
    expectation gave that light the beam's (the beam behind the plane capped by the seen
    minutes' mean only where the clear beam was under half the plane's clear POA): healthy
    cloudy days +9.3 … +9.8 % (Hobart) and +14.6 … +42.5 % (Palmer), four of them an
    underperformance at confidence 1.0 (generated held-out skies, seed 11). Now the beam
    where the plane is blind is the one its seen minutes make likely
    (sim.sky_sensor._unseen_beam) and the band widens by that guess
    (faults.blind_beam_sd_wh): measured +2.7 … +3.5 % and +8.5 … +17.8 %, every day's truth
    inside its band (Palmer's widened to 11–18 % on its cloudy days), no finding; the clear
    days within 1.6 %."""
    d, e, days = _elsewhere((latitude, longitude, zone, altitude, tilt, 0.0), "2026-11-28", 11)
    found = faults_over_days(days)
    assert d.kinds.count("clear") < 6  # the cloudy days this is about
    for k in range(6):
        sl = slice(k * 1440, (k + 1) * 1440)
        ratio = e["tracker_power_w"].to_numpy()[sl].sum() / d.healthy_tracker_power_w[sl].sum()
        limit = 0.02 if d.kinds[k] == "clear" else cloudy_limit
        assert abs(ratio - 1) < limit, (k, d.kinds[k], ratio)
        energy = days[k]["features"]["energy"]
        assert energy["measured_wh"] >= energy["low_wh"], (k, energy)
        assert not [f for f in found[k] if f["confidence"] >= 0.5], (k, found[k])


def test_a_midday_dropout_of_the_fixed_logger_widens_the_band() -> None:
    """A reviewer's finding: minutes without a fixed-array reading while the sun is in front
    of the plane took the clear beam the clearness filled across the gap suggests, with no
    spread, so a healthy day's truth fell under its band (Golden, June, the fixed logger
    silent 11:00–14:00 each day; seeds 11–18: 5 of 48 days under it, 4 now). Those minutes
    now carry the blind beam's spread (sim.sky_sensor._unseen_beam): seed 14's first day,
    overcast, is inside its band."""
    site = replace(SITE, latitude=GOLDEN[0], longitude=GOLDEN[1], timezone=GOLDEN[2],
                   altitude=GOLDEN[3], arrays={**SITE.arrays, "fixed": replace(
                       SITE.arrays["fixed"], surface_tilt=GOLDEN[4], surface_azimuth=GOLDEN[5])})
    first = pd.Timestamp("2026-06-10", tz=site.timezone)
    d = logger_days(site, first, 6, 14)
    fixed = d.fixed_power_w.copy()
    hour = d.times.tz_convert(site.timezone).hour
    gap = (hour >= 11) & (hour < 14)
    fixed[gap] = np.nan
    e = sky_sensor.weather_aware_twin(site, first, first + pd.Timedelta(days=6), fixed)
    days = features_by_day(site, first, e, d.healthy_tracker_power_w)
    assert d.kinds[0] == "overcast"
    energy = days[0]["features"]["energy"]
    assert energy["measured_wh"] >= energy["low_wh"], energy
    assert (e["tracker_blind_sd_w"].to_numpy()[gap] > 0).mean() > 0.9


def test_an_overcast_midnight_sun_day_is_no_shape_fault() -> None:
    """Tromsø (69.7° N) in June, the fixed plane at 50° facing south: the sun circles the sky
    and is behind the plane half the day, where a bright deck reads as clear, so an overcast
    day's mean clearness passed the shape fits' gate (MIN_CLEARNESS) and a healthy tracker
    was named ``stuck`` (generated held-out skies, seed 13: day 2 at confidence ≥ 0.5; seeds
    11 and 14 likewise). The gate now reads the plane's clearness where it sees the beam
    (``beam_seen``): no shape fault on any day."""
    d, _, days = _elsewhere(TROMSO, "2026-06-10", 13)
    found = faults_over_days(days)
    assert d.kinds.count("overcast") >= 2
    for k in range(6):
        assert not [f for f in found[k] if f["confidence"] >= 0.5
                    and f["kind"] in ("stuck", "azimuth_offset", "clock_offset")], (k, found[k])


def test_the_blind_beams_uncertainty_is_its_minutes_correlated_sum() -> None:
    """faults.blind_beam_sd_wh against the quadratic form aᵀ K a written out (K the
    exp(−lag / sky_sensor.BEAM_PERSISTENCE_MIN) correlation of every pair of minutes), and
    band_uncertainty adding twice its share of the day's expected energy to the instrument's
    in quadrature."""
    rng = np.random.default_rng(5)
    a = np.where(rng.random(1440) < 0.3, rng.uniform(0.0, 80.0, 1440), 0.0)
    lag = np.abs(np.subtract.outer(np.arange(1440), np.arange(1440)))
    want = np.sqrt(a @ np.exp(-lag / sky_sensor.BEAM_PERSISTENCE_MIN) @ a) / 60.0
    day = pd.DataFrame({"tracker_blind_sd_w": a, "tracker_power_w": np.full(1440, 300.0),
                        "poa_clear": np.full(1440, 500.0), "flag": 0,
                        "sky_source": "fixed_array"})
    assert blind_beam_sd_wh(day) == pytest.approx(want, rel=1e-9)
    assert band_uncertainty(day) == pytest.approx(
        np.hypot(INVERSION_UNCERTAINTY, 2.0 * want / (300.0 * 24.0)), rel=1e-9)
    assert band_uncertainty(day.assign(tracker_blind_sd_w=0.0)) == INVERSION_UNCERTAINTY


@pytest.mark.parametrize("kind", ["clear", "partly"])
def test_a_tracker_that_stops_part_way_through_a_day_is_stuck_from_then(kind: str) -> None:
    """A tester's finding: a tracker that stops at 13:00 and holds the orientation it had
    then (seed 31, February; a clear or partly cloudy day after a clear one, a partly
    cloudy day after it). That day it made 0.93 (clear) and 0.92 (partly) of the expected
    energy, then inside its band, and no fixed orientation fits its tracking morning:
    nothing was named. The stop fit (faults._stopped) names ``stuck`` that day (measured
    confidence 0.89 and 0.88), from 12:59, its ``since_time``; the next day, stuck all day,
    keeps the run's day and minute and the orientation (57° of elevation, then 56°). Since
    the second sky takes the clear beam in the clear spells (sim.sky_sensor.decompose), the
    band's lower edge is 0.95 and 0.93 of the expected energy there: the energy alone now
    tells it too."""
    d = logger_days(SITE, FIRST, 3, SEED, fault="stuck", fault_day=1, stop_local="13:00",
                    kinds=["clear", kind, "partly"])
    e = sky_sensor.weather_aware_twin(SITE, FIRST, FIRST + pd.Timedelta(days=3),
                                      d.fixed_power_w)
    days = features_by_day(SITE, FIRST, e, d.tracker_power_w)
    found = faults_over_days(days)
    energy = days[1]["features"]["energy"]
    assert energy["measured_wh"] < energy["low_wh"], energy  # the band tells (it could not)
    assert not [f for f in found[0] if f["confidence"] >= 0.5], found[0]
    stop = FIRST + pd.Timedelta(days=1, hours=13)
    stuck = []
    for k in (1, 2):
        mine = [f for f in found[k] if f["kind"] == "stuck"]
        assert len(mine) == 1 and mine[0]["confidence"] >= 0.8, (k, found[k])
        assert mine[0]["since"] == stop.date().isoformat(), mine[0]
        got = pd.Timestamp(mine[0]["since_time"])
        assert abs((got - stop).total_seconds()) <= 5 * 60, mine[0]
        stuck.append(mine[0])
    assert stuck[0]["detail"].endswith(f"from {stuck[0]['since_time'][11:16]} "
                                       "(tracking until then)"), stuck[0]
    assert "from" not in stuck[1]["detail"], stuck[1]  # stuck all that day
    assert abs(stuck[1]["magnitude"] - stuck[0]["magnitude"]) <= 2.0, stuck


def test_silent_days_in_a_row_are_one_dropout_since_the_first() -> None:
    """Three days in a row without a reading are one dropout since the first of them (the
    diagnosis listed three, "since" each day: a tester's finding); a day with its readings
    between two silent days ends the run, and so does a gap in the dates."""
    def day(date: str, missing_min: int) -> dict:
        return {"date": date, "features": {"missing_daylight_min": missing_min}}

    days = [day("2026-11-27", 0), day("2026-11-28", 600), day("2026-11-29", 610),
            day("2026-11-30", 605), day("2026-12-01", 0), day("2026-12-02", 590),
            day("2026-12-04", 600)]
    since = [[f["since"] for f in found if f["kind"] == "dropout"]
             for found in faults_over_days(days)]
    assert since == [[], ["2026-11-28"], ["2026-11-28"], ["2026-11-28"], [], ["2026-12-02"],
                     ["2026-12-04"]]


def _stuck_day(date: str, azimuth_deg: float, tilt_deg: float, ratio: float) -> dict[str, Any]:
    """A day's features whose best explanation is ``stuck`` at that pose, its residual
    ``ratio`` × the healthy one (confidence 1 − ratio)."""
    return {"date": date, "features": {
        "residual": 0.2, "clearness": 0.8,
        "stuck": {"residual": 0.2 * ratio, "tilt_deg": tilt_deg, "azimuth_deg": azimuth_deg,
                  "stopped_at": None},
        "azimuth_offset": {"residual": 0.19, "offset_deg": 30.0},
        "clock_offset": {"residual": 0.19, "offset_s": 600.0}}}


def test_a_runs_pose_is_its_best_fitting_days() -> None:
    """A tester's finding: a tracker stuck at azimuth 82°, elevation 52° was fitted so on
    its clear days, then at azimuth 50°, elevation 45° (confidence 0.67) on a partly cloudy
    one — and the alert, which names the latest day's finding, sent the technician to a
    pose 32° off. A run's pose is that of its best-fitting day; a better one replaces it."""
    days = [_stuck_day("2026-12-01", 82.0, 38.0, 0.10), _stuck_day("2026-12-02", 50.0, 45.0, 0.33),
            _stuck_day("2026-12-03", 83.0, 38.0, 0.05)]
    found = [[f for f in day if f["kind"] == "stuck"][0] for day in faults_over_days(days)]
    assert [f["since"] for f in found] == ["2026-12-01"] * 3
    assert [f["confidence"] for f in found] == [0.9, 0.67, 0.95]  # each day's own
    assert found[0]["detail"] == "stuck at azimuth 82°, elevation 52°"
    assert found[1]["detail"].startswith("stuck at azimuth 82°, elevation 52° (the run's best "
                                         "fit: 2026-12-01, confidence 0.90)"), found[1]
    assert found[1]["magnitude"] == 52.0
    assert found[2]["detail"] == "stuck at azimuth 83°, elevation 52°"


def test_the_library_path_judges_the_fixed_array_under_a_sensors_sky() -> None:
    """Under a POA sensor's sky the fixed array is judged against its own band
    (``fixed_underperformance``, faults.judged_features) on the library path as in the
    service's: its readings 40 % low from the third of four days (seed 31) read 38.0 and
    38.3 % short (the healthy days' ratios 1.02 and 1.03 of the expectation); without its
    readings nothing is said of it."""
    d = logger_days(SITE, FIRST, 4, SEED)
    fixed = d.fixed_power_w * np.where(np.arange(d.fixed_power_w.size) >= 2 * 1440, 0.6, 1.0)
    e = sky_sensor.weather_aware_twin(SITE, FIRST, FIRST + pd.Timedelta(days=4), fixed,
                                      sensors=d.sensors("fixed_poa_w_m2"))
    days = features_by_day(SITE, FIRST, e, d.tracker_power_w, fixed_power_w=fixed)
    assert all(day["features"]["sensor_sky"] for day in days)
    found = [[f for f in day if f["kind"] == "fixed_underperformance"]
             for day in faults_over_days(days)]
    assert found[:2] == [[], []]
    for (f,) in found[2:]:
        assert f["array"] == "fixed" and f["since"] == days[2]["date"]
        assert f["magnitude"] == pytest.approx(40.0, abs=2.5), f
    unjudged = faults_over_days(features_by_day(SITE, FIRST, e, d.tracker_power_w))
    assert not any(f["kind"] == "fixed_underperformance" for day in unjudged for f in day)


def test_a_steady_shortfall_under_a_sensors_sky_names_the_losses_it_would_be() -> None:
    """A fixed array 15 % down every day (seed 31, a POA sensor's sky) reads as a steady
    loss from its third day on, naming the dc_loss_pct that would give it: 13 % (12.6–13.7 %
    a day; this healthy generated array reads 1.02–1.03 of its expectation); 10 % down, 8 %.
    Losses compound: with 14 % in the config and the array a further 15 % down, the advice
    is 1 − 0.86 · 0.87 = 25 %, not 14 + 13; a config's 45 % and 15 % more (53 %) is past the
    50 % a config allows and named a fault. One whose losses vary by day (snow: 50, 20,
    40 %) is not steady, and a run that begins with a snow day and goes on 15 % down says it
    from its third steady day, since the first of them; a loss that comes overnight after
    healthy days is named a step, not losses (every day under the sensor's sky counts, below
    its band or not: the days below a wide band alone are the deeper ones)."""
    d = logger_days(SITE, FIRST, DAYS, SEED)

    @functools.cache
    def expected(dc_loss_pct: float) -> tuple[Any, pd.DataFrame]:
        """The site with the fixed array's losses, and its expectation under the POA
        sensor's sky (the sky is the sensor's: the array's readings do not enter it)."""
        site = replace(SITE, arrays={**SITE.arrays, "fixed": replace(
            SITE.arrays["fixed"], dc_loss_pct=dc_loss_pct)})
        return site, sky_sensor.weather_aware_twin(
            site, FIRST, FIRST + pd.Timedelta(days=DAYS), d.fixed_power_w,
            sensors=d.sensors("fixed_poa_w_m2"))

    def findings(day_factors: list[float], dc_loss_pct: float = 0.0) -> list[str]:
        site, e = expected(dc_loss_pct)
        fixed = d.fixed_power_w * (1 - dc_loss_pct / 100) * np.repeat(day_factors, 1440)
        days = features_by_day(site, FIRST, e, d.tracker_power_w, fixed_power_w=fixed)
        return [" / ".join(f["detail"] for f in day if f["kind"] == "fixed_underperformance")
                for day in faults_over_days(days)]

    def advice(texts: list[str]) -> list[tuple[int, int, str]]:
        """(steady %, days, since) and the dc_loss_pct advised, per day from the third."""
        out = []
        for text in texts[2:]:
            m = re.search(r"steady at (\d+) % \([\d.]+–[\d.]+ %\) over the (\d) days since "
                          r"(\S+): .*(set its dc_loss_pct to about (\d+) %|a fault, not losses)",
                          text)
            assert m is not None, text
            out.append((int(m.group(1)), int(m.group(2)), m.group(3), m.group(5) or "fault"))
        return out

    steady = findings([0.85] * DAYS)
    assert all(steady) and not any("steady" in x for x in steady[:2]), steady
    start = FIRST.date().isoformat()
    assert advice(steady) == [(13, k, start, "13") for k in range(3, DAYS + 1)]
    assert {a[3] for a in advice(findings([0.9] * DAYS))} == {"8"}
    with_losses = advice(findings([0.85] * DAYS, dc_loss_pct=14.0))
    assert {(a[0], a[3]) for a in with_losses} == {(13, "25")}, with_losses
    assert "(from 14 %)" in findings([0.85] * DAYS, dc_loss_pct=14.0)[-1]
    assert {a[3] for a in advice(findings([0.85] * DAYS, dc_loss_pct=45.0))} == {"fault"}
    varying = findings([0.5, 0.8, 0.6, 1.0, 1.0, 1.0])
    assert all(varying[:3]) and not any("steady" in x for x in varying)
    after_snow = findings([0.5, 0.85, 0.85, 0.85, 0.85, 0.85])
    assert not any("steady" in x for x in after_snow[:3])
    since = (FIRST + pd.Timedelta(days=1)).date().isoformat()
    assert f"over the 3 days since {since}" in after_snow[3], after_snow[3]
    assert "set its dc_loss_pct to about 13 %" in after_snow[3]
    step = findings([1.0, 1.0, 0.85, 0.85, 0.85, 0.85])  # healthy, then down overnight
    assert not any("steady" in x for x in step[:4])
    since = (FIRST + pd.Timedelta(days=2)).date().isoformat()
    assert f"a step down on {since}" in step[4] and "a string or an inverter down" in step[4]
    assert "dc_loss_pct" not in step[4].split("steady at")[1], step[4]


def test_the_library_path_cuts_days_at_local_midnights_across_a_clock_change() -> None:
    """Across Oslo's autumn change (25 October 2026: 1,500 minutes) the days are cut at the
    local midnights as the service cuts them: 1,440-minute slices labelled 25 October twice
    and dropped an hour (a tester's finding); the run's last, partial day is left out."""
    lat, lon, zone, altitude, tilt, azimuth = TROMSO
    site = replace(SITE, latitude=lat, longitude=lon, timezone=zone, altitude=altitude,
                   arrays={**SITE.arrays, "fixed": replace(
                       SITE.arrays["fixed"], surface_tilt=tilt, surface_azimuth=azimuth)})
    first = pd.Timestamp("2026-10-24", tz=zone)
    d = logger_days(site, first, 4, SEED)
    e = sky_sensor.weather_aware_twin(site, first, first + pd.Timedelta(days=4), d.fixed_power_w)
    assert len(e) == 4 * 1440  # four times 24 hours: to 23:00 on 27 October, local
    days = features_by_day(site, first, e, d.tracker_power_w)
    assert [day["date"] for day in days] == ["2026-10-24", "2026-10-25", "2026-10-26"]
    with pytest.raises(ValueError, match="not at first_day"):
        features_by_day(site, first + pd.Timedelta(hours=1), e, d.tracker_power_w)
