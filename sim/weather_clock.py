"""Is a series of irradiance on the sun's time? The shift that best aligns it with the clear
sky at its place.

One rule (:func:`best_shift`) serves the diagnosis's check of a logger's sky
(``backend.diagnosis.faults.sky_clock``: the fixed plane's POA against its clear-sky POA)
and the twin's check of a weather file (:func:`irradiance_shift`: the file's GHI against
the clear-sky GHI at the site). A file whose times are misread — hour-start means read as
hour ends (``weather_stamped``), or times in another zone — runs late or early by a whole
or half interval, or by hours; its energy and gain are then those of another sun.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

#: A weather file whose GHI best aligns with the clear sky this far or farther from its
#: stamps' time [min] is warned of (:func:`shift_warning`). Correctly read files measured
#: 0–5 min over a month and at most 10 on a single day (docs/validation.md, section 5):
#: hourly TMY3 and EPW typical years, 1- to 60-minute measured series. Misread means are off
#: by half or a whole interval: 30 or 60 min for hourly ones, 15 for 30-minute instants read
#: as interval-end means (a converted NSRDB year) or 15-minute hour-start means read as
#: ends — the smallest misreading, so it is warned of (it had passed, at the threshold).
WEATHER_SHIFT_WARN_MIN = 15.0
#: The grid the weather's GHI is compared on [min], and the shifts searched [min]: half a
#: day either way, so a file in another zone (UTC at Delhi: +330 min) reads its whole shift
WEATHER_GRID_MIN = 5
WEATHER_MAX_SHIFT_MIN = 720
#: A day counts when its GHI is at least this share of its clear-sky GHI over the (mean
#: solar) day — a sum a shift barely changes — (enough sun to show the shape of the day) …
SUNNY_DAY_CLEARNESS = 0.5
#: … over at least this many minutes of clear-sky GHI above 50 W m⁻²; the clearest this
#: many days are fitted (a year's run: the check's time bounded) …
SUNNY_DAY_MIN_MIN = 120
SHIFT_MAX_DAYS = 20
#: … and a day counts whose GHI follows the clear sky's shape, shifted, within this relative
#: RMS (:func:`scaled_fit`): a cloudy day's best shift is the clouds', up to 85 min on a
#: typical year's single days
SHIFT_MAX_RESIDUAL = 0.06


def scaled_fit(m: np.ndarray, x: np.ndarray) -> tuple[float, float]:
    """Best scale ``s`` and the relative RMS residual of ``m ≈ s·x`` (residual / mean m)."""
    den = float(np.dot(x, x))
    s = float(np.dot(m, x) / den) if den > 0 else 0.0
    mean = float(np.mean(m)) if m.size else 0.0
    r = float(np.sqrt(np.mean((m - s * x) ** 2)) / mean) if mean > 0 else np.inf
    return s, r


def best_shift(measured: np.ndarray, clear: np.ndarray, ok: np.ndarray, max_shift: int,
               coarse: int, min_points: int) -> dict[str, float] | None:
    """The shift ``τ`` (in grid steps, over ±``max_shift``) minimising the scaled residual of
    ``measured(t) ≈ s · clear(t − τ)`` over the points ``ok``: every ``coarse`` steps, then
    step by step around the best. ``τ`` > 0: the measured series runs late against the
    clear sky. ``{"shift", "residual", "residual_at_0"}`` (relative RMS, :func:`scaled_fit`);
    None with fewer than ``min_points`` points ``ok``."""
    idx = np.flatnonzero(ok)
    if idx.size < min_points:
        return None

    def shifted(tau: int) -> tuple[float, int]:
        j = idx - tau
        inside = (j >= 0) & (j < clear.size)
        if inside.sum() < min_points:
            return (np.inf, tau)
        return (scaled_fit(measured[idx[inside]], clear[j[inside]])[1], tau)

    best = min(shifted(tau) for tau in range(-max_shift, max_shift + 1, coarse))
    best = min(shifted(tau) for tau in range(best[1] - coarse + 1, best[1] + coarse))
    return {"shift": float(best[1]), "residual": best[0], "residual_at_0": shifted(0)[0]}


def irradiance_shift(weather: pd.DataFrame, latitude: float, longitude: float,
                     altitude: float, start: pd.Timestamp, end: pd.Timestamp
                     ) -> dict[str, Any] | None:
    """How far [min] the weather's GHI (UTC index, each value at its instant) runs from the
    clear-sky GHI at the place over ``[start, end)``: on each day (mean solar time) with
    enough sun (:data:`SUNNY_DAY_CLEARNESS`, :data:`SUNNY_DAY_MIN_MIN`) the shift of
    :func:`best_shift` on a :data:`WEATHER_GRID_MIN` grid; their median. ``{"shift_min",
    "days"}``, None without such a day. Clear sky: Ineichen with pvlib's Linke table
    (:func:`sim.sky.clearsky_ineichen`), sun by NREL SPA."""
    from sim.sky import clearsky_ineichen
    from sim.sun import solar_position

    step = pd.Timedelta(minutes=WEATHER_GRID_MIN)
    pad = pd.Timedelta(minutes=WEATHER_MAX_SHIFT_MIN)
    first = max(start.tz_convert("UTC"), weather.index[0]).ceil(step)
    last = min(end.tz_convert("UTC"), weather.index[-1])
    if not last > first:
        return None
    grid = pd.date_range(first - pad, last + pad, freq=step)
    ns = weather.index.as_unit("ns").asi8.astype(float)
    ghi = np.interp(grid.as_unit("ns").asi8.astype(float), ns,
                    weather["ghi"].to_numpy(float), left=np.nan, right=np.nan)
    sun = solar_position(grid, latitude, longitude, altitude)
    zen = sun["apparent_zenith"].to_numpy()
    clear = np.where(zen < 90.0, clearsky_ineichen(grid, zen, latitude, longitude,
                                                   altitude)["ghi"], 0.0)
    clear = np.nan_to_num(clear)
    inside = (grid >= first) & (grid < last) & np.isfinite(ghi)
    solar_day = (grid + pd.Timedelta(hours=longitude / 15.0)).floor("D").asi8
    day_of = np.unique(solar_day, return_inverse=True)[1]
    per_min = WEATHER_GRID_MIN

    def per_day(values: np.ndarray) -> np.ndarray:
        return np.bincount(day_of, weights=values.astype(float))

    sunlit = per_day(inside & (clear > 50.0)) * per_min
    sums = per_day(np.where(inside, np.nan_to_num(ghi), 0.0)), per_day(np.where(inside, clear, 0))
    ratio = np.divide(sums[0], sums[1], out=np.zeros_like(sums[0]), where=sums[1] > 0)
    days = np.flatnonzero((sunlit >= SUNNY_DAY_MIN_MIN) & (ratio >= SUNNY_DAY_CLEARNESS))
    sunny = days[np.argsort(-ratio[days], kind="stable")][:SHIFT_MAX_DAYS]
    fits = []
    measured = np.nan_to_num(ghi)
    for day in sunny:
        ok = inside & (day_of == day) & (clear > 50.0)
        fit = best_shift(measured, clear, ok, WEATHER_MAX_SHIFT_MIN // per_min, 3,
                         SUNNY_DAY_MIN_MIN // per_min)
        if fit is not None and fit["residual"] < SHIFT_MAX_RESIDUAL:
            fits.append((fit["shift"] * per_min, fit["residual"]))
    if not fits:
        return None
    shift, residual = np.median(np.array(fits), axis=0)
    return {"shift_min": float(shift), "days": len(fits), "residual": round(float(residual), 3)}


def shift_warning(shift: dict[str, Any] | None, station: dict[str, Any] | None
                  ) -> str | None:
    """Words for a weather file whose irradiance runs
    :data:`WEATHER_SHIFT_WARN_MIN` or more from the sun (:func:`irradiance_shift`), naming the shift
    and its likely causes for the file's kind (``station["format"]``, ``["stamped"]``);
    None otherwise."""
    if shift is None or abs(shift["shift_min"]) < WEATHER_SHIFT_WARN_MIN:
        return None
    tau = shift["shift_min"]
    late = "late" if tau > 0 else "early"
    head = (f"the weather's irradiance runs {abs(tau):.0f} min {late} against the sun at the "
            f"site (its GHI best matches the clear sky shifted by {tau:+.0f} min, the median "
            f"of {shift['days']} sunny days): the run's energy and gain are those of another "
            "sun. ")
    fmt = (station or {}).get("format")
    if fmt == "measured":
        stamped = station.get("stamped") if station else None
        slip = ("means stamped at their interval's start read as its end (the default "
                "interval_end) run a whole interval early (60 min for hourly means), "
                "instants read as interval ends half of one" if tau < 0 else
                "means stamped at their interval's end read as its start run a whole "
                "interval late (60 min for hourly means), read as instants half of one")
        causes = (f"Its times are read as {stamped} (weather_stamped / --weather-stamped): "
                  f"{slip}; or its times are in another zone than they say (a local clock "
                  "written as UTC, or the wrong --weather-timezone / weather_timezone) — "
                  "check what the file's times mark and in which zone")
    else:
        causes = ("Check the file's time zone (its header's UTC offset against the zone its "
                  "hours were written in) and whether its hours are labelled by their start "
                  "or their end")
    return head + causes


def weather_clock(weather: pd.DataFrame, latitude: float, longitude: float, altitude: float,
                  start: pd.Timestamp, end: pd.Timestamp, station: dict[str, Any] | None
                  ) -> dict[str, Any]:
    """The clock check of a run on ``weather`` (UTC index, on the run's times) at a place
    [° N, ° E, m]: ``{"weather_shift_min", "weather_warning"}`` — :func:`irradiance_shift`'s
    median shift [min] (None without a sunny day to fit) and :func:`shift_warning`'s words
    from :data:`WEATHER_SHIFT_WARN_MIN` on (None within it). The one rule of every run on a
    weather file, the twin's (``backend.twin.scenario.run_scenario``) and a plant's
    (``heliotwin plant simulate``)."""
    shift = irradiance_shift(weather, latitude, longitude, altitude, start, end)
    return {"weather_shift_min": None if shift is None else shift["shift_min"],
            "weather_warning": shift_warning(shift, station)}
