"""Sun position: NREL SPA reference case, interpolated SPA vs pvlib, Duffie–Beckman (seed 001)."""

from typing import Any

import numpy as np
import pandas as pd
import pvlib
import pytest

from sim import sun
from sim.sun import PVLIB_SPA_INTERNALS, equation_of_time_spencer, solar_position
from vision.sphere import angular_separation_deg


def angular_separation(z1: Any, a1: Any, z2: Any, a2: Any) -> np.ndarray:
    """Great-circle angle [°] between (zenith, azimuth) pairs."""
    return angular_separation_deg(a1, 90.0 - np.asarray(z1), a2, 90.0 - np.asarray(z2))


def cooper_declination(day_of_year: float) -> float:
    """Seed 001, eq. 1, written independently of pvlib: δ = 23.45 sin(360 (284 + N)/365)."""
    return float(23.45 * np.sin(np.deg2rad(360.0 * (284.0 + day_of_year) / 365.0)))

# Reda & Andreas (2004), Appendix A.5 (../shared/reference/spa_reference.json).
SPA_CASE: dict[str, Any] = dict(
    latitude=39.742476,
    longitude=-105.1786,
    altitude=1830.14,
    pressure=82000.0,
    temperature=11.0,
    delta_t=67.0,
)
SPA_TIME = pd.Timestamp("2003-10-17T12:30:30-07:00")
# Duffie–Beckman vs SPA at Tehuantepec over 2024, daylight, 20 min: measured 1.165° worst,
# 0.413° mean (Cooper's declination is good to ~1°, the EoT to ~1 min) — far below seed
# 001's 100 mrad (5.7°) open-loop drift, which is mechanical, not the algorithm.
MAX_DB_SEP_DEG = 1.2
MEAN_DB_SEP_DEG = (0.39, 0.44)


def test_spa_reference_case() -> None:
    pos = solar_position(SPA_TIME, **SPA_CASE).iloc[0]
    assert abs(pos["apparent_zenith"] - 50.11162) <= 1e-4
    assert abs(pos["azimuth"] - 194.34024) <= 1e-4


def test_interpolated_spa_matches_pvlib_spa() -> None:
    # 12 days at 1 min: long enough for the hourly-grid route of sim.sun._spa
    times = pd.date_range("2024-06-10", periods=12 * 1440, freq="1min", tz="UTC")
    ours = solar_position(times, 16.28875, -95.240871, 50.0, 100725.0, 27.0, 69.0)
    ref = pvlib.solarposition.spa_python(times, 16.28875, -95.240871, 50.0, 100725.0, 27.0, 69.0)
    sep = angular_separation(ours["zenith"], ours["azimuth"], ref["zenith"], ref["azimuth"])
    assert np.max(sep) < 1e-5
    assert np.max(np.abs(ours["apparent_zenith"] - ref["apparent_zenith"])) < 1e-5


def test_single_instants_from_the_cached_grid_match_pvlib_spa() -> None:
    """One instant at a time (a sky frame's sun, the twin's scrubbed minute) is interpolated
    between cached hourly nodes: within 1e-5° of pvlib's own SPA anywhere, over 40 years —
    among them hours whose sidereal time minus right ascension turns past 360° — measured
    1.7e-6° at worst."""
    rng = np.random.default_rng(7)
    seps, dz = [], []
    for _ in range(120):
        t = pd.DatetimeIndex([pd.Timestamp("2000-01-01", tz="UTC")
                              + pd.Timedelta(seconds=float(rng.uniform(0, 40 * 365 * 86400)))])
        lat, lon = float(rng.uniform(-89, 89)), float(rng.uniform(-180, 180))
        ours = solar_position(t, lat, lon, 100.0, 100725.0, 27.0, 69.0)
        ref = pvlib.solarposition.spa_python(t, lat, lon, 100.0, 100725.0, 27.0, 69.0)
        seps.append(float(angular_separation(ours["zenith"], ours["azimuth"],
                                             ref["zenith"], ref["azimuth"])[0]))
        dz.append(abs(float(ours["apparent_zenith"].iloc[0] - ref["apparent_zenith"].iloc[0])))
    assert max(seps) < 1e-5 and max(dz) < 1e-5


def test_an_hours_instants_compute_its_nodes_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """The nodes an hour's instants read (its start, its end and the grid's spare one) are
    computed on the first instant asked for, in one call, and serve the rest of the hour;
    the next hour computes one node more."""
    calls: list[int] = []
    real = sun._spa_geocentric

    def counting(unixtime: np.ndarray, delta_t: float) -> tuple[np.ndarray, ...]:
        calls.append(len(unixtime))
        return real(unixtime, delta_t)

    monkeypatch.setattr(sun, "_spa_geocentric", counting)
    monkeypatch.setattr(sun, "_geocentric_cache", {})
    first = pd.Timestamp("2031-05-04T10:00:30Z")
    for s in range(0, 3500, 300):
        solar_position(first + pd.Timedelta(seconds=s), 16.3, -95.2)
    assert calls == [3]
    solar_position(first + pd.Timedelta(hours=1, minutes=30), 16.3, -95.2)
    assert calls == [3, 1]


