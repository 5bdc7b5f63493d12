"""``heliotwin readings import`` (``backend.measurements.logger_file``, its CLI module):
real loggers' files as their data systems wrote them (``tests/data/loggers/``, NREL's, from
pvanalytics), each read against pandas reading the same file by hand; the same readings in
a Campbell TOA5 table, a European ``;`` export with decimal commas and Unix times; the
refusals a user meets; and the command posting to a ``heliotwin serve`` over a socket, the
energy the service then answers against the file's own trapezoid."""

from __future__ import annotations

import gzip
import io
import json
import re
import zipfile
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pandas as pd
import pytest
from live_service import ServerProcess

from backend.measurements.logger_file import read_logger_file

ROOT = Path(__file__).resolve().parents[2]
LOGGERS = ROOT / "tests" / "data" / "loggers"
#: SERF West's positive string (its DC transducers) and its sensors, on a clock at UTC−7
SERF_WEST = {"voltage_v": "dc_pos_voltage__774", "current_a": "dc_pos_current__775",
             "poa_irradiance_w_m2": "poa_irradiance__771", "temp_module_c": "module_temp_1__781",
             "temp_air_c": "ambient_temp__780"}
CASES = {  # file: (columns, timezone, pandas' time format, {field: (column, scale)}, cadence)
    "serf_west_15min.csv": (SERF_WEST, "Etc/GMT+7", "ISO8601",
                            {f: (c, 1.0) for f, c in SERF_WEST.items()}, 900.0),
    "nrel_RSF_II.csv": ({"power_w": "ac_power_kw_1137:kW", "wind_speed_m_s": "wind_speed__1051"},
                        "Etc/GMT+7", "%m/%d/%Y %H:%M",
                        {"power_w": ("ac_power_kw_1137", 1000.0),
                         "wind_speed_m_s": ("wind_speed__1051", 1.0)}, 900.0),
    "serf_east_1min_ac_power.csv": ({"power_w": "ac_power__752"}, None, None,
                                    {"power_w": ("ac_power__752", 1.0)}, 60.0),
    "nrel_1axis_tracker_mesa_ac_power.csv": ({"power_w": "ac_power"}, None, None,
                                             {"power_w": ("ac_power", 1.0)}, 900.0),
}


@pytest.mark.parametrize("name", list(CASES))
def test_a_real_loggers_file_reads_as_pandas_reads_it_by_hand(name: str) -> None:
    columns, zone, time_format, expect, cadence = CASES[name]
    lf = read_logger_file(LOGGERS / name, columns, timezone=zone)
    ref = pd.read_csv(LOGGERS / name, index_col=0)
    if zone is None:  # ISO times with their UTC offsets
        times = pd.to_datetime(ref.index, utc=True)
    else:
        times = pd.to_datetime(ref.index, format=time_format).tz_localize(zone).tz_convert("UTC")
    assert (lf.times_utc.as_unit("s").asi8 == times.as_unit("s").asi8).all()
    for field, (column, scale) in expect.items():
        np.testing.assert_allclose(lf.values[field], ref[column] * scale, rtol=1e-12)
    assert lf.cadence_s() == cadence and len(lf.readings("fixed")) == len(ref)
    assert lf.lines[0] == 2 and lf.lines[-1] == len(ref) + 1


def _serf_west() -> pd.DataFrame:
    ref = pd.read_csv(LOGGERS / "serf_west_15min.csv", index_col=0)
    ref.index = pd.to_datetime(ref.index)
    return ref


def _toa5(ref: pd.DataFrame) -> str:
    """The file's positive string as a Campbell CR1000 would log it: TOA5's four header lines
    (the layout of Campbell's LoggerNet manual), its DC power in kW, NAN for a lost value."""
    out = ['"TOA5","SERF_W","CR1000","1234","CR1000.Std.32","CPU:serf.CR1","4321","Table15"',
           '"TIMESTAMP","RECORD","Vdc_pos_Avg","Idc_pos_Avg","Pdc_pos_Avg"',
           '"TS","RN","Volts","Amps","kW"', '"","","Avg","Avg","Avg"']
    for k, (t, r) in enumerate(ref.iterrows()):
        v, i = float(r["dc_pos_voltage__774"]), float(r["dc_pos_current__775"])
        cells = ["NAN", "NAN", "NAN"] if k == 40 else [f"{v!r}", f"{i!r}", f"{v * i / 1000!r}"]
        out.append(f'"{t:%Y-%m-%d %H:%M:%S}",{k},' + ",".join(cells))
    return "\r\n".join(out) + "\r\n"


def _european(ref: pd.DataFrame, sep: str = ";") -> str:
    """The same as a European portal writes it: Excel's sep= line, ';', decimal commas,
    D.M.YYYY times, units in the header; or tab-separated with a 2-digit year."""
    rows = ["sep=;", "Datum;U_DC [V];I_DC [A]"] if sep == ";" else ["Datum\tU_DC [V]\tI_DC [A]"]
    when = "%d.%m.%Y %H:%M" if sep == ";" else "%d.%m.%y %H:%M"
    rows += [f"{t.strftime(when)}{sep}{str(r['dc_pos_voltage__774']).replace('.', ',')}{sep}"
             f"{str(r['dc_pos_current__775']).replace('.', ',')}" for t, r in ref.iterrows()]
    return "\n".join(rows) + "\n"


def _unix(ref: pd.DataFrame) -> str:
    """The same as an Arduino logger writes it: Unix seconds, columns named as the fields."""
    t = (ref.index.tz_localize("Etc/GMT+7").as_unit("s").asi8).tolist()
    rows = ["unix_s,voltage_v,current_a"] + [
        f"{s},{v!r},{i!r}" for s, v, i in zip(t, ref["dc_pos_voltage__774"].tolist(),
                                             ref["dc_pos_current__775"].tolist(), strict=True)]
    return "\n".join(rows) + "\n"


def _spreadsheet(ref: pd.DataFrame, year_first: bool) -> str:
    """The same as a spreadsheet saves it: US Excel's 1/2/22 1:15:00 PM, or 2022/01/02 13:15."""
    def stamp(t: pd.Timestamp) -> str:
        if year_first:
            return f"{t:%Y/%m/%d %H:%M}"
        return f"{t.month}/{t.day}/{t:%y} {(t.hour + 11) % 12 + 1}:{t:%M:%S %p}"
    rows = ["Time,Volts,Amps"] + [
        f"{stamp(t)},{r['dc_pos_voltage__774']},{r['dc_pos_current__775']}"
        for t, r in ref.iterrows()]
    return "\n".join(rows) + "\n"


