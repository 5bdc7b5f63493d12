"""A plant's wind stow (sim/plant/simulate.py, the twin's rule sim/stow.py): every collector
flat in the stowed steps, unshaded on pivots at one height, its power that of a flat plane
by pvlib alone, the minutes a stow controller written step by step holds, the loss what the
plant without the stow makes more."""

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pvlib import atmosphere, irradiance, location, pvsystem, temperature

from sim.paths import default_plants_dir
from sim.plant.layout import plant_from_dict
from sim.plant.simulate import simulate_plant
from sim.sky import iam_physical
from sim.stow import WindStow

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
# a stow controller as one runs, a step at a time (not sim.stow's vector form); 15 m/s, 30 min
from test_stow import DAY, RELEASE_MIN, THRESHOLD_M_S, TZ, controller_stowed  # noqa: E402


def _plant(**tracker: float):  # type: ignore[no-untyped-def]
    """Peñarroya's 29 trackers (pivots all at z = 0) at Tehuantepec, stowing as ``tracker``."""
    d = json.loads((default_plants_dir() / "penarroya.json").read_text())
    d.update(latitude_deg=16.28875, longitude_deg=-95.240871, altitude_m=50.0, timezone=TZ)
    if tracker:
        d["tracker"] = tracker
    return plant_from_dict(d)


def _windy_day(plant) -> pd.DataFrame:  # type: ignore[no-untyped-def]
    """A clear day (pvlib's Ineichen) at 5 min, 18 m/s 09:00–10:25 and 14:00–14:55, a lone
    gust at 11:40 (past the hold: a second stow), 4 m/s elsewhere; covers the closing instant."""
    times = pd.date_range(DAY, DAY + pd.Timedelta(days=1), freq="300s")
    loc = location.Location(plant.latitude, plant.longitude, altitude=plant.altitude)
    w = loc.get_clearsky(times, model="ineichen")
    w["temp_air"] = 27.0
    hhmm = times.hour * 100 + times.minute
    w["wind_speed"] = np.where(((hhmm >= 900) & (hhmm < 1030)) | (hhmm == 1140)
                               | ((hhmm >= 1400) & (hhmm < 1500)), 18.0, 4.0)
    return w.tz_convert("UTC")


def test_a_plant_stows_flat_and_reports_what_it_cost() -> None:
    plant = _plant(stow_wind_speed_m_s=THRESHOLD_M_S, stow_release_min=RELEASE_MIN)
    assert plant.wind_stow == WindStow(THRESHOLD_M_S, RELEASE_MIN)
    w = _windy_day(plant)
    r = simulate_plant(plant, DAY, DAY + pd.Timedelta(days=1), 300.0, "backtrack", w)
    s, ser = r.summary(), r.series
    stowed = controller_stowed(ser.index, w.loc[ser.index, "wind_speed"].to_numpy())
    day = (ser["apparent_elevation"] > 0).to_numpy()
    # 09:00–10:50, 11:40–12:05, 14:00–15:20 (the hold after each last gust): 46 steps
    assert s["stow_min"] == 5 * int((stowed & day).sum()) == 230
    assert s["stow_wind_speed_m_s"] == THRESHOLD_M_S
    flat = stowed & day
    assert (ser["surface_elevation"][flat] == 90.0).all()
    assert (ser["trackers_shaded"][flat] == 0).all()  # flat at one height: no shade
    # the flat plant's power by pvlib alone: Perez POA on a horizontal plane, the physical
    # IAM on the beam, SAPM open-rack cell temperature, PVWatts DC, 29 collectors
    t = ser.index[flat]
    sp = location.Location(plant.latitude, plant.longitude, altitude=plant.altitude
                           ).get_solarposition(t, temperature=plant.temp_air)
    wx = w.loc[t]
    dni_extra = irradiance.get_extra_radiation(t)
    poa = irradiance.get_total_irradiance(
        0.0, 180.0, sp["apparent_zenith"], sp["azimuth"], wx["dni"], wx["ghi"], wx["dhi"],
        dni_extra=dni_extra, airmass=atmosphere.get_relative_airmass(sp["apparent_zenith"]),
        albedo=plant.albedo, model="perez")
    g = poa["poa_direct"] * iam_physical(sp["apparent_zenith"].to_numpy()) + poa["poa_diffuse"]
    t_cell = temperature.sapm_cell(poa["poa_global"], wx["temp_air"], wx["wind_speed"],
                                   -3.56, -0.075, 3.0)
    ref_w = plant.n_trackers * pvsystem.pvwatts_dc(g, t_cell, plant.collector.power_stc,
                                                   plant.collector.gamma_pdc)
    # measured: within 3.7e-9 (relative) at every stowed step
    np.testing.assert_allclose(ser["power_w"][flat], ref_w, rtol=1e-7)
    # the loss is what the same plant without the stow makes more
    free = simulate_plant(_plant(), DAY, DAY + pd.Timedelta(days=1), 300.0, "backtrack", w)
    fs = free.summary()
    assert fs["plant_energy_wh"] - s["plant_energy_wh"] == pytest.approx(s["stow_loss_wh"],
                                                                         abs=0.01)
    # measured: 182,465 Wh of the free plant's 2,081,287 (8.8 %)
    assert 0.08 < s["stow_loss_wh"] / fs["plant_energy_wh"] < 0.10
    assert not {"stow_min", "stow_loss_wh", "stow_wind_speed_m_s"} & set(fs)
    assert fs["fixed_energy_wh"] == s["fixed_energy_wh"]


def test_a_plant_without_wind_in_its_sky_says_null() -> None:
    plant = _plant(stow_wind_speed_m_s=THRESHOLD_M_S)
    assert plant.wind_stow == WindStow(THRESHOLD_M_S, 30.0)  # the hold's default
    w = _windy_day(plant).drop(columns=["wind_speed"])
    s = simulate_plant(plant, DAY, DAY + pd.Timedelta(hours=14), 1800.0, "sun", w).summary()
    assert s["stow_min"] is None and s["stow_loss_wh"] is None
    s = simulate_plant(plant, DAY, DAY + pd.Timedelta(hours=14), 1800.0, "sun").summary()
    assert s["stow_min"] is None and s["stow_loss_wh"] is None  # clear sky: no wind


@pytest.mark.parametrize(("tracker", "words"), [
    ({"stow_wind_speed_m_s": 0}, "tracker: field 'stow_wind_speed_m_s' must be positive"),
    ({"stow_wind_speed_m_s": 15, "stow_release_min": -1}, "'stow_release_min' = -1.0 outside"),
    ({"stow_release_min": 10}, "'stow_release_min' is only used with 'stow_wind_speed_m_s'"),
    ({"stow_wind_speed": 15}, "unknown field 'stow_wind_speed'"),
])
def test_a_plant_files_bad_stow_is_refused_naming_the_field(tracker: dict, words: str) -> None:
    with pytest.raises(ValueError, match=words):
        _plant(**tracker)
