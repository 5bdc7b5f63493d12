"""Sun position: NREL SPA (through pvlib) and the Duffie–Beckman approximation.

Two methods, one output shape (a DataFrame with pvlib's column names):

- ``"spa"`` — the NREL Solar Position Algorithm (Reda & Andreas 2004,
  doi:10.1016/j.solener.2003.12.003) as implemented by :mod:`pvlib.spa`, with
  pressure, temperature and ΔT honoured. The expensive geocentric part
  (heliocentric VSOP87 series, nutation, aberration, ~100 periodic terms per
  step) is evaluated on an hourly grid and linearly interpolated — for a long
  series computed, for one spanning a day or less (one instant) taken from a
  per-process cache of the grid's nodes — and the observer-dependent
  (topocentric) part of SPA — parallax, hour angle, elevation, refraction,
  azimuth — runs at every time stamp with
  pvlib's own SPA functions. The geocentric quantities (right ascension,
  declination, Earth–Sun distance, sidereal time minus right ascension) vary so
  slowly that linear interpolation over one hour is off by less than 1e-5°
  (checked against ``pvlib.solarposition.spa_python`` in tests/sim/test_sun.py).
- ``"duffie-beckman"`` — seed 001, eqs. 1–4 (González-Camarillo et al. 2025,
  after Duffie & Beckman, *Solar Engineering of Thermal Processes*): Cooper's
  declination, hour angle from standard time with longitude correction and the
  equation of time, spherical-Earth zenith and azimuth — each step pvlib's
  function of that name, chosen to reproduce seed 001's open loop.

The SPA path calls functions of :mod:`pvlib.spa` that pvlib does not document
as public (they pay for the 16× speed-up of the hourly geocentric grid), so
``pyproject.toml`` pins the pvlib range they are tested on and
``tests/sim/test_sun.py`` checks that pin and that each function still exists
(:data:`PVLIB_SPA_INTERNALS`).

Azimuths are degrees clockwise from true north (pvlib convention) everywhere.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike
from pvlib import atmosphere

METHODS = ("spa", "duffie-beckman")

#: SPA geocentric quantities are evaluated on a grid of this spacing [s] and
#: interpolated when the series is longer than the grid (see module docstring).
SPA_GEOCENTRIC_STEP_S = 3600.0

#: Undocumented :mod:`pvlib.spa` functions this module relies on (tested to exist).
PVLIB_SPA_INTERNALS = (
    "solar_position_numpy", "julian_day", "julian_ephemeris_day", "julian_ephemeris_century",
    "julian_ephemeris_millennium", "heliocentric_radius_vector", "equatorial_horizontal_parallax",
    "uterm", "xterm", "yterm", "parallax_sun_right_ascension", "topocentric_sun_declination",
    "topocentric_local_hour_angle", "topocentric_elevation_angle_without_atmosphere",
    "atmospheric_refraction_correction", "topocentric_elevation_angle",
    "topocentric_astronomers_azimuth", "topocentric_azimuth_angle",
)

_COLUMNS = ["apparent_zenith", "zenith", "apparent_elevation", "elevation", "azimuth"]


def _as_utc_index(times: pd.DatetimeIndex | pd.Timestamp) -> pd.DatetimeIndex:
    """Return ``times`` as a UTC DatetimeIndex; naive times are misuse."""
    if isinstance(times, pd.Timestamp):
        times = pd.DatetimeIndex([times])
    times = pd.DatetimeIndex(times)
    if times.tz is None:
        raise ValueError("times must be timezone-aware (got naive timestamps)")
    return times.tz_convert("UTC")


def _unix_seconds(times: pd.DatetimeIndex) -> np.ndarray:
    """Seconds since 1970-01-01 UTC as float64, independent of the index resolution."""
    return np.asarray((times - pd.Timestamp(0, tz="UTC")) / pd.Timedelta(seconds=1), dtype=float)


def _spa_geocentric(unixtime: np.ndarray, delta_t: float) -> tuple[np.ndarray, ...]:
    """SPA geocentric part (Reda & Andreas 2004, steps 3.1–3.8) via :mod:`pvlib.spa`.

    Returns
    -------
    v_minus_alpha : apparent sidereal time minus geocentric right ascension [°], unwrapped
    delta : geocentric sun declination [°]
    radius : Earth heliocentric radius vector [AU]
    """
    from pvlib import spa

    v, alpha, delta = spa.solar_position_numpy(
        unixtime, 0.0, 0.0, 0.0, 1013.25, 12.0, delta_t, 0.5667, 1, sst=True
    )
    # the radius vector alone (SPA step 3.2.8), not a second run of the whole chain
    jme = spa.julian_ephemeris_millennium(spa.julian_ephemeris_century(
        spa.julian_ephemeris_day(spa.julian_day(unixtime), delta_t)))
    radius = spa.heliocentric_radius_vector(jme)
    v_minus_alpha = np.rad2deg(np.unwrap(np.deg2rad(np.asarray(v) - np.asarray(alpha))))
    return v_minus_alpha, np.asarray(delta), np.asarray(radius)


def _spa_topocentric(
    v_minus_alpha: np.ndarray,
    delta: np.ndarray,
    radius: np.ndarray,
    latitude: float,
    longitude: float,
    altitude: float,
    pressure_hpa: float,
    temperature: float,
) -> dict[str, np.ndarray]:
    """SPA topocentric part (Reda & Andreas 2004, steps 3.9–3.15) via :mod:`pvlib.spa`."""
    from pvlib import spa

    hour_angle = np.mod(v_minus_alpha + longitude, 360.0)  # eq. 11 (H = ν + σ − α)
    xi = spa.equatorial_horizontal_parallax(radius)
    u = spa.uterm(latitude)
    x = spa.xterm(u, latitude, altitude)
    y = spa.yterm(u, latitude, altitude)
    delta_alpha = spa.parallax_sun_right_ascension(x, xi, hour_angle, delta)
    delta_prime = spa.topocentric_sun_declination(delta, x, y, xi, delta_alpha, hour_angle)
    hour_angle_prime = spa.topocentric_local_hour_angle(hour_angle, delta_alpha)
    e0 = spa.topocentric_elevation_angle_without_atmosphere(latitude, delta_prime, hour_angle_prime)
    delta_e = spa.atmospheric_refraction_correction(pressure_hpa, temperature, e0, 0.5667)
    e = spa.topocentric_elevation_angle(e0, delta_e)
    gamma = spa.topocentric_astronomers_azimuth(hour_angle_prime, delta_prime, latitude)
    return {
        "apparent_zenith": 90.0 - e,
        "zenith": 90.0 - e0,
        "apparent_elevation": e,
        "elevation": e0,
        "azimuth": np.asarray(spa.topocentric_azimuth_angle(gamma), dtype=float),
    }


#: At most this many hourly nodes of the geocentric grid are kept (:func:`_cached_nodes`:
#: some 85 days of hours, 0.5 MB measured with tracemalloc).
GEOCENTRIC_CACHE_NODES = 2048
#: A series spanning at most this many nodes takes them from that cache.
GEOCENTRIC_CACHED_SPAN_NODES = 26
_geocentric_cache: dict[tuple[float, float], tuple[float, float, float]] = {}


def _cached_nodes(grid: np.ndarray, delta_t: float) -> tuple[np.ndarray, ...]:
    """:func:`_spa_geocentric` at the hourly ``grid`` nodes, each computed once per process.

    Why: a request about one instant — a sky frame's sun, the twin's scene at a scrubbed
    minute, the status of a site now — paid the whole SPA chain for it (4.2 ms on a 2-core
    AMD EPYC, 2.5 times a 640 × 480 frame's detection; 0.74 ms from the cache). The nodes
    an hour's instants read (its start, its end and the grid's spare one) serve every
    instant of it, interpolated as a long series is (within 1e-5° of pvlib's SPA:
    tests/sim/test_sun.py). Those missing are computed in one call. Sidereal time minus
    right ascension is kept modulo 360° and unwrapped over the nodes asked for (a node's
    turn count depends on the grid it came from). The cache is emptied when full (a process
    that asks about more than :data:`GEOCENTRIC_CACHE_NODES` hours). The service's worker
    threads share it: each call reads its nodes into a dict of its own first, so another
    thread's emptying cannot take them away, and a node computed twice is the same."""
    keys = [(float(t), float(delta_t)) for t in grid]
    nodes = {k: _geocentric_cache.get(k) for k in keys}
    missing = [k for k, v in nodes.items() if v is None]
    if missing:
        va, delta, radius = _spa_geocentric(np.array([k[0] for k in missing]), delta_t)
        if len(_geocentric_cache) + len(missing) > GEOCENTRIC_CACHE_NODES:
            _geocentric_cache.clear()
        for k, a, d, r in zip(missing, va, delta, radius, strict=True):
            nodes[k] = _geocentric_cache[k] = (float(a) % 360.0, float(d), float(r))
    table = np.array([nodes[k] for k in keys])
    return np.rad2deg(np.unwrap(np.deg2rad(table[:, 0]))), table[:, 1], table[:, 2]


