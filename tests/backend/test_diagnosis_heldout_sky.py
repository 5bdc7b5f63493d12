"""Issue 27 held out: real 1-minute skies at stations the diagnosis was never tuned on
(tests/data/heldout-sky; tests/backend/heldout_sky.py). A healthy tracker and the fixed
array are made from the measured DNI, DHI and GHI (Perez's transposition, pvlib), and the
diagnosis' expected tracker energy from the fixed plane's POA sensor and from the fixed
array's power is held to what docs/diagnosis.md ("Held-out real skies") measured.

The miss there (Payerne, 23 June 2016, −10 % on a clear day) is held by its cause, not by
its size: the error lies in the minutes the fixed plane sees the sun from behind, where
the beam can only be guessed and is bounded by a clear sky whose climatological turbidity
puts the low sun's beam at under 0.6 of the measured one.
"""

from __future__ import annotations

import heldout_sky
import numpy as np
import pandas as pd
import pytest

STATIONS = {st.site_id: st for st in heldout_sky.STATIONS}
#: (station, day, path) → (the measured error of the expected tracker energy [%], tolerance)
MEASURED = {
    ("heldout_alamosa", "2016-01-01", "poa_sensor"): (-0.7, 0.5),
    ("heldout_tucson", "2018-10-18", "poa_sensor"): (-0.3, 0.5),
    ("heldout_tucson", "2018-10-18", "fixed_array"): (0.1, 0.5),
    ("heldout_payerne", "2016-06-16", "poa_sensor"): (-0.3, 0.5),
    ("heldout_payerne", "2016-06-16", "fixed_array"): (-0.1, 0.5),
}


def _day(site_id: str, date: str):  # noqa: ANN202
    st = STATIONS[site_id]
    site = heldout_sky.station_site(st)
    day = pd.Timestamp(date, tz=site.timezone)
    df = heldout_sky.planes(site, heldout_sky.load(st), "perez")
    return site, day, heldout_sky.logged_day(site, df, day)


@pytest.mark.parametrize("case", sorted(MEASURED))
def test_the_expected_energy_holds_a_held_out_day(case: tuple[str, str, str]) -> None:
    """Clear days at Alamosa and Tucson, an overcast one at Payerne: within the targets
    (3 %, 8 %), at the error measured, the truth inside the band."""
    site_id, date, path = case
    site, day, lg = _day(site_id, date)
    r = heldout_sky.judged(site, lg, day, path)
    err, tol = MEASURED[case]
    assert r["error_pct"] == pytest.approx(err, abs=tol), r
    assert r["inside"] == 1.0, r


def test_payerne_23_june_misses_behind_the_plane() -> None:
    """The clear 23 June 2016 at Payerne (GHI / DNI clear-sky index 1.08 / 1.28): the error
    lies in the minutes the sun is behind or grazing the 38.7° plane facing south (dawn
    and dusk in June), where the expected beam is bounded by the Ineichen clear sky, and the
    measured DNI was 1.7× that clear sky's at 10–20° of sun (pvlib's Linke turbidity 4.45);
    where the plane sees the sun, the expectation is 1 % low. A better guess of that beam
    moves the first two figures: update them with docs/diagnosis.md."""
    from pvlib.location import Location

    site, day, lg = _day("heldout_payerne", "2016-06-23")
    r = heldout_sky.judged(site, lg, day, "poa_sensor")
    assert not r["inside"], r  # −10.0 %, the truth above its band: docs/diagnosis.md
    assert r["blind_pct"] == pytest.approx(-9.0, abs=0.5), r
    assert r["seen_pct"] == pytest.approx(-1.0, abs=0.5), r
    loc = Location(site.latitude, site.longitude, altitude=site.altitude)
    sp = loc.get_solarposition(lg.times)
    cs = loc.get_clearsky(lg.times, solar_position=sp)
    low = ((sp["apparent_elevation"] >= 10) & (sp["apparent_elevation"] < 20)).to_numpy()
    ratio = lg.data["dni"].to_numpy()[low].sum() / cs["dni"].to_numpy()[low].sum()
    assert ratio == pytest.approx(1.67, abs=0.02)


