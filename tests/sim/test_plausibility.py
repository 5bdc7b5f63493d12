"""No impossible number from any simulation path (issue 22, "How it will be checked").

A sweep over the twin's paths — sites from 60° N to 35° S (the built-in Tehuantepec and
sites defined here), clear sky and typical years (TMY3 and EPW) at their own station and far
from it, every controller, flat modules and a concentrator — with three physical limits on
every step:

- plane-of-array irradiance at most 1.1 × the extraterrestrial normal irradiance E0
  (Spencer 1971 via pvlib; nothing on the ground receives more than the top of the
  atmosphere but a little ground reflection and cloud enhancement);
- array power at most 1.1 × its nameplate at the cell temperature, P_STC · (1 + γ (T_cell −
  25 °C)) with the CEC table's γ (a module makes its STC power at 1000 W m⁻² and loses γ per
  kelvin), scaled by G_poa / 1000 W m⁻² where the plane of array gets more than that: a clear
  January noon at 35° S, 580 m, puts 1,100 W m⁻² on the tracker and 1.12 × the nameplate out
  of it, which is physics, not an error (the irradiance limit above bounds G_poa);
- a pointing error only while the tracker tracks: none at night, none with the sun below the
  stated elevation, none while the controller has it stowed.

Spans are short (a day or two, coarse steps; the camera loop a few hours across sunset) so
the module runs in seconds; the cases are sampled so that every site, weather kind,
controller and receiver appears.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from test_sky import write_epw

from sim.control import ControlSettings
from sim.disturbances import Disturbances
from sim.pv import cec_module_parameters
from sim.sites import Site, load_site, site_from_dict
from sim.sky import extra_radiation, pvlib_tmy3_path, read_typical_year, typical_year_at_site
from sim.twin import CONTROLLERS, POINTING_MIN_ELEVATION_DEG, TwinResult, simulate

SAND_POINT_TMY3 = pvlib_tmy3_path().parent / "703165TY.csv"  # Sand Point, Alaska, 55.3° N


def _site(site_id: str, lat: float, lon: float, alt: float, tz: str, tilt: float) -> Site:
    azimuth = 180.0 if lat >= 0 else 0.0  # the fixed array faces the equator
    return site_from_dict({
        "site_id": site_id, "latitude_deg": lat, "longitude_deg": lon, "altitude_m": alt,
        "timezone": tz, "arrays": {
            "tracker": {"mount": "tracker"},
            "fixed": {"mount": "fixed", "surface_tilt_deg": tilt, "surface_azimuth_deg": azimuth},
        }})


SITES = {
    "tehuantepec": load_site("tehuantepec"),  # 16.3° N
    "helsinki": _site("helsinki", 60.17, 24.94, 20.0, "Europe/Helsinki", 45.0),
    "canberra": _site("canberra", -35.28, 149.13, 580.0, "Australia/Sydney", 32.0),
    "quito": _site("quito", -0.18, -78.47, 2850.0, "America/Guayaquil", 5.0),  # equator, high
    "greensboro": _site("greensboro", 36.1, -79.95, 273.0, "America/New_York", 36.0),
    "sand_point": _site("sand_point", 55.317, -160.517, 7.0, "America/Anchorage", 45.0),
}


@pytest.fixture(scope="module")
def years(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[pd.DataFrame, dict]]:
    """pvlib's two TMY3 files and an EPW written from the Greensboro one (pvlib ships none)."""
    epw = write_epw(tmp_path_factory.mktemp("epw") / "greensboro.epw")
    return {"tmy3": read_typical_year(pvlib_tmy3_path()),
            "tmy3_sand_point": read_typical_year(SAND_POINT_TMY3),
            "epw": read_typical_year(epw)}


def _weather(years: dict, kind: str | None, site: Site, start: pd.Timestamp,
             end: pd.Timestamp) -> pd.DataFrame | None:
    """The typical year ``kind`` at ``site`` as the service runs it (the station's own hours
    when it is the site, its sky moved otherwise); None: clear sky."""
    if kind is None:
        return None
    tmy, st = years[kind]
    return typical_year_at_site(tmy, st["utc_offset_h"], start, end,
                                (st["latitude"], st["longitude"], st["altitude"]),
                                (site.latitude, site.longitude, site.altitude))


def _nameplate_w(site: Site, array: str, temp_cell: np.ndarray) -> np.ndarray:
    arr = site.arrays[array]
    p = cec_module_parameters(arr.module)
    return float(p["STC"]) * arr.modules * (1.0 + float(p["gamma_r"]) / 100.0 * (temp_cell - 25.0))


