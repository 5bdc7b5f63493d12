"""Sky: clear-sky irradiance, plane-of-array transposition, AOI, IAM, TMY weather (pvlib).

Every function is a thin, vectorised wrapper over pvlib that fixes the
model choices the twin uses and names units:

- clear sky: Ineichen & Perez (2002, doi:10.1016/S0038-092X(02)00045-2) with
  the Linke turbidity climatology shipped with pvlib (Remund et al. 2003),
  Kasten & Young (1989) relative air mass — as ``pvlib.location.Location.get_clearsky``;
- transposition: Hay & Davies (1980) by default, Perez (1990) on request,
  ``pvlib.irradiance.get_total_irradiance``;
- angle of incidence: ``pvlib.irradiance.aoi``;
- incidence-angle modifier: the physical (Fresnel + Beer) model of De Soto et
  al. (2006, doi:10.1016/j.solener.2005.06.010), the one the CEC model was
  fitted with, ``pvlib.iam.physical``;
- weather: TMY3 files through ``pvlib.iotools.read_tmy3``, EPW files through
  ``pvlib.iotools.read_epw``, PVGIS typical years (CSV, JSON; a PVGIS EPW told by its
  comment) through ``pvlib.iotools.read_pvgis_tmy`` (:func:`_pvgis_typical_year`), told
  apart by their first line (:func:`sniff_weather_format`;
  any other file is refused saying what is read); a typical year is mapped onto any run's years by
  :func:`typical_year_on` (calendar hour of the station's standard time, wrapped
  at the year's ends); :func:`typical_year_at_site` moves a distant station's sky to the
  site (Perez et al. 1990 kt′ at the same solar time, Erbs et al. 1982 decomposition), and
  :func:`limit_to_extraterrestrial` keeps any weather within the top of the atmosphere;
  measured weather of its own dates (a CSV of time, GHI, DNI, DHI, or an NSRDB download as
  it is) is read by :func:`read_measured`. Every weather value stands at the middle of the
  interval it averages, or at its instant (:func:`weather_middles`), and is interpolated
  linearly onto a run's steps (:func:`weather_at`).
"""

from __future__ import annotations

import datetime as dt
import functools
import io
import re
from pathlib import Path
from typing import IO, Any

import numpy as np
import pandas as pd

from sim import sun

TRANSPOSITION_MODELS = ("haydavies", "perez", "isotropic")


def extra_radiation(times: pd.DatetimeIndex) -> np.ndarray:
    """Extraterrestrial normal irradiance [W m⁻²] (Spencer 1971).

    Via ``pvlib.irradiance.get_extra_radiation``.
    """
    from pvlib import irradiance

    return np.asarray(irradiance.get_extra_radiation(times), dtype=float)


