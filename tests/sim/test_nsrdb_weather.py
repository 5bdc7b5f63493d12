"""NSRDB downloads: actual years as measured weather (``sim.sky.read_measured``), a typical
year as one (``sim.sky.read_typical_year``), PSM files of one place (Craig, Colorado) in
``tests/data/nsrdb/`` (README). Checked against pvlib's own reader of the same files and
against the sun (``sim.weather_clock``)."""

from __future__ import annotations

import gzip
import io
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from sim.sky import read_measured
from sim.weather_clock import irradiance_shift, shift_warning
from tests.test_cli_site import sites_env

DATA = Path(__file__).resolve().parents[1] / "data" / "nsrdb"
FILES = {"psm3": "nsrdb_psm3_401182_2017.csv", "psm4": "nsrdb_psm4_401182_2023.csv",
         "tmy": "nsrdb_psm4_401182_tmy-2023.csv"}
CRAIG = (40.53, -108.54, 2168.0)


def nsrdb_text(kind: str) -> str:
    """The download as NSRDB wrote it (``psm3``: 2017, ``psm4``: 2023, 30-min steps;
    ``tmy``: a PSM4 typical year, hourly, README)."""
    return gzip.decompress((DATA / f"{FILES[kind]}.gz").read_bytes()).decode()


def nsrdb_file(kind: str, folder: Path) -> Path:
    """The download unpacked into ``folder``, under its name here."""
    path = folder / FILES[kind]
    path.write_text(nsrdb_text(kind))
    return path


@pytest.mark.parametrize("kind", ["psm3", "psm4"])
def test_an_nsrdb_year_reads_as_pvlib_reads_it_at_its_stamps(kind: str) -> None:
    from pvlib import iotools

    weather, station = read_measured(io.StringIO(nsrdb_text(kind)), name=FILES[kind])
    ref, meta = iotools.read_nsrdb_psm4(io.StringIO(nsrdb_text(kind)))
    ref = ref.tz_convert("UTC")
    assert len(ref) == 17520 and meta["Time Zone"] == -7
    for ours, theirs in (("ghi", "ghi"), ("dni", "dni"), ("dhi", "dhi"),
                         ("temp_air", "temp_air"), ("wind_speed", "wind_speed")):
        assert (weather.loc[ref.index, ours] == ref[theirs]).all(), ours
    year = ref.index[0].year
    assert station["stamped"] == "instant"
    assert station["start"] == f"{year}-01-01T07:00:00+00:00"  # local midnight, UTC−7
    assert station["end"] == f"{year + 1}-01-01T06:30:00+00:00"
    assert station["name"] == (f"{FILES[kind]}: NSRDB location 401182 (40.53, -108.54), "
                               "UTC-7 h, values at their stamps")


@pytest.mark.parametrize("kind", ["psm3", "psm4"])
def test_an_nsrdb_year_is_on_the_suns_time(kind: str) -> None:
    """Measured 0 min in each month with sunny days (−5, one step of the grid, in May 2017);
    the same values written as a CSV and
    read with its default (interval_end means) run 15 min early, at the warning's threshold
    (which let it pass before 2026-12-07): the reason NSRDB's own file is read at its
    stamps."""
    weather, _ = read_measured(io.StringIO(nsrdb_text(kind)))
    year = weather.index[1].year
    months = 0
    for month in range(1, 13):
        start = pd.Timestamp(year, month, 1, tz="UTC")
        found = irradiance_shift(weather, *CRAIG, start, start + pd.DateOffset(months=1))
        if found is not None:
            months += 1
            assert abs(found["shift_min"]) <= 5.0, (month, found)  # the 5-min grid
    assert months >= 10
    rows = weather.iloc[1:-1]
    text = "time,ghi,dni,dhi\n" + "".join(
        f"{t.isoformat()},{r.ghi},{r.dni},{r.dhi}\n" for t, r in rows.iterrows())
    as_means, _ = read_measured(io.StringIO(text))
    june = pd.Timestamp(year, 6, 1, tz="UTC")
    found = irradiance_shift(as_means, *CRAIG, june, june + pd.DateOffset(months=1))
    assert found is not None and found["shift_min"] == pytest.approx(-15.0, abs=2.5)
    assert "15 min early" in shift_warning(found, {"format": "measured",
                                                   "stamped": "interval_end"})