def _spa(
    times: pd.DatetimeIndex,
    latitude: float,
    longitude: float,
    altitude: float,
    pressure: float,
    temperature: float,
    delta_t: float,
) -> dict[str, np.ndarray]:
    """NREL SPA with the geocentric part interpolated on an hourly grid: computed for a long
    series, taken from :func:`_cached_nodes` for one spanning a day or less."""
    unixtime = _unix_seconds(times)
    n_grid = 0
    if len(unixtime):
        t0 = np.floor(unixtime.min() / SPA_GEOCENTRIC_STEP_S) * SPA_GEOCENTRIC_STEP_S
        n_grid = int(np.ceil((unixtime.max() - t0) / SPA_GEOCENTRIC_STEP_S)) + 2
    if n_grid and (n_grid < len(unixtime) or n_grid <= GEOCENTRIC_CACHED_SPAN_NODES):
        grid = t0 + SPA_GEOCENTRIC_STEP_S * np.arange(n_grid)
        g_va, g_delta, g_radius = (_cached_nodes(grid, delta_t)
                                   if n_grid <= GEOCENTRIC_CACHED_SPAN_NODES
                                   else _spa_geocentric(grid, delta_t))
        v_minus_alpha = np.interp(unixtime, grid, g_va)
        delta = np.interp(unixtime, grid, g_delta)
        radius = np.interp(unixtime, grid, g_radius)
    else:
        v_minus_alpha, delta, radius = _spa_geocentric(unixtime, delta_t)
    return _spa_topocentric(
        v_minus_alpha, delta, radius, latitude, longitude, altitude, pressure / 100.0, temperature
    )