def _arduino(ref: pd.DataFrame) -> str:
    """The same as an Arduino logger in Mexico writes it to its SD card: a date column
    (day/month/year) and a clock column, Spanish names."""
    rows = ["Fecha,Hora,Voltaje,Corriente"] + [
        f"{t:%d/%m/%Y},{t:%H:%M:%S},{r['dc_pos_voltage__774']},{r['dc_pos_current__775']}"
        for t, r in ref.iterrows()]
    return "\n".join(rows) + "\n"


@pytest.mark.parametrize("layout", ["TOA5", "european", "european_tab", "unix", "excel_us",
                                    "year_first", "arduino"])
def test_the_same_readings_in_other_loggers_layouts(layout: str) -> None:
    ref = _serf_west()
    plain = read_logger_file(LOGGERS / "serf_west_15min.csv",
                             {"voltage_v": SERF_WEST["voltage_v"],
                              "current_a": SERF_WEST["current_a"]}, timezone="Etc/GMT+7")
    if layout == "TOA5":
        lf = read_logger_file(_toa5(ref).encode(), {"power_w": "Pdc_pos_Avg",
                                                    "voltage_v": "Vdc_pos_Avg",
                                                    "current_a": "Idc_pos_Avg"},
                              timezone="Etc/GMT+7")
        assert lf.layout == "TOA5" and lf.lines[0] == 5 and lf.time_column == "TIMESTAMP"
        assert lf.columns["power_w"] == ("Pdc_pos_Avg", "kW")
        assert lf.columns["voltage_v"] == ("Vdc_pos_Avg", "Volts")
        assert lf.sendable.sum() == len(ref) - 1 and not lf.sendable[40]  # the NAN row
        got = lf.readings("fixed")
        assert got[60]["power_w"] == pytest.approx(got[60]["voltage_v"] * got[60]["current_a"])
    elif layout.startswith("european"):
        tab = layout.endswith("tab")
        lf = read_logger_file(_european(ref, "\t" if tab else ";").encode("latin-1"),
                              {"voltage_v": "U_DC [V]", "current_a": "I_DC [A]"},
                              timezone="Etc/GMT+7")
        assert (lf.layout, lf.lines[0]) == (("CSV (tab, decimal comma)", 2) if tab else
                                            ("CSV (';', decimal comma)", 3))
        assert lf.columns["voltage_v"] == ("U_DC [V]", "V") and not lf.notes[1:]
        got = lf.readings("fixed")
    elif layout == "unix":  # gzipped, as a logger's archive is
        lf = read_logger_file(gzip.compress(_unix(ref).encode()))  # no mapping, no zone
        assert set(lf.columns) == {"voltage_v", "current_a"}
        got = lf.readings("fixed")
    elif layout == "arduino":
        lf = read_logger_file(_arduino(ref).encode(), {"voltage_v": "Voltaje",
                                                       "current_a": "Corriente"},
                              timezone="Etc/GMT+7")
        assert lf.time_column == "Fecha + Hora"
        assert lf.notes[0].startswith("times: day/month/year on a clock in Etc/GMT+7")
        explicit = read_logger_file(_arduino(ref).encode(), {"voltage_v": "Voltaje",
                                                             "current_a": "Corriente"},
                                    timezone="Etc/GMT+7", time_column="Fecha+Hora")
        assert (explicit.times_utc == lf.times_utc).all()
        got = lf.readings("fixed")
    else:
        lf = read_logger_file(_spreadsheet(ref, layout == "year_first").encode(),
                              {"voltage_v": "Volts", "current_a": "Amps"}, timezone="Etc/GMT+7")
        assert lf.notes[0] == ("times: year/month/day" if layout == "year_first" else
                               "times: month/day/year") + " on a clock in Etc/GMT+7, column 'Time'"
        got = lf.readings("fixed")
    want = [r for k, r in enumerate(plain.readings("fixed")) if layout != "TOA5" or k != 40]
    assert [(r["ts"], r["voltage_v"], r["current_a"]) for r in got] == [
        (r["ts"], r["voltage_v"], r["current_a"]) for r in want]



def _serf_east_minutes() -> pd.Series:
    """SERF East's 1-minute AC power [W] (real, ISO times with offsets), by UTC time."""
    ref = pd.read_csv(LOGGERS / "serf_east_1min_ac_power.csv", index_col=0)
    return pd.Series(ref["ac_power__752"].to_numpy(), pd.to_datetime(ref.index, utc=True))


def _metered(minutes: pd.Series, every: str = "15min") -> tuple[pd.Series, pd.Series]:
    """What an inverter's meter and a portal make of a logger's minutes: the running total
    [Wh] at each ``every`` stamp (each minute's power over its minute, summed), and each
    interval's energy [Wh] stamped at its end; both as pandas makes them by hand."""
    total = (minutes.clip(lower=0) / 60.0).cumsum()
    stamps = total.index[total.index.floor(every) == total.index]
    interval = (minutes.clip(lower=0) / 60.0).resample(every, closed="right",
                                                       label="right").sum()
    return total[stamps], interval


