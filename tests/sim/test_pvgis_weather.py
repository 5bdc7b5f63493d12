"""PVGIS typical years (``sim.sky.read_typical_year``): real downloads at 45° N 8° E in
``tests/data/pvgis/`` (README: what the files say). Checked against pvlib's own reader of
the same files and against the sun (``sim.weather_clock.irradiance_shift``), not against
the product's reading of itself."""

from __future__ import annotations

import gzip
import io
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from sim.sky import read_typical_year, typical_year_on
from sim.weather_clock import irradiance_shift
from tests.test_cli_site import sites_env

DATA = Path(__file__).resolve().parents[1] / "data" / "pvgis"
TMY = "tmy_45.000_8.000_2005_2023"


def pvgis_text(kind: str) -> str:
    """The TMY download as PVGIS wrote it (``csv``, ``json`` or ``epw``)."""
    return gzip.decompress((DATA / f"{TMY}.{kind}.gz").read_bytes()).decode()


def pvgis_file(kind: str, folder: Path) -> Path:
    """The TMY download unpacked into ``folder``, under PVGIS's own name."""
    path = folder / f"{TMY}.{kind}"
    path.write_text(pvgis_text(kind))
    return path


def test_the_csv_json_and_epw_downloads_read_to_one_typical_year() -> None:
    years = {kind: read_typical_year(io.StringIO(pvgis_text(kind)))
             for kind in ("csv", "json", "epw")}
    csv, station = years["csv"]
    assert len(csv) == 8760 and list(csv.columns) == ["ghi", "dni", "dhi", "temp_air",
                                                      "wind_speed"]
    assert station == {"format": "pvgis", "name": "TMY", "latitude": 45.0, "longitude": 8.0,
                       "altitude": 250.0, "utc_offset_h": 0.0, "irradiance_offset_h": 0.1761}
    assert years["json"][1]["name"] == "TMY, PVGIS-SARAH3"
    assert years["epw"][1] == {**station, "name": "TMY as EPW"}  # its TZ of 1 not taken
    assert np.array_equal(years["json"][0].to_numpy(), csv.to_numpy())
    epw = years["epw"][0]  # the EPW writes the wind to 0.1 m/s
    assert np.array_equal(epw[["ghi", "dni", "dhi", "temp_air"]].to_numpy(),
                          csv[["ghi", "dni", "dhi", "temp_air"]].to_numpy())
    assert np.abs(epw["wind_speed"] - csv["wind_speed"]).max() <= 0.05 + 1e-9


def test_the_irradiance_of_instants_is_moved_to_the_hours_middles() -> None:
    """The file's G(h) is 149 W m⁻² at 09:00 + 0.1761 h UTC and 165 at 10:00 + 0.1761 h on
    1 January (its lines 28 and 29, as pvlib reads them); the hour 09:00–10:00 takes the
    line between them at 09:30, 149 + (0.5 − 0.1761) × 16. The air temperature (ERA5) is of
    the stamp itself: 3.23 and 4.27 °C, 3.75 at 09:30."""
    from pvlib import iotools

    raw, _ = iotools.read_pvgis_tmy(io.BytesIO(pvgis_text("csv").encode()), "csv")
    nine = pd.Timestamp("2018-01-01 09:00", tz="UTC")
    ten = nine + pd.Timedelta(hours=1)
    assert (raw.loc[nine, "ghi"], raw.loc[ten, "ghi"]) == (149.0, 165.0)
    weather, _ = read_typical_year(io.StringIO(pvgis_text("csv")))
    mid = weather.iloc[9]
    assert weather.index[9] == nine + pd.Timedelta(minutes=30)
    assert mid["ghi"] == pytest.approx(149.0 + (0.5 - 0.1761) * 16.0, abs=1e-9)
    assert mid["temp_air"] == pytest.approx((3.23 + 4.27) / 2, abs=1e-9)
    # the year wraps: 31 December 23:30 lies between its 23:10 and 1 January's 00:10
    last, first = raw.loc[raw.index.month == 12].iloc[-1], raw.iloc[0]
    assert weather.iloc[-1]["temp_air"] == pytest.approx(
        (last["temp_air"] + first["temp_air"]) / 2, abs=1e-9)


def _shift_min(text: str) -> float:
    """How far the year's GHI runs from the clear sky at its place in June [min]."""
    weather, st = read_typical_year(io.StringIO(text))
    start = pd.Timestamp("2024-06-01", tz="UTC")
    end = start + pd.DateOffset(months=1)
    on = typical_year_on(weather, st["utc_offset_h"], start, end)
    found = irradiance_shift(on, st["latitude"], st["longitude"], st["altitude"], start, end)
    assert found is not None and found["days"] >= 10, found
    return float(found["shift_min"])


