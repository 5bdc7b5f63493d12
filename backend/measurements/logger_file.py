"""A logger's own export file read as the service's readings (``heliotwin readings import``).

Loggers write their history in their own layout: a Campbell Scientific TOA5 table (a line
naming the logger, then the column names, their units and their processing), a data
system's CSV (``measured_on,ac_power__752`` with ISO times; ``1/2/2022 0:00`` without an
offset), a European portal's export (``;`` between cells, decimal commas). The service
takes readings named and scaled its own way (``backend.measurements.fields``: ``power_w``,
``voltage_v`` …, with UTC offsets), so a user had to rewrite the file before a back-fill.

:func:`read_logger_file` reads such a file as it is and says what it did:

- **Columns** are mapped by the user (``{"power_w": "ac_power_kw_1137:kW"}``, or a sum of
  columns, ``"P_INV1:kW+P_INV2:kW"``, for :data:`ADDITIVE_FIELDS`); a column already named as a
  field maps to itself. Nothing is guessed from a name: two power
  columns in one file (an array's and an inverter's) are common.
- **Units**: the one given after ``:``, else the file's (TOA5's units line, or a header's
  ``[kW]`` / ``(kW)``), else the field's own, and the summary says which
  (:data:`UNITS`).
- **Times**: ISO 8601 with or without an offset, ``M/D/YYYY`` or ``D/M/YYYY`` (the order the
  steps are regular in, or ``date_order``; a 2-digit year, a 12-hour clock), ``YYYY/MM/DD``,
  ``D.M.YYYY``, Unix seconds; a date column and a clock column beside it. A time without an
  offset is read on the logger's clock, ``timezone`` (an IANA zone; ``Etc/GMT+7`` for a
  clock on UTC−7 all year), by :func:`sim.sky.clock_times_to_utc`.
- **Compressed**: a gzip archive of such a file is read as the file; an **Excel workbook**
  (``.xlsx``, a portal's export) as its first sheet (:func:`_xlsx_text`), and a units row
  under a header (``[Wh]``, ``W``) is read as the columns' units (:func:`_row_units`).
- **Energy instead of power**: a portal's export of each interval's energy (``energy_wh``)
  or a meter's running total (``energy_total_wh``) is sent as the mean power over each
  interval (:func:`power_from_energy`): the energy rule then integrates it back.
- **Missing cells** (blank, ``NAN`` — Campbell's mark —, ``NaN``, ``null``, ``-``, ``n/a``)
  leave that field out of the reading; a row left without power or voltage and current is
  not sent (counted, with its first line). Any other text is refused naming line and column.

A weather station's own file (its POA, GHI, temperatures, wind) is read the same way with
``station=True`` and its values joined to an array logger's readings by time
(:func:`join_station`): a reading carries its array's power and the sensors beside it.

The stamps are sent as they are: what they mark (an instant, or the end of the interval
a mean covers) is the site's ``readings_stamped``, one rule for every logger
(:func:`sim.energy.interval_middles`).
"""

from __future__ import annotations

import csv
import gzip
import io
import re
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

import numpy as np
import pandas as pd

from backend.measurements.fields import SENSOR_NAMES
from sim.sky import UTC_OFFSET_AT_END, clock_times_to_utc, weather_text

#: Energy a file may give instead of power: each row's interval's energy, or a meter's
#: running total; sent as the mean power over each interval (:func:`power_from_energy`).
ENERGY_FIELDS = ("energy_wh", "energy_total_wh")
#: The fields a file's columns may be mapped to: the electrical ones, the sensors, energy.
FIELDS = ("power_w", "voltage_v", "current_a", *SENSOR_NAMES, *ENERGY_FIELDS)
#: The fields a weather station's file gives (``station=True``): the sky and the air, and a
#: module's back-of-module temperature.
STATION_FIELDS = ("poa_irradiance_w_m2", "ghi_w_m2", "temp_air_c", "wind_speed_m_s",
                  "temp_module_c")
#: The fields a sum of columns may be mapped to (``power_w=P_INV1+P_INV2``): an array on
#: several inverters or strings in parallel adds its power, current and energy.
ADDITIVE_FIELDS = ("power_w", "current_a", "energy_wh", "energy_total_wh")
#: A meter's step longer than this many times the file's spacing spans rows missing: its
#: energy is not sent as a power (a mean over a longer interval than the readings' would be
#: placed as one of theirs). The bound sim.energy puts on a regular series's steps.
METER_MAX_STEP = 1.5

#: Per field, the units a file may give it in: normalised unit (:func:`_unit_key`) → (scale,
#: offset) onto the field's own unit, value·scale + offset. The first is the field's own.
_POWER = {"w": (1.0, 0.0), "watts": (1.0, 0.0), "kw": (1e3, 0.0), "kilowatts": (1e3, 0.0),
          "mw": (1e6, 0.0)}