def test_a_meters_total_and_a_portals_interval_energy_are_sent_as_each_intervals_mean_power(
        ) -> None:
    """An inverter's running total in kWh to 1 Wh (a ``;`` export, local clock) and a
    portal's 15-minute energies in Wh, made from SERF East's real 1-minute power: each
    reading is the interval's mean power as pandas resamples the minutes, to the total's
    resolution (4 W at 1 Wh a quarter hour) and the energies' rounding. A reset of the
    meter and a two-hour gap are not spread as power, and the notes say so with their lines
    and the energy left out."""
    minutes = _serf_east_minutes()
    means = minutes.clip(lower=0).resample("15min", closed="right", label="right").mean()
    total, interval = _metered(minutes)
    clock = total.index.tz_convert("Etc/GMT+7").strftime("%d.%m.%Y %H:%M")
    kwh = [f"{x / 1000:.3f}".replace(".", ",") for x in total.to_numpy()]
    text = "Datum;Zählerstand [kWh]\n" + "".join(
        f"{t};{e}\n" for t, e in zip(clock, kwh, strict=True))
    meter = read_logger_file(text.encode(), {"energy_total_wh": "Zählerstand [kWh]"},
                             timezone="Etc/GMT+7")
    assert meter.power_from == "energy_total_wh" and "power_w" not in meter.columns
    assert meter.columns["energy_total_wh"] == ("Zählerstand [kWh]", "kWh")
    got = pd.Series(meter.values["power_w"].to_numpy(), meter.times_utc)
    want = means.reindex(got.index)
    assert np.isnan(got.iloc[0]) and len(meter.readings("fixed")) == len(total) - 1
    np.testing.assert_allclose(got.iloc[1:], want.iloc[1:], atol=4.0 + 1e-6)
    assert any("smallest rise is 1 Wh: an interval's power is known to 4 W" in n
               for n in meter.notes)

    portal = "Time,Energy (Wh)\n" + "".join(
        f"{t:%Y-%m-%dT%H:%M:%SZ},{e:.1f}\n" for t, e in interval.items())
    lf = read_logger_file(portal.encode(), {"energy_wh": "Energy (Wh)"})
    assert lf.power_from == "energy_wh" and lf.cadence_s() == 900.0
    np.testing.assert_allclose(lf.values["power_w"], means.reindex(lf.times_utc), atol=0.2)
    assert lf.notes[-1] == ("power_w: 'Energy (Wh)', each row's energy over its interval (the "
                            "rows' spacing, 900 s): the interval's mean power")

    # a meter swapped (its total back to 0 at 18 Mar 17:00 UTC) and two hours lost after it
    swap = int(np.flatnonzero(total.index == pd.Timestamp("2022-03-18 17:00Z"))[0])
    new_kwh = (total - total.iloc[swap - 1]).to_numpy() / 1000 - 0.5
    cells = [f"{x:.3f}".replace(".", ",") for x in new_kwh]
    rows = [f"{t};{kwh[k] if k < swap else cells[k]}\n" for k, t in enumerate(clock)
            if not swap + 7 <= k < swap + 15]  # 8 rows lost after the swap
    broken = read_logger_file(("Datum;Zählerstand [kWh]\n" + "".join(rows)).encode(),
                              {"energy_total_wh": "Zählerstand [kWh]"}, timezone="Etc/GMT+7")
    assert np.isnan(broken.values["power_w"].iloc[swap])
    lost_wh = 1000 * (round(new_kwh[swap + 15], 3) - round(new_kwh[swap + 6], 3))  # over the gap
    notes = " ".join(broken.notes)  # the file's line of row k is k + 2
    assert (f"goes back on 1 rows (a reset — a day's total at midnight — or a new meter; the "
            f"first at line {swap + 2}): their intervals are not sent") in notes
    assert (f"'Zählerstand [kWh]' spans a gap 1 × (a step over 1.5 × its 900 s spacing: rows "
            f"missing, or blank totals; the "
            f"first ending at line {swap + 9}): the {lost_wh:.6g} Wh it rose over them are not "
            "sent as power") in notes
    assert broken.sendable.sum() == meter.sendable.sum() - 8 - 2



def _bms_ghi() -> pd.Series:
    """NREL BMS's 1-minute GHI [W m⁻²] of 20 Jan 2022 (real; ISO times at −07:00), by UTC."""
    ref = pd.read_csv(LOGGERS / "midc_bms_ghi_20220120.csv", index_col=0)
    return pd.Series(ref.iloc[:, 0].to_numpy(), pd.to_datetime(ref.index, utc=True))


def test_a_weather_stations_file_is_joined_to_the_readings_by_time() -> None:
    """A plant's weather station logs apart from its strings. SERF West's own file split in
    two — the positive string's voltage and current, and a station's ``;`` export of its POA,
    module and air temperature — joins to exactly the readings of the file whole. NREL BMS's
    real 1-minute GHI beside 15-minute readings: as instants each reading takes the GHI at
    its stamp; as means stamped at the interval's end (start) the mean of the minutes in
    (t − 15 min, t] ([t, t + 15 min)), as pandas resamples them; two lost hours of the
    station leave their readings without (at least half an interval's rows, else none)."""
    from backend.measurements.logger_file import join_station

    ref = _serf_west()
    strings = ref[["dc_pos_voltage__774", "dc_pos_current__775"]]
    station = ref[["poa_irradiance__771", "module_temp_1__781", "ambient_temp__780"]]
    whole = read_logger_file(LOGGERS / "serf_west_15min.csv", SERF_WEST, timezone="Etc/GMT+7")
    lf = read_logger_file(strings.to_csv().encode(), {"voltage_v": "dc_pos_voltage__774",
                                                      "current_a": "dc_pos_current__775"},
                          timezone="Etc/GMT+7")
    met = read_logger_file(station.to_csv(sep=";", decimal=",").encode(), {
        "poa_irradiance_w_m2": "poa_irradiance__771", "temp_module_c": "module_temp_1__781",
        "temp_air_c": "ambient_temp__780"}, timezone="Etc/GMT+7", station=True)
    notes = join_station(lf, met, "instant", "met.csv")
    assert lf.readings("fixed") == whole.readings("fixed")
    assert notes == ["sensors from met.csv (poa_irradiance_w_m2, temp_module_c, temp_air_c): its "
                     "value at each reading's stamp (linear between its rows, none across a gap "
                     "over 1.5 × its 900 s spacing); 480 of 480 readings have them"]

    ghi = _bms_ghi()
    lost = (ghi.index >= pd.Timestamp("2022-01-20 18:00Z")) \
        & (ghi.index < pd.Timestamp("2022-01-20 20:00Z"))
    station_text = "Time,GHI [W/m2]\n" + "".join(
        f"{t:%Y-%m-%dT%H:%M:%SZ},{g}\n" for t, g in ghi[~lost].items())
    stamps = pd.date_range("2022-01-20 07:15Z", "2022-01-21 06:45Z", freq="15min")
    readings = "ts,power_w\n" + "".join(f"{t:%Y-%m-%dT%H:%M:%SZ},100\n" for t in stamps)
    kept = ghi[~lost]
    for stamped, want in (
            ("instant", kept.reindex(stamps)),
            ("interval_end", kept.resample("15min", closed="right", label="right").mean()),
            ("interval_start", kept.resample("15min", closed="left", label="left").mean())):
        lf = read_logger_file(readings.encode())
        met = read_logger_file(station_text.encode(), {"ghi_w_m2": "GHI [W/m2]"}, station=True)
        (note,) = join_station(lf, met, stamped, "bms.csv")
        got = pd.Series(lf.values["ghi_w_m2"].to_numpy(), lf.times_utc)
        if stamped != "instant":  # an interval of the lost hours has no mean
            side = "right" if stamped == "interval_end" else "left"
            count = kept.resample("15min", closed=side, label=side).count()
            want = want.where(count.reindex(want.index) >= 7.5)
        np.testing.assert_allclose(got, want.reindex(got.index), rtol=1e-12, atol=1e-9)
        # the 8 stamps of 18:00-19:45 (instants, interval starts) or 18:15-20:00 (ends: the
        # quarter ending 20:00 has 1 of its 15 minutes)
        assert got.isna().sum() == 8, (stamped, got[got.isna()])
        assert note.endswith(f"{len(stamps) - 8} of {len(stamps)} readings have them")



