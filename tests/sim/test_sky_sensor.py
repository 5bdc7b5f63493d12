"""The fixed array as a sky sensor (sim/sky_sensor.py) on held-out realistic days.

The days come from tests/sim/realistic_sky.py: a two-state cloud process on the clear
sky (no decomposition model), varying air temperature and wind, both arrays through the
twin, 1 % logger noise. Thresholds were set on seeds 1–3; these are seeds 11–14.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sim import pv, sky_sensor
from sim.sites import load_site
from tests.sim.realistic_sky import logger_days

SITE = load_site("tehuantepec")
FIRST = pd.Timestamp("2026-05-10", tz=SITE.timezone)
DAYS = 6


@pytest.fixture(scope="module", params=[11, 12, 13, 14])
def held_out(request):
    d = logger_days(SITE, FIRST, DAYS, seed=request.param)
    e = sky_sensor.weather_aware_twin(SITE, FIRST, FIRST + pd.Timedelta(days=DAYS),
                                      d.fixed_power_w)
    return d, e


def test_expected_tracker_energy_within_the_issue_limits(held_out) -> None:
    """The issue's limits (3 % clear, 8 % cloudy) and the diagnosis's band
    (backend.diagnosis.faults.band_wh): a healthy day's truth never under it (it would read
    as an underperformance), and above it on one day of the 24 (seed 13's last, overcast,
    −5.5 %: a clear gap at dusk while the sun grazed the plane, blind to it,
    sim.sky_sensor._unseen_beam; −2.0 % before, when the plane was trusted there)."""
    from backend.diagnosis.faults import band_uncertainty, band_wh

    d, e = held_out
    above = 0
    for k in range(DAYS):
        sl = slice(k * 1440, (k + 1) * 1440)
        truth = d.healthy_tracker_power_w[sl].sum()
        expected = e["tracker_power_w"].to_numpy()[sl].sum()
        limit = 0.03 if d.kinds[k] == "clear" else 0.08
        assert abs(expected / truth - 1) < limit, (k, d.kinds[k], expected / truth)
        alt = e["tracker_power_alt_w"].to_numpy()[sl].sum()
        lo, hi = band_wh(expected, alt, band_uncertainty(e.iloc[sl]))
        assert lo <= truth, (k, d.kinds[k], truth / lo)
        above += truth > hi
        if d.kinds[k] == "clear":
            fixed = d.fixed_power_w[sl].sum()
            gain_true = 100 * (truth / fixed - 1)
            gain_exp = 100 * (expected / e["fixed_power_w"].to_numpy()[sl].sum() - 1)
            assert abs(gain_exp - gain_true) < 3.0
    assert above <= 1


def test_inversion_reproduces_the_fixed_array_it_came_from(held_out) -> None:
    """Closure: the fixed array's twin power under the reconstructed sky ≈ its readings."""
    d, e = held_out
    for k in range(DAYS):
        sl = slice(k * 1440, (k + 1) * 1440)
        ratio = e["fixed_power_w"].to_numpy()[sl].sum() / d.fixed_power_w[sl].sum()
        assert abs(ratio - 1) < 0.01  # held-out max 0.33 %, tuning seeds 1–3 0.41 %


def test_invert_poa_recovers_the_model_irradiance_and_flags_ill_posed_minutes() -> None:
    times = pd.date_range(FIRST.tz_convert("UTC") + pd.Timedelta(hours=13), periods=300,
                          freq="60s")
    clear = sky_sensor.fixed_clear_sky(SITE, times)
    fixed = SITE.arrays["fixed"]
    g = np.linspace(50, 1000, times.size)
    # forward: the twin's model with the clear sky's beam share — the inversion's own model
    # is checked for its root only; accuracy on independent data is the held-out test above
    t_cell = pv.cell_temperature(g, 27.0, 1.0, fixed.temperature_model)
    p = pv.array_mpp(g, t_cell, fixed)["power_w"]
    p[10] = np.nan
    p[20:27] = p[20]
    p[40] = 0.0
    p[50] = 5 * p[50]
    inv = sky_sensor.invert_poa(p, clear.assign(beam_clear=0.0), fixed, 27.0, 1.0)
    flags = inv["flag"].to_numpy()
    assert flags[10] == sky_sensor.FLAGS["missing"]
    assert (flags[20:27] == sky_sensor.FLAGS["stale"]).all()
    assert flags[40] == sky_sensor.FLAGS["zero"]
    assert flags[50] == sky_sensor.FLAGS["above_clear_sky"]
    ok = flags == 0
    # the bisection's midpoint: within half its last interval
    half_step = sky_sensor.G_MAX / 2 ** (sky_sensor._BISECTIONS + 1)
    assert np.abs(inv["poa_global"].to_numpy()[ok] - g[ok]).max() < half_step + 1e-9
    assert np.isnan(inv["poa_global"].to_numpy()[~ok]).all()


