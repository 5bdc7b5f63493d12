"""Measured weather (``sim.sky.read_measured``): a CSV of time, GHI, DNI, DHI of its own
dates; the twin's energy on NREL's measured RMIS irradiance (pvanalytics' data) against an
independent pvlib computation; refusals naming the line and the column."""

from __future__ import annotations

import io
import json
from importlib.resources import files
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from backend.twin.scenario import Scenario, run_scenario
from sim.sites import site_from_dict
from sim.sky import read_measured

ROOT = Path(__file__).resolve().parents[2]
#: NREL's RMIS station, Golden CO (pvanalytics' example of irradiance_RMIS_NREL.csv); its
#: stamps are Mountain Standard Time (the file's solar zenith column is least at 12:05–12:30)
GOLDEN = {"latitude_deg": 39.742, "longitude_deg": -105.18, "altitude_m": 1829.0,
          "timezone": "Etc/GMT+7"}


def rmis_csv(rows: slice = slice(None)) -> str:
    """pvanalytics' 5-minute RMIS GHI, DNI, DHI (1–5 Feb 2019; ``rows`` of them) in the
    documented format. Rows 313–962 (2 Feb 02:10 to 4 Feb 08:15) have blanks: the
    instruments' own gaps."""
    raw = pd.read_csv(files("pvanalytics") / "data" / "irradiance_RMIS_NREL.csv").iloc[rows]
    times = pd.to_datetime(raw["measured_on"], format="%m/%d/%Y %H:%M").dt.tz_localize(
        "Etc/GMT+7")
    out = pd.DataFrame({"time": times.map(lambda t: t.isoformat()),
                        "ghi": raw["irradiance_ghi__7981"], "dni": raw["irradiance_dni__7982"],
                        "dhi": raw["irradiance_dhi__7983"]})
    return out.to_csv(index=False)


def golden_site() -> object:
    cfg = json.loads((ROOT / "sim" / "data" / "sites" / "tehuantepec.json").read_text())
    cfg.update(site_id="golden", **GOLDEN, temp_air_c=0.0)
    cfg["arrays"]["fixed"].update(surface_tilt_deg=34.0, surface_azimuth_deg=180.0)
    return site_from_dict(cfg)


def pvlib_energy_wh(site_cfg: dict, weather: pd.DataFrame, times: pd.DatetimeIndex
                    ) -> dict[str, float]:
    """Tracker and fixed energy [Wh] by pvlib alone: weather linear between its rows'
    instants, SPA, Hay–Davies, physical IAM, SAPM cell temperature, CEC single diode × 4
    strings, trapezoids (the recipe of the tester's ``ref.py``)."""
    import pvlib
    from pvlib import atmosphere, iam, irradiance, pvsystem, temperature

    t = times.as_unit("ns").asi8 / 1e9
    tw = weather.index.as_unit("ns").asi8 / 1e9
    ghi, dni, dhi = (np.interp(t, tw, weather[c].to_numpy(float)) for c in ("ghi", "dni", "dhi"))
    sp = pvlib.solarposition.get_solarposition(
        times, site_cfg["latitude_deg"], site_cfg["longitude_deg"], site_cfg["altitude_m"],
        pressure=atmosphere.alt2pres(site_cfg["altitude_m"]), temperature=0.0)
    zen, az = sp["apparent_zenith"], sp["azimuth"]
    mod = pvsystem.retrieve_sam("CECMod")["Kyocera_Solar_KD205GX_LP"]
    out = {}
    for name, tilt, azimuth in (("tracker", zen.clip(upper=90), az), ("fixed", 34.0, 180.0)):
        poa = irradiance.get_total_irradiance(
            tilt, azimuth, zen, az, dni, ghi, dhi, dni_extra=irradiance.get_extra_radiation(
                times), airmass=atmosphere.get_relative_airmass(zen), albedo=0.2,
            model="haydavies")
        eff = (poa["poa_direct"].fillna(0) * iam.physical(irradiance.aoi(tilt, azimuth, zen, az))
               + poa["poa_diffuse"].fillna(0)).where(zen < 90, 0.0)
        cell = temperature.sapm_cell(poa["poa_global"].fillna(0).where(zen < 90, 0.0), 0.0, 1.0,
                                     **temperature.TEMPERATURE_MODEL_PARAMETERS["sapm"][
                                         "open_rack_glass_polymer"])
        params = pvsystem.calcparams_cec(eff, cell, mod.alpha_sc, mod.a_ref, mod.I_L_ref,
                                         mod.I_o_ref, mod.R_sh_ref, mod.R_s, mod.Adjust)
        p = (pvsystem.max_power_point(*params)["p_mp"].fillna(0).clip(lower=0) * 4).where(
            eff > 0, 0.0).to_numpy()
        out[name] = float(np.sum((p[1:] + p[:-1]) / 2 * np.diff(t)) / 3600)
    return out