def test_a_portals_excel_workbook_with_a_units_row_reads_as_its_csv() -> None:
    """A portal's export as an .xlsx workbook (Fronius Solar.web's layout: a header, a units
    row under it, ``[dd.MM.yyyy HH:mm]`` and ``[Wh]``, Excel date-time cells on the plant's
    clock), made with openpyxl from SERF East's real minutes as 5-minute energies: each
    reading is the interval's mean power as pandas resamples the minutes, the unit read from
    the units row. The same rows as a ``;`` CSV with the units row read alike; a units row
    is no data row, and an old .xls or a zip that is no workbook is refused, saying what to
    do."""
    from openpyxl import Workbook

    minutes = _serf_east_minutes()
    _, energy = _metered(minutes, "5min")
    energy = energy.iloc[1:-1]  # whole intervals of the file
    local = energy.index.tz_convert("Etc/GMT+7").tz_localize(None)
    book = Workbook()
    sheet = book.active
    sheet.title = "Daten"
    sheet.append(["Date and time", "Energy | Symo 8.2-3-M (1)"])
    sheet.append(["[dd.MM.yyyy HH:mm]", "[Wh]"])
    for t, e in zip(local, energy.round(2), strict=True):
        sheet.append([t.to_pydatetime(), float(e)])
    buf = io.BytesIO()
    book.save(buf)
    lf = read_logger_file(buf.getvalue(), {"energy_wh": "Energy | Symo 8.2-3-M (1)"},
                          timezone="Etc/GMT+7")
    assert lf.layout == "Excel workbook, sheet 'Daten'" and lf.lines[0] == 3
    assert lf.columns == {"energy_wh": ("Energy | Symo 8.2-3-M (1)", "Wh")}
    means = minutes.clip(lower=0).resample("5min", closed="right", label="right").mean()
    # energies to 0.01 Wh: the power to 0.005 Wh over 300 s, 0.06 W
    np.testing.assert_allclose(lf.values["power_w"], means.reindex(lf.times_utc), atol=0.0601)
    text = "Date and time;Energy\n[dd.MM.yyyy HH:mm];kWh\n" + "".join(
        f"{t:%d.%m.%Y %H:%M};{e / 1000:.5f}\n" for t, e in zip(local, energy, strict=True))
    csv_lf = read_logger_file(text.encode(), {"energy_wh": "Energy"}, timezone="Etc/GMT+7")
    assert csv_lf.columns["energy_wh"] == ("Energy", "kWh")
    np.testing.assert_allclose(csv_lf.values["power_w"], means.reindex(csv_lf.times_utc),
                               atol=0.0601)
    with pytest.raises(ValueError, match=r"Excel 97-2003 workbook \(.xls\): open it and save "
                                         r"it as .xlsx or CSV"):
        read_logger_file(b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1" + bytes(500))
    archive = io.BytesIO()
    with zipfile.ZipFile(archive, "w") as z:
        z.writestr("readings.csv", "ts,power_w\n")
    with pytest.raises(ValueError, match="the file is a zip archive but no .xlsx workbook"):
        read_logger_file(archive.getvalue())


def test_columns_that_add_up_map_to_one_field() -> None:
    """An array on two inverters is one array's power: ``power_w=A+B`` adds the columns, each
    in its own unit (RSF II's plant in kW and its second inverter in W, as pandas adds them;
    the physics is not the point), a cell missing in either leaves the sum missing; a field
    that does not add up (a voltage), a part the file lacks, or a unit given for one part of
    columns whose file gives none is refused."""
    name = "nrel_RSF_II.csv"
    both = "ac_power_kw_1137:kW + inv2_ac_power_w__1047:W"
    lf = read_logger_file(LOGGERS / name, {"power_w": both}, timezone="Etc/GMT+7")
    ref = pd.read_csv(LOGGERS / name, index_col=0)
    np.testing.assert_allclose(lf.values["power_w"], ref["ac_power_kw_1137"] * 1000
                               + ref["inv2_ac_power_w__1047"], rtol=1e-12)
    assert lf.columns["power_w"] == ("ac_power_kw_1137 + inv2_ac_power_w__1047", "kW + W")
    text = "ts,P1 [kW],P2 [W]\n2022-01-02T10:00Z,1.5,250\n2022-01-02T10:15Z,,300\n"
    gap = read_logger_file(text.encode(), {"power_w": "P1 [kW] + P2 [W]"})
    assert gap.columns["power_w"] == ("P1 [kW] + P2 [W]", "kW + W")
    assert gap.readings("fixed") == [{"ts": "2022-01-02T10:00:00Z", "array": "fixed",
                                      "power_w": 1750.0}]
    with pytest.raises(ValueError, match=r"voltage_v=.*: only power_w, current_a, energy_wh, "
                                         r"energy_total_wh add up over columns"):
        read_logger_file(text.encode(), {"voltage_v": "P1 [kW]+P2 [W]",
                                         "current_a": "P2 [W]"})
    with pytest.raises(ValueError, match=r"the file has no column 'P3'"):
        read_logger_file(text.encode(), {"power_w": "P1 [kW]+P3"})
    with pytest.raises(ValueError, match=r"a unit is given for some of the columns only; give "
                                         r"each its own"):  # not P_INV1 in W, P_INV2 in kW
        read_logger_file(LOGGERS / name, {"power_w": "ac_power_kw_1137+inv2_ac_power_w__1047:kW"},
                         timezone="Etc/GMT+7")

REFUSED = [
    ("ts,power_w\n2022-01-02 10:00,5\n2022-01-02 10:01,6\n", {},
     r"ts: the times have no UTC offset .* with --timezone"),
    ("ts,power_w\n2022-01-02T10:00Z,5\n2022-01-02T10:01Z,abc\n", {},
     r"column 'power_w': 'abc' at line 3 is not a number"),
    ("ts,power_w\n1/2/2022 10:00,5\n1/2/2022 10:15,6\n", {"timezone": "UTC"},
     r"month/day/year and as day/month/year alike .* --date-order mdy or dmy"),
    ("ts,power_w\n2022-11-06 00:45,5\n2022-11-06 01:30,6\n2022-11-06 02:15,6\n",
     {"timezone": "America/Denver"}, r"'2022-11-06 01:30' at line 3 repeats or is skipped"),
    ("ts,power_w\n2022-03-13 01:45,5\n2022-03-13 02:30,6\n", {"timezone": "America/Denver"},
     r"'2022-03-13 02:30' at line 3 repeats or is skipped"),
    ("ts,P\n2022-01-02T10:00Z,5\n", {"columns": {"power_w": "P:furlongs"}},
     r"unit 'furlongs' is not one of w, watts, kw"),
    ("ts,P\n2022-01-02T10:00Z,5\n", {"columns": {"power_w": "Q"}},
     r"no column 'Q'; its columns are 'ts', 'P'"),
    ("ts,P\n2022-01-02T10:00Z,5\n", {},
     r"map power_w \(or energy_wh, energy_total_wh\), or voltage_v and current_a"),
    ("ts,P,E\n2022-01-02T10:00Z,5,1\n2022-01-02T10:15Z,6,2\n",
     {"columns": {"power_w": "P", "energy_wh": "E"}},
     r"map one of power_w, energy_wh .* and energy_total_wh .*; got power_w, energy_wh"),
    ("ts,E [W]\n2022-01-02T10:00Z,5\n2022-01-02T10:15Z,6\n", {"columns": {"energy_wh": "E [W]"}},
     r"energy_wh='E \[W\]': unit 'W' is not one of wh, kwh, mwh"),
    ("ts,E\n2022-01-02T10:00Z,5\n", {"columns": {"energy_total_wh": "E"}},
     r"energy_total_wh='E': two rows at different times are needed"),
    ("ts,power_w\n2022-01-02T10:00Z,5\n\n2022-01-02T10:01Z,6,7\n", {},
     r"line 4 has 3 cells; the header has 2"),
    ("ts,power_w\n2022-01-02T10:00Z,5\n", {"timezone": "Mars/Olympus"}, None),  # offsets: unused
    ("ts,power_w\n2022-01-02 10:00,5\n", {"timezone": "Mars/Olympus"},
     r"'Mars/Olympus' is not an IANA time zone"),
]


@pytest.mark.parametrize(("text", "kwargs", "match"), REFUSED)
def test_a_file_it_cannot_read_is_refused_naming_line_column_and_remedy(
        text: str, kwargs: dict, match: str | None) -> None:
    if match is None:
        assert len(read_logger_file(text.encode(), **kwargs).readings("a")) == 1
        return
    with pytest.raises(ValueError, match=match):
        read_logger_file(text.encode(), **kwargs)


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory):
    """A ``heliotwin serve`` on SQLite over a socket with two sites at Golden, tehuantepec's
    arrays as strings of 8 modules (a SERF West string's 3.0 kW peak under twice their
    rating) or 12 (SERF East's 4.6 kW AC peak): ``serf`` (a fixed array of 8, a tracker of
    12; stamps as instants) and ``meter`` (12 each; ``readings_stamped`` ``interval_end``,
    as a meter's totals are); the sites' directory in ``HELIOTWIN_SITES_DIR``."""
    tmp_path = tmp_path_factory.mktemp("import")
    sites = tmp_path / "sites"
    sites.mkdir()
    base = json.loads((ROOT / "sim" / "data" / "sites" / "tehuantepec.json").read_text())
    for site_id, modules, extra in (
            ("serf", {"fixed": 8, "tracker": 12}, {}),
            ("meter", {"fixed": 12, "tracker": 12}, {"readings_stamped": "interval_end"})):
        site = {**base, "site_id": site_id, "name": f"{site_id} at Golden",
                "latitude_deg": 39.7407, "longitude_deg": -105.1686, "altitude_m": 1794.0,
                "timezone": "America/Denver", "temp_air_c": 10.0, **extra}
        site["arrays"] = {a: {**base["arrays"][a], "modules_in_series": modules[a],
                              "strings_in_parallel": 1} for a in ("tracker", "fixed")}
        (sites / f"{site_id}.json").write_text(json.dumps(site))
    env = {"HELIOTWIN_SITES_DIR": str(sites)}
    server = ServerProcess(f"sqlite:///{tmp_path / 'import.sqlite'}", tmp_path / "server.log",
                           extra_env=env).start()
    try:
        yield server, env
    finally:
        server.stop()