def test_decompose_rejects_unknown_models() -> None:
    times = pd.date_range("2026-05-10T18:00Z", periods=3, freq="60s")
    clear = sky_sensor.fixed_clear_sky(SITE, times)
    with pytest.raises(ValueError, match="model"):
        sky_sensor.decompose(np.full(3, 500.0), clear, SITE, "perez")


def _day_sources(e: pd.DataFrame) -> list[str]:
    src = e["sky_source"].to_numpy()
    return [pd.Series(src[k * 1440:(k + 1) * 1440]).mode()[0] for k in range(len(e) // 1440)]


def test_a_pyranometer_is_the_sky_where_the_fixed_array_gives_none() -> None:
    """A GHI pyranometer (±2 % gain, 1 % noise) and a thermometer beside the arrays,
    held-out seed 15, the fixed array's logger down on days 0, 2 and 3: those days take
    their sky from the pyranometer, through DIRINT on the horizontal plane, except day 2,
    which it covers under half of (off from 09:00 local: the clear sky); day 1, with the
    fixed array's power, is the fixed array's — it comes before a pyranometer."""
    d = logger_days(SITE, FIRST, 4, seed=15)
    sensors = d.sensors("ghi_w_m2", "temp_air_c")
    sensors.iloc[2 * 1440 + 9 * 60:3 * 1440, 0] = np.nan  # day 2: off from 09:00 local
    fixed = d.fixed_power_w.copy()
    for k in (0, 2, 3):
        fixed[k * 1440:(k + 1) * 1440] = np.nan
    e = sky_sensor.weather_aware_twin(SITE, FIRST, FIRST + pd.Timedelta(days=4), fixed,
                                      sensors=sensors)
    assert _day_sources(e) == ["sensor_ghi", "fixed_array", "clear_sky", "sensor_ghi"]
    for k in (0, 1, 3):
        sl = slice(k * 1440, (k + 1) * 1440)
        ratio = e["tracker_power_w"].to_numpy()[sl].sum() / d.healthy_tracker_power_w[sl].sum()
        # development seeds 1–9, 54 days: at most 2.6 % off (the instrument's ±2 % gain)
        assert abs(ratio - 1) < 0.03, (k, d.kinds[k], ratio)


def test_a_cell_on_the_fixed_plane_comes_before_a_pyranometer_and_its_faults_are_flagged(
        ) -> None:
    d = logger_days(SITE, FIRST, 2, seed=16)
    sensors = d.sensors("ghi_w_m2", "fixed_poa_w_m2")
    frozen = slice(11 * 60, 13 * 60)  # day 1, 11:00–13:00 local: the cell's logger froze
    sensors.iloc[frozen, 1] = 512.0
    e = sky_sensor.weather_aware_twin(SITE, FIRST, FIRST + pd.Timedelta(days=2),
                                      d.fixed_power_w, sensors=sensors)
    assert _day_sources(e) == ["sensor_poa", "sensor_poa"]
    flag = e["flag"].to_numpy()[frozen]
    assert ((flag & sky_sensor.FLAGS["stale"]) > 0).all()
    assert not e["valid"].to_numpy()[frozen].any()
    for k in range(2):
        sl = slice(k * 1440, (k + 1) * 1440)
        ratio = e["tracker_power_w"].to_numpy()[sl].sum() / d.healthy_tracker_power_w[sl].sum()
        # partly cloudy days, development max 3.1 %; since the beam behind or grazing the
        # plane is capped by the minutes around, day 1 of this seed read 3.5 % low (1.0 %
        # before): its dawn's clear gaps are unseen; since that beam is the one the seen
        # minutes make likely (sky_sensor._unseen_beam), 5.7 % low
        assert abs(ratio - 1) < 0.06, (k, d.kinds[k], ratio)


@pytest.mark.parametrize("cadence_min", [1, 15])
def test_a_coarse_loggers_held_values_are_not_a_frozen_logger(cadence_min: int) -> None:
    """The fixed array's power in 10 W steps (a meter reporting 0.01 kW), every minute or
    every 15 minutes (interpolated between readings, as the service's minute grid is): its
    held values are the resolution, not a frozen logger. Before, these two days had 330 and
    155 minutes flagged stale at 1 minute, 125 and 63 at 15 (two equal readings made a
    stale run); now none, and the expected tracker energy is within 1 % of the
    full-resolution logger's at 1 minute (measured +0.1 %, −0.4 %). Where the flags took
    more than half a day's minutes the day fell back to the clear sky (50 W steps; 10 W on
    other seeds read +1.5 to +4.6 % on cloudy days). Frozen loggers are still flagged
    (above)."""
    d = logger_days(SITE, FIRST, 2, seed=31)  # overcast, then clear
    end = FIRST + pd.Timedelta(days=2)
    full = sky_sensor.weather_aware_twin(SITE, FIRST, end, d.fixed_power_w)
    p = np.round(d.fixed_power_w / 10.0) * 10.0
    t = np.arange(p.size)
    read = t % cadence_min == 0
    p = np.interp(t, t[read], p[read])
    e = sky_sensor.weather_aware_twin(SITE, FIRST, end, p)
    assert not ((e["flag"].to_numpy() & sky_sensor.FLAGS["stale"]) > 0).any()
    for k in range(2):
        sl = slice(k * 1440, (k + 1) * 1440)
        assert sky_sensor.main_sky_source(e.iloc[sl]) == "fixed_array"
        got, ref = (x["tracker_power_w"].to_numpy()[sl].sum() for x in (e, full))
        if cadence_min == 1:
            assert abs(got / ref - 1) < 0.01, (k, d.kinds[k], got / ref)


def test_a_dark_winter_day_far_north_is_a_measured_sky_and_a_dead_array_is_not() -> None:
    """Reykjavík (64.1° N), 1 December, a fixed plane at 60°: its clear-sky POA peaks at
    357 W m⁻², so "zero" as 0.5 % of the rating (4.1 W of 820 W) was 1.5 % of the clear
    sky, and a dark overcast day at 1.5 % of it was refused minute by minute — the day's sky
    fell back to the clear sky and the diagnosis called it sky_unusable, "a tripped breaker"
    (a tester's finding). Zero is now 0.5 % of what the array makes under the clear sky;
    the measurable minutes are those with the sun at 2° or more (sky_sensor.measurable)."""
    import dataclasses

    from sim import twin

    base = load_site("tehuantepec")
    site = dataclasses.replace(base, latitude=64.13, longitude=-21.9, altitude=20.0,
                               timezone="Atlantic/Reykjavik")
    site = dataclasses.replace(site, arrays={**site.arrays, "fixed": dataclasses.replace(
        site.arrays["fixed"], surface_tilt=60.0, surface_azimuth=180.0)})
    t0 = pd.Timestamp("2024-12-01", tz=site.timezone)
    t1 = t0 + pd.Timedelta(days=1)
    clear_w = twin.simulate(site, t0, t1).series["fixed_power_w"].to_numpy()
    dark = sky_sensor.weather_aware_twin(site, t0, t1, 0.015 * clear_w)
    assert sky_sensor.main_sky_source(dark) == "fixed_array"
    assert not ((dark["flag"].to_numpy().astype(int) & sky_sensor.FLAGS["zero"]) > 0).any()
    dead = sky_sensor.weather_aware_twin(site, t0, t1, np.zeros_like(clear_w))
    assert sky_sensor.main_sky_source(dead) == "clear_sky"
    zero = (dead["flag"].to_numpy().astype(int) & sky_sensor.FLAGS["zero"]) > 0
    assert zero.sum() > 0.5 * sky_sensor.measurable(dead).sum()


def test_a_back_of_module_sensor_sets_the_air_the_arrays_cells_are_modelled_in() -> None:
    """The fixed array's back-of-module temperature (``fixed_temp_module_c``), made by pvlib's
    SAPM module model (``sapm_module``) at the POA sensor's irradiance in air at 5 °C where
    the site's default is 25 °C: the air the twin models both arrays' cells in is 5 °C
    wherever the sensors read (sim.sky_sensor.module_air_temperature), and the arrays'
    expected energy rises by the cells' 20 °C less (the KD205GX-LP's −0.46 %/°C of its rating
    at the maximum power point, on cells near 50 °C: 0.977 / 0.885, about 10.4 %; 10.7 and
    10.9 % measured)."""
    from pvlib import temperature

    p = temperature.TEMPERATURE_MODEL_PARAMETERS["sapm"]["open_rack_glass_polymer"]
    d = logger_days(SITE, FIRST, 1, seed=17, kinds=["clear"])
    plain = d.sensors("fixed_poa_w_m2")
    sensors = plain.assign(fixed_temp_module_c=temperature.sapm_module(
        plain["fixed_poa_w_m2"].to_numpy(), 5.0, SITE.wind_speed, p["a"], p["b"]))
    end = FIRST + pd.Timedelta(days=1)
    e = sky_sensor.weather_aware_twin(SITE, FIRST, end, d.fixed_power_w, sensors=sensors)
    base = sky_sensor.weather_aware_twin(SITE, FIRST, end, d.fixed_power_w, sensors=plain)
    read = np.isfinite(sensors["fixed_poa_w_m2"].to_numpy())
    assert read.sum() > 1000
    np.testing.assert_allclose(e["temp_air"].to_numpy()[read], 5.0, atol=1e-9)
    np.testing.assert_allclose(base["temp_air"].to_numpy(), SITE.temp_air)
    for array in ("tracker", "fixed"):
        gain = e[f"{array}_power_w"].sum() / base[f"{array}_power_w"].sum()
        assert 1.10 < gain < 1.115, (array, gain)


def test_losses_left_out_of_the_config_cancel_on_a_clear_day_only() -> None:
    """docs/sites.md, "An array's losses": both arrays 15 % down (their logged power × 0.85),
    the sky read from the fixed array's power. With the losses in the config (``dc_loss_pct``
    15 on both) the tracker's expectation is the lossy truth. Without them the sky reads
    15 % dimmer: on a clear day the ideal tracker under it lands on the same expectation
    (0.4 % under), but on a partly cloudy day the dimmer sky is split into less beam and the
    expectation falls 11.1 % (seeds 18–21: clear −0.4…+0.9 %, partly cloudy −1.4…−11.1 %,
    overcast −0.2…−2.7 %) — a tracker's loss of that size would hide there."""
    import dataclasses

    d = logger_days(SITE, FIRST, 2, seed=18, kinds=["clear", "partly"])
    lossy = dataclasses.replace(SITE, arrays={name: dataclasses.replace(a, dc_loss_pct=15.0)
                                              for name, a in SITE.arrays.items()})
    end = FIRST + pd.Timedelta(days=2)
    told = sky_sensor.weather_aware_twin(lossy, FIRST, end, 0.85 * d.fixed_power_w)
    untold = sky_sensor.weather_aware_twin(SITE, FIRST, end, 0.85 * d.fixed_power_w)
    ratio = []
    for k in range(2):
        sl = slice(k * 1440, (k + 1) * 1440)
        truth = 0.85 * d.healthy_tracker_power_w[sl].sum()
        a = told["tracker_power_w"].to_numpy()[sl].sum()
        assert abs(a / truth - 1) < 0.015, (k, a / truth)  # 0.2 % and 1.1 % measured
        ratio.append(untold["tracker_power_w"].to_numpy()[sl].sum() / a)
    assert abs(ratio[0] - 1) < 0.006 and 0.88 < ratio[1] < 0.90, ratio