_IRRADIANCE = {"w/m2": (1.0, 0.0), "kw/m2": (1e3, 0.0)}
_TEMPERATURE = {"c": (1.0, 0.0), "k": (1.0, -273.15), "f": (5 / 9, -32 * 5 / 9)}
_ANGLE = {"deg": (1.0, 0.0), "degrees": (1.0, 0.0), "rad": (180 / np.pi, 0.0)}
_MRAD = {"mrad": (1.0, 0.0), "rad": (1e3, 0.0)}
_ENERGY = {"wh": (1.0, 0.0), "kwh": (1e3, 0.0), "mwh": (1e6, 0.0)}
UNITS: dict[str, dict[str, tuple[float, float]]] = {
    "power_w": _POWER,
    "voltage_v": {"v": (1.0, 0.0), "volts": (1.0, 0.0), "mv": (1e-3, 0.0), "kv": (1e3, 0.0)},
    "current_a": {"a": (1.0, 0.0), "amps": (1.0, 0.0), "amperes": (1.0, 0.0),
                  "ma": (1e-3, 0.0)},
    "poa_irradiance_w_m2": _IRRADIANCE, "ghi_w_m2": _IRRADIANCE,
    "temp_module_c": _TEMPERATURE, "temp_air_c": _TEMPERATURE,
    "wind_speed_m_s": {"m/s": (1.0, 0.0), "meters/second": (1.0, 0.0),
                       "km/h": (1 / 3.6, 0.0), "mph": (0.44704, 0.0), "kn": (0.514444, 0.0),
                       "knots": (0.514444, 0.0)},
    "azimuth_deg": _ANGLE, "elevation_deg": _ANGLE,
    "sun_offset_x_mrad": _MRAD, "sun_offset_y_mrad": _MRAD,
    "energy_wh": _ENERGY, "energy_total_wh": _ENERGY,
}
#: Each field's own unit, as the summary writes it.
OWN_UNITS = {"power_w": "W", "voltage_v": "V", "current_a": "A", "poa_irradiance_w_m2": "W/m²",
             "ghi_w_m2": "W/m²", "temp_module_c": "°C", "temp_air_c": "°C",
             "wind_speed_m_s": "m/s", "azimuth_deg": "°", "elevation_deg": "°",
             "sun_offset_x_mrad": "mrad", "sun_offset_y_mrad": "mrad",
             "energy_wh": "Wh", "energy_total_wh": "Wh"}
#: Cells that mean "no value": Campbell's NAN, pandas' and spreadsheets' marks.
MISSING = frozenset({"", "nan", "null", "none", "na", "n/a", "-", "--", "#n/a", "inf", "-inf"})
DATE_ORDERS = ("mdy", "dmy")


@dataclass
class LoggerFile:
    """What :func:`read_logger_file` read: one row per time, in the file's order."""

    layout: str  # "TOA5", "CSV (',')", "CSV (';', decimal comma)" …
    time_column: str
    times_utc: pd.DatetimeIndex
    values: pd.DataFrame  # the mapped fields in their own units, NaN where missing
    lines: np.ndarray  # each row's line in the file (1-based)
    columns: dict[str, tuple[str, str]]  # field → (the file's column, the unit read)
    notes: list[str] = field(default_factory=list)
    power_from: str | None = None  # the energy field power_w was made from, if any

    @cached_property
    def sendable(self) -> np.ndarray:
        """Rows with power, or with voltage and current: the ones a reading is made of (once:
        every batch of :meth:`readings` asks)."""
        v = self.values
        has = v["power_w"].notna() if "power_w" in v else pd.Series(False, index=v.index)
        if "voltage_v" in v and "current_a" in v:
            has |= v["voltage_v"].notna() & v["current_a"].notna()
        return has.to_numpy()

    def readings(self, array: str, start: int = 0, stop: int | None = None
                 ) -> list[dict[str, Any]]:
        """The sendable rows ``[start, stop)`` (counted among the sendable ones) as the
        service's JSON readings of ``array`` (``ts`` in UTC): each field that has a value,
        voltage and current only together. Made a batch at a time by a caller that posts
        them, so a year of minutes is never all dictionaries at once."""
        rows = np.flatnonzero(self.sendable)[start:stop]
        values = self.values.iloc[rows].round(6)
        if "voltage_v" in values:
            lone = values["voltage_v"].isna() | values["current_a"].isna()
            values.loc[lone, ["voltage_v", "current_a"]] = np.nan
        stamps = self.times_utc[rows].strftime("%Y-%m-%dT%H:%M:%SZ").tolist()
        names = list(values.columns)
        return [{"ts": ts, "array": array,
                 **{n: x for n, x in zip(names, row, strict=True) if x == x}}  # x == x: not NaN
                for ts, row in zip(stamps, values.to_numpy().tolist(), strict=True)]

    def cadence_s(self) -> float | None:
        """The sendable rows' :func:`spacing_s`."""
        return spacing_s(self.times_utc[self.sendable].as_unit("ns").asi8 / 1e9)


def spacing_s(times_s: np.ndarray) -> float | None:
    """A series' spacing [s]: the median step between its distinct times (a stamp written
    twice is no interval of 0 s; the rows in any order); None under two distinct times. The
    one rule for the readings' cadence, a meter's interval and a station's spacing."""
    t = np.unique(np.asarray(times_s, np.float64))
    return float(np.median(np.diff(t))) if t.size > 1 else None


def _unit_key(unit: str) -> str:
    """A unit as :data:`UNITS` names it: lower case, no spaces, ``m²``/``m^2`` as ``m2``,
    ``°C``/``Deg C``/``degC`` as ``c``."""
    u = unit.strip().lower().replace(" ", "").replace("²", "2").replace("^", "")
    u = re.sub(r"^(deg|°)(?=[cfk]$)", "", u)
    return {"degree": "deg", "°": "deg", "m/sec": "m/s", "ms-1": "m/s", "wm-2": "w/m2",
            "kwm-2": "kw/m2"}.get(u, u)