def test_the_command_posts_a_real_loggers_file_and_the_service_counts_its_energy(
        served, heliotwin_cli) -> None:
    """SERF West's two DC strings (15 min, a clock at UTC−7) in one run: the positive string
    with its POA, module and air temperature into the fixed array, the negative one into
    the tracker (site ``serf``). Every reading stored, again as duplicates, and each array's
    energy over the five days the file's own trapezoid (the energy rule, no gap over 15
    min). The night voltages (−0.002 V, a transducer's offset) had been refused. The
    inverter's 6 kW DC power into one array is refused naming the file's first line past
    its rating."""
    server, env = served
    token = server.token("serf")
    args = ["readings", "import", str(LOGGERS / "serf_west_15min.csv"), "--site", "serf",
            "--timezone", "Etc/GMT+7", "--url", server.base_url, "--token", token]
    both = [*args, *[f"--column=fixed.{f}={c}" for f, c in SERF_WEST.items()],
            "--column=tracker.voltage_v=dc_neg_voltage__776",
            "--column=tracker.current_a=dc_neg_current__777"]
    first = heliotwin_cli(*both, env=env)
    assert first.returncode == 0, first.stderr
    for array in ("fixed", "tracker"):
        assert (f"posted {array} to {server.base_url}: 480 accepted, 0 duplicates, stored "
                "through 2022-01-07T06:46:00Z") in first.stdout
    assert "every 900 s" in first.stdout and "readings_stamped" in first.stdout
    # again, the token from the environment (kept out of ps): all duplicates
    without_flag = [a for a in both if a not in ("--token", token)]
    again = heliotwin_cli(*without_flag, "--json", env={**env, "HELIOTWIN_TOKEN": token})
    assert again.returncode == 0, again.stderr
    assert {a: v["duplicates"] for a, v in json.loads(again.stdout)["arrays"].items()} == {
        "fixed": 480, "tracker": 480}
    refused = heliotwin_cli(*args, "--array", "fixed", "--column=power_w=dc_power__772",
                            env=env)
    assert refused.returncode == 1
    assert ("line 44: power_w 4739 W is over 2 × array 'fixed''s rating"
            in refused.stderr), refused.stderr
    r = httpx.get(f"{server.base_url}/api/v1/sites/serf/energy", params={
        "start": "2022-01-02", "end": "2022-01-07", "interval": "day"}, timeout=60)
    assert r.status_code == 200, r.text
    ref = _serf_west()
    t_s = ref.index.tz_localize("Etc/GMT+7").as_unit("s").asi8.astype(float)
    for array, sign in (("fixed", "pos"), ("tracker", "neg")):
        measured = sum(d["arrays"][array]["measured_wh"] for d in r.json()["rows"])
        v = ref.filter(like=f"dc_{sign}_voltage").iloc[:, 0]
        i = ref.filter(like=f"dc_{sign}_current").iloc[:, 0]
        power = (v * i).to_numpy()
        assert measured == pytest.approx(np.trapezoid(power, t_s) / 3600, rel=1e-12)
    m = httpx.get(f"{server.base_url}/api/v1/sites/serf/measurements", params={
        "array": "fixed", "start": "2022-01-02T15:01:00-07:00",
        "end": "2022-01-02T15:02:00-07:00"}, timeout=60).json()
    assert m["points"][0]["voltage_v"] == 223.79
    assert m["points"][0]["poa_irradiance_w_m2"] == 526.2