def test_a_pvgis_epw_is_on_the_suns_time_and_read_as_any_epw_it_was_40_min_early() -> None:
    """Measured 0 min from every download; the same EPW without the comment that names
    PVGIS's instants is read as any EPW (hour-start means on its header's UTC+1): −40 min,
    the reading this replaced."""
    for kind in ("csv", "json", "epw"):
        assert abs(_shift_min(pvgis_text(kind))) <= 2.5, kind
    plain = pvgis_text("epw").replace("Irradiance Time Offset (h):-0.8239", "")
    assert _shift_min(plain) == pytest.approx(-40.0, abs=2.5)


def test_a_pvgis_hourly_series_is_refused_saying_what_to_do() -> None:
    series = DATA / "pvgis_hourly_Timeseries_45.000_8.000_SA_30deg_0deg_2016_2016.csv"
    with pytest.raises(ValueError, match=r"not a typical year \(TMY\): a PVGIS hourly series "
                                         r".* dhi = Gd\(i\), dni = Gb\(i\) / sin H_sun"):
        read_typical_year(series)


def test_a_pvgis_year_is_not_a_clock_slip_far_from_greenwich() -> None:
    """A PVGIS year is in UTC by the format: at Tehuantepec (95° W) its offset 0 is no sign
    slip, where an EPW's header of 0 h is refused unless forced."""
    from backend.twin.scenario import StationTooFar, check_station
    from sim.sites import load_site

    site = load_site("tehuantepec")
    station = {"format": "pvgis", "name": "TMY", "latitude": site.latitude,
               "longitude": site.longitude, "altitude": 30.0, "utc_offset_h": 0.0}
    assert check_station(station, site, force=False)["distance_km"] == 0.0
    with pytest.raises(StationTooFar, match="file written in UTC"):
        check_station({**station, "format": "epw"}, site, force=False)


def test_a_site_from_a_pvgis_year_runs_on_it(heliotwin_cli: Callable[..., Any],
                                             tmp_path: Path) -> None:
    """``site from-weather`` on the JSON download: the place, the longitude's whole-hour zone
    said on stderr (PVGIS names none); ``simulate --pvgis`` then runs at 0 km, on the sun's
    time; the same file given as ``--tmy3`` is refused naming ``--pvgis``."""
    import json

    env = sites_env(tmp_path / "sites")
    path = pvgis_file("json", tmp_path)
    made = heliotwin_cli("site", "from-weather", str(path), "--id", "piedmont", env=env)
    assert made.returncode == 0, made.stderr
    assert "note: zone Etc/GMT-1: the longitude's whole hour" in made.stderr
    config = json.loads((tmp_path / "sites" / "piedmont.json").read_text())
    assert (config["latitude_deg"], config["longitude_deg"], config["timezone"]) == (
        45.0, 8.0, "Etc/GMT-1")
    run = heliotwin_cli("simulate", "--site", "piedmont", "--start", "2024-06-01", "--end",
                        "2024-06-08", "--step-s", "300", "--pvgis", str(path), "--json",
                        env=env)
    assert run.returncode == 0, run.stderr
    summary = json.loads(run.stdout)
    assert summary["weather"]["format"] == "pvgis"
    assert summary["weather"]["distance_km"] == 0.0
    assert abs(summary["weather_shift_min"]) <= 2.5 and summary["weather_warning"] is None
    wrong = heliotwin_cli("simulate", "--site", "piedmont", "--start", "2024-06-01", "--end",
                          "2024-06-02", "--tmy3", str(path), env=env)
    assert wrong.returncode == 2 and "pass it as --pvgis" in wrong.stderr


@pytest.mark.parametrize(("edit", "message"), [
    (("20180101:0900,3.23,99.4,149.0,", "20180101:0900,3.23,99.4,9999.0,"),
     "the PVGIS file's ghi is 9999 W m⁻² on 01 Jan 09:00 UTC"),
    (("20180101:0900,", "20180101:1000,"), r"01 Jan 09:00–10:00 is missing"),
    (('{"inputs"', '{"input"'), None),
])
def test_a_broken_pvgis_year_is_refused_naming_what_is_wrong(
        edit: tuple[str, str], message: str | None) -> None:
    text = pvgis_text("json" if edit[0].startswith("{") else "csv")
    assert edit[0] in text
    with pytest.raises(ValueError, match=message or "not a readable PVGIS typical year: "
                                                    "KeyError 'inputs'"):
        read_typical_year(io.StringIO(text.replace(edit[0], edit[1], 1)))