def _header_unit(name: str) -> str | None:
    """A unit written in a column's name: ``P_AC [kW]``, ``Power (W)`` — not a number in
    brackets, as ``Energy | Symo 8.2-3-M (1)`` numbers its inverter."""
    m = re.search(r"[\[(]([^\[\]()]+)[\])]\s*$", name)
    unit = m.group(1).strip() if m else None
    return unit if unit and (_unit_key(unit) in _UNIT_KEYS or _UNIT_LETTERS.fullmatch(unit)) \
        else None


#: Every unit a file may give a field in (:data:`UNITS`), as :func:`_unit_key` writes them.
_UNIT_KEYS = frozenset(k for units in UNITS.values() for k in units)
#: A cell that may be a unit of a column no field is mapped to (``%``, ``hPa``, ``Ohm``).
_UNIT_LETTERS = re.compile(r"[A-Za-z%°µΩ/²³·^*-]{1,12}")


def _row_units(cells: list[str]) -> list[str]:
    """A units row's units, one per cell ("" where none), or [] when the row is not one: a
    portal's export may put one under its header (``[dd.MM.yyyy HH:mm]``, ``[Wh]``, ``W``,
    ``%``, ``-``) — every cell bracketed, a unit's letters or a missing value's mark, at
    least one a unit a field can be given in, none a number or a time (a data row's time
    cell never reads as a unit)."""
    units, known = [], False
    for cell in cells:
        c = cell.strip()
        inner = c[1:-1].strip() if len(c) > 1 and (c[0], c[-1]) in (("[", "]"), ("(", ")")) \
            else c
        is_unit = bool(inner) and _unit_key(inner) in _UNIT_KEYS
        if c and inner == c and not is_unit and not _UNIT_LETTERS.fullmatch(c) \
                and c.lower() not in MISSING:
            return []  # a value or a time: a data row
        known |= is_unit
        units.append(inner if is_unit else "")
    return units if known else []


def _xlsx_text(raw: bytes) -> tuple[str, str, int]:
    """An .xlsx workbook's first worksheet as CSV text (``,``; a date-time cell in ISO 8601,
    naive as Excel keeps it: read on ``timezone``; a cell formatted as a date alone as a
    date, so a clock column beside it completes it), the sheet's name, and the sheet's row
    of the text's first line (empty rows above a header are left out): a portal's export
    (Fronius Solar.web, Huawei FusionSolar …) is a workbook (openpyxl, read-only)."""
    import datetime as dt

    from openpyxl import load_workbook

    def cell_text(cell: Any) -> str:
        v = cell.value
        if v is None:
            return ""
        if isinstance(v, dt.datetime):  # a date's format without hours or seconds: a date
            fmt = str(getattr(cell, "number_format", "")).lower()
            return v.date().isoformat() if v.time() == dt.time() and "h" not in fmt \
                and "s" not in fmt else v.isoformat(sep=" ")
        if isinstance(v, dt.date | dt.time):
            return v.isoformat()
        return repr(v) if isinstance(v, float) else str(v)

    try:
        book = load_workbook(io.BytesIO(raw), read_only=True, data_only=True)
    except Exception as exc:  # a zip that is no workbook: BadZipFile, KeyError, …
        raise ValueError(f"the file is a zip archive but no .xlsx workbook ({type(exc).__name__}"
                         f": {exc})") from None
    try:
        sheet = book.worksheets[0]
        sheet.reset_dimensions()  # a size the exporter stored wrong would cut rows silently
        rows = [[cell_text(c) for c in row] for row in sheet.iter_rows()]
    except Exception as exc:  # a damaged sheet (a download cut short)
        raise ValueError(f"the workbook's first sheet cannot be read ({type(exc).__name__}: "
                         f"{exc})") from None
    finally:
        book.close()
    first = next((i for i, row in enumerate(rows) if any(row)), None)
    if first is None:
        raise ValueError(f"the workbook's first sheet {sheet.title!r} is empty (its sheets: "
                         f"{', '.join(repr(n) for n in book.sheetnames)}): move the readings "
                         "to the first sheet")
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerows(rows[first:])
    return out.getvalue(), sheet.title, first + 1


def _header(text: str, sep: str | None = None) -> tuple[list[list[str]], int, str, str]:
    """The header's rows (TOA5's four, a CSV's one and a units row under it, if any:
    :func:`_row_units`), the file line the body starts after, the
    layout's name (TOA5, or a CSV) and its separator: ``sep`` where it is known (a
    workbook's text), else ``,``, ``;`` or a tab, the one its header line holds most (an
    Excel ``sep=`` first line says it)."""
    head = text[:65536].splitlines()[:6]
    skip = 0
    if head and head[0].lower().startswith("sep=") and len(head[0].strip()) == 5:
        sep, skip, head = head[0].strip()[4], 1, head[1:]
    if not head or not head[0].strip():
        raise ValueError("the file is empty, or its first line is blank")
    if sep is None:
        sep = max((",", ";", "\t"), key=lambda s: head[0].count(s))
    rows = list(csv.reader(io.StringIO("\n".join(head)), delimiter=sep))
    toa5 = bool(rows[0]) and rows[0][0] == "TOA5"
    n = 4 if toa5 else (2 if len(rows) > 1 and _row_units(rows[1]) else 1)
    if len(rows) < n:
        raise ValueError("the file ends inside its header")
    name = "TOA5" if toa5 else ("CSV (tab)" if sep == "\t" else f"CSV ('{sep}')")
    return rows[:n], skip + n, name, sep