def test_a_meters_total_is_posted_and_the_service_counts_the_meters_energy(
        served, heliotwin_cli, tmp_path: Path) -> None:
    """An inverter's running total (kWh to 1 Wh, every 15 min; made from SERF East's real
    1-minute power, as :func:`_metered`) posted by the command to site ``meter``, whose
    stamps end their intervals: the service's energy over the two days is the meter's own
    rise between its first and last totals, and the day it read whole, 19 March, the
    minutes' own energy. Posted to a site that takes its stamps as instants, the command
    says what to set."""
    server, env = served
    total, _ = _metered(_serf_east_minutes())
    path = tmp_path / "meter.csv"
    path.write_text("Time;E_total [kWh]\n" + "".join(
        f"{t:%Y-%m-%dT%H:%M:%SZ};{e / 1000:.3f}\n" for t, e in total.items()))
    run = heliotwin_cli("readings", "import", str(path), "--site", "meter", "--array", "fixed",
                        "--column", "energy_total_wh=E_total [kWh]", "--url", server.base_url,
                        env={**env, "HELIOTWIN_TOKEN": server.token("meter")})
    assert run.returncode == 0, run.stderr
    assert "energy_total_wh ← 'E_total [kWh]' [kWh] (power_w: each interval's mean)" \
        in run.stdout
    assert f"{len(total) - 1} accepted" in run.stdout and "readings_stamped" not in run.stdout
    r = httpx.get(f"{server.base_url}/api/v1/sites/meter/energy", params={
        "start": "2022-03-18", "end": "2022-03-21", "interval": "day", "array": "fixed"},
        timeout=60)
    assert r.status_code == 200, r.text
    days = {row["period_start"][:10]: row["arrays"]["fixed"]["measured_wh"]
            for row in r.json()["rows"]}
    rounded_wh = np.round(total.to_numpy() / 1000, 3) * 1000  # as the file says it
    assert sum(days.values()) == pytest.approx(rounded_wh[-1] - rounded_wh[0], rel=1e-12)
    minutes = _serf_east_minutes().clip(lower=0)
    local = minutes.index.tz_convert("America/Denver")
    whole = minutes[(local >= pd.Timestamp("2022-03-19", tz="America/Denver"))
                    & (local < pd.Timestamp("2022-03-20", tz="America/Denver"))]
    assert days["2022-03-19"] == pytest.approx(whole.sum() / 60, abs=1.0)  # its 1-Wh steps
    instant = heliotwin_cli("readings", "import", str(path), "--site", "serf", "--array",
                            "tracker", "--column", "energy_total_wh=E_total [kWh]", "--url",
                            server.base_url, env={**env, "HELIOTWIN_TOKEN": server.token("serf")})
    assert instant.returncode == 0, instant.stderr
    assert ("note: the readings are means made from energy (energy_total_wh) and site serf "
            "takes their stamps as instants (readings_stamped): set it to interval_end (a "
            "meter's total ends each interval)") in instant.stdout