def test_duffie_beckman_textbook_values() -> None:
    # Duffie & Beckman, Solar Engineering of Thermal Processes, Example 1.5.1 (Feb 3,
    # n = 34: E = -13.5 min) and Example 1.6.1 (Feb 13, n = 44: declination -14 deg).
    assert equation_of_time_spencer(34) == pytest.approx(-13.5, abs=0.1)
    assert cooper_declination(44) == pytest.approx(-14.0, abs=0.1)
    # Cooper's equation peaks at +23.45 deg near the June solstice (n = 172)
    assert cooper_declination(172) == pytest.approx(23.45, abs=0.01)


def test_duffie_beckman_example_solar_time() -> None:
    # Example 1.5.1: Madison (89.4 W, standard meridian 90 W), 10:30 CST on Feb 3 is
    # 10:19 solar time (correction 4 (90 - 89.4) - 13.5 = -11 min); the hour angle is
    # 15 deg/h * (10:19 - 12:00) (morning), so the sun is east of south.
    t = pd.Timestamp("2024-02-03T10:30:00-06:00")
    pos = solar_position(t, 43.0, -89.4, method="duffie-beckman").iloc[0]
    delta = np.deg2rad(cooper_declination(34))
    omega = np.deg2rad(15 * (10 + 19 / 60 - 12))
    phi = np.deg2rad(43.0)
    cos_z = np.sin(delta) * np.sin(phi) + np.cos(delta) * np.cos(phi) * np.cos(omega)
    assert pos["zenith"] == pytest.approx(np.rad2deg(np.arccos(cos_z)), abs=0.05)
    assert 90 < pos["azimuth"] < 180


def test_duffie_beckman_within_its_accuracy_of_spa_over_a_year() -> None:
    # Cooper's declination is good to ~1 deg and the EoT to ~1 min (0.25 deg):
    # seed 001 finds the algorithms differ by far less than its 100 mrad drift.
    times = pd.date_range("2024-01-01", "2025-01-01", freq="20min", inclusive="left", tz="UTC")
    db = solar_position(times, 16.28875, -95.240871, method="duffie-beckman")
    ref = pvlib.solarposition.spa_python(times, 16.28875, -95.240871)
    day = ref["elevation"] > 0
    sep = angular_separation(db["zenith"], db["azimuth"], ref["zenith"], ref["azimuth"])[day]
    assert np.max(sep) < MAX_DB_SEP_DEG
    assert MEAN_DB_SEP_DEG[0] < np.mean(sep) < MEAN_DB_SEP_DEG[1]


@pytest.mark.parametrize(("latitude", "day"), [(90.0, "2024-06-21"), (-90.0, "2024-12-21")])
def test_duffie_beckman_at_a_pole_follows_the_sun_round(latitude: float, day: str) -> None:
    """At a pole eq. 4's cos(latitude) is zero: the azimuth read 180° at every hour and the
    tracker never moved (a tester's finding). Now within 1° of pvlib's SPA round the day."""
    times = pd.date_range(f"{day}T00:00Z", periods=24, freq="1h")
    db = solar_position(times, latitude, 0.0, method="duffie-beckman")["azimuth"].to_numpy()
    ref = pvlib.solarposition.get_solarposition(times, latitude, 0.0)["azimuth"].to_numpy()
    diff = np.abs((db - ref + 180.0) % 360.0 - 180.0)
    assert diff.max() < 1.0, diff


def test_pvlib_in_the_range_its_spa_internals_are_tested_on() -> None:
    # sim.sun calls undocumented pvlib.spa functions: the installed pvlib must be in
    # the range pyproject.toml pins, and every function must still be there.
    from importlib.metadata import requires, version

    from packaging.requirements import Requirement

    pin = next(Requirement(r) for r in requires("heliotwin") or [] if r.startswith("pvlib"))
    assert pin.specifier, "pvlib must be pinned to a tested range"
    assert version("pvlib") in pin.specifier
    assert any(s.operator in ("<", "<=", "~=", "==") for s in pin.specifier), "no upper bound"
    missing = [name for name in PVLIB_SPA_INTERNALS if not callable(getattr(pvlib.spa, name,
                                                                            None))]
    assert not missing


def test_misuse_raises() -> None:
    with pytest.raises(ValueError, match="timezone-aware"):
        solar_position(pd.Timestamp("2024-01-01 12:00"), 0.0, 0.0)
    with pytest.raises(ValueError, match="spa, duffie-beckman"):
        solar_position(SPA_TIME, 0.0, 0.0, method="grena")