def _body(text: str, skip: int, sep: str, width: int) -> tuple[pd.DataFrame, np.ndarray]:
    """The rows after the header as text cells (pandas' C reader: a year of minutes is
    read in seconds), blank lines dropped, and each row's line in the file (1-based). A row
    with more cells than the header is refused naming its line; a shorter one's missing
    cells are blank (missing values)."""
    try:
        frame = pd.read_csv(io.StringIO(text), sep=sep, header=None, skiprows=skip,
                            names=range(width), dtype=str, keep_default_na=False,
                            skip_blank_lines=False, skipinitialspace=True, engine="c")
    except pd.errors.ParserError as exc:
        m = re.search(r"Expected (\d+) fields in line (\d+), saw (\d+)", str(exc))
        if m is None:
            raise ValueError(f"the file cannot be read as a table: {exc}") from None
        raise ValueError(f"line {m.group(2)} has {m.group(3)} cells; the header has "
                         f"{width}") from None
    filled = np.zeros(len(frame), bool)
    for col in frame.columns:  # leading blanks are skipped (skipinitialspace)
        filled |= frame[col].to_numpy() != ""
    kept = np.flatnonzero(filled)
    if not kept.size:
        raise ValueError("the file has a header and no rows")
    return frame.iloc[kept].reset_index(drop=True), kept + skip + 1


def _numbers(cells: pd.Series, decimal_comma: bool, column: str, lines: np.ndarray
             ) -> np.ndarray:
    """A column's cells as numbers, NaN for the :data:`MISSING` marks; any other text is
    refused naming its line, the column and how many such cells."""
    text = cells.fillna("")
    if decimal_comma:
        text = text.str.replace(",", ".", regex=False)
    values = pd.to_numeric(text, errors="coerce").to_numpy(dtype=float, copy=True)
    odd = np.flatnonzero(~np.isfinite(values))  # few: only these cells' text is looked at
    marks = text.iloc[odd].str.strip()
    bad = odd[~marks.str.lower().isin(MISSING).to_numpy()]
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"column {column!r}: {marks.loc[text.index[i]][:20]!r} at line "
                         f"{lines[i]} is not a number ({bad.size} such cells; a missing value "
                         "may be blank or NAN)")
    values[odd] = np.nan
    return values


_ISO = re.compile(r"^\d{4}-\d\d-\d\d(?:[T ]\d\d?:\d\d(?::\d\d(?:\.\d+)?)?)?")
#: Dates a spreadsheet or a portal writes: year first (2022/01/02), or day and month first
#: with a 4- or 2-digit year (1/2/2022, 02.01.22), then a clock (13:15, 1:15:00 PM)
_YEAR_FIRST = re.compile(r"^\d{4}([/.])\d{1,2}\1\d{1,2}(?!\d)")
_YEAR_LAST = re.compile(r"^\d{1,2}([/.-])\d{1,2}\1(\d{4}|\d{2})(?!\d)")
_CLOCK = re.compile(r"[ T]+\d{1,2}:\d\d(:\d\d)?(\s*[AaPp]\.?[Mm]\.?)?$")
_UNIX = re.compile(r"^\d{9,10}(?:\.\d+)?$")
_CLOCK_ONLY = re.compile(r"^\d{1,2}:\d\d(:\d\d(\.\d+)?)?(\s*[AaPp]\.?[Mm]\.?)?$")


def _times(cells: pd.Series, column: str, lines: np.ndarray, timezone: str | None,
           date_order: str | None) -> tuple[pd.DatetimeIndex, list[str]]:
    """The time column as UTC instants, and notes on how it was read (see the module)."""
    text = cells.fillna("").astype(str).str.strip()
    first = text.iloc[0]

    def where(i: int) -> str:
        return f"line {lines[i]}"

    notes: list[str] = []
    if _UNIX.match(first):
        secs = pd.to_numeric(text, errors="coerce")
        if secs.isna().any():
            i = int(np.flatnonzero(secs.isna().to_numpy())[0])
            raise ValueError(f"{column}: {text.iloc[i][:30]!r} at {where(i)} is not a Unix "
                             "time like the first row's")
        return pd.DatetimeIndex(pd.to_datetime(secs, unit="s", utc=True)), [
            f"times: Unix seconds in column {column!r}"]
    offset = text.str.contains(UTC_OFFSET_AT_END, regex=True).to_numpy()
    if _ISO.match(first):
        if offset.all():
            parsed = pd.to_datetime(text, format="ISO8601", errors="coerce", utc=True)
        elif not offset.any():
            parsed = pd.to_datetime(text, format="ISO8601", errors="coerce")
        else:
            i = int(np.flatnonzero(offset != offset[0])[0])
            raise ValueError(f"{column}: {text.iloc[i][:30]!r} at {where(i)} has "
                             f"{'a' if offset[i] else 'no'} UTC offset while line {lines[0]} "
                             f"has {'one' if offset[0] else 'none'}: write all alike")
        form = "ISO 8601"
    else:
        parsed, form = _calendar_times(text, column, where, date_order)
    if parsed.isna().any():
        i = int(np.flatnonzero(parsed.isna().to_numpy())[0])
        raise ValueError(f"{column}: {text.iloc[i][:30]!r} at {where(i)} is not a time like "
                         f"line {lines[0]}'s ({first[:30]!r}, {form})")
    if parsed.dt.tz is not None:
        notes.append(f"times: {form} with UTC offsets in column {column!r}")
        return pd.DatetimeIndex(parsed).tz_convert("UTC"), notes
    if timezone is None:
        raise ValueError(f"{column}: the times have no UTC offset ({first[:30]!r} at "
                         f"{where(0)}): say which clock they were read on with --timezone — "
                         "an IANA zone (America/Denver), or Etc/GMT+7 for a logger's clock "
                         "on UTC−7 all year (most loggers do not change for summer time)")
    try:
        ZoneInfo(timezone)
    except (ZoneInfoNotFoundError, ValueError):
        raise ValueError(f"timezone: {timezone!r} is not an IANA time zone (America/Denver, "
                         "Etc/GMT+7 for UTC−7)") from None
    notes.append(f"times: {form} on a clock in {timezone}, column {column!r}")
    return clock_times_to_utc(parsed, timezone, text, where), notes