def test_measured_rmis_irradiance_gives_pvlibs_energy() -> None:
    """1 February 2019, measured 5-min irradiance at Golden: the twin at 60 s within
    0.25 % of pvlib on the same values placed at their 5-minute intervals' middles
    (measured: tracker 8,268.3 against 8,278.2 Wh, −0.12 %; fixed 6,092.2 against
    6,097.7 Wh, −0.09 %: the twin caps the low-sun minutes above the top of the
    atmosphere, ``sim.sky.limit_to_extraterrestrial``, pvlib does not). (5 February is
    no reference: its morning's GHI sits at the top of the atmosphere with half of it
    diffuse, DNI cos z + DHI 30 % over GHI, and the cap takes 8.5 % of the tracker's day.)
    A run a minute past the file's last interval is refused naming its span."""
    rows, day = slice(0, 313), "2019-02-01"
    weather, station = read_measured(io.StringIO(rmis_csv(rows)), "interval_end",
                                     name="rmis.csv")
    site = golden_site()
    start = pd.Timestamp(day, tz="Etc/GMT+7")
    end = start + pd.Timedelta(days=1)
    scenario = Scenario("golden", start, end, 60.0, weather=weather,
                        station={**station, "forced": False})
    twin = run_scenario(site, scenario).summary()
    raw = pd.read_csv(io.StringIO(rmis_csv(rows)))
    mid = pd.DatetimeIndex(pd.to_datetime(raw["time"], utc=True)) - pd.Timedelta(minutes=2.5)
    ref_weather = raw[["ghi", "dni", "dhi"]].clip(lower=0).set_axis(mid)
    times = pd.date_range(start, end, freq="60s").tz_convert("UTC")
    ref = pvlib_energy_wh(GOLDEN, ref_weather, times)
    assert ref["tracker"] > 1000
    assert twin["tracker_energy_wh"] == pytest.approx(ref["tracker"], rel=2.5e-3)
    assert twin["fixed_energy_wh"] == pytest.approx(ref["fixed"], rel=2.5e-3)
    last = pd.Timestamp(station["end"]).tz_convert("Etc/GMT+7")
    with pytest.raises(ValueError, match=f"covers .* to {last}; the run"):
        Scenario("golden", start, last + pd.Timedelta(minutes=1), 60.0, weather=weather,
                 station=station)


def test_the_whole_rmis_file_is_refused_at_its_first_blank() -> None:
    with pytest.raises(ValueError, match="ghi is blank at line 315; 413 such cells"):
        read_measured(io.StringIO(rmis_csv()))


@pytest.mark.parametrize(("stamped", "first_mid"), [
    ("interval_end", "2024-06-01T00:05:00+00:00"),
    ("interval_start", "2024-06-01T00:15:00+00:00"),
    ("instant", "2024-06-01T00:10:00+00:00")])
def test_each_stamp_is_placed_at_its_intervals_middle(stamped: str, first_mid: str) -> None:
    text = ("time,GHI,DNI,DHI,temp_air_c\n2024-06-01T00:10:00Z,10,0,10,20\n"
            "2024-06-01T00:20:00Z,20,0,20,21\n2024-06-01T00:30:00Z,30,0,30,22\n")
    weather, station = read_measured(io.StringIO(text), stamped)
    assert weather.loc[pd.Timestamp(first_mid), "ghi"] == 10  # the first value's instant
    assert list(weather.columns) == ["ghi", "dni", "dhi", "temp_air"]
    span = {"interval_end": ("00:00", "00:30"), "interval_start": ("00:10", "00:40"),
            "instant": ("00:10", "00:30")}[stamped]
    assert (station["start"][11:16], station["end"][11:16]) == span