def equation_of_time_spencer(day_of_year: ArrayLike) -> np.ndarray:
    """Equation of time [min], Spencer (1971) as Duffie & Beckman use it (their eq. 1.5.3;
    seed 001's D&B step): ``pvlib.solarposition.equation_of_time_spencer71``."""
    from pvlib import solarposition

    return np.asarray(solarposition.equation_of_time_spencer71(np.asarray(day_of_year)))


def _duffie_beckman(
    times: pd.DatetimeIndex, latitude: float, longitude: float, pressure: float, temperature: float
) -> dict[str, np.ndarray]:
    """Seed 001, eqs. 1–4 (Duffie–Beckman) with pvlib's implementations of each step.

    Cooper's declination (eq. 1, ``declination_cooper69``), Spencer's equation
    of time and the hour angle from true solar time (``hour_angle``: standard
    time + 4 (L_loc − L_std) + E, the same instant whatever meridian the clock
    keeps), spherical-Earth zenith (eqs. 2–3, ``solar_zenith_analytical``) and
    azimuth (eq. 4 in its quadrant-safe form, ``solar_azimuth_analytical``, which
    already measures clockwise from north, so seed 001's from-south convention
    needs no conversion). N is the day of year in the standard time of the
    zone meridian nearest the site, as the seed counts it. Refraction for
    ``apparent_*`` is SPA's eq. 42.
    """
    from pvlib import solarposition, spa

    standard_meridian = 15.0 * np.round(longitude / 15.0)
    local_standard = times + pd.Timedelta(hours=float(standard_meridian / 15.0))
    day_of_year = np.asarray(local_standard.day_of_year, dtype=float)
    eot_min = equation_of_time_spencer(day_of_year)
    declination_rad = np.asarray(solarposition.declination_cooper69(day_of_year))
    hour_angle = np.asarray(solarposition.hour_angle(times, longitude, eot_min))
    # pvlib counts from UTC midnight: wrap to (−180°, 180°], the range its azimuth's sign needs
    hour_angle_rad = np.deg2rad(180.0 - np.mod(180.0 - hour_angle, 360.0))
    latitude_rad = np.deg2rad(latitude)
    zenith_rad = np.asarray(solarposition.solar_zenith_analytical(
        latitude_rad, hour_angle_rad, declination_rad))
    # eq. 4 divides by cos(latitude): at a pole it gave 180° at every hour (a tester's
    # finding); a thousandth of a degree off the pole, with that place's zenith, it is
    # the azimuth's limit there (to 0.001°)
    azimuth_latitude_rad = np.deg2rad(np.clip(latitude, -90.0 + 1e-3, 90.0 - 1e-3))
    azimuth_zenith_rad = zenith_rad if azimuth_latitude_rad == latitude_rad else np.asarray(
        solarposition.solar_zenith_analytical(azimuth_latitude_rad, hour_angle_rad,
                                              declination_rad))
    with np.errstate(invalid="ignore", divide="ignore"):
        azimuth_rad = np.asarray(solarposition.solar_azimuth_analytical(
            azimuth_latitude_rad, hour_angle_rad, declination_rad, azimuth_zenith_rad))
    elevation = 90.0 - np.rad2deg(zenith_rad)
    delta_e = spa.atmospheric_refraction_correction(
        pressure / 100.0, temperature, elevation, 0.5667
    )
    apparent_elevation = elevation + delta_e
    return {
        "apparent_zenith": 90.0 - apparent_elevation,
        "zenith": np.rad2deg(zenith_rad),
        "apparent_elevation": apparent_elevation,
        "elevation": elevation,
        "azimuth": np.mod(np.rad2deg(azimuth_rad), 360.0),
    }