def _calendar_times(text: pd.Series, column: str, where: Any, date_order: str | None
                    ) -> tuple[pd.Series, str]:
    """Times written as a spreadsheet or a portal writes them (:data:`_YEAR_FIRST`,
    :data:`_YEAR_LAST`, :data:`_CLOCK`), naive, and the form they were read in. Day and month
    first: the order :func:`_pick_date_order` finds (``D.M.`` is day first unless
    ``date_order`` says otherwise)."""
    first = text.iloc[0]
    ymd, ydm = _YEAR_FIRST.match(first), _YEAR_LAST.match(first)
    clock = _CLOCK.search(first)
    if (ymd is None and ydm is None) or (clock is None and len(first) > 10):
        raise ValueError(f"{column}: {first[:30]!r} at {where(0)} is not a time this reader "
                         "knows: ISO 8601 (2022-01-02 13:15, with or without a UTC offset), "
                         "2022/01/02 13:15, M/D/YYYY or D/M/YYYY H:MM[:SS] [AM|PM], "
                         "D.M.YYYY H:MM, a 2-digit year, or Unix seconds")
    ampm = clock is not None and clock.group(2) is not None
    hms = "" if clock is None else (
        (" %I" if ampm else " %H") + ":%M" + (":%S" if clock.group(1) else "")
        + (" %p" if ampm else ""))
    text = text.str.replace("T", " ", regex=False)
    if ampm:  # 1:15pm, 1:15 P.M. → 1:15 PM
        text = text.str.replace(r"\s*([AaPp])\.?[Mm]\.?$", lambda m: f" {m.group(1).upper()}M",
                                regex=True)
    if ymd is not None:
        sep = ymd.group(1)
        return pd.to_datetime(text, format=f"%Y{sep}%m{sep}%d{hms}", errors="coerce"), \
            "year/month/day"
    assert ydm is not None
    sep, year = ydm.group(1), "%Y" if len(ydm.group(2)) == 4 else "%y"
    orders = [date_order] if date_order else (["dmy"] if sep == "." else list(DATE_ORDERS))
    tried = {order: pd.to_datetime(text, errors="coerce", format=(
        f"%m{sep}%d{sep}{year}" if order == "mdy" else f"%d{sep}%m{sep}{year}") + hms)
        for order in orders}
    parsed = _pick_date_order(tried, text, where, date_order)
    return parsed, {"mdy": "month/day/year", "dmy": "day/month/year"}[
        next(k for k, v in tried.items() if v is parsed)]


def _pick_date_order(tried: dict[str, pd.Series], text: pd.Series, where: Any,
                     date_order: str | None) -> pd.Series:
    """Of month- and day-first readings, the one every time parses in and whose steps are
    regular (the fewest distinct spacings; a logger's clock ticks evenly): ``1/2/2022`` to
    ``1/6/2022`` read day-first jumps a month a day. Refused as ambiguous when both read
    alike well and differ (every day ≤ 12 and as regular either way)."""
    ok = {k: v for k, v in tried.items() if not v.isna().any()}
    if not ok:
        return next(iter(tried.values()))  # the caller names the first bad line
    if len(ok) == 1:
        return next(iter(ok.values()))

    def irregularity(v: pd.Series) -> int:
        return int(np.unique(np.diff(v.to_numpy().astype("datetime64[s]").astype(np.int64))
                             ).size)

    score = {k: irregularity(v) for k, v in ok.items()}
    best = min(score.values())
    winners = [k for k, s in score.items() if s == best]
    if len(winners) > 1 and not ok["mdy"].equals(ok["dmy"]):
        raise ValueError(f"the dates read as month/day/year and as day/month/year alike "
                         f"({text.iloc[0][:30]!r} at {where(0)}): say which with "
                         "--date-order mdy or dmy")
    return ok[winners[0]]


