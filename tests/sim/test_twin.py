"""The twin: day energies vs an independent pvlib ModelChain, physical consistency, TMY3."""

import numpy as np
import pandas as pd
import pytest
from pvlib_reference import modelchain_dc_power

from sim.sites import load_site, site_from_dict
from sim.sky import pvlib_tmy3_path, read_tmy3
from sim.twin import SERIES_COLUMNS, simulate

TZ = "America/Mexico_City"


@pytest.fixture(scope="module")
def site():
    return load_site("tehuantepec")


@pytest.mark.parametrize("day", ["2024-03-15", "2024-04-25", "2024-12-21", "2024-06-21"])
def test_day_energy_agrees_with_pvlib_modelchain(site, day) -> None:
    start = pd.Timestamp(day, tz=TZ)
    result = simulate(site, start, start + pd.Timedelta(days=1))
    ref = modelchain_dc_power(
        result.series.index, temp_air=site.temp_air, wind_speed=site.wind_speed
    )
    ref_wh = ref.sum() / 60.0
    s = result.summary()
    assert s["tracker_energy_wh"] == pytest.approx(ref_wh["tracker"], rel=0.02)
    assert s["fixed_energy_wh"] == pytest.approx(ref_wh["fixed"], rel=0.02)
    ref_gain = 100 * (ref_wh["tracker"] / ref_wh["fixed"] - 1)
    assert s["gain_pct"] == pytest.approx(ref_gain, abs=1.0)
    assert s["tracker_peak_w"] == pytest.approx(ref["tracker"].max(), rel=0.02)


def test_physically_consistent(site) -> None:
    start = pd.Timestamp("2024-03-14", tz=TZ)
    result = simulate(site, start, start + pd.Timedelta(days=3))
    s = result.series
    assert list(s.columns) == SERIES_COLUMNS
    assert len(s) == 3 * 1440 and str(s.index.tz) == "UTC"
    day = s["apparent_elevation"] > 0
    night = ~day
    assert (s.loc[night, ["tracker_power_w", "fixed_power_w"]] == 0).all().all()
    # the ideal tracker faces the sun: AOI ~ 0 whenever the sun is up
    assert s.loc[day, "tracker_aoi"].max() < 1e-3
    assert (s.loc[day, "fixed_aoi"] >= s.loc[day, "tracker_aoi"] - 1e-9).all()
    # its beam is maximal, so it never makes less power than the fixed array
    assert (s["tracker_power_w"] >= s["fixed_power_w"] - 1.0).all()
    # P = I V, power below the 4 x 205 W STC rating at these cell temperatures
    assert np.allclose(s["tracker_power_w"], s["tracker_current_a"] * s["tracker_voltage_v"])
    assert s["tracker_power_w"].max() < 4 * 205
    assert (s.loc[day, "tracker_temp_cell"] >= site.temp_air).all()
    # on clear days the gain of two-axis tracking at 16 N lies in the 20-45 % the
    # literature reports for clear skies (seed 000, introduction)
    daily = s[["tracker_power_w", "fixed_power_w"]].tz_convert(TZ).resample("1D").sum()
    gains = 100 * (daily["tracker_power_w"] / daily["fixed_power_w"] - 1)
    assert ((gains > 20) & (gains < 45)).all()
    # the tracker's joints stay in their limits and the azimuth sweep is continuous by day
    assert (
        s["azimuth_joint_deg"]
        .between(site.tracker.azimuth_min_deg, site.tracker.azimuth_max_deg)
        .all()
    )
    steps = np.abs(np.diff(s.loc[day, "azimuth_joint_deg"].to_numpy()))
    assert np.sort(steps)[-3] < 5  # only the jumps between days are large


@pytest.mark.parametrize("first_day", ["2024-06-18", "2024-05-01", "2024-08-04"])
def test_azimuth_joint_sweeps_continuously_each_day(site, first_day) -> None:
    # June: the noon sun is north of the zenith at 16 N, the sweep passes through 0;
    # early May / early August: the sun passes (nearly) through the zenith, the only
    # place an azimuth-elevation mount must swing fast (its singularity).
    start = pd.Timestamp(first_day, tz=TZ)
    s = simulate(site, start, start + pd.Timedelta(days=7)).series.tz_convert(TZ)
    day = s[s["apparent_elevation"] > 0]
    same_day = day.index.normalize()[1:] == day.index.normalize()[:-1]
    steps = np.abs(np.diff(day["azimuth_joint_deg"].to_numpy()))[same_day]
    high_sun = day["apparent_elevation"].to_numpy()[1:][same_day] > 88.0
    assert np.all(steps[~high_sun] < 5.0)
    assert day["azimuth_joint_deg"].between(-90, 450).all()


def test_one_step_and_errors(site) -> None:
    t = pd.Timestamp("2024-03-15T12:00:00-06:00")
    r = simulate(site, t, t + pd.Timedelta(seconds=60))
    assert len(r.series) == 1 and r.series["tracker_power_w"].iloc[0] > 500
    with pytest.raises(ValueError, match="ideal"):
        simulate(site, t, t + pd.Timedelta(hours=1), controller="pid")
    with pytest.raises(ValueError, match="after start"):
        simulate(site, t, t - pd.Timedelta(hours=1))
    with pytest.raises(ValueError, match="timezone-aware"):
        simulate(site, pd.Timestamp("2024-03-15"), t)
    fisheye = load_site("guadalajara_fisheye")
    with pytest.raises(ValueError, match="tracker"):
        simulate(fisheye, t, t + pd.Timedelta(hours=1))


def test_twin_on_pvlib_tmy3_weather() -> None:
    weather, meta = read_tmy3(pvlib_tmy3_path(), coerce_year=1990)
    site = site_from_dict(
        {
            "site_id": "greensboro",
            "latitude_deg": meta["latitude"],
            "longitude_deg": meta["longitude"],
            "altitude_m": meta["altitude"],
            "timezone": "America/New_York",
            "arrays": {
                "tracker": {"mount": "tracker"},
                "fixed": {"mount": "fixed", "surface_tilt_deg": 16, "surface_azimuth_deg": 180},
            },
        }
    )
    start = pd.Timestamp("1990-05-01 00:30", tz="UTC")
    result = simulate(site, start, start + pd.Timedelta(days=31), step_s=3600, weather=weather)
    s = result.summary()
    assert s["sky"] == "weather"
    w = weather.loc[result.series.index]
    ref = modelchain_dc_power(
        w.index, meta["latitude"], meta["longitude"], meta["altitude"], weather=w
    )
    assert s["tracker_energy_wh"] == pytest.approx(ref["tracker"].sum(), rel=0.03)
    assert s["fixed_energy_wh"] == pytest.approx(ref["fixed"].sum(), rel=0.03)
    # real (partly cloudy) weather gives a smaller gain than a clear sky
    clear = simulate(site, start, start + pd.Timedelta(days=31), step_s=3600).summary()
    assert 0 < s["gain_pct"] < clear["gain_pct"]


def test_progress_callback_reaches_one(site) -> None:
    seen: list[float] = []
    start = pd.Timestamp("2024-01-01", tz=TZ)
    simulate(site, start, start + pd.Timedelta(days=100), step_s=120, progress=seen.append)
    assert len(seen) >= 2 and seen == sorted(seen) and seen[-1] == 1.0