def test_a_bad_nsrdb_cell_is_named_by_its_line_and_a_typical_year_sent_on() -> None:
    text = nsrdb_text("psm4")
    lines = text.splitlines(keepends=True)
    assert lines[3].startswith("2023,1,1,0,0,")
    cells = lines[9].split(",")  # 03:00 local, line 10 of the file
    cells[18] = "abc"  # GHI
    broken = "".join([*lines[:9], ",".join(cells), *lines[10:]])
    with pytest.raises(ValueError, match=r"ghi is 'abc', not a number, at line 10;"):
        read_measured(io.StringIO(broken))
    # a typical year: 8,760 hours whose months come from several years
    hourly = [ln for ln in lines[3:] if ln.split(",")[4] == "0"][:8760]  # Minute 0
    tmy = [ln.replace("2023,", "2019,", 1) if ln.startswith("2023,7,") else ln
           for ln in hourly]
    with pytest.raises(ValueError, match=r"an NSRDB typical year \(TMY: 8,760 hours, its "
                                         r"months from several years\) is not measured "
                                         r"weather: it is read as a typical year \(--nsrdb"):
        read_measured(io.StringIO("".join([*lines[:3], *tmy])))


def test_a_run_on_an_nsrdb_year_at_its_place(heliotwin_cli: Callable[..., Any],
                                             tmp_path: Path) -> None:
    """``simulate --weather-csv`` on the PSM4 download at a site made at its place, September
    2023: on the
    sun's time, the file named with its place; a run outside 2023 refused naming its span."""
    import json

    env = sites_env(tmp_path / "sites")
    made = heliotwin_cli("site", "create", "--id", "craig", "--latitude-deg", "40.53",
                         "--longitude-deg", "-108.54", "--timezone", "America/Denver", env=env)
    assert made.returncode == 0, made.stderr
    path = nsrdb_file("psm4", tmp_path)
    run = heliotwin_cli("simulate", "--site", "craig", "--start", "2023-09-01", "--end",
                        "2023-10-01", "--step-s", "600", "--weather-csv", str(path), "--json",
                        env=env)
    assert run.returncode == 0, run.stderr
    summary = json.loads(run.stdout)
    assert summary["sky"] == "weather" and summary["weather"]["stamped"] == "instant"
    assert "NSRDB location 401182" in summary["weather"]["name"]
    assert abs(summary["weather_shift_min"]) <= 2.5 and summary["weather_warning"] is None
    outside = heliotwin_cli("simulate", "--site", "craig", "--start", "2024-06-01", "--end",
                            "2024-06-02", "--weather-csv", str(path), env=env)
    assert outside.returncode == 2 and "the measured weather covers 2023-01-01" in outside.stderr


def test_a_site_from_an_nsrdb_download_takes_its_place_and_zone(
        heliotwin_cli: Callable[..., Any], tmp_path: Path) -> None:
    """``site from-weather`` on the PSM3 download: its header's place and Local Time Zone
    (−7: ``Etc/GMT+7``), the year's means as the clear sky's air temperature and wind."""
    import json

    env = sites_env(tmp_path / "sites")
    path = nsrdb_file("psm3", tmp_path)
    made = heliotwin_cli("site", "from-weather", str(path), "--id", "craig", env=env)
    assert made.returncode == 0, made.stderr
    config = json.loads((tmp_path / "sites" / "craig.json").read_text())
    weather, _ = read_measured(path)
    assert (config["latitude_deg"], config["longitude_deg"], config["altitude_m"],
            config["timezone"]) == (40.53, -108.54, 2168.0, "Etc/GMT+7")
    assert config["temp_air_c"] == round(float(weather["temp_air"].mean()), 1)
    assert config["notes"] == "zone Etc/GMT+7: the NSRDB file's Local Time Zone, -7 h"
    assert "NSRDB location 401182" in config["source"]