def test_the_command_posts_strings_and_their_weather_stations_file_together(
        served, heliotwin_cli, tmp_path: Path) -> None:
    """SERF West's positive string and its station's POA and temperatures, as two files (the
    station a ``;`` export with decimal commas), posted by one command to site ``meter``'s
    fixed array: the readings stored carry the station's values at their stamps (the
    station as fine as the readings: no means to take). A dry run says what it joined; a
    field in both files, a station's power and an array not imported are refused, each in
    the station's flags' words; so is posting to a site that takes these 15-minute stamps as
    instants (``serf``): a stored reading is never replaced, so the join must be the one
    the site will read."""
    server, env = served
    ref = _serf_west()
    strings, met = tmp_path / "strings.csv", tmp_path / "met.csv"
    ref[["dc_pos_voltage__774", "dc_pos_current__775"]].to_csv(strings)
    ref[["poa_irradiance__771", "ambient_temp__780"]].to_csv(met, sep=";", decimal=",")
    args = ["readings", "import", str(strings), "--site", "meter", "--array", "fixed",
            "--timezone", "Etc/GMT+7", "--column=voltage_v=dc_pos_voltage__774",
            "--column=current_a=dc_pos_current__775", "--sensors", str(met),
            "--sensors-column=poa_irradiance_w_m2=poa_irradiance__771",
            "--sensors-column=temp_air_c=ambient_temp__780", "--url", server.base_url]
    dry = heliotwin_cli(*args, "--dry-run")
    assert dry.returncode == 0, dry.stderr
    assert ("  sensors: met.csv (CSV (';', decimal comma)), 480 rows, beside fixed's readings\n"
            "    poa_irradiance_w_m2 ← 'poa_irradiance__771' [W/m²]\n") in dry.stdout
    assert "480 of 480 readings have them" in dry.stdout and "a dry run does not read" \
        in dry.stdout
    run = heliotwin_cli(*args, env={**env, "HELIOTWIN_TOKEN": server.token("meter")})
    assert run.returncode == 0, run.stderr
    assert "posted fixed to" in run.stdout and "480 accepted" in run.stdout
    m = httpx.get(f"{server.base_url}/api/v1/sites/meter/measurements", params={
        "array": "fixed", "start": "2022-01-02T15:01:00-07:00",
        "end": "2022-01-02T15:02:00-07:00"}, timeout=60).json()
    row = ref.loc["2022-01-02 15:01:00"]
    assert m["points"][0]["poa_irradiance_w_m2"] == row["poa_irradiance__771"] == 526.2
    assert m["points"][0]["temp_air_c"] == pytest.approx(row["ambient_temp__780"], abs=1e-6)
    assert m["points"][0]["voltage_v"] == 223.79
    for extra, message in (
            (["--sensors-column=voltage_v=poa_irradiance__771"],
             "met.csv: --sensors-column: 'voltage_v' is not a field of a weather station"),
            (["--column=poa_irradiance_w_m2=dc_pos_voltage__774"],
             "met.csv: --sensors-column: poa_irradiance_w_m2: mapped in both files"),
            (["--sensors-array=tracker"], "--sensors-array: name the array whose readings "
                                          "carry the station's values, one of fixed")):
        bad = heliotwin_cli(*args, *extra, "--dry-run")
        assert bad.returncode == 2 and message in bad.stderr, bad.stderr
    # a site that takes 15-minute stamps as instants: the join would be stored as it is
    # done, so nothing is posted until the site says what its stamps mark
    instant = [a if a != "meter" else "serf" for a in args]
    refused = heliotwin_cli(*instant, env={**env, "HELIOTWIN_TOKEN": server.token("serf")})
    assert refused.returncode == 2 and "set the site's readings_stamped first, or give " \
        "--sensors-at-stamps" in refused.stderr and "nothing was posted" in refused.stderr

def test_a_dry_run_says_what_it_would_post_and_a_column_needs_an_array(heliotwin_cli) -> None:
    path = str(LOGGERS / "nrel_RSF_II.csv")
    run = heliotwin_cli("readings", "import", path, "--site", "rsf", "--timezone", "Etc/GMT+7",
                        "--column=fixed.power_w=ac_power_kw_1137:kW",
                        "--column=tracker.power_w=inv2_ac_power_w__1047", "--dry-run")
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines()[:7] == [
        "read: nrel_RSF_II.csv (CSV (',')), 480 rows",
        "  rsf/fixed: 480 readings from 2022-01-02T07:00:00Z to 2022-01-07T06:45:00Z, every "
        "900 s",
        "    power_w ← 'ac_power_kw_1137' [kW]",
        '    its highest power as sent: {"ts": "2022-01-05T20:45:00Z", "array": "fixed", '
        '"power_w": 207500.2}',
        "  rsf/tracker: 480 readings from 2022-01-02T07:00:00Z to 2022-01-07T06:45:00Z, every "
        "900 s",
        "    power_w ← 'inv2_ac_power_w__1047' [W]",
        '    its highest power as sent: {"ts": "2022-01-05T20:45:00Z", "array": "tracker", '
        '"power_w": 87153.49}']
    assert run.stdout.rstrip().endswith("dry run: nothing posted")
    bad = heliotwin_cli("readings", "import", path, "--site", "rsf", "--column=power_w=x",
                        "--dry-run")
    assert bad.returncode == 2
    assert "--column: 'power_w=x' names no array: give --array" in bad.stderr
    no_token = heliotwin_cli("readings", "import", path, "--site", "rsf", "--array", "fixed")
    assert no_token.returncode == 2 and "--token: the site's write token" in no_token.stderr
    assert "or set HELIOTWIN_TOKEN" in no_token.stderr


def test_a_portal_export_in_local_summer_time_reads_its_repeated_hour_in_order() -> None:
    """A year exported in the site's local time has the hour the clocks go back twice, first
    in summer time: read in order (it had been refused as a time the change repeats)."""
    times = ["2022-11-06 00:30", "2022-11-06 01:00", "2022-11-06 01:30", "2022-11-06 01:00",
             "2022-11-06 01:30", "2022-11-06 02:00"]
    text = "ts,power_w\n" + "".join(f"{t},{k}\n" for k, t in enumerate(times))
    lf = read_logger_file(text.encode(), timezone="America/Denver")
    assert [f"{t:%H:%M}" for t in lf.times_utc] == ["06:30", "07:00", "07:30", "08:00", "08:30",
                                                   "09:00"]
    assert lf.cadence_s() == 1800.0


def test_a_busy_service_is_retried_and_a_gone_one_stops_the_import_naming_the_lines() -> None:
    from backend.cli import CliError
    from backend.cli.readings import post_readings

    lf = read_logger_file(LOGGERS / "nrel_1axis_tracker_mesa_ac_power.csv",
                          {"power_w": "ac_power"})
    calls: list[int] = []
    waits: list[float] = []

    def busy_once(request: httpx.Request) -> httpx.Response:
        calls.append(len(json.loads(gzip.decompress(request.content))["readings"]))
        if len(calls) == 1:
            return httpx.Response(503, text="busy")
        return httpx.Response(200, json={"accepted": calls[-1], "duplicates": 0,
                                         "stored_through": "2010-07-01T05:45:00Z"})

    with httpx.Client(base_url="http://logger.test", transport=httpx.MockTransport(busy_once)
                      ) as c:
        got = post_readings(c, "golden", "tracker", "tok", lf, sleep=waits.append)
    assert got == {"accepted": 576, "duplicates": 0, "stored_through": "2010-07-01T05:45:00Z"}
    assert calls == [576, 576] and waits == [1.0]

    def gone(request: httpx.Request) -> httpx.Response:
        raise httpx.ConnectError("refused", request=request)

    with httpx.Client(base_url="http://logger.test", transport=httpx.MockTransport(gone)) as c, \
            pytest.raises(CliError, match=r"did not take tracker's lines 2–577 after 5 tries "
                                          r"\(ConnectError: refused\); 0 of its readings"):
        post_readings(c, "golden", "tracker", "tok", lf, sleep=waits.append)
    assert waits == [1.0, 1.0, 2.0, 4.0, 8.0]