def check_plausible(run: TwinResult) -> None:
    """The three limits of the module docstring on every step of ``run``."""
    s = run.series
    e0 = extra_radiation(s.index)
    for array in ("tracker", "fixed"):
        poa = s[f"{array}_poa_global"].to_numpy()
        worst = np.argmax(poa / e0)
        assert poa[worst] <= 1.1 * e0[worst], (array, s.index[worst], poa[worst], e0[worst])
        power = s[f"{array}_power_w"].to_numpy()
        limit = 1.1 * _nameplate_w(run.site, array, s[f"{array}_temp_cell"].to_numpy()) * (
            np.maximum(poa / 1000.0, 1.0))
        assert (power <= limit).all(), (array, s.index[np.argmax(power - limit)], power.max())
    err = s["pointing_error_mrad"]
    sun = s["apparent_elevation"]
    assert err[sun <= POINTING_MIN_ELEVATION_DEG].isna().all()  # night and the low sun
    if run.controller != "ideal":
        # a stow command (the elevation joint to its maximum, the panel flat) under a sun
        # lower than 45°: the tracker is stowed, no pointing error
        stow = (s["elevation_command_deg"] >= run.site.tracker.elevation_max_deg - 1e-9) & (
            sun < 45.0)
        assert err[stow].isna().all()
    summary = run.summary()
    assert summary["pointing_error_minutes"] <= summary["daylight_steps"] * run.step_s / 60
    if summary["pointing_error_minutes"]:
        assert summary["pointing_error_max_mrad"] == pytest.approx(float(err.max()))


# (site, weather, first day, days, step [s]): every site on clear sky; each typical year at
# its station and far from it, in the season that stresses it (long days at 60° N, the polar
# edge of Sand Point's winter, the southern summer under a northern winter's sky)
WEATHER_CASES = [
    ("tehuantepec", None, "2024-03-20", 2, 300),
    ("helsinki", None, "2024-06-20", 2, 300),
    ("helsinki", None, "2024-12-20", 2, 600),
    ("canberra", None, "2024-01-10", 2, 300),
    ("quito", None, "2024-09-22", 2, 300),
    ("greensboro", "tmy3", "2024-04-15", 3, 300),
    ("tehuantepec", "tmy3", "2024-04-15", 3, 120),  # issue 22.1's case, fine steps
    ("canberra", "tmy3", "2024-01-10", 2, 300),
    ("greensboro", "epw", "2024-07-01", 2, 300),
    ("helsinki", "epw", "2024-06-20", 2, 300),
    ("sand_point", "tmy3_sand_point", "2024-12-20", 2, 300),
    ("quito", "tmy3_sand_point", "2024-12-20", 2, 300),
]


@pytest.mark.parametrize(("site_id", "kind", "day", "days", "step_s"), WEATHER_CASES)
@pytest.mark.parametrize("receiver", ["flat", "cpv"])
def test_every_site_and_weather_stays_physical(years, site_id: str, kind: str | None,
                                               day: str, days: int, step_s: int,
                                               receiver: str) -> None:
    site = SITES[site_id]
    start = pd.Timestamp(day, tz=site.timezone)
    end = start + pd.Timedelta(days=days)
    run = simulate(site, start, end, step_s=step_s, receiver=receiver,
                   weather=_weather(years, kind, site, start, end))
    check_plausible(run)
    assert run.summary()["tracker_energy_wh"] > 0


# every controller, each at another site and sky, with the disturbances that made the
# issue's numbers (a clock offset that stows the tracker with the sun up, a pedestal yaw)
CONTROLLER_CASES = [
    ("open_loop_spa", "helsinki", None, "2024-06-20", "flat"),
    ("open_loop_duffie_beckman", "canberra", "tmy3", "2024-01-10", "cpv"),
    ("chronological", "quito", None, "2024-09-22", "flat"),
    ("hybrid", "tehuantepec", "tmy3", "2024-04-15", "cpv"),
    ("closed_loop_camera", "tehuantepec", None, "2024-03-14", "flat"),
    ("open_loop_model", "quito", "tmy3_sand_point", "2024-12-20", "cpv"),
]


def test_the_cases_cover_every_controller() -> None:
    assert {c[0] for c in CONTROLLER_CASES} | {"ideal"} == set(CONTROLLERS)


@pytest.mark.parametrize(("controller", "site_id", "kind", "day", "receiver"), CONTROLLER_CASES)
def test_every_controller_stays_physical(years, controller: str, site_id: str,
                                         kind: str | None, day: str, receiver: str) -> None:
    site = SITES[site_id]
    settings = ControlSettings(stow_elevation_deg=3.0)
    if controller == "closed_loop_camera":
        # a frame every 5 s from 16:00 to 20:00: tracking, stowing at sunset, the night
        start = pd.Timestamp(f"{day} 16:00", tz=site.timezone)
        end = start + pd.Timedelta(hours=4)
        settings = replace(settings, camera_interval_s=5.0)
    else:
        start = pd.Timestamp(day, tz=site.timezone)
        end = start + pd.Timedelta(days=1)
    run = simulate(site, start, end, step_s=300 if controller != "closed_loop_camera" else 60,
                   controller=controller, receiver=receiver, settings=settings,
                   disturbances=Disturbances(clock_offset_s=600.0, pedestal_yaw_deg=1.0),
                   weather=_weather(years, kind, site, start, end))
    check_plausible(run)
    s = run.series
    stowed_with_sun = (s["elevation_command_deg"] >= 90.0 - 1e-9) & (
        s["apparent_elevation"] > 0)
    assert stowed_with_sun.any()  # the case does reach a stow with the sun up
    summary = run.summary()
    assert summary["pointing_error_minutes"] > 0
    # 10 min of clock (≤ 2.5° of sun) and a 1° yaw: below 0.1 rad wherever it is stated
    assert summary["pointing_error_max_mrad"] < 100.0