def test_times_without_an_offset_are_read_in_the_zone_given() -> None:
    text = "timestamp,ghi,dni,dhi\n2024-06-01 10:00,500,600,100\n2024-06-01 10:15,510,610,100\n"
    weather, _ = read_measured(io.StringIO(text), "instant", "Australia/Darwin")
    assert weather.index[0].isoformat() == "2024-06-01T00:30:00+00:00"
    with pytest.raises(ValueError, match=r"'2024-06-01 10:00' at line 2 has no UTC offset"):
        read_measured(io.StringIO(text))


@pytest.mark.parametrize(("times", "line"), [
    (["2023-04-01 22:50", "2023-04-01 23:00", "2023-04-01 23:10"], 3),  # 23:00 falls twice
    (["2023-09-02 23:50", "2023-09-03 00:00", "2023-09-03 00:10"], 3),  # 00:00 is skipped
])
def test_a_local_time_a_clock_change_repeats_or_skips_is_refused_naming_its_line(
        times: list[str], line: int) -> None:
    """Santiago's clocks go back at midnight on 2 April 2023 and forward on 3 September: the
    refusal was pandas' "Cannot infer dst time from 2023-04-01 23:00:00, try using the
    'ambiguous' argument", naming no line; the fixed zone of the same clock reads them."""
    text = "time,ghi,dni,dhi\n" + "".join(f"{t},0,0,0\n" for t in times)
    with pytest.raises(ValueError, match=rf"'{times[1]}' at line {line} repeats or is skipped "
                                         "at a clock change in America/Santiago"):
        read_measured(io.StringIO(text), timezone="America/Santiago")
    weather, _ = read_measured(io.StringIO(text), timezone="Etc/GMT+4")
    assert len(weather) == 5  # the three rows and the two edges


