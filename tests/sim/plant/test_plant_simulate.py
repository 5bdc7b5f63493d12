"""A plant day: shade statistics against twoaxistracking on pvlib's own sun and clear sky."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from plant_reference import twoaxistracking_fractions

from sim.plant.layout import load_plant
from sim.plant.simulate import local_day, simulate_plant, sky_conditions

PLANT = load_plant("penarroya")


def test_winter_day_shade_statistics_match_an_independent_computation() -> None:
    import pvlib

    start = pd.Timestamp("2021-12-21", tz="Europe/Madrid")
    end = start + pd.Timedelta(days=1)
    result = simulate_plant(PLANT, start, end, step_s=600, strategy="sun")
    s = result.summary()
    times = pd.date_range(start, end, freq="600s", inclusive="left")
    loc = pvlib.location.Location(PLANT.latitude, PLANT.longitude, altitude=PLANT.altitude)
    sp = loc.get_solarposition(times)
    day = sp["apparent_elevation"].to_numpy() > 0
    az = sp["azimuth"].to_numpy()[day]
    el = sp["apparent_elevation"].to_numpy()[day]
    frac = twoaxistracking_fractions(PLANT.positions, az, el, 12.0, 5.0)
    dni = loc.get_clearsky(times, solar_position=sp)["dni"].to_numpy()[day]
    assert s["daylight_steps"] == int(day.sum())
    assert s["fraction_of_daylight_any_shaded"] == pytest.approx(
        float((frac > 0).any(axis=1).mean()), abs=1e-9)
    dni_w = float(np.sum(dni * frac.mean(axis=1)) / np.sum(dni))
    assert s["dni_weighted_shaded_fraction"] == pytest.approx(dni_w, rel=2e-3)
    assert 0 < s["shading_loss_area_pct"] < s["shading_loss_electrical_pct"] < 20
    assert s["plant_energy_wh"] < s["plant_energy_area_model_wh"] < s["plant_energy_unshaded_wh"]


def test_summer_day_nobody_shaded_and_tracker_beats_fixed() -> None:
    start = pd.Timestamp("2021-06-21", tz="Europe/Madrid")
    s = simulate_plant(PLANT, start, start + pd.Timedelta(days=1), step_s=900).summary()
    assert s["fraction_of_daylight_any_shaded"] < 0.2
    assert s["gain_vs_fixed_pct"] > 20


def test_tmy3_weather_from_a_distant_station_and_bad_input() -> None:
    """pvlib's TMY3 (Greensboro NC) laid on Peñarroya by the twin's rule: only the state of
    the sky crosses the ocean, so no beam exceeds what the plant's own sun allows."""
    from sim.sky import pvlib_tmy3_path, read_typical_year, typical_year_at_site

    weather, meta = read_typical_year(pvlib_tmy3_path(), "tmy3")
    start = pd.Timestamp("2021-01-01", tz="Europe/Madrid")
    end = start + pd.Timedelta(days=2)
    w = typical_year_at_site(weather, meta["utc_offset_h"], start, end,
                             (meta["latitude"], meta["longitude"], meta["altitude"]),
                             (PLANT.latitude, PLANT.longitude, PLANT.altitude))
    assert w.index[0] <= start and w.index[-1] >= end
    assert w["dni"].max() < 1100.0
    s = simulate_plant(PLANT, start, end, step_s=1800, weather=w).summary()
    assert s["sky"] == "weather" and s["plant_energy_wh"] > 0
    with pytest.raises(ValueError, match="timezone-aware"):
        simulate_plant(PLANT, pd.Timestamp("2021-01-01"), pd.Timestamp("2021-01-02"))
    with pytest.raises(ValueError, match="step_s must be positive"):
        simulate_plant(PLANT, start, end, step_s=0)


def test_chunks_of_time_change_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    """The run is done in chunks that share one candidate table (sim.plant.shading.BinTable):
    chunks of 50 steps give the summary of a single chunk."""
    import sim.plant.simulate as simulate

    start = pd.Timestamp("2021-12-19", tz="Europe/Madrid")
    end = start + pd.Timedelta(days=3)
    whole = simulate_plant(PLANT, start, end, step_s=600, strategy="sun")
    monkeypatch.setattr(simulate, "_CHUNK", 50)
    parts = simulate_plant(PLANT, start, end, step_s=600, strategy="sun")
    assert whole.any_shaded_steps > 0
    a, b = whole.summary(), parts.summary()
    assert a.keys() == b.keys()
    for k, v in a.items():
        assert b[k] == (pytest.approx(v, rel=1e-12) if isinstance(v, float) else v), k
    pd.testing.assert_frame_equal(whole.series, parts.series, rtol=1e-12)