def airmass(apparent_zenith: np.ndarray, altitude: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Relative (Kasten & Young 1989) and absolute air mass [-] via ``pvlib.atmosphere``.

    Parameters
    ----------
    apparent_zenith : array_like
        Refraction-corrected solar zenith [°].
    altitude : float
        Site elevation [m] (pressure from ``pvlib.atmosphere.alt2pres``).
    """
    from pvlib import atmosphere

    am_rel = np.asarray(atmosphere.get_relative_airmass(apparent_zenith, "kastenyoung1989"))
    am_abs = np.asarray(atmosphere.get_absolute_airmass(am_rel, atmosphere.alt2pres(altitude)))
    return am_rel.astype(float), am_abs.astype(float)


@functools.lru_cache(maxsize=64)
def _daily_linke(latitude: float, longitude: float) -> np.ndarray:
    """pvlib's Linke turbidity for every UTC day of year 1–366, leap and common years
    (rows 0 and 1): ``lookup_linke_turbidity`` reads its HDF5 table on every call,
    which dominated short requests such as ``/positions``."""
    from pvlib import clearsky

    out = np.empty((2, 366))
    for row, year in enumerate((2016, 2015)):
        days = pd.date_range(f"{year}-01-01 12:00", periods=366 if row == 0 else 365,
                             freq="D", tz="UTC")
        out[row, : len(days)] = np.asarray(clearsky.lookup_linke_turbidity(
            days, latitude, longitude), dtype=float)
    out[1, 365] = out[1, 364]
    return out


def linke_turbidity(times: pd.DatetimeIndex, latitude: float, longitude: float) -> np.ndarray:
    """pvlib's ``lookup_linke_turbidity(times, latitude, longitude)`` (interpolated by UTC day
    of year), from a per-place cache of its 366 daily values: identical numbers."""
    utc = times.tz_convert("UTC") if times.tz is not None else times
    table = _daily_linke(float(latitude), float(longitude))
    row = np.where(utc.is_leap_year, 0, 1)
    return table[row, np.asarray(utc.day_of_year) - 1]


def clearsky_ineichen(
    times: pd.DatetimeIndex,
    apparent_zenith: np.ndarray,
    latitude: float,
    longitude: float,
    altitude: float = 0.0,
) -> dict[str, np.ndarray]:
    """Clear-sky GHI, DNI, DHI [W m⁻²] — Ineichen/Perez with pvlib's Linke turbidity table.

    Same recipe as ``pvlib.location.Location(...).get_clearsky(times)``:
    ``lookup_linke_turbidity`` (interpolated by day of year), Kasten–Young air
    mass, ``get_extra_radiation``, ``pvlib.clearsky.ineichen``.

    Parameters
    ----------
    times : pandas.DatetimeIndex
        Timezone-aware times.
    apparent_zenith : array_like
        Refraction-corrected solar zenith at ``times`` [°].
    latitude, longitude : float
        [°].
    altitude : float
        [m].

    Returns
    -------
    dict
        ``ghi``, ``dni``, ``dhi`` [W m⁻²]; also ``dni_extra`` [W m⁻²] and
        ``airmass_relative`` [-] for the transposition.
    """
    from pvlib import clearsky

    linke = linke_turbidity(times, latitude, longitude)
    am_rel, am_abs = airmass(apparent_zenith, altitude)
    dni_extra = extra_radiation(times)
    # with the sun down pvlib divides by an infinite air mass: those NaNs become 0 below
    with np.errstate(divide="ignore", invalid="ignore"):
        cs = clearsky.ineichen(
            np.asarray(apparent_zenith, dtype=float),
            am_abs,
            linke,
            altitude=altitude,
            dni_extra=dni_extra,
        )
    out = {k: np.nan_to_num(np.asarray(cs[k], dtype=float)) for k in ("ghi", "dni", "dhi")}
    out["dni_extra"] = dni_extra
    out["airmass_relative"] = am_rel
    return out


def angle_of_incidence(
    surface_tilt: np.ndarray | float,
    surface_azimuth: np.ndarray | float,
    solar_zenith: np.ndarray,
    solar_azimuth: np.ndarray,
) -> np.ndarray:
    """Angle of incidence [°] between sun and surface normal via ``pvlib.irradiance.aoi``."""
    from pvlib import irradiance

    return np.asarray(
        irradiance.aoi(surface_tilt, surface_azimuth, solar_zenith, solar_azimuth), dtype=float
    )


def iam_physical(aoi: np.ndarray) -> np.ndarray:
    """Incidence-angle modifier [-] of De Soto et al. (2006).

    Via ``pvlib.iam.physical`` (glass n = 1.526, K = 4 m⁻¹, L = 2 mm).
    """
    from pvlib import iam

    return np.asarray(iam.physical(np.asarray(aoi, dtype=float)), dtype=float)


def poa_irradiance(
    surface_tilt: np.ndarray | float,
    surface_azimuth: np.ndarray | float,
    solar_zenith: np.ndarray,
    solar_azimuth: np.ndarray,
    dni: np.ndarray,
    ghi: np.ndarray,
    dhi: np.ndarray,
    dni_extra: np.ndarray,
    airmass_relative: np.ndarray | None = None,
    albedo: float = 0.2,
    model: str = "haydavies",
) -> dict[str, np.ndarray]:
    """Plane-of-array irradiance [W m⁻²] via ``pvlib.irradiance.get_total_irradiance``.

    Parameters
    ----------
    surface_tilt, surface_azimuth : array_like
        Surface orientation [°] (pvlib convention).
    solar_zenith, solar_azimuth : array_like
        Sun position [°] (pass the apparent zenith, as pvlib's ModelChain does).
    dni, ghi, dhi, dni_extra : array_like
        [W m⁻²].
    airmass_relative : array_like, optional
        Needed by ``"perez"`` [-].
    albedo : float
        Ground reflectance [-].
    model : {"haydavies", "perez", "isotropic"}

    Returns
    -------
    dict
        ``poa_global``, ``poa_direct``, ``poa_diffuse`` [W m⁻²] (NaN → 0).
    """
    from pvlib import irradiance

    if model not in TRANSPOSITION_MODELS:
        raise ValueError(f"model must be one of {', '.join(TRANSPOSITION_MODELS)}; got {model!r}")
    tot = irradiance.get_total_irradiance(
        surface_tilt,
        surface_azimuth,
        solar_zenith,
        solar_azimuth,
        dni,
        ghi,
        dhi,
        dni_extra=dni_extra,
        airmass=airmass_relative,
        albedo=albedo,
        model=model,
    )
    return {
        k: np.nan_to_num(np.asarray(tot[k], dtype=float))
        for k in ("poa_global", "poa_direct", "poa_diffuse")
    }


def effective_irradiance(
    poa_direct: np.ndarray, poa_diffuse: np.ndarray, aoi: np.ndarray
) -> np.ndarray:
    """Irradiance reaching the cells [W m⁻²]: IAM on the beam, diffuse as is, no spectral loss.

    The same combination as ``pvlib.modelchain.ModelChain`` with
    ``aoi_model="physical"`` and ``spectral_model="no_loss"``.
    """
    return np.asarray(poa_direct) * iam_physical(aoi) + np.asarray(poa_diffuse)


def pvlib_tmy3_path() -> Path:
    """Path of the real TMY3 file that ships with pvlib (723170TYA, Greensboro NC)."""
    import pvlib

    return Path(pvlib.__file__).parent / "data" / "723170TYA.CSV"


def read_tmy3(path: str | Path, coerce_year: int | None = None) -> tuple[pd.DataFrame, dict]:
    """Read a TMY3 file with ``pvlib.iotools.read_tmy3`` for the twin.

    TMY3 values are hour-ending averages; the index is moved back 30 min to the
    middle of each hour so that interpolation onto finer steps is centred.

    Returns
    -------
    weather : pandas.DataFrame
        UTC index; ``ghi``, ``dni``, ``dhi`` [W m⁻²], ``temp_air`` [°C],
        ``wind_speed`` [m s⁻¹].
    metadata : dict
        ``latitude``, ``longitude`` [°], ``altitude`` [m], ``TZ`` [h], ``Name``…
    """
    from pvlib import iotools

    data, meta = iotools.read_tmy3(str(path), coerce_year=coerce_year, map_variables=True)
    weather = data[["ghi", "dni", "dhi", "temp_air", "wind_speed"]].astype(float)
    weather.index = (data.index - pd.Timedelta(minutes=30)).tz_convert("UTC")
    return weather, dict(meta)


WEATHER_FORMATS = ("tmy3", "epw", "pvgis", "nsrdb")
WEATHER_COLUMNS = ("ghi", "dni", "dhi", "temp_air", "wind_speed")
HOURS_PER_TYPICAL_YEAR = 8760
#: Days before each month in a year of 365 days (a typical year has no 29 February).
_DAYS_BEFORE_MONTH = np.cumsum([0, 31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30])


def weather_format(first_line: str) -> str:
    """``"epw"``, ``"tmy3"``, ``"pvgis"`` or ``"nsrdb"`` from a weather file's first line.

    An EPW file starts with its ``LOCATION,`` record (EnergyPlus Auxiliary
    Programs, "EnergyPlus Weather File Data Dictionary"); a TMY3 file with the
    station's USAF number, name, state, UTC offset, latitude, longitude and
    elevation (Wilcox & Marion 2008, NREL/TP-581-43156, section 2.1); a PVGIS download
    (the EU JRC's tool) with ``Latitude (decimal degrees):`` (CSV) or ``{`` (JSON); an NSRDB
    download with :data:`NSRDB_FIRST_CELLS` (a typical year or an actual one:
    :func:`nsrdb_is_typical_year`).
    """
    line = first_line.lstrip("\ufeff").strip()
    if line.upper().startswith("LOCATION,"):
        return "epw"
    if line.startswith("{") or line.lower().startswith("latitude (decimal degrees)"):
        return "pvgis"
    if line.startswith(NSRDB_FIRST_CELLS):
        return "nsrdb"
    head = line.split(",")
    if len(head) >= 7 and head[0].strip().isdigit():
        return "tmy3"
    shown = " ".join(line.split())
    shown = shown if len(shown) <= 60 else shown[:57] + "…"
    raise ValueError(f"neither TMY3 nor EPW nor PVGIS: its first line {shown!r} is not a "
                     "TMY3 CSV's (USAF number, name, state, UTC offset, latitude, longitude, "
                     "elevation) nor an EPW file's (LOCATION,…) nor a PVGIS download's "
                     "(Latitude (decimal degrees): …, or JSON); only those formats are read "
                     "(not TMY2 .tm2 files)")


def weather_format_or_none(first_line: str) -> str | None:
    """:func:`weather_format`, or None for a line of no typical year's format."""
    try:
        return weather_format(first_line)
    except ValueError:
        return None


def weather_text(raw: bytes) -> str:
    """A weather file's bytes as text: UTF-8 (a byte-order mark dropped), else Latin-1, which
    every byte decodes. An EPW or TMY3 written on Windows names its station in Latin-1
    (``Tromsø``): the CLI refused it with "'utf-8' codec can't decode byte 0xf8" while the
    same file uploaded ran (a tester's finding)."""
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def weather_buffer(source: str | Path | IO[str]) -> IO[str]:
    """A weather file (a path, read by :func:`weather_text`, or a text buffer) as a buffer."""
    if isinstance(source, (str, Path)):
        return io.StringIO(weather_text(Path(source).read_bytes()))
    return source


def sniff_weather_format(source: str | Path | IO[str], fmt: str | None = None) -> str:
    """The format of a weather file (path or text buffer) read from its first line
    (:func:`weather_format`); a buffer is left where it was.

    ``fmt`` (``"tmy3"`` or ``"epw"``), when given, is what the caller was told the file
    is: a file whose content says otherwise is refused naming both, as reading it with
    the other format's reader fails with pvlib's bare KeyError.
    """
    if fmt is not None and fmt not in WEATHER_FORMATS:
        raise ValueError(f"format must be one of {', '.join(WEATHER_FORMATS)}; got {fmt!r}")
    if isinstance(source, (str, Path)):
        with open(source, encoding="utf-8", errors="replace") as f:
            first = f.readline()
    else:
        start = source.tell()
        first = source.readline()
        source.seek(start)
    found = weather_format(first)
    if fmt is not None and found != fmt:
        raise ValueError(f"the file is {found.upper()} (by its first line), not {fmt.upper()}")
    return found


def weather_middles(stamps: pd.DatetimeIndex, stamped: str,
                    interval_s: float | None = None) -> pd.DatetimeIndex:
    """The instants a weather file's values stand for: the middle of the interval each
    value averages (``stamped`` ``"interval_end"`` or ``"interval_start"``), or the stamp
    itself (``"instant"``). The twin interpolates linearly between these instants
    (:func:`weather_at`) for every weather file, typical year or measured: the rule of
    :func:`sim.energy.interval_middles`, which places a logger's readings the same way.
    ``interval_s``: every value's interval [s] (a typical year's hour); otherwise the
    spacing of the (sorted) stamps."""
    from sim.energy import interval_middles

    ns = stamps.as_unit("ns").asi8.astype(np.float64) / 1e9
    mid = interval_middles(ns, stamped, MEASURED_MAX_INTERVAL_S, interval_s)
    return pd.DatetimeIndex(pd.to_datetime(np.round(mid * 1e3).astype(np.int64), unit="ms",
                                           utc=True)).tz_convert(stamps.tz)


def _refuse_sub_hourly_epw(data: pd.DataFrame) -> None:
    """Refuse an EPW of more than one record an hour (its DATA PERIODS' records per hour,
    its ``minute`` field varying): pvlib's ``read_epw`` keeps only the hour of each record,
    so six 10-minute records became six copies of one hour."""
    per_hour = int(data.groupby(["month", "day", "hour"]).size().max()) if len(data) else 1
    if per_hour > 1:
        raise ValueError(
            f"a sub-hourly EPW ({per_hour} records an hour, {len(data):,} rows) is not read: "
            "an EPW typical year is read hour by hour — average it to hourly records, or run "
            "on it as measured weather (a CSV of time, ghi, dni, dhi: --weather-csv)")


def _hour_label(hour: int) -> str:
    """An hour of a 365-day year [0, 8760) as "16 Jun 16:00–17:00"."""
    t = pd.Timestamp("2023-01-01") + pd.Timedelta(hours=int(hour))
    return f"{t:%d %b %H:00}–{t + pd.Timedelta(hours=1):%H:00}"


def _check_hours(hour: np.ndarray, first_line: int, fmt: str) -> None:
    """Refuse a typical year whose rows are not the 8,760 hours once each, naming the
    first hour missing and the first there twice with its lines (it had said only "8759 of
    8760 rows": a tester could not find the row among 8,760)."""
    count = np.bincount(hour, minlength=HOURS_PER_TYPICAL_YEAR)
    missing, twice = np.flatnonzero(count == 0), np.flatnonzero(count > 1)
    if not missing.size and not twice.size:
        return
    def more(hours: np.ndarray) -> str:
        return f", and {hours.size - 1} more hours" if hours.size > 1 else ""

    what = []
    if twice.size:
        lines = np.flatnonzero(hour == twice[0])[:2] + first_line
        what.append(f"{_hour_label(twice[0])} is there twice (lines {lines[0]:,} and "
                    f"{lines[1]:,}){more(twice)}")
    if missing.size:
        what.append(f"{_hour_label(missing[0])} is missing{more(missing)}")
    raise ValueError(f"a typical year has {HOURS_PER_TYPICAL_YEAR:,} hours, each once "
                     f"(station time); this {fmt.upper()} file has {len(hour):,} rows: "
                     f"{'; '.join(what)}")


def _calendar_hour(index: pd.DatetimeIndex) -> np.ndarray:
    """Hour of a 365-day year [0, 8760) of mid-hour stamps; 29 February counts as the 28th."""
    month = index.month.to_numpy()
    day = np.where((month == 2) & (index.day.to_numpy() == 29), 28, index.day.to_numpy())
    return (_DAYS_BEFORE_MONTH[month - 1] + day - 1) * 24 + index.hour.to_numpy()


def read_typical_year(source: str | Path | IO[str], fmt: str | None = None
                      ) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Read a typical year (TMY3, EPW, PVGIS, NSRDB) with pvlib, in its station's standard time.

    ``pvlib.iotools.read_tmy3`` labels each hour by its end, ``read_epw`` by its
    start (hour − 1); both are moved to the middle of the hour, so interpolation
    onto finer steps is centred. The months of a typical year come from
    different years; only the calendar hour matters (:func:`typical_year_on`).

    A PVGIS typical year (CSV or JSON, or an EPW PVGIS wrote, told by its ``Irradiance Time
    Offset`` comment) is read by :func:`_pvgis_typical_year`: its clock is UTC whatever its
    EPW header says, and its irradiance is of instants, not hourly means; an NSRDB typical
    year by :func:`_read_nsrdb_typical_year`, its values at their stamps too.

    Parameters
    ----------
    source : path or text buffer
    fmt : {"tmy3", "epw", "pvgis", "nsrdb"}, optional
        What the caller was told the file is; a file whose first line says otherwise is
        refused (:func:`sniff_weather_format`). Default: read from the first line.

    Returns
    -------
    weather : pandas.DataFrame
        8760 rows in calendar order, indexed by the mid-hour time in the
        station's standard time (fixed UTC offset); ``ghi``, ``dni``, ``dhi``
        [W m⁻²], ``temp_air`` [°C], ``wind_speed`` [m s⁻¹].
    station : dict
        ``format``, ``name``, ``latitude``, ``longitude`` [°], ``altitude`` [m],
        ``utc_offset_h`` [h].
    """
    from pvlib import iotools

    src = weather_buffer(source)
    fmt = sniff_weather_format(src, fmt)
    if fmt == "pvgis":
        return _read_pvgis(src)
    if fmt == "nsrdb":
        return _read_nsrdb_typical_year(src)
    pvgis_offset_h = pvgis_epw_offset_h(src) if fmt == "epw" else None
    try:
        if fmt == "tmy3":
            data, meta = iotools.read_tmy3(src, map_variables=True)
            name = str(meta.get("Name", "")).strip('"')
            # read_tmy3 moves 29 February onto 1 March: the file's own dates tell it
            leap = data["Date (MM/DD/YYYY)"].astype(str).str.startswith("02/29").to_numpy()
        else:
            data, meta = iotools.read_epw(src)
            name = ", ".join(str(meta.get(k, "")).strip() for k in ("city", "country")
                             if str(meta.get(k, "")).strip())
            leap = ((data["month"] == 2) & (data["day"] == 29)).to_numpy()
            _refuse_sub_hourly_epw(data)
            if pvgis_offset_h is not None:  # its hours are UTC, labelled by their end
                place = {k: float(meta[k]) for k in ("latitude", "longitude", "altitude")}
                data.index = pd.DatetimeIndex(data.index).tz_localize(None).tz_localize("UTC")
                return _pvgis_typical_year(data, 1.0 + pvgis_offset_h, place,
                                           "TMY as EPW", first_line=9)
        offset = float(meta["TZ"])
        place = {k: float(meta[k]) for k in ("latitude", "longitude", "altitude")}
    except (KeyError, IndexError) as exc:  # pvlib's bare KeyError of a missing column
        raise ValueError(f"not a readable {fmt.upper()} file: no {exc} in it") from None
    except TypeError as exc:  # pvlib's arithmetic on a text cell (the EPW hour 'x': a 500)
        raise ValueError(f"not a readable {fmt.upper()} file: a column holds text where "
                         f"numbers are due ({exc})") from None
    if leap.any():
        raise ValueError(
            f"this {fmt.upper()} file has 29 February ({len(data):,} rows: an actual year, not "
            f"a typical one); a typical year has {HOURS_PER_TYPICAL_YEAR:,} hours and a run "
            "over a leap year's 29 February repeats the 28th — delete 29 February's "
            f"{int(leap.sum())} rows, or run on it as measured weather (a CSV of time, ghi, "
            "dni, dhi: --weather-csv)")
    stamped = "interval_end" if fmt == "tmy3" else "interval_start"
    middle = weather_middles(pd.DatetimeIndex(data.index), stamped, interval_s=3600.0)
    hour = _calendar_hour(middle)
    first_line = 3 if fmt == "tmy3" else 9  # the data's first line, after the header lines

    def where(i: int) -> str:
        return f"line {i + first_line:,} ({_hour_label(hour[i])} station time)"

    _check_hours(hour, first_line, fmt)
    missing = [c for c in WEATHER_COLUMNS if c not in data.columns]
    if missing:  # (pandas' own KeyError read "no "['dni'] not in index" in it", a tester's find)
        raise ValueError(f"not a readable {fmt.upper()} file: no {', '.join(missing)} "
                         f"column in it")
    weather = _numeric_cells(data, list(WEATHER_COLUMNS), where, fmt.upper())
    weather.index = pd.DatetimeIndex(middle)
    weather = weather.iloc[np.argsort(hour, kind="stable")]
    _check_irradiance(weather, fmt)
    station = {"format": fmt, "name": name, **place, "utc_offset_h": offset}
    return weather, station


#: What to do with a PVGIS hourly series (``seriescalc``: the irradiance on one plane, its
#: stamps ``20230101:0010`` the instants of its values)
_PVGIS_SERIES = ("a PVGIS hourly series (seriescalc, irradiance on one plane) is not read as it "
                 "is: write its rows as measured weather, a CSV of time (its 20230101:0010 as "
                 "2023-01-01T00:10:00Z), ghi, dni, dhi (a horizontal plane's series: ghi = "
                 "Gb(i) + Gd(i) + Gr(i), dhi = Gd(i), dni = Gb(i) / sin H_sun), its times "
                 "instants (--weather-stamped / weather_stamped: instant)")
#: PVGIS's note of when its irradiance was taken, in its CSV's header and its EPW's comments
_PVGIS_OFFSET_NOTE = "irradiance time offset (h):"


def pvgis_epw_offset_h(src: IO[str]) -> float | None:
    """The ``Irradiance Time Offset (h):`` an EPW written by PVGIS states in a ``COMMENTS``
    line (−0.8239: its values are of instants 0.8239 h before each hour's label), or None
    for any other EPW; the buffer is left where it was."""
    start = src.tell()
    head = [src.readline() for _ in range(8)]
    src.seek(start)
    for line in head:
        low = line.lower()
        if low.startswith("comments") and _PVGIS_OFFSET_NOTE in low:
            try:
                return float(low.split(_PVGIS_OFFSET_NOTE, 1)[1].split(",")[0])
            except ValueError:
                return None
    return None


def _read_pvgis(src: IO[str]) -> tuple[pd.DataFrame, dict[str, Any]]:
    """A PVGIS TMY download, CSV or JSON (``pvlib.iotools.read_pvgis_tmy``), as a typical
    year (:func:`_pvgis_typical_year`). A PVGIS file that is not a TMY (an hourly series of
    one plane, ``seriescalc``) is refused saying what to do with it, a JSON file that is not
    PVGIS's saying so."""
    import json

    from pvlib import iotools

    text = src.read()
    is_json = text.lstrip().startswith("{")
    if is_json:
        try:
            outputs = json.loads(text).get("outputs")
        except ValueError as exc:
            raise ValueError(f"not a readable PVGIS typical year: invalid JSON ({exc})"
                             ) from None
        if not isinstance(outputs, dict) or "tmy_hourly" not in outputs:
            raise ValueError("a JSON file that is not a PVGIS TMY download (no outputs."
                             "tmy_hourly)" + (f": {_PVGIS_SERIES}"
                                              if isinstance(outputs, dict) else ""))
    elif "time(UTC)," not in text[:2000]:  # the TMY's header row, after 18 lines at most
        raise ValueError(f"a PVGIS file that is not a typical year (TMY): {_PVGIS_SERIES}")
    try:
        if is_json:
            data, meta = iotools.read_pvgis_tmy(io.StringIO(text), pvgis_format="json")
            location = meta["inputs"]["location"]
            offset_h = location.get("irradiance_time_offset")
            db = meta["inputs"].get("meteo_data", {}).get("radiation_db")
            first_line = 1
        else:
            data, meta = iotools.read_pvgis_tmy(io.BytesIO(text.encode()), pvgis_format="csv")
            location = meta["inputs"]
            offset_h = location.get("irradiance time offset")
            db = None
            first_line = 19 if offset_h is not None else 18
        place = {"latitude": float(location["latitude"]),
                 "longitude": float(location["longitude"]),
                 "altitude": float(location["elevation"])}
    except (KeyError, IndexError, TypeError, ValueError) as exc:
        raise ValueError(f"not a readable PVGIS typical year: {type(exc).__name__} {exc}"
                         ) from None
    name = f"TMY, {db}" if db else "TMY"
    return _pvgis_typical_year(data, 0.0 if offset_h is None else float(offset_h), place,
                               name, first_line)


def _pvgis_typical_year(data: pd.DataFrame, irradiance_offset_h: float,
                        place: dict[str, float], name: str, first_line: int
                        ) -> tuple[pd.DataFrame, dict[str, Any]]:
    """A PVGIS typical year (``data`` indexed by its UTC stamps) as :func:`read_typical_year`
    gives every typical year (:func:`_typical_year_of_instants`, UTC).

    PVGIS's irradiance is not an hourly mean but the satellite's instant: its TMY says
    ``Irradiance Time Offset (h): 0.1761`` after each stamp (at 45° N; the EPW it writes says
    −0.8239 h from hours labelled by their end, and its hourly series stamp those instants,
    ``…:0010``; PVGIS's radiation is SARAH's, Huld et al. 2012, Solar Energy 86, 1803); its
    air temperature and wind (ERA5) are of the stamp. Measured against the sun
    (:mod:`sim.weather_clock`) at the file's place: 0 min; read as hour-start means, as any
    EPW, on its header's ``TZ`` of 1, a PVGIS EPW had run 40 min early."""
    stamps = pd.DatetimeIndex(data.index).tz_convert("UTC").tz_localize(None)
    offsets = {c: irradiance_offset_h if c in ("ghi", "dni", "dhi") else 0.0
               for c in WEATHER_COLUMNS}
    weather = _typical_year_of_instants(data.set_axis(stamps), offsets, 0.0, "pvgis",
                                        first_line)
    return weather, {"format": "pvgis", "name": name, **place, "utc_offset_h": 0.0,
                     "irradiance_offset_h": round(float(irradiance_offset_h), 4)}


def _typical_year_of_instants(data: pd.DataFrame, offsets_h: dict[str, float],
                              utc_offset_h: float, fmt: str, first_line: int) -> pd.DataFrame:
    """A typical year of instants (PVGIS's, NSRDB's: not hourly means) as
    :func:`read_typical_year` gives every typical year: one value per calendar hour at the
    hour's middle on the file's clock, UTC + ``utc_offset_h`` (``data`` indexed by its
    stamps there, naive), each column interpolated linearly from its instants (each stamp,
    ``offsets_h[column]`` hours after it) to the middles, around the year's end. The file's
    hours are refused naming one missing or twice (:func:`_check_hours`), an irradiance out
    of bounds naming its hour (:func:`_check_irradiance`)."""
    stamps = pd.DatetimeIndex(data.index)
    hour = _calendar_hour(stamps)
    _check_hours(hour, first_line, fmt)
    missing = [c for c in WEATHER_COLUMNS if c not in data.columns]
    if missing:
        raise ValueError(f"not a readable {fmt.upper()} typical year: no "
                         f"{', '.join(missing)} column in it")
    order = np.argsort(hour, kind="stable")
    raw = data[list(WEATHER_COLUMNS)].iloc[order].astype(float)
    if not np.isfinite(raw.to_numpy()).all():
        raise ValueError(f"not a readable {fmt.upper()} typical year: a value is blank or "
                         "not a number")
    raw.index = stamps[order]
    clock = f"UTC{utc_offset_h:+g}" if utc_offset_h else "UTC"
    _check_irradiance(raw, fmt, f"%d %b %H:%M {clock}")
    minute_h = (raw.index - raw.index.floor("h")).total_seconds().to_numpy() / 3600.0
    at = np.arange(HOURS_PER_TYPICAL_YEAR, dtype=float)
    out = np.empty(raw.shape)
    for j, col in enumerate(WEATHER_COLUMNS):
        out[:, j] = np.interp(at + 0.5, at + minute_h + offsets_h[col], raw[col].to_numpy(),
                              period=HOURS_PER_TYPICAL_YEAR)
    zone = dt.timezone(dt.timedelta(hours=utc_offset_h))
    middles = (raw.index.floor("h") + pd.Timedelta(minutes=30)).tz_localize(zone)
    return pd.DataFrame(out, index=middles, columns=list(WEATHER_COLUMNS))


#: A measured series' rows are at most this far apart [s]: a longer gap is no weather to
#: interpolate across (an hour is a typical year's cadence) …
MEASURED_MAX_INTERVAL_S = 3600.0
#: … and at least this far [s] (finer data: average it to minutes; a year of seconds is
#: 31 million rows)
MEASURED_MIN_INTERVAL_S = 60.0
#: What a measured series' stamps mark unless told (``sim.energy.READING_STAMPS``): the end
#: of the interval each value averages, as a TMY3 file's and most loggers' (a Campbell
#: Scientific table's) stamps do
MEASURED_STAMPED_DEFAULT = "interval_end"
#: A measured CSV's columns by what they hold (header names read case-insensitively; the
#: second name carries the unit): the time, GHI, DNI, DHI [W m⁻²], then optional air
#: temperature [°C] and wind speed [m s⁻¹]
MEASURED_COLUMNS = {"time": ("time", "timestamp"), "ghi": ("ghi", "ghi_w_m2"),
                    "dni": ("dni", "dni_w_m2"), "dhi": ("dhi", "dhi_w_m2"),
                    "temp_air": ("temp_air", "temp_air_c"),
                    "wind_speed": ("wind_speed", "wind_speed_m_s")}


def _numeric_cells(raw: pd.DataFrame, columns: list[str], where: Any, fmt: str
                   ) -> pd.DataFrame:
    """``raw``'s ``columns`` as numbers; a blank or a text cell is refused naming the column
    and where its row is (``where(i)`` of its position i: a line, an hour). A blank GHI
    cell had read "missing irradiance (ghi, dni or dhi)", a text one pandas' bare "could
    not convert string to float: 'abc'" (a tester's findings)."""
    out = pd.DataFrame(index=raw.index)
    for col in columns:
        values = pd.to_numeric(raw[col], errors="coerce")
        bad = ~np.isfinite(values.to_numpy(dtype=float))
        if bad.any():
            at = int(np.flatnonzero(bad)[0])
            cell = raw[col].iloc[at]
            what = ("blank" if pd.isna(cell) or not str(cell).strip()
                    else f"{str(cell).strip()[:20]!r}, not a number,")
            raise ValueError(f"the {fmt} file's {col} is {what} at {where(at)}; "
                             f"{int(bad.sum())} such cells in {col} — fill them, or use "
                             "another file")
        out[col] = values.astype(float)
    return out


def read_measured(source: str | Path | IO[str], stamped: str = MEASURED_STAMPED_DEFAULT,
                  timezone: str | None = None, name: str = ""
                  ) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Read a measured irradiance series: a CSV with a header row, a ``time`` (or
    ``timestamp``) column and ``ghi``, ``dni``, ``dhi`` [W m⁻²], optionally ``temp_air``
    [°C] and ``wind_speed`` [m s⁻¹] (:data:`MEASURED_COLUMNS`; other columns ignored).

    An NSRDB download (PSM3 or PSM4 CSV, :data:`NSRDB_FIRST_CELLS`) is read as it is
    (:func:`_nsrdb_rows`): its values at their stamps (``stamped`` and ``timezone`` not
    used), its lines counted as the file's.

    Times are ISO 8601 with a UTC offset (``2024-06-01T10:05:00+09:30``), or without one
    when ``timezone`` (an IANA zone; ``Etc/GMT-10`` for a fixed UTC+10) says where they
    were read; rows every :data:`MEASURED_MIN_INTERVAL_S` to :data:`MEASURED_MAX_INTERVAL_S`,
    regular or not, any order. ``stamped`` says what a stamp marks (``"interval_end"``,
    ``"interval_start"`` or ``"instant"``; default :data:`MEASURED_STAMPED_DEFAULT`): each
    value is placed at its interval's middle (:func:`weather_middles`, the typical year's
    rule) and interpolated linearly onto the run's steps (:func:`weather_at`). The series
    is weather of its own dates, not wrapped onto a typical year: it covers from the start
    of its first interval to the end of its last (``station["start"]``, ``["end"]``), and
    the first and last values hold to those edges.

    Refused, naming the column and the line: a blank or text cell, a time without an
    offset (and no ``timezone``), a time twice, a gap over an hour, irradiance outside
    −10…1,500 W m⁻².

    Returns
    -------
    weather : pandas.DataFrame
        UTC index; the columns read.
    station : dict
        ``format`` ``"measured"``, ``name``, ``stamped``, ``start`` and ``end`` (ISO, UTC);
        no place: the series is taken as the site's own (``latitude`` etc. None) — but an
        NSRDB year's place, whose distance to the site is then checked.
    """
    if stamped not in ("interval_end", "interval_start", "instant"):
        raise ValueError(f"stamped must be interval_end, interval_start or instant; got "
                         f"{stamped!r}")
    src = weather_buffer(source)
    first = src.readline()
    _refuse_pvgis(first)
    src.seek(0)
    header_lines = 1
    if weather_format_or_none(first) == "nsrdb":
        raw, where, place = _nsrdb_rows(src)
        name = f"{name}: {where}" if name else where
        stamped, timezone, header_lines = "instant", None, 3
    else:
        raw = pd.read_csv(src, dtype=str, skipinitialspace=True)
        by_lower = {str(c).strip().lower(): c for c in raw.columns}
        found = {key: next((by_lower[n] for n in names if n in by_lower), None)
                 for key, names in MEASURED_COLUMNS.items()}
        missing = [k for k in ("time", "ghi", "dni", "dhi") if found[k] is None]
        if missing:
            raise ValueError(f"a measured weather CSV needs the columns time, ghi, dni and dhi "
                             f"(W m⁻²) in its header; {', '.join(missing)} not found among "
                             f"{', '.join(map(str, raw.columns[:12]))}")
        raw = raw.rename(columns={v: k for k, v in found.items() if v is not None})
    if len(raw) < 2:
        raise ValueError(f"a measured weather CSV needs at least 2 rows; it has {len(raw)}")

    def line(i: int) -> str:
        return f"line {i + header_lines + 1}"  # after the header's lines

    times = _measured_times(raw["time"], timezone, line)
    cols = [c for c in WEATHER_COLUMNS if c in raw.columns]
    values = _numeric_cells(raw, cols, line, "measured")
    values.index = pd.DatetimeIndex(times).tz_convert("UTC").as_unit("ns")
    order = np.argsort(values.index.asi8, kind="stable")
    values, rows = values.iloc[order], order
    step_s = np.diff(values.index.asi8) / 1e9
    if (step_s == 0).any():
        i = int(np.flatnonzero(step_s == 0)[0])
        raise ValueError(f"time: {values.index[i].isoformat()} is there twice ({line(rows[i])} "
                         f"and {line(rows[i + 1])}); keep one")
    for bad, why in ((step_s > MEASURED_MAX_INTERVAL_S, "no rows for more than an hour: "
                      "the twin does not interpolate across a gap — run on the dates either "
                      "side of it, or fill it"),
                     (step_s < MEASURED_MIN_INTERVAL_S, "rows less than a minute apart: "
                      "average them to 1 minute or more")):
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(f"time: {values.index[i].isoformat()} ({line(rows[i])}) to "
                             f"{values.index[i + 1].isoformat()} ({line(rows[i + 1])}): {why}")
    _check_irradiance(values, "measured", "%Y-%m-%d %H:%M UTC")
    values.index = weather_middles(values.index, stamped)
    half = 0.0 if stamped == "instant" else 0.5  # of the first and last intervals
    first = values.index[0] - pd.Timedelta(seconds=half * step_s[0])
    last = values.index[-1] + pd.Timedelta(seconds=half * step_s[-1])
    edges = pd.DataFrame([values.iloc[0].to_numpy(), values.iloc[-1].to_numpy()],
                         index=pd.DatetimeIndex([first, last]), columns=values.columns)
    weather = pd.concat([edges.iloc[:1], values, edges.iloc[1:]])
    weather = weather[~weather.index.duplicated(keep="first")]
    station = {"format": "measured", "name": name, "latitude": None, "longitude": None,
               "altitude": None, "utc_offset_h": None, "stamped": stamped,
               "start": first.isoformat(), "end": last.isoformat()}
    if header_lines == 3:  # an NSRDB year says where it is: its distance is checked
        station.update({k: place[k] for k in ("latitude", "longitude", "altitude")})
    return weather, station


#: The first cells of an NSRDB download (NREL's National Solar Radiation Database, PSM3 and
#: PSM4 CSV: a line of names and a line of values about the place, then the data's header)
NSRDB_FIRST_CELLS = "Source,Location ID,"
#: An NSRDB download's columns read, by the names the measured CSV's rows take
_NSRDB_COLUMNS = {"ghi": "GHI", "dni": "DNI", "dhi": "DHI", "temp_air": "Temperature",
                  "wind_speed": "Wind Speed"}


def _nsrdb_rows(src: IO[str]) -> tuple[pd.DataFrame, str, dict[str, Any]]:
    """An NSRDB download's rows as a measured CSV's (``time`` with the header's UTC offset,
    ``ghi``, ``dni``, ``dhi``, ``temp_air``, ``wind_speed`` as text), where it is from in
    words, and its place (:func:`nsrdb_header`).

    NSRDB's irradiance (PSM: Sengupta et al. 2018, Renewable and Sustainable Energy Reviews
    89, 51) stands at its stamps: read so, the two downloads in ``tests/data/nsrdb/`` sit
    0 min from the sun in every month with sunny days (:mod:`sim.weather_clock`), read as
    interval-end means 15 min early; its stamps are in the header's ``Time Zone`` (0 for a
    UTC download). An NSRDB typical year (8,760 rows, its months from several years) is
    refused naming where it is read (:func:`read_typical_year`)."""
    place, body = _nsrdb_body(src, ["GHI", "DNI", "DHI"])
    tz_h = place["utc_offset_h"]
    if _nsrdb_typical(body):
        raise ValueError(
            f"an NSRDB typical year (TMY: {len(body):,} hours, its months from several "
            "years) is not measured weather: it is read as a typical year (--nsrdb PATH, "
            "or uploaded)")
    stamp = _nsrdb_stamps(body)
    sign = "+" if tz_h >= 0 else "-"
    zone = f"{sign}{int(abs(tz_h)):02d}:{round(abs(tz_h) % 1 * 60):02d}"
    ints = stamp.astype(str)
    time = (ints["Year"] + "-" + ints["Month"].str.zfill(2) + "-" + ints["Day"].str.zfill(2)
            + "T" + ints["Hour"].str.zfill(2) + ":" + ints["Minute"].str.zfill(2) + ":00"
            + zone)
    raw = pd.DataFrame({"time": time})
    for key, column in _NSRDB_COLUMNS.items():
        if column in body.columns:
            raw[key] = body[column]
    where = (f"NSRDB location {place['location_id']} ({place['latitude']:.2f}, "
             f"{place['longitude']:.2f}), UTC{tz_h:+g} h, values at their stamps")
    return raw, where, place


def _nsrdb_body(src: IO[str], columns: list[str]) -> tuple[dict[str, Any], pd.DataFrame]:
    """An NSRDB download's place (:func:`nsrdb_header`) and rows (as text); refused naming
    the stamp's fields or ``columns`` its data's header lacks."""
    place = nsrdb_header(src)
    body = pd.read_csv(src, dtype=str, skipinitialspace=True)
    missing = [c for c in ["Year", "Month", "Day", "Hour", "Minute", *columns]
               if c not in body.columns]
    if missing:
        raise ValueError(f"an NSRDB file without the columns {', '.join(missing)} in its "
                         "third line")
    return place, body


def _nsrdb_typical(body: pd.DataFrame) -> bool:
    """Whether an NSRDB download's rows are a typical year: 8,760 hours whose months come
    from several years (a TMY, TGY or TDY), not one actual year."""
    return len(body) == HOURS_PER_TYPICAL_YEAR and body["Year"].dropna().nunique() > 1


def _nsrdb_stamps(body: pd.DataFrame) -> pd.DataFrame:
    """An NSRDB download's Year, Month, Day, Hour and Minute as whole numbers; a row without
    them refused naming its line."""
    stamp = body[["Year", "Month", "Day", "Hour", "Minute"]].apply(pd.to_numeric,
                                                                    errors="coerce")
    bad = stamp.isna().any(axis=1).to_numpy()
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"time: line {i + 4} has no whole Year, Month, Day, Hour and Minute")
    return stamp.astype(int)


def nsrdb_is_typical_year(source: str | Path | IO[str]) -> bool:
    """Whether a weather file is an NSRDB typical year (:func:`_nsrdb_typical`); False for
    any other file. A buffer is left where it was."""
    src = weather_buffer(source)
    start = src.tell()
    try:
        if weather_format_or_none(src.readline()) != "nsrdb":
            return False
        src.readline()
        body = pd.read_csv(src, dtype=str, usecols=lambda c: c == "Year")
        return "Year" in body.columns and _nsrdb_typical(body)
    finally:
        src.seek(start)


def _read_nsrdb_typical_year(src: IO[str]) -> tuple[pd.DataFrame, dict[str, Any]]:
    """An NSRDB typical year (TMY, TGY, TDY; PSM3 or PSM4 CSV) as a typical year on its
    header's clock (``Time Zone``): its values stand at their stamps, as an actual year's do
    (:func:`_nsrdb_rows`), so each column is interpolated from them to the hours' middles
    (:func:`_typical_year_of_instants`; stamps at minute 30 are the middles themselves). An
    actual year is refused saying it is measured weather of its own dates."""
    place, body = _nsrdb_body(src, list(_NSRDB_COLUMNS.values()))
    if not _nsrdb_typical(body):
        raise ValueError(
            f"an NSRDB download of an actual year ({len(body):,} rows, "
            f"{body['Year'].dropna().iloc[0]}): measured weather of its own dates "
            "(--weather-csv PATH, or uploaded), not a typical year")
    stamp = _nsrdb_stamps(body)
    stamps = pd.to_datetime(stamp.rename(columns=str.lower))
    values = _numeric_cells(body.rename(columns={v: k for k, v in _NSRDB_COLUMNS.items()}),
                            list(WEATHER_COLUMNS), lambda i: f"line {i + 4}", "NSRDB")
    weather = _typical_year_of_instants(values.set_axis(pd.DatetimeIndex(stamps)),
                                        dict.fromkeys(WEATHER_COLUMNS, 0.0),
                                        place["utc_offset_h"], "nsrdb", first_line=4)
    station = {"format": "nsrdb", "name": f"location {place['location_id']}",
               **{k: place[k] for k in ("latitude", "longitude", "altitude")},
               "utc_offset_h": place["utc_offset_h"]}
    return weather, station


def nsrdb_header(src: IO[str]) -> dict[str, Any]:
    """The place of an NSRDB download from its first two lines (the buffer left after them):
    ``latitude``, ``longitude`` [°], ``altitude`` [m], ``utc_offset_h`` (its stamps' zone,
    ``Time Zone``), ``local_utc_offset_h`` (the place's standard time, ``Local Time Zone``),
    ``location_id``; a field missing or not a number is refused naming it."""
    head = pd.read_csv(io.StringIO(src.readline() + src.readline()), dtype=str).iloc[0]
    fields = {"latitude": "Latitude", "longitude": "Longitude", "altitude": "Elevation",
              "utc_offset_h": "Time Zone", "local_utc_offset_h": "Local Time Zone"}
    out: dict[str, Any] = {"location_id": str(head.get("Location ID", "?"))}
    for key, name in fields.items():
        try:
            out[key] = float(head[name])
        except (KeyError, ValueError, TypeError):
            raise ValueError(f"an NSRDB file whose second line has no readable {name!r} "
                             "(its place and time zone)") from None
    return out


def _refuse_pvgis(first_line: str) -> None:
    """Refuse a PVGIS download (its CSV opens with ``Latitude (decimal degrees):``, its JSON
    with ``{``) as measured weather, saying how to read it: it had been refused with pandas'
    "Error tokenizing data. C error: Expected 1 fields in line 5, saw 2", or its JSON shown
    as the columns found (a tester's finding). A PVGIS TMY is a typical year
    (:func:`read_typical_year`)."""
    head = first_line.lstrip("\ufeff").strip()
    if weather_format_or_none(head) == "pvgis":
        raise ValueError("a PVGIS download (or JSON) is not measured weather: a PVGIS "
                         "typical year (TMY) is read as one (--pvgis PATH, or uploaded); "
                         + _PVGIS_SERIES)


#: An ISO 8601 time that ends in its UTC offset (``Z``, ``+09:30``, ``-0700``, ``+02``): the
#: test of a measured weather CSV's times and of a logger file's
#: (``backend.measurements.logger_file``)
UTC_OFFSET_AT_END = re.compile(r"(?:Z|[+-]\d\d(?::?\d\d)?)$")


def _measured_times(column: pd.Series, timezone: str | None, line: Any) -> pd.DatetimeIndex:
    """A measured CSV's time column as UTC instants: every time with its UTC offset, or,
    given ``timezone``, every time without one read there; refused naming the first bad
    line otherwise (a blank, no ISO 8601 time, a missing offset)."""
    text = column.fillna("").astype(str).str.strip()
    offset = text.str.contains(UTC_OFFSET_AT_END, regex=True)
    want = timezone is None or offset.any()
    if (offset != want).any():
        i = int(np.flatnonzero((offset != want).to_numpy())[0])
        raise ValueError(f"time: {text.iloc[i][:30]!r} at {line(i)} "
                         + ("has no UTC offset: write every time with one (…T10:05:00+09:30, "
                            "…Z), or none of them and say the zone they were read in "
                            "(--weather-timezone / weather_timezone)" if want else
                            "has a UTC offset while others have none: write all alike"))
    parsed = pd.to_datetime(text, format="ISO8601", errors="coerce", utc=want)
    if parsed.isna().any():
        i = int(np.flatnonzero(parsed.isna().to_numpy())[0])
        raise ValueError(f"time: {text.iloc[i][:30]!r} at {line(i)} is not an ISO 8601 time "
                         "(2024-06-01T10:05:00+09:30)")
    if timezone is not None and not want:
        return clock_times_to_utc(parsed, timezone, text, line)
    return pd.DatetimeIndex(parsed).tz_convert("UTC")


def clock_times_to_utc(parsed: pd.Series, timezone: str, text: pd.Series, line: Any
                       ) -> pd.DatetimeIndex:
    """Times without a UTC offset (``parsed``, naive) read on a clock in ``timezone`` (an IANA
    zone) as UTC instants. The hour a clock change repeats is read as the clock wrote it when
    the times run in order through it twice (a portal's export in local time: 01:00–01:59
    first in summer time, then in standard time; pandas' ``ambiguous="infer"``). Otherwise a
    time it repeats, or one it skips, is refused naming its line (``line(i)``) and its cell
    (``text``): the error had been pandas' "Cannot infer dst time …, try using the
    'ambiguous' argument". The rule of a measured weather CSV and of a logger's file
    (``backend.measurements.logger_file``)."""
    try:
        local = parsed.dt.tz_localize(timezone, ambiguous="infer", nonexistent="NaT")
    except ValueError:  # a repeated hour written once, or out of order: not inferable
        local = parsed.dt.tz_localize(timezone, ambiguous="NaT", nonexistent="NaT")
    if local.isna().any():
        i = int(np.flatnonzero(local.isna().to_numpy())[0])
        raise ValueError(f"time: {text.iloc[i][:30]!r} at {line(i)} repeats or is skipped "
                         f"at a clock change in {timezone} — give the times a UTC offset, "
                         "or name the fixed zone of the logger's clock, e.g. Etc/GMT+4 "
                         "for UTC−4")
    return pd.DatetimeIndex(local).tz_convert("UTC")


#: The most any of GHI, DNI, DHI can be [W m⁻²]: the solar constant at perihelion (≈ 1,414)
#: and a little; EPW writes 9999 for a missing one (EnergyPlus Auxiliary Programs, "EnergyPlus
#: Weather File (EPW) Data Dictionary": "missing value = 9999")
IRRADIANCE_MAX_W_M2 = 1500.0
#: A weather file's irradiance may dip this far below 0 (a pyranometer's night offset) and
#: is read as 0; further is no irradiance [W m⁻²]
IRRADIANCE_NIGHT_OFFSET_W_M2 = -10.0


def _check_irradiance(weather: pd.DataFrame, fmt: str,
                      when: str = "%d %b %H:%M (station time)") -> None:
    """Refuse a typical year whose GHI, DNI or DHI lies outside
    [:data:`IRRADIANCE_NIGHT_OFFSET_W_M2`, :data:`IRRADIANCE_MAX_W_M2`], naming the column,
    the hour and how many such hours; set the small negatives of a night offset to 0
    (in place). An EPW's 9999 ("missing") was capped at the top of the atmosphere and read
    as a clear sky: five missing hours put a June day 50 % up and its gain 9 points off; a
    negative DNI took the beam off the tracker (a tester's findings). Its ``wind_speed``, if
    any, is checked too (:func:`_check_wind`)."""
    irr = weather[["ghi", "dni", "dhi"]]
    bad = (irr < IRRADIANCE_NIGHT_OFFSET_W_M2) | (irr > IRRADIANCE_MAX_W_M2)
    if bad.to_numpy().any():
        col = str(bad.any().idxmax())
        at = bad[col].to_numpy().argmax()
        value = float(irr[col].iloc[at])
        why = ("EPW's mark of a missing value" if fmt == "epw" and value == 9999.0 else
               f"outside {IRRADIANCE_NIGHT_OFFSET_W_M2:g}…{IRRADIANCE_MAX_W_M2:g} W m⁻²")
        raise ValueError(
            f"the {fmt.upper() if fmt in WEATHER_FORMATS else fmt} file's {col} is "
            f"{value:g} W m⁻² on "
            f"{irr.index[at].strftime(when)}: {why}; "
            f"{int(bad.to_numpy().sum())} such values in all — fill them, or use another file")
    weather[["ghi", "dni", "dhi"]] = irr.clip(lower=0.0)
    if "wind_speed" in weather.columns:
        _check_wind(weather["wind_speed"], fmt, when)


#: The most a weather file's wind speed can be [m s⁻¹]: the highest surface gust measured,
#: 113.2 m s⁻¹ (WMO World Weather & Climate Extremes Archive, Barrow Island, 10 April 1996).
#: EPW writes 999 for a missing wind speed ("EnergyPlus Weather File (EPW) Data Dictionary":
#: "missing value = 999")
WIND_SPEED_MAX_M_S = 113.2


def _check_wind(wind_m_s: pd.Series, fmt: str, when: str) -> None:
    """Refuse a weather file whose wind speed lies outside [0, :data:`WIND_SPEED_MAX_M_S`],
    naming the hour and the count. An EPW's 999 ("missing") was read as 999 m s⁻¹: the wind
    stow (:mod:`sim.stow`) held the tracker flat through four missing hours and their
    interpolation (320 daylight minutes, 318 Wh "lost" on a Sand Point day at 12 m s⁻¹), and
    the cells were cooled as in a gale (a review of the stow)."""
    bad = (wind_m_s < 0.0) | (wind_m_s > WIND_SPEED_MAX_M_S)
    if bad.to_numpy().any():
        at = int(bad.to_numpy().argmax())
        value = float(wind_m_s.iloc[at])
        why = ("EPW's mark of a missing value" if fmt == "epw" and value == 999.0 else
               f"outside 0…{WIND_SPEED_MAX_M_S:g} m s⁻¹")
        raise ValueError(
            f"the {fmt.upper() if fmt in WEATHER_FORMATS else fmt} file's wind_speed is "
            f"{value:g} m s⁻¹ on {wind_m_s.index[at].strftime(when)}: {why}; "
            f"{int(bad.to_numpy().sum())} such values in all — fill them, or use another file")


def typical_year_on(weather: pd.DataFrame, utc_offset_h: float, start: pd.Timestamp,
                    end: pd.Timestamp) -> pd.DataFrame:
    """A typical year laid onto the calendar of a run ``[start, end)``, hourly, UTC.

    A typical meteorological year is one year of calendar hours recorded in its
    station's standard time (Wilcox & Marion 2008, NREL/TP-581-43156), so any
    run's hour takes the typical year's value for the same month, day and hour
    of the station's clock, whatever the run's year: the first and last hours
    wrap around (31 December 23:30 is followed by 1 January 00:30), a run may
    span years, and 29 February of a leap year repeats 28 February.

    Parameters
    ----------
    weather : pandas.DataFrame
        8760 rows in calendar order, as from :func:`read_typical_year`.
    utc_offset_h : float
        The station's standard-time offset from UTC [h].
    start, end : pandas.Timestamp
        The run's range (timezone-aware).

    Returns
    -------
    pandas.DataFrame
        Mid-hour rows from an hour before ``start`` to an hour after ``end``,
        UTC index, the columns of ``weather``.
    """
    if len(weather) != HOURS_PER_TYPICAL_YEAR:
        raise ValueError(f"a typical year has {HOURS_PER_TYPICAL_YEAR} rows, not {len(weather)}")
    if start.tzinfo is None or end.tzinfo is None:
        raise ValueError("start and end must be timezone-aware")
    zone = pd.Timedelta(hours=utc_offset_h)
    first = (start.tz_convert("UTC") + zone).tz_localize(None).floor("h") - pd.Timedelta(hours=1)
    last = (end.tz_convert("UTC") + zone).tz_localize(None).ceil("h") + pd.Timedelta(hours=1)
    local = pd.date_range(first, last, freq="h") + pd.Timedelta(minutes=30)
    rows = weather.to_numpy(float)[_calendar_hour(local)]
    index = (local - zone).tz_localize("UTC")
    return pd.DataFrame(rows, index=index, columns=weather.columns)


#: Two places whose verticals are at most this far apart [°] (great-circle angle; ≈ 111 km)
#: see the sun within this angle of each other at every instant: a station this close is the
#: site, and its measured hours are used as they are (:func:`typical_year_at_site`).
SAME_SKY_DEG = 1.0
#: The station's clearness is read only from hours with its sun at least this high [°]:
#: below it an hourly mean over a rising or setting sun makes the ratio meaningless.
TRANSFER_MIN_ELEVATION_DEG = 5.0


def weather_at(times: pd.DatetimeIndex, weather: pd.DataFrame, temp_air_c: float,
               wind_speed_m_s: float, closing: bool = False) -> dict[str, np.ndarray]:
    """``ghi``, ``dni``, ``dhi`` [W m⁻²], ``temp_air`` [°C] and ``wind_speed`` [m s⁻¹] of
    ``weather`` (a timezone-aware index) interpolated linearly onto ``times``; a column of
    air temperature or wind it lacks is the constant given.

    The weather must cover ``times``. ``closing``: the last of ``times`` closes a run's last
    step (:func:`sim.energy.simulation_times`) and, past the weather's last row, takes that
    row (a weather file that ends with the range; even alone in a run's last chunk).
    ValueError says what is missing or which range is not covered.
    """
    missing = [c for c in ("ghi", "dni", "dhi") if c not in weather.columns]
    if missing:
        raise ValueError(f"weather lacks columns {missing}")
    if weather.index.tz is None:
        raise ValueError("weather index must be timezone-aware")
    t_w = sun._unix_seconds(weather.index)
    t = sun._unix_seconds(times)
    steps = t[:-1] if closing else t
    if steps.size and (steps[0] < t_w[0] or steps[-1] > t_w[-1]):
        raise ValueError(f"weather covers {weather.index[0].tz_convert('UTC').isoformat()}.."
                         f"{weather.index[-1].tz_convert('UTC').isoformat()}, not the run "
                         f"{times[0].tz_convert('UTC').isoformat()}.."
                         f"{times[steps.size - 1].tz_convert('UTC').isoformat()}")
    out = {c: np.interp(t, t_w, weather[c].to_numpy(float)) for c in ("ghi", "dni", "dhi")}
    for column, constant in (("temp_air", temp_air_c), ("wind_speed", wind_speed_m_s)):
        out[column] = (np.interp(t, t_w, weather[column].to_numpy(float))
                       if column in weather else np.full(len(t), float(constant)))
    return out


def kt_prime_factor(airmass_relative: np.ndarray) -> np.ndarray:
    """kt / kt′ [-]: Perez et al. (1990, doi:10.1016/0038-092X(90)90036-C), eq. 1,
    1.031 exp(−1.4 / (0.9 + 9.4 / AM)) + 0.1 — the factor by which
    ``pvlib.irradiance.clearness_index_zenith_independent`` divides the clearness index."""
    am = np.asarray(airmass_relative, dtype=float)
    return 1.031 * np.exp(-1.4 / (0.9 + 9.4 / am)) + 0.1


def limit_to_extraterrestrial(ghi: np.ndarray, dni: np.ndarray, dhi: np.ndarray,
                              apparent_zenith: np.ndarray, dni_extra: np.ndarray
                              ) -> dict[str, np.ndarray]:
    """GHI, DNI, DHI [W m⁻²] within what the top of the atmosphere allows at that sun position.

    No horizontal irradiance can exceed the extraterrestrial horizontal irradiance
    ``E₀ cos θz`` (clearness index ≤ 1, Duffie & Beckman, *Solar Engineering of Thermal
    Processes*, 4th ed., eq. 2.9.3): GHI and DHI are capped there, and the beam takes at most
    what the diffuse leaves of it, ``DNI cos θz ≤ E₀ cos θz − DHI`` (so ``DNI ≤ E₀``); none
    is below 0. Data
    within these limits are returned unchanged — at its own station a TMY is touched only in
    hours whose mean is laid onto a sun a degree or two above the horizon; an hour measured
    under a high sun and laid onto a sun on the horizon (a distant station) loses its beam.
    With the sun below the horizon all three are 0.
    """
    cos_z = np.maximum(np.cos(np.radians(np.asarray(apparent_zenith, dtype=float))), 0.0)
    e0 = np.asarray(dni_extra, dtype=float)
    top = e0 * cos_z
    # and never below 0: a negative DNI took the beam off the tracker's plane (a tester's
    # finding, a TMY3 hour at −300 W m⁻²)
    ghi = np.clip(np.asarray(ghi, dtype=float), 0.0, top)
    dhi = np.clip(np.asarray(dhi, dtype=float), 0.0, top)
    with np.errstate(divide="ignore", invalid="ignore"):
        beam_max = np.where(cos_z > 0, np.maximum(e0 - dhi / cos_z, 0.0), 0.0)
    dni = np.clip(np.asarray(dni, dtype=float), 0.0, beam_max)
    return {"ghi": ghi, "dni": dni, "dhi": dhi}


def _nearest_valid(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``values`` with each invalid entry replaced by its nearest valid neighbour in order."""
    good = np.flatnonzero(valid)
    k = np.arange(len(values))
    right = np.searchsorted(good, k).clip(0, len(good) - 1)
    left = (right - 1).clip(0, len(good) - 1)
    pick = np.where(np.abs(good[left] - k) <= np.abs(good[right] - k), good[left], good[right])
    return np.where(valid, values, values[pick])


def typical_year_at_site(weather: pd.DataFrame, utc_offset_h: float, start: pd.Timestamp,
                         end: pd.Timestamp, station_location: tuple[float, float, float],
                         site_location: tuple[float, float, float]) -> pd.DataFrame:
    """A typical year on the run ``[start, end)`` at a site, from a station anywhere.

    Within :data:`SAME_SKY_DEG` of the site the station's hours are the site's
    (:func:`typical_year_on`, unchanged). Farther away its GHI, DNI and DHI belong to another
    sun and cannot be carried (a beam measured with the sun at 10° laid onto a sun at 1° gave
    2,300 W m⁻² on a tracker): only the state of the sky is moved, as the zenith-independent
    clearness index kt′ of Perez et al. (1990, doi:10.1016/0038-092X(90)90036-C, eq. 1), at
    the same mean solar time (the station's hour whose sun stands where the site's does in
    its day: shifted by the longitude difference / 15° h⁻¹). At the site kt′ gives back kt
    at the site's air mass, GHI = kt · E₀ · cos θz, and the Erbs et al. (1982,
    doi:10.1016/0038-092X(82)90302-4, eq. 1) decomposition (``pvlib.irradiance.erbs``) splits
    it into DNI and DHI. Station hours with its sun below :data:`TRANSFER_MIN_ELEVATION_DEG`
    take kt′ of the nearest hour that has it (a site whose day is longer than the station's).
    The station's air temperature and wind belong to its climate, not the site's: they are
    left out, so the twin takes the site's own (``Site.temp_air``, ``Site.wind_speed``).

    Parameters
    ----------
    weather, utc_offset_h, start, end
        As :func:`typical_year_on` (the typical year, its station's UTC offset [h], the run).
    station_location, site_location : tuple
        (latitude [°], longitude [°], altitude [m]).

    Returns
    -------
    pandas.DataFrame
        Hourly rows covering the run (UTC index): the columns of ``weather`` at the station;
        ``ghi``, ``dni``, ``dhi`` [W m⁻²] only, moved, elsewhere.
    """
    from pvlib import irradiance

    from sim import sun
    from vision.sphere import angular_separation_deg

    s_lat, s_lon, s_alt = (float(v) for v in station_location)
    lat, lon, alt = (float(v) for v in site_location)
    if float(angular_separation_deg(s_lon, s_lat, lon, lat)) <= SAME_SKY_DEG:
        return typical_year_on(weather, utc_offset_h, start, end)
    shift_h = ((lon - s_lon + 180.0) % 360.0 - 180.0) / 15.0
    on = typical_year_on(weather, utc_offset_h + shift_h, start, end)
    at_station = on.index + pd.Timedelta(hours=shift_h)
    pos = sun.solar_position(at_station, s_lat, s_lon, s_alt)
    kt = irradiance.clearness_index(on["ghi"].to_numpy(), pos["zenith"].to_numpy(),
                                    extra_radiation(at_station), max_clearness_index=1.0)
    am = airmass(pos["apparent_zenith"].to_numpy(), s_alt)[0]
    valid = pos["apparent_elevation"].to_numpy() >= TRANSFER_MIN_ELEVATION_DEG
    if not valid.any():
        raise ValueError(f"the station's sun stays below {TRANSFER_MIN_ELEVATION_DEG}° over "
                         f"the run: its sky cannot be moved to the site")
    with np.errstate(invalid="ignore"):
        kt_prime = np.where(valid, np.asarray(kt) / kt_prime_factor(am), 0.0)
    kt_prime = _nearest_valid(kt_prime, valid)
    here = sun.solar_position(on.index, lat, lon, alt)
    zenith = here["zenith"].to_numpy()
    up = here["apparent_elevation"].to_numpy() > 0
    am_here = np.nan_to_num(airmass(here["apparent_zenith"].to_numpy(), alt)[0], nan=40.0)
    kt_here = np.minimum(kt_prime * kt_prime_factor(am_here), 1.0)
    ghi = np.where(up, kt_here * extra_radiation(on.index) * np.maximum(np.cos(np.radians(
        zenith)), 0.0), 0.0)
    split = irradiance.erbs(ghi, zenith, on.index)
    return pd.DataFrame({"ghi": ghi, "dni": np.asarray(split["dni"], dtype=float),
                         "dhi": np.asarray(split["dhi"], dtype=float)}, index=on.index)