def test_the_data_close_and_are_stamped_at_solar_noon() -> None:
    """The README's checks of the data: closure under 5 % on every day taken, and the clear
    symmetric days' GHI-weighted mean time within 3.5 min of solar noon."""
    for st in heldout_sky.STATIONS:
        site = heldout_sky.station_site(st)
        raw = heldout_sky.load(st)
        for date in st.days:
            start = pd.Timestamp(date, tz=site.timezone)
            d = raw[(raw.index >= start) & (raw.index < start + pd.Timedelta(days=1))]
            assert heldout_sky.closure_pct(site, d) < 5.0, (st.site_id, date)
            if (st.site_id, date) in (("heldout_payerne", "2016-06-23"),
                                      ("heldout_payerne", "2016-06-27"),
                                      ("heldout_alamosa", "2016-01-01"),
                                      ("heldout_tucson", "2018-10-18")):
                assert abs(heldout_sky.noon_offset_min(site, d)) < 3.5, (st.site_id, date)
    assert np.isclose(heldout_sky.station_site(STATIONS["heldout_payerne"]).latitude, 46.815)


def _clear_day_faults(transposition: str, offset_deg: float) -> list[tuple[str, float]]:
    """The faults named on a clear 21 June at Payerne (Ineichen by pvlib), the loggers' power
    made with the product's PV model but the truth's planes transposed by ``transposition``
    in pvlib directly, the tracker pointing ``offset_deg`` off in azimuth."""
    import warnings

    from pvlib import atmosphere, irradiance, location, solarposition

    from backend.diagnosis import faults
    from sim import pv, sky, sky_sensor

    site = heldout_sky.station_site(heldout_sky.STATIONS[0])
    start = pd.Timestamp("2016-06-21", tz=site.timezone)
    grid = pd.date_range(start.tz_convert("UTC"), periods=1440, freq="60s")
    cs = location.Location(site.latitude, site.longitude, altitude=site.altitude
                           ).get_clearsky(grid)
    sp = solarposition.get_solarposition(grid, site.latitude, site.longitude, site.altitude)
    zen, az = sp["apparent_zenith"], sp["azimuth"]
    up = (sp["apparent_elevation"] > 0).to_numpy()
    tair = np.full(grid.size, 20.0)
    power = {}
    for arr, tilt, surf_az in ((site.arrays["tracker"], zen.clip(upper=90.0),
                                (az + offset_deg) % 360.0),
                               (site.arrays["fixed"], site.arrays["fixed"].surface_tilt,
                                site.arrays["fixed"].surface_azimuth)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            p = irradiance.get_total_irradiance(
                tilt, surf_az, zen, az, cs["dni"], cs["ghi"], cs["dhi"],
                dni_extra=irradiance.get_extra_radiation(grid), albedo=arr.albedo,
                model=transposition, airmass=atmosphere.get_relative_airmass(zen))
        aoi = np.minimum(irradiance.aoi(tilt, surf_az, zen, az).to_numpy(), 90.0)
        g, b = (np.nan_to_num(p[k].to_numpy()) for k in ("poa_global", "poa_direct"))
        e = sky.effective_irradiance(b, g - b, aoi)
        tc = pv.cell_temperature(g, tair, np.full(grid.size, site.wind_speed),
                                 arr.temperature_model)
        power[arr.name] = np.where(up & (g > 0),
                                   np.nan_to_num(pv.array_mpp(e, tc, arr)["power_w"]), 0.0)
    gs = grid.as_unit("s").asi8
    fine = {"fixed_power_w": sky_sensor.readings_fine(gs, power["fixed"], gs)}
    sensors = pd.DataFrame({"temp_air_c": tair}, index=grid)
    twin = sky_sensor.weather_aware_twin(site, start, start + pd.Timedelta(days=1),
                                         power["fixed"], sensors=sensors, fine=fine)
    days = faults.features_by_day(site, start, twin, power["tracker"])
    return [(f["kind"], f["confidence"]) for f in faults.faults_over_days(days)[0]]


def test_a_healthy_day_under_another_transposition_is_no_azimuth_offset() -> None:
    """A checker's truth transposed by the isotropic sky (no circumsolar light on the
    sun-facing plane) runs 4–5 % below the twin's Hay-Davies on a clear summer day: a
    healthy tracker was named ``azimuth_offset`` 37° at 0.76, its fit at scale 1.05 — more
    than the twin gives at any pointing (``faults.AZIMUTH_OFFSET_MAX_SCALE``). A real 40°
    offset is still named, under either sky."""
    kinds = [k for k, _ in _clear_day_faults("isotropic", 0.0)]
    assert "azimuth_offset" not in kinds, kinds
    for sky_model in ("haydavies", "isotropic"):
        named = dict(_clear_day_faults(sky_model, 40.0))
        assert named.get("azimuth_offset", 0.0) >= 0.5, (sky_model, named)