def read_logger_file(source: str | Path | bytes, columns: dict[str, str] | None = None,
                     timezone: str | None = None, time_column: str | None = None,
                     date_order: str | None = None, fields_by_name: bool = True,
                     station: bool = False) -> LoggerFile:
    """Read a logger's export (see the module). ``columns``: field → ``"NAME"`` or
    ``"NAME:UNIT"`` (the file's column; its unit when the file does not say it or says it
    otherwise). ``time_column``: the column of the times (default: TOA5's ``TIMESTAMP``,
    else the first column whose first cell reads as a time). ``date_order``: ``"mdy"`` or
    ``"dmy"`` for slash dates the file cannot tell. ``fields_by_name``: a column named as a
    field maps to it (not when the file holds several arrays' readings). ``station``: a
    weather station's file, of :data:`STATION_FIELDS` only and no power (every row kept;
    :func:`join_station`). Errors are :class:`ValueError`s naming the column, the line and
    what to do."""
    if date_order is not None and date_order not in DATE_ORDERS:
        raise ValueError(f"date_order must be mdy or dmy; got {date_order!r}")
    raw = source if isinstance(source, bytes) else Path(source).read_bytes()
    if raw[:2] == b"\x1f\x8b":  # a gzip archive of the file (.csv.gz, .dat.gz)
        raw = gzip.decompress(raw)
    if raw[:8] == b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1":  # OLE2: Excel 97-2003
        raise ValueError("the file is an Excel 97-2003 workbook (.xls): open it and save it as "
                         ".xlsx or CSV")
    sheet, first_row = None, 1
    if raw[:4] == b"PK\x03\x04":  # a zip: an .xlsx workbook, read as its first sheet's CSV
        text, sheet, first_row = _xlsx_text(raw)
    else:
        text = weather_text(raw)
    header, skip, layout, sep = _header(text, "," if sheet is not None else None)
    if sheet is not None:
        layout = f"Excel workbook, sheet {sheet!r}"
    toa5 = layout == "TOA5"
    names = [c.strip() for c in header[1 if toa5 else 0]]
    width = len(names)
    differ: list[str] = []  # a name's unit against the units row's, where both say one
    if toa5:
        file_units = ([c.strip() for c in header[2]] + [""] * width)[:width]
    else:  # a header's [kW], else a units row under it (a portal's export)
        row = (_row_units(header[1]) if len(header) > 1 else []) + [""] * width
        file_units = [(_header_unit(n) or row[i]) for i, n in enumerate(names)]
        differ = [f"{n!r} says {u!r}, the units row {row[i]!r}" for i, (n, u) in
                  enumerate(zip(names, file_units, strict=True))
                  if u and row[i] and _unit_key(u) != _unit_key(row[i])]
    frame, lines = _body(text, skip, sep, width)
    lines = lines + (first_row - 1)  # a sheet's rows above its header
    del text
    blank = [i for i, n in enumerate(names) if not n]
    label = {i: (n or f"column {i + 1}") for i, n in enumerate(names)}
    index = _column_index(names)

    tcol, clock = _time_column(frame, names, label, index, time_column, toa5)
    when, when_label = frame[tcol], label[tcol]
    if clock is not None:  # a date column and a clock column beside it
        when, when_label = frame[tcol].str.strip() + " " + frame[clock].str.strip(), \
            f"{label[tcol]} + {label[clock]}"
    times, notes = _times(when, when_label, lines, timezone, date_order)
    if differ:
        notes.append("units: the column's name is read before the units row where they "
                     "differ: " + "; ".join(differ) + " (give NAME:UNIT where that is wrong)")
    decimal_comma = sep != "," and _has_decimal_commas(frame, tcol)
    if decimal_comma:
        layout = layout[:-1] + ", decimal comma)"

    allowed = STATION_FIELDS if station else FIELDS
    mapping = dict(columns or {})
    for i, n in enumerate(names if fields_by_name else []):  # a column named as a field
        if n.lower() in allowed and n.lower() not in mapping and i not in blank:
            mapping[n.lower()] = n
    given = columns or {}
    if any(f in given for f in ENERGY_FIELDS) and "power_w" not in given:
        mapping.pop("power_w", None)  # energy mapped: a column named power_w is not the power
    elif "power_w" in mapping:  # energy columns named as fields beside a power column
        mapping = {f: c for f, c in mapping.items() if f not in ENERGY_FIELDS or f in given}
    unknown = [f for f in mapping if f not in allowed]
    if unknown:
        raise ValueError(f"column: {unknown[0]!r} is not a field"
                         + (" of a weather station" if station else "")
                         + f"; the fields are {', '.join(allowed)}")
    if station and not mapping:
        raise ValueError("column: map a weather station's fields to the file's columns ("
                         + ", ".join(allowed) + "); its columns are "
                         + ", ".join(repr(label[i]) for i in range(width)))
    values = pd.DataFrame(index=frame.index)
    used: dict[str, tuple[str, str]] = {}
    unitless = []
    for fld, spec in mapping.items():
        # NAME[:UNIT], or a sum of them (an array on two inverters: P_INV1:kW+P_INV2:W); a
        # column's whole name first (a meter's "A+" is one column)
        head, colon, unit_part = spec.rpartition(":")
        pieces = [spec] if spec in index or (colon and head in index and "+" not in unit_part) \
            else [x.strip() for x in spec.split("+")]
        named = [(x, "") if x in index or ":" not in x else
                 (x.rpartition(":")[0].strip(), x.rpartition(":")[2].strip()) for x in pieces]
        parts = [n for n, _ in named]
        for part in parts:
            if part not in index:
                raise ValueError(f"column: {fld}={spec!r}: the file has no column {part!r}; "
                                 "its columns are "
                                 + ", ".join(repr(label[i]) for i in range(width)))
        if len(parts) > 1 and fld not in ADDITIVE_FIELDS:
            raise ValueError(f"column: {fld}={spec!r}: only {', '.join(ADDITIVE_FIELDS)} add up "
                             "over columns")
        if len(parts) > 1 and any(u for _, u in named) and not all(
                u or file_units[index[n]] for n, u in named):
            raise ValueError(f"column: {fld}={spec!r}: a unit is given for some of the columns "
                             "only; give each its own (P_INV1:kW+P_INV2:kW)")
        read_units, total = [], np.zeros(len(frame))
        for part, unit_given in named:
            i = index[part]
            unit = unit_given or file_units[i]
            units = UNITS[fld]
            key = _unit_key(unit) if unit else next(iter(units))
            if key not in units:
                raise ValueError(f"column: {fld}={spec!r}: unit {unit!r} is not one of "
                                 f"{', '.join(units)} (give NAME:UNIT)")
            scale, add = units[key]
            # a cell missing in any column leaves the sum missing: a part of the array unread
            total = total + _numbers(frame[i], decimal_comma, label[i], lines) * scale + add
            read_units.append(unit or OWN_UNITS[fld])
            if not unit:
                unitless.append(f"{fld} = {label[i]!r} in {OWN_UNITS[fld]}")
        values[fld] = total
        used[fld] = (" + ".join(label[index[n]] for n in parts),
                     " + ".join(dict.fromkeys(read_units)))
    if unitless:
        notes.append("no unit in the file, read in the field's own: " + ", ".join(unitless)
                     + " (give NAME:UNIT where that is wrong)")
    energy = [f for f in ENERGY_FIELDS if f in values]
    if energy and ("power_w" in values or len(energy) > 1):
        raise ValueError("column: map one of power_w, energy_wh (each interval's energy) and "
                         "energy_total_wh (a meter's running total); got "
                         + ", ".join([f for f in ("power_w", *ENERGY_FIELDS) if f in values]))
    power_from = energy[0] if energy else None
    if power_from is not None:
        values["power_w"], made = power_from_energy(times, values.pop(power_from).to_numpy(),
                                                    power_from, used[power_from][0], lines)
        notes.extend(made)
    if station:
        return LoggerFile(layout, when_label, times, values, lines, used, notes)
    if "power_w" not in values and not {"voltage_v", "current_a"} <= set(values):
        raise ValueError("column: map power_w (or energy_wh, energy_total_wh), or voltage_v "
                         "and current_a, to the file's columns (--column power_w=NAME[:UNIT]); "
                         "its columns are "
                         + ", ".join(repr(label[i]) for i in range(width) if i != tcol))
    if ("voltage_v" in values) != ("current_a" in values):
        raise ValueError("column: voltage_v and current_a go together; map both or neither")
    return LoggerFile(layout, when_label, times, values, lines, used, notes, power_from)