def test_an_nsrdb_typical_year_reads_at_its_stamps_on_its_clock() -> None:
    """Its stamps are at minute 30 of each hour, UTC−7: the hours' middles themselves, so
    every value is the file's (as pvlib reads it), in calendar order; 0 min from the sun in
    each season at its place."""
    from pvlib import iotools

    from sim.sky import nsrdb_is_typical_year, read_typical_year, typical_year_on

    text = nsrdb_text("tmy")
    assert nsrdb_is_typical_year(io.StringIO(text))
    assert not nsrdb_is_typical_year(io.StringIO(nsrdb_text("psm4")))
    weather, station = read_typical_year(io.StringIO(text))
    assert station == {"format": "nsrdb", "name": "location 401182",
                       "latitude": 40.53, "longitude": -108.54, "altitude": 2168.0,
                       "utc_offset_h": -7.0}
    ref, _ = iotools.read_nsrdb_psm4(io.StringIO(text))
    assert len(weather) == len(ref) == 8760 and (ref.index.minute == 30).all()
    ref = ref.iloc[np.lexsort((ref.index.hour, ref.index.day, ref.index.month))]
    for col in ("ghi", "dni", "dhi", "temp_air", "wind_speed"):
        assert np.array_equal(weather[col].to_numpy(), ref[col].to_numpy()), col
    assert str(weather.index[12]) == f"{ref.index[12].year}-01-01 12:30:00-07:00"
    for month in (3, 6, 9, 12):
        start = pd.Timestamp(2024, month, 1, tz="UTC")
        end = start + pd.DateOffset(months=1)
        on = typical_year_on(weather, station["utc_offset_h"], start, end)
        found = irradiance_shift(on, *CRAIG, start, end)
        assert found is not None and abs(found["shift_min"]) <= 5.0, (month, found)
    with pytest.raises(ValueError, match=r"an NSRDB download of an actual year \(17,520 "
                                         r"rows, 2023\): measured weather .*--weather-csv"):
        read_typical_year(io.StringIO(nsrdb_text("psm4")))


def test_a_run_on_an_nsrdb_typical_year(heliotwin_cli: Callable[..., Any],
                                        tmp_path: Path) -> None:
    """``site from-weather`` and ``simulate --nsrdb`` on the typical year: the site at its
    place and zone, the run on the sun's time; its actual year given as ``--nsrdb`` is
    refused naming ``--weather-csv``."""
    import json

    env = sites_env(tmp_path / "sites")
    tmy, year = nsrdb_file("tmy", tmp_path), nsrdb_file("psm4", tmp_path)
    made = heliotwin_cli("site", "from-weather", str(tmy), "--id", "craig", env=env)
    assert made.returncode == 0, made.stderr
    config = json.loads((tmp_path / "sites" / "craig.json").read_text())
    assert (config["latitude_deg"], config["timezone"]) == (40.53, "Etc/GMT+7")
    run = heliotwin_cli("simulate", "--site", "craig", "--start", "2026-06-01", "--end",
                        "2026-07-01", "--step-s", "600", "--nsrdb", str(tmy), "--json", env=env)
    assert run.returncode == 0, run.stderr
    summary = json.loads(run.stdout)
    assert summary["weather"]["format"] == "nsrdb" and summary["weather"]["distance_km"] == 0
    assert abs(summary["weather_shift_min"]) <= 5.0 and summary["weather_warning"] is None
    wrong = heliotwin_cli("simulate", "--site", "craig", "--start", "2023-06-01", "--end",
                          "2023-06-02", "--nsrdb", str(year), env=env)
    assert wrong.returncode == 2 and "an NSRDB download of an actual year" in wrong.stderr


def test_an_nsrdb_year_far_from_the_site_is_refused_unless_forced(
        heliotwin_cli: Callable[..., Any], tmp_path: Path) -> None:
    """Measured weather is the site's own, but an NSRDB year says where it is from: at
    Tehuantepec, 3,000 km from Craig, it is refused naming ``--force``; forced, it runs and
    says how far."""
    import json

    path = nsrdb_file("psm4", tmp_path)
    args = ["simulate", "--site", "tehuantepec", "--start", "2023-06-01", "--end",
            "2023-06-02", "--step-s", "600", "--weather-csv", str(path)]
    far = heliotwin_cli(*args)
    assert far.returncode == 2, far.stderr
    assert "--weather-csv: the weather station" in far.stderr
    assert "km from site tehuantepec" in far.stderr and "set --force" in far.stderr
    forced = heliotwin_cli(*args, "--force", "--json")
    assert forced.returncode == 0, forced.stderr
    weather = json.loads(forced.stdout)["weather"]
    assert weather["format"] == "measured" and weather["forced"] is True
    assert 2900 < weather["distance_km"] < 3100, weather