@pytest.mark.parametrize(("rows", "message"), [
    (["2024-06-01T10:00+09:30,1,2,3", "2024-06-01T10:00+09:30,1,2,3"],
     r"2024-06-01T00:30:00\+00:00 is there twice \(line 2 and line 3\)"),
    (["2024-06-01T10:00+09:30,1,2,3", "2024-06-01T12:00+09:30,1,2,3"],
     r"\(line 2\) to .* \(line 3\): no rows for more than an hour"),
    (["2024-06-01T10:00+09:30,1,2,3", "2024-06-01T10:00:30+09:30,1,2,3"],
     "less than a minute apart"),
    (["2024-06-01T10:00+09:30,1,,3", "2024-06-01T10:10+09:30,1,2,3"],
     "dni is blank at line 2"),
    (["2024-06-01T10:00+09:30,1,2,3", "2024-06-01T10:10+09:30,abc,2,3"],
     "ghi is 'abc', not a number, at line 3"),
    (["yesterday,1,2,3", "2024-06-01T10:10+09:30,1,2,3"], "'yesterday' at line 2"),
    (["2024-06-01T10:00+09:30,1,2,3", "2024-06-01T10:10+09:30,1,2,3000"],
     "dhi is 3000 W m⁻² on 2024-06-01 00:40 UTC"),
])
def test_a_bad_measured_file_is_refused_naming_the_line(rows: list[str], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        read_measured(io.StringIO("time,ghi,dni,dhi\n" + "\n".join(rows) + "\n"))


@pytest.mark.parametrize("head", ["Latitude (decimal degrees):\t28.610\n"
                                  "Longitude (decimal degrees):\t77.210\n",
                                  '{"inputs": {"location": {"latitude": 28.61}}}\n'])
def test_a_pvgis_download_is_refused_saying_how_to_write_it(head: str) -> None:
    """A PVGIS CSV was refused with pandas' "Error tokenizing data. C error: Expected 1
    fields in line 5, saw 2", its JSON with the JSON shown as the columns found. Its TMY is
    a typical year (``tests/sim/test_pvgis_weather.py``)."""
    rows = "time(UTC),T2m,G(h),Gb(n),Gd(h)\n20230101:0010,20.8,0.0,0.0,0.0\n"
    with pytest.raises(ValueError, match=r"a PVGIS download .* typical year \(TMY\) is read "
                                         r"as one \(--pvgis PATH.* ghi, dni, dhi \(a "
                                         r"horizontal plane's series: ghi = Gb\(i\)"):
        read_measured(io.StringIO(head + rows))


def test_a_file_without_the_columns_names_what_it_has() -> None:
    with pytest.raises(ValueError, match="dni, dhi not found among measured_on"):
        read_measured(io.StringIO("measured_on,ghi\n2024-06-01T10:00Z,1\n"))


def _tmy3_lines() -> list[str]:
    from sim.sky import pvlib_tmy3_path

    return pvlib_tmy3_path().read_text(encoding="latin-1").splitlines()


def test_a_tmy3_of_a_leap_year_is_refused_naming_29_february(tmp_path: Path) -> None:
    """8,784 rows (an actual year with 29 February) had read "a typical year has 8760
    distinct hours; this TMY3 file has 8760 of 8784 rows" (a tester's finding)."""
    from sim.sky import read_typical_year

    lines = _tmy3_lines()
    feb28 = [x for x in lines[2:] if x.startswith("02/28/")]
    feb29 = [x.replace("02/28/", "02/29/", 1) for x in feb28]
    at = lines.index(feb28[-1]) + 1
    path = tmp_path / "leap.csv"
    path.write_text("\n".join(lines[:at] + feb29 + lines[at:]) + "\n")
    with pytest.raises(ValueError, match=r"has 29 February \(8,784 rows.*delete 29 February's "
                                         r"24 rows, or run on it as measured weather"):
        read_typical_year(path)


def test_a_sub_hourly_epw_is_refused_saying_so(tmp_path: Path) -> None:
    from sim.sky import read_typical_year
    from tests.sim.test_sky import write_epw

    lines = write_epw(tmp_path / "hourly.epw").read_text().splitlines()
    head, rows = lines[:8], lines[8:]
    ten = [",".join(f[:4] + [str(m)] + f[5:]) for f in (r.split(",") for r in rows)
           for m in (10, 20, 30, 40, 50, 60)]
    path = tmp_path / "ten.epw"
    path.write_text("\n".join(head[:7] + ["DATA PERIODS,1,6,Data,Sunday, 1/ 1,12/31"] + ten)
                    + "\n")
    with pytest.raises(ValueError, match=r"a sub-hourly EPW \(6 records an hour, 52,560 rows\) "
                                         "is not read"):
        read_typical_year(path)


def _tmy3_with(tmp_path: Path, edit: object) -> Path:
    """pvlib's Greensboro TMY3 with its data rows (0-based, line = row + 3) edited."""
    lines = _tmy3_lines()
    rows = [x.split(",") for x in lines[2:]]
    edit(rows)  # type: ignore[operator]
    path = tmp_path / "edited.csv"
    path.write_text("\n".join(lines[:2] + [",".join(r) for r in rows]) + "\n")
    return path


@pytest.mark.parametrize(("edit", "message"), [
    (lambda r: r[4000].__setitem__(4, ""),
     r"ghi is blank at line 4,003 \(16 Jun 16:00–17:00 station time\)"),
    (lambda r: r[4000].__setitem__(7, "abc"),
     r"dni is 'abc', not a number, at line 4,003 \(16 Jun 16:00–17:00 station time\)"),
    (lambda r: r.pop(1000), r"8,759 rows: 11 Feb 16:00–17:00 is missing"),
    (lambda r: r.__setitem__(2000, list(r[1999])),
     r"8,760 rows: 25 Mar 07:00–08:00 is there twice \(lines 2,002 and 2,003\); "
     r"25 Mar 08:00–09:00 is missing"),
])
def test_a_bad_typical_year_is_refused_naming_the_column_line_and_hour(
        tmp_path: Path, edit: object, message: str) -> None:
    """A blank GHI had read "missing irradiance (ghi, dni or dhi)", a text DNI "could not
    convert string to float", a missing row "8759 of 8759 rows", a duplicated hour "8759 of
    8760 rows": none said where (a tester's findings; the README said "naming the hour")."""
    from sim.sky import read_typical_year

    with pytest.raises(ValueError, match=message):
        read_typical_year(_tmy3_with(tmp_path, edit))