def test_cli_weather_from_a_distant_station_needs_force(capsys: pytest.CaptureFixture[str]
                                                        ) -> None:
    """``plant simulate --tmy3`` follows the twin's station rule (check_station): Greensboro
    is 6,000+ km from Peñarroya — refused naming --force, then run with it, the summary
    naming the station and its distance."""
    import json

    from backend import cli
    from sim.sky import pvlib_tmy3_path

    argv = ["plant", "simulate", "--plant", "penarroya", "--start", "2021-06-01",
            "--end", "2021-06-02", "--step-s", "3600", "--tmy3", str(pvlib_tmy3_path()),
            "--json", "--no-progress"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "--tmy3:" in err and "km from plant penarroya" in err and "--force" in err
    assert cli.main([*argv, "--force"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["weather_station"]["forced"] is True
    assert summary["weather_station"]["distance_km"] > 6000
    assert summary["sky"] == "weather" and summary["plant_energy_wh"] > 0


@pytest.mark.parametrize(("date", "zone", "hours"), [
    ("2024-10-27", "Europe/Madrid", 25),       # autumn: 02:00+02 → 02:00+01 (hour repeated)
    ("2024-03-31", "Europe/Madrid", 23),       # spring: 02:00+01 → 03:00+02
    ("2024-06-21", "Europe/Madrid", 24),
    ("2024-04-06", "America/Santiago", 25),    # back at midnight: 24:00-03 → 23:00-04
    ("2024-09-08", "America/Santiago", 23),    # its midnight does not exist (00:00 → 01:00)
])
def test_a_local_day_runs_midnight_to_midnight(date: str, zone: str, hours: int) -> None:
    """``local_day``: the date's midnight to the next date's, as zoneinfo counts them (not
    midnight + 24 h: on the autumn day that is 23:00 of the same date)."""
    import datetime as dt
    from zoneinfo import ZoneInfo

    day = dt.date.fromisoformat(date)

    def midnight_utc(d: dt.date) -> dt.datetime:
        return dt.datetime(d.year, d.month, d.day, tzinfo=ZoneInfo(zone)).astimezone(dt.UTC)

    start, end = local_day(day, zone)
    assert start == midnight_utc(day)
    assert end == midnight_utc(day + dt.timedelta(days=1))
    assert (end - start) == pd.Timedelta(hours=hours)
    assert end.tz_convert(zone).date() == day + dt.timedelta(days=1)


def test_a_polar_night_has_no_dni_weighted_fraction() -> None:
    """At 69.6° N on 21 December the sun stays below the horizon: no daylight step, no beam,
    so every fraction of the summary is None (it was NaN for the DNI-weighted one, which no
    JSON holds) and the summary is strict JSON."""
    import dataclasses
    import json

    polar = dataclasses.replace(PLANT, plant_id="polar", latitude=69.6, longitude=18.9,
                                timezone="Europe/Oslo")
    start = pd.Timestamp("2024-12-21", tz="Europe/Oslo")
    s = simulate_plant(polar, start, start + pd.Timedelta(days=1), step_s=1800).summary()
    assert s["daylight_steps"] == 0 and s["plant_energy_wh"] == 0
    for key in ("fraction_of_daylight_any_shaded", "dni_weighted_shaded_fraction",
                "mean_shaded_fraction", "shading_loss_electrical_pct", "gain_vs_fixed_pct"):
        assert s[key] is None, key
    json.dumps(s, allow_nan=False)


def test_the_plant_sun_is_refracted_at_the_plant_s_pressure_and_temperature() -> None:
    """The position server's sun near the horizon at a plant 2,400 m up: pvlib's own rule
    (pressure from the altitude, ``alt2pres``; the air temperature given) is the reference.
    Sea level at 12 °C had been taken: 1.456° served where 1.360° was due at Atacama."""
    from dataclasses import replace

    import pvlib

    plant = replace(PLANT, latitude=-23.5, longitude=-70.0, altitude=2400.0, temp_air=20.0)
    times = pd.date_range("2021-12-21T10:00Z", periods=4, freq="2min")
    ref = pvlib.solarposition.get_solarposition(times, -23.5, -70.0, altitude=2400.0,
                                                temperature=20.0)
    sky = sky_conditions(plant, times)
    assert ref["apparent_elevation"].iloc[0] == pytest.approx(1.3595, abs=1e-3)  # near 0°
    np.testing.assert_allclose(sky["apparent_elevation"], ref["apparent_elevation"], atol=1e-3)


def _greensboro_in_the_wrong_zone(tmp_path: Path) -> Path:
    """pvlib's Greensboro TMY3 with its header's UTC offset −4 for −5: each hour placed an
    hour early against the sun."""
    from sim.sky import pvlib_tmy3_path

    lines = pvlib_tmy3_path().read_text().splitlines(keepends=True)
    assert lines[0].startswith('723170,"GREENSBORO PIEDMONT TRIAD INT",NC,-5.0,')
    wrong = tmp_path / "utc-4.csv"
    wrong.write_text(lines[0].replace(",-5.0,", ",-4.0,") + "".join(lines[1:]))
    return wrong


def test_cli_weather_read_in_the_wrong_zone_is_warned(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``plant simulate --tmy3`` runs the twin's clock check (sim.weather_clock): pvlib's
    Greensboro TMY3 at a plant on the station reads within 5 min of the sun, no warning;
    the same file whose header says UTC−4 instead of −5 (each hour placed an hour early
    against the sun: a shift built here, −60 min from the right file's) is warned of, in
    the JSON and as a ``warning:`` line of the text. It ran silently before."""
    import json

    from backend import cli
    from sim.paths import default_plants_dir
    from sim.sky import pvlib_tmy3_path

    plant = json.loads((default_plants_dir() / "penarroya.json").read_text())
    plant.update(plant_id="greensboro", latitude_deg=36.1, longitude_deg=-79.95,
                 altitude_m=273.0, timezone="America/New_York")
    (tmp_path / "greensboro.json").write_text(json.dumps(plant))
    wrong = _greensboro_in_the_wrong_zone(tmp_path)
    argv = ["plant", "simulate", "--plant", "greensboro", "--plants-dir", str(tmp_path),
            "--start", "2021-06-01", "--end", "2021-06-15", "--step-s", "1800",
            "--no-progress"]
    assert cli.main([*argv, "--tmy3", str(pvlib_tmy3_path()), "--json"]) == 0
    right = json.loads(capsys.readouterr().out)
    assert abs(right["weather_shift_min"]) <= 5 and right["weather_warning"] is None, right
    assert cli.main([*argv, "--tmy3", str(wrong), "--json"]) == 0
    misread = json.loads(capsys.readouterr().out)
    shift = misread["weather_shift_min"]  # measured −65 (the right file's −5, an hour early)
    assert shift - right["weather_shift_min"] == pytest.approx(-60, abs=5), misread
    assert f"runs {-shift:.0f} min early" in misread["weather_warning"], misread
    assert cli.main([*argv, "--tmy3", str(wrong)]) == 0
    text = capsys.readouterr().out
    assert f"\nwarning: the weather's irradiance runs {-shift:.0f} min early" in text, text


def test_a_sweep_on_weather_read_in_the_wrong_zone_is_warned(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``plant sweep --tmy3`` runs the same check (one case, in process): the right file
    −5 min and no warning, the one an hour early −65 and warned — in the JSON, and as a
    ``warning:`` line on stderr beside the CSV."""
    import json

    from backend import cli
    from sim.sky import pvlib_tmy3_path

    argv = ["plant", "sweep", "--collector-m", "12x5", "--lat", "36.1", "--lon", "-79.95",
            "--layouts", "square", "--gcr", "0.25", "--start", "2021-06-01", "--end",
            "2021-06-15", "--step-s", "1800", "--no-progress"]
    assert cli.main([*argv, "--tmy3", str(pvlib_tmy3_path()), "--json"]) == 0
    right = json.loads(capsys.readouterr().out)
    assert abs(right["weather_shift_min"]) <= 5 and right["weather_warning"] is None, right
    wrong = _greensboro_in_the_wrong_zone(tmp_path)
    assert cli.main([*argv, "--tmy3", str(wrong), "--json"]) == 0
    misread = json.loads(capsys.readouterr().out)
    shift = misread["weather_shift_min"]
    assert shift - right["weather_shift_min"] == pytest.approx(-60, abs=5), misread
    assert cli.main([*argv, "--tmy3", str(wrong), "--csv"]) == 0
    out = capsys.readouterr()
    assert out.out.startswith("layout,gcr,") and len(out.out.splitlines()) == 2, out.out
    assert f"warning: the weather's irradiance runs {-shift:.0f} min early" in out.err, out.err