def test_units_written_in_a_real_header_are_read_and_blank_nights_not_sent() -> None:
    """pvanalytics' snow example names each unit in its header (``POA [W/m²]``, ``INV1 AC
    Power [kW]``) and leaves the combiner's voltage and current and the AC power blank at
    night: the kW read as kW, the blank rows counted out, every value as pandas reads it."""
    name = "snow_data.csv"
    columns = {"power_w": "INV1 AC Power [kW]", "poa_irradiance_w_m2": "POA [W/m²]",
               "temp_module_c": "Module Temp [C]", "temp_air_c": "Ambient Temp [C]"}
    lf = read_logger_file(LOGGERS / name, columns, timezone="Etc/GMT+7")
    assert {f: u for f, (_, u) in lf.columns.items()} == {
        "power_w": "kW", "poa_irradiance_w_m2": "W/m²", "temp_module_c": "C",
        "temp_air_c": "C"}
    assert not any(n.startswith("no unit") for n in lf.notes)
    ref = pd.read_csv(LOGGERS / name, index_col=0)
    np.testing.assert_allclose(lf.values["power_w"], ref["INV1 AC Power [kW]"] * 1000)
    np.testing.assert_allclose(lf.values["poa_irradiance_w_m2"], ref["POA [W/m²]"])
    sent = lf.readings("fixed")
    assert len(sent) == int(ref["INV1 AC Power [kW]"].notna().sum()) == lf.sendable.sum()
    assert len(sent) < len(ref)  # the nights' blank rows
    vi = read_logger_file(LOGGERS / name, {"voltage_v": "INV1 CB2 Voltage [V]",
                                           "current_a": "INV1 CB2 Current [A]"},
                          timezone="Etc/GMT+7")
    assert vi.columns == {"voltage_v": ("INV1 CB2 Voltage [V]", "V"),
                          "current_a": ("INV1 CB2 Current [A]", "A")}


def test_a_meters_a_plus_column_is_one_column_not_a_sum() -> None:
    """A bidirectional meter names its import register ``A+`` (OBIS 1.8.0): that column,
    with or without a unit after it, is one column, not a sum of ``A`` and nothing."""
    text = "ts,A+,A-\n2022-01-02T10:00Z,1.000,0.5\n2022-01-02T10:15Z,1.250,0.5\n"
    for spec in ("A+", "A+:kWh"):
        lf = read_logger_file(text.encode(), {"energy_total_wh": spec})
        assert lf.columns["energy_total_wh"][0] == "A+"
    assert lf.readings("fixed") == [{"ts": "2022-01-02T10:15:00Z", "array": "fixed",
                                     "power_w": 1000.0}]



def test_a_meters_totals_on_a_site_stamping_interval_starts_are_told_to_end_them() -> None:
    """A meter's totals end their intervals: a site that reads stamps as interval starts
    would place each an interval early, and the import says so."""
    from backend.cli.readings import _stamp_note

    summary = {"site_id": "s", "arrays": {"fixed": {"power_from": "energy_total_wh",
                                                    "cadence_s": 900.0}}}
    (note,) = _stamp_note({"readings_stamped": "interval_start"}, summary)
    assert "each would be placed an interval early — set it to interval_end" in note
    assert _stamp_note({"readings_stamped": "interval_end"}, summary) == []
    summary["arrays"]["fixed"]["power_from"] = "energy_wh"  # a portal's: either may be right
    assert _stamp_note({"readings_stamped": "interval_start"}, summary) == []


def test_a_workbooks_date_and_clock_columns_its_rows_and_its_sheets() -> None:
    """A workbook as exporters write them (a reviewer's cases): a date column formatted as a
    date beside a clock column is one time (it read as midnight, every row); a sheet whose
    stored size is wrong is read whole (openpyxl's read-only mode trusts it: 96 rows cut to
    9); empty rows above the header are skipped, the lines named as the sheet's rows; an
    empty first sheet is refused naming the sheets."""
    import datetime as dt

    from openpyxl import Workbook

    def workbook(rows: list[list[Any]], date_format: str | None = None, blank_rows: int = 0,
                 first_empty: bool = False) -> bytes:
        book = Workbook()
        if first_empty:
            book.active.title = "Cover"
            sheet = book.create_sheet("Data")
        else:
            sheet = book.active
        for _ in range(blank_rows):
            sheet.append([])
        for row in rows:
            sheet.append(row)
        if date_format:
            for (cell,) in sheet.iter_rows(min_row=blank_rows + 2, max_col=1):
                cell.number_format = date_format
        buf = io.BytesIO()
        book.save(buf)
        return buf.getvalue()

    day = dt.datetime(2022, 6, 1)
    rows = [["Date", "Time", "power_w"]] + [[day, dt.time(12, 15 * k), 100.0 * k]
                                          for k in range(4)]
    lf = read_logger_file(workbook(rows, "dd.mm.yyyy", blank_rows=2), timezone="UTC")
    assert [f"{t:%H:%M}" for t in lf.times_utc] == ["12:00", "12:15", "12:30", "12:45"]
    assert lf.time_column == "Date + Time" and list(lf.lines) == [4, 5, 6, 7]
    assert list(lf.values["power_w"]) == [0.0, 100.0, 200.0, 300.0]

    long_rows = [["ts", "power_w"]] + [[day + dt.timedelta(minutes=15 * k), 1.0]
                                       for k in range(96)]
    raw = workbook(long_rows)
    with zipfile.ZipFile(io.BytesIO(raw)) as z:
        parts = {n: z.read(n) for n in z.namelist()}
    sheet_xml = parts["xl/worksheets/sheet1.xml"]
    parts["xl/worksheets/sheet1.xml"] = re.sub(rb'<dimension ref="[^"]*" ?/>',
                                               b'<dimension ref="A1:B10"/>', sheet_xml)
    stale = io.BytesIO()
    with zipfile.ZipFile(stale, "w") as z:
        for n, data in parts.items():
            z.writestr(n, data)
    assert b'ref="A1:B10"' in parts["xl/worksheets/sheet1.xml"]
    assert len(read_logger_file(stale.getvalue(), timezone="UTC").readings("fixed")) == 96

    with pytest.raises(ValueError, match=r"first sheet 'Cover' is empty \(its sheets: 'Cover', "
                                         r"'Data'\): move the readings to the first sheet"):
        read_logger_file(workbook(long_rows, first_empty=True), timezone="UTC")