def join_station(lf: LoggerFile, station: LoggerFile, stamped: str, name: str) -> list[str]:
    """Put a weather station's values (``station``, read with ``station=True``) beside
    ``lf``'s readings as their sensors, in place, and say how (notes; ``name``: the
    station's file as the notes call it).

    A reading takes the station's value at its stamp, linear between the station's rows at
    most :data:`METER_MAX_STEP` of its spacings apart, the energy rule's line
    (:func:`sim.energy.on_grid`); but where the readings are interval means (``stamped``,
    the site's ``readings_stamped``: ``interval_end`` or ``interval_start``) and the station
    reads at least twice per interval, the mean of its rows in the reading's interval (a
    15-minute mean of power beside the sky of the same quarter hour, not of its last
    minute; at least half the interval's rows, else none). A field both files give is
    refused: which one is the reading's would be a guess."""
    from sim.energy import on_grid

    both = sorted(set(lf.values) & set(station.values))
    if both:
        raise ValueError(f"column: {', '.join(both)}: mapped in both files; map each field "
                         "from one of them")
    ts = station.times_utc.as_unit("s").asi8.astype(np.float64)
    order = np.argsort(ts, kind="stable")
    ts = ts[order]
    station_s = spacing_s(ts)
    if station_s is None:
        raise ValueError(f"{name}: two rows at different times are needed to join its values")
    t = lf.times_utc.as_unit("s").asi8.astype(np.float64)
    interval_s = lf.cadence_s() or 0.0
    means = stamped != "instant" and 2 * station_s <= interval_s
    if stamped == "interval_end":  # the station's rows in (t − interval, t]
        first = np.searchsorted(ts, t - interval_s, side="right")
        last = np.searchsorted(ts, t, side="right")
    else:  # [t, t + interval)
        first = np.searchsorted(ts, t, side="left")
        last = np.searchsorted(ts, t + interval_s, side="left")
    for fld in station.values:
        v = station.values[fld].to_numpy(np.float64)[order]
        if not means:
            lf.values[fld] = on_grid(ts, v, t, METER_MAX_STEP * station_s)
            continue
        ok = np.isfinite(v)
        total = np.concatenate(([0.0], np.cumsum(np.where(ok, v, 0.0))))
        count = np.concatenate(([0], np.cumsum(ok)))
        n = count[last] - count[first]
        enough = n >= 0.5 * interval_s / station_s
        lf.values[fld] = np.where(enough, (total[last] - total[first]) / np.maximum(n, 1),
                                  np.nan)
    got = lf.values[list(station.values)].notna().any(axis=1).to_numpy() & lf.sendable
    how = (f"the mean of its rows in each reading's interval ({interval_s:g} s, readings "
           f"stamped {stamped})" if means else
           f"its value at each reading's stamp (linear between its rows, none across a gap "
           f"over {METER_MAX_STEP:g} × its {station_s:g} s spacing)")
    return [f"sensors from {name} ({', '.join(station.values)}): {how}; "
            f"{int(got.sum())} of {int(lf.sendable.sum())} readings have them"]