def solar_position(
    times: pd.DatetimeIndex | pd.Timestamp,
    latitude: float,
    longitude: float,
    altitude: float = 0.0,
    pressure: float = 101325.0,
    temperature: float = 12.0,
    delta_t: float = 67.0,
    method: str = "spa",
) -> pd.DataFrame:
    """Sun position for a site.

    Parameters
    ----------
    times : pandas.DatetimeIndex or pandas.Timestamp
        Timezone-aware times.
    latitude, longitude : float
        Site coordinates [°], north and east positive.
    altitude : float
        Site elevation above sea level [m].
    pressure : float
        Local air pressure [Pa] (for refraction).
    temperature : float
        Local air temperature [°C] (for refraction).
    delta_t : float
        ΔT = TT − UT1 [s] (SPA only).
    method : {"spa", "duffie-beckman"}
        NREL SPA via pvlib, or seed 001 eqs. 1–4.

    Returns
    -------
    pandas.DataFrame
        Indexed like ``times`` (in UTC), columns ``apparent_zenith``, ``zenith``,
        ``apparent_elevation``, ``elevation``, ``azimuth`` [°]; apparent = with
        atmospheric refraction (SPA eq. 42), azimuth clockwise from north.
    """
    index = _as_utc_index(times)
    if method == "spa":
        cols = _spa(index, latitude, longitude, altitude, pressure, temperature, delta_t)
    elif method == "duffie-beckman":
        cols = _duffie_beckman(index, latitude, longitude, pressure, temperature)
    else:
        raise ValueError(f"method must be one of {', '.join(METHODS)}; got {method!r}")
    return pd.DataFrame({k: np.asarray(cols[k], dtype=float) for k in _COLUMNS}, index=index)


def daylight_s(t0_s: float, t1_s: float, step_s: float, latitude: float, longitude: float,
               altitude: float = 0.0, temperature: float = 12.0) -> float:
    """Seconds of ``[t0_s, t1_s]`` (Unix seconds) with the sun's apparent elevation above 0°,
    from the sun at the middles of steps of about ``step_s`` (each middle counts its whole
    step: the error is at most a step at each sunrise and sunset)."""
    if t1_s <= t0_s:
        return 0.0
    n = max(1, int((t1_s - t0_s) // step_s))
    mid = t0_s + (np.arange(n) + 0.5) * (t1_s - t0_s) / n
    when = pd.DatetimeIndex(pd.to_datetime(mid, unit="s", utc=True))
    pos = solar_position(when, latitude, longitude, altitude,
                         float(atmosphere.alt2pres(altitude)), temperature)
    return float(np.count_nonzero(pos["apparent_elevation"].to_numpy() > 0.0)) * (t1_s - t0_s) / n