def power_from_energy(times_utc: pd.DatetimeIndex, energy_wh: np.ndarray, kind: str,
                      column: str, lines: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Each row's power [W] from a file's energy [Wh] and notes on how it was made: the mean
    over the interval the energy covers, which the energy rule integrates back (a portal's
    or an inverter's export gives energy, not power).

    ``kind`` ``"energy_wh"``: each row's energy over its own interval, the rows' median
    spacing (a row after a gap still covers one interval); what its stamp marks, the start
    or the end, is the site's ``readings_stamped``. ``"energy_total_wh"``: a meter's running
    total; a row's power is its rise since the row before over the time between them, the
    mean over the interval its stamp ends. A total that goes back (a reset, a new meter) or
    a step over :data:`METER_MAX_STEP` spacings (a gap) gives no power there, and the notes
    say how much energy that leaves out; the smallest rise bounds the power's resolution."""
    t = times_utc.as_unit("s").asi8.astype(np.float64)
    have = np.flatnonzero(np.isfinite(energy_wh))
    order = have[np.argsort(t[have], kind="stable")]
    steps_s = np.diff(t[order])
    spacing = spacing_s(t[order])
    if spacing is None:
        raise ValueError(f"column: {kind}={column!r}: two rows at different times are needed "
                         "to know the interval its energy covers")
    power_w = np.full(energy_wh.size, np.nan)
    if kind == "energy_wh":
        power_w[have] = energy_wh[have] * 3600.0 / spacing
        return power_w, [f"power_w: {column!r}, each row's energy over its interval (the "
                         f"rows' spacing, {spacing:g} s): the interval's mean power"]
    rise_wh = np.diff(energy_wh[order])
    later = order[1:]
    gap = steps_s > METER_MAX_STEP * spacing
    ok = (steps_s > 0) & ~gap & (rise_wh >= 0)
    power_w[later[ok]] = rise_wh[ok] * 3600.0 / steps_s[ok]
    notes = [f"power_w: {column!r}, a meter's running total: each row's rise since the row "
             "before over the time between them, the mean power of the interval its stamp "
             "ends"]
    if (back := np.flatnonzero(rise_wh < 0)).size:
        notes.append(f"{column!r} goes back on {back.size} rows (a reset — a day's total at "
                     f"midnight — or a new meter; the first at line {lines[later[back[0]]]}): "
                     "their intervals are not sent")
    if (over := np.flatnonzero(gap & (rise_wh >= 0))).size:
        notes.append(f"{column!r} spans a gap {over.size} × (a step over {METER_MAX_STEP:g} × "
                     f"its {spacing:g} s spacing: rows missing, or blank totals; the first "
                     f"ending at line {lines[later[over[0]]]}): the "
                     f"{rise_wh[over].sum():.6g} Wh it rose over them are not sent as power")
    if (rises := rise_wh[rise_wh > 0]).size:
        least = float(rises.min())
        notes.append(f"{column!r}'s smallest rise is {least:.6g} Wh: an interval's power is "
                     f"known to {least * 3600.0 / spacing:.3g} W at best")
    return power_w, notes


def _column_index(names: list[str]) -> dict[str, int]:
    """The file's column names → their position; a name given twice is refused."""
    index: dict[str, int] = {}
    for i, n in enumerate(names):
        if n and n in index:
            raise ValueError(f"the header names column {n!r} twice")
        if n:
            index[n] = i
    return index


def _time_column(frame: pd.DataFrame, names: list[str], label: dict[int, str],
                 index: dict[str, int], time_column: str | None, toa5: bool
                 ) -> tuple[int, int | None]:
    """The position of the times, and of a clock column that completes a date column (an
    Arduino's or a spreadsheet's ``Date,Time``): ``time_column`` (``"Date+Time"`` for such
    a pair), TOA5's ``TIMESTAMP``, else the first column whose first cell reads as a time
    (an unnamed first column: a pandas index), with the column after it when that holds
    only clock times and this only dates."""
    if time_column is not None:
        parts = time_column.split("+") if time_column not in index else [time_column]
        if len(parts) > 2:
            raise ValueError(f"time_column: {time_column!r} is one column, or a date column "
                             "and a clock column as DATE+CLOCK")
        for part in parts:
            if part not in index:
                raise ValueError(f"time_column: the file has no column {part!r}; its "
                                 f"columns are {', '.join(repr(label[i]) for i in label)}")
        return index[parts[0]], (index[parts[1]] if len(parts) > 1 else None)
    if toa5 and "TIMESTAMP" in index:
        return index["TIMESTAMP"], None
    for i in range(len(names)):
        cell = str(frame[i].iloc[0]).strip()
        if _ISO.match(cell) or _YEAR_FIRST.match(cell) or _YEAR_LAST.match(cell) or (
                _UNIX.match(cell) and names[i].lower() in ("ts", "time", "timestamp",
                                                           "unix", "unix_s", "epoch")):
            after = str(frame[i + 1].iloc[0]).strip() if i + 1 < len(names) else ""
            date_only = not _UNIX.match(cell) and _CLOCK.search(cell) is None
            return i, (i + 1 if date_only and _CLOCK_ONLY.match(after) else None)
    raise ValueError("time_column: no column of times found (ISO 8601, M/D/YYYY H:MM, "
                     "D.M.YYYY H:MM, a date and a clock column, or Unix seconds named "
                     "ts/time/timestamp); name it with --time-column (Date+Time for a pair)")


def _has_decimal_commas(frame: pd.DataFrame, tcol: int) -> bool:
    """Whether a file whose cells are not split by commas writes its numbers with decimal
    commas (``12,5``)."""
    sample = frame.drop(columns=[tcol]).head(200).to_numpy().ravel()
    return any(re.fullmatch(r"-?\d+,\d+", str(c).strip()) for c in sample)
