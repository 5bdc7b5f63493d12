"""A plant over a time range: sun, weather, strategy, shade and DC energy.

Per step: SPA sun (:func:`sim.sun.solar_position`); clear sky (Ineichen–Perez,
:func:`sim.sky.clearsky_ineichen`) or weather; the strategy's common orientation
(:mod:`sim.plant.strategies`); every collector's shade (:mod:`sim.plant.shading`);
Perez POA (:func:`sim.sky.poa_irradiance`) with the physical IAM on the beam
(:func:`sim.sky.iam_physical`); the beam scaled by the area or the
Martinez-Moreno factor (:mod:`sim.plant.electrical`); SAPM cell temperature
(``pvlib.temperature.sapm_cell``, open rack glass/polymer: a = −3.56, b = −0.075,
ΔT = 3 °C) and PVWatts DC power (``pvlib.pvsystem.pvwatts_dc``). A fixed plant of
the same collectors on the same pivots (``Plant.fixed_tilt``/``fixed_azimuth``),
with its own shade, is simulated alongside.

Weather comes on the run's times (a typical year is laid on them by
:func:`sim.sky.typical_year_at_site`, the twin's rule for a station near or far).

Wind stow: a plant whose file gives ``tracker.stow_wind_speed_m_s`` (``Plant.wind_stow``,
the twin's rule, :class:`sim.stow.WindStow`), run on weather with a ``wind_speed`` column,
lays every collector flat (surface elevation 90°, its azimuth kept) in the steps
:meth:`sim.stow.WindStow.stowed` marks: one anemometer, the whole plant stows. Flat collectors
on pivots at one height shade nothing; the shading code computes whatever the pivots' heights
leave. The series gains ``stow_loss_w`` [W] (the plant's power in the strategy's orientation
minus its power flat, bypass-diode model), the summary ``stow_min`` (daylight minutes stowed)
and ``stow_loss_wh``; without wind in the run's sky both are None.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from pvlib import atmosphere

from sim.energy import (
    check_step,
    energy_per_period_wh,
    gain_pct,
    run_energy_wh,
    simulation_times,
)
from sim.plant.electrical import beam_factors
from sim.plant.fields import horizon_elevation
from sim.plant.layout import Plant
from sim.plant.shading import BinTable, PlantShade, plant_shade, sum_columns
from sim.plant.strategies import orientations
from sim.sky import clearsky_ineichen, iam_physical, poa_irradiance, weather_at
from sim.stow import daylight_minutes
from sim.sun import solar_position

FloatArray = NDArray[np.float64]
_CHUNK = 50_000  # steps per chunk (bounded memory; the temporaries stay small)
_SAPM = {"a": -3.56, "b": -0.075, "deltaT": 3.0}
#: Daily clearness index below which a day counts as cloudy [-].
CLOUDY_KT = 0.4
#: :attr:`PlantResult.series`' columns, in order.
_SERIES_COLUMNS = ("solar_azimuth", "apparent_elevation", "dni", "ghi", "ghi_extra",
                   "surface_azimuth", "surface_elevation", "poa_global",
                   "mean_shaded_fraction", "trackers_shaded", "power_w", "power_area_w",
                   "power_unshaded_w", "fixed_power_w", "tracker_power_w")


def local_day(date: dt.date, timezone: str) -> tuple[pd.Timestamp, pd.Timestamp]:
    """``[start, end)`` of the local calendar ``date`` in ``timezone``: its midnight and the
    next date's, so a DST change day lasts 23 or 25 hours (midnight + 24 h on the autumn day
    is 23:00 of the same date). A midnight the clocks skip is the first instant after it,
    a repeated one its first occurrence."""
    def midnight(d: dt.date) -> pd.Timestamp:
        return pd.Timestamp(d.isoformat()).tz_localize(timezone, ambiguous=True,
                                                       nonexistent="shift_forward")

    return midnight(date), midnight(date + dt.timedelta(days=1))


def sky_conditions(plant: Plant, times: pd.DatetimeIndex, weather: pd.DataFrame | None = None,
                   closing: bool = False) -> dict[str, FloatArray]:
    """Sun (SPA) and irradiance at ``times``: the ``sky`` dict of :mod:`sim.plant.strategies`.

    Clear sky (Ineichen–Perez) unless ``weather`` (covering ``times``) is given;
    irradiance is zero with the sun down. ``closing``: the last of ``times`` closes a
    run's last step (:func:`sim.energy.simulation_times`); past the weather's last row it
    takes that row, as the twin's does.
    """
    # refraction at the plant's pressure and air temperature, as the twin's sun (it took sea
    # level at 12 °C: 0.1° too high at sunrise at 2,400 m, served to the trackers)
    pos = solar_position(times, plant.latitude, plant.longitude, plant.altitude,
                         float(atmosphere.alt2pres(plant.altitude)), plant.temp_air)
    sky: dict[str, FloatArray] = {
        "solar_azimuth": pos["azimuth"].to_numpy(),
        "apparent_elevation": pos["apparent_elevation"].to_numpy(),
        "apparent_zenith": pos["apparent_zenith"].to_numpy(),
        "zenith": pos["zenith"].to_numpy(),
    }
    cs = clearsky_ineichen(times, sky["apparent_zenith"], plant.latitude, plant.longitude,
                           plant.altitude)
    sky["dni_extra"], sky["airmass_relative"] = cs["dni_extra"], cs["airmass_relative"]
    if weather is None:
        for k in ("ghi", "dni", "dhi"):
            sky[k] = cs[k]
        sky["temp_air"] = np.full(len(times), plant.temp_air)
        sky["wind_speed"] = np.full(len(times), plant.wind_speed)
    else:
        sky.update(weather_at(times, weather, plant.temp_air, plant.wind_speed, closing))
    night = sky["apparent_elevation"] <= 0
    sky["dni"] = np.where(night, 0.0, sky["dni"])
    for k in ("ghi", "dhi"):
        sky[k] = np.where(night, 0.0, np.maximum(sky[k], 0.0))
    return sky


def field_shade(plant: Plant, sky: dict[str, FloatArray], saz: FloatArray, sel: FloatArray,
                band_edges: Any = (), table: BinTable | None = None
                ) -> tuple[PlantShade, NDArray[np.bool_]]:
    """Every collector's shade (:func:`sim.plant.shading.plant_shade`), and the steps where
    the plant's sloped ground hides the sun (:func:`sim.plant.fields.horizon_elevation`):
    there every collector's fraction is 1. ``band_edges`` are kept for a rectangle; a
    polygon's strings are clipped by :func:`sim.plant.electrical.beam_factors` itself."""
    c = plant.collector
    shade = plant_shade(plant.positions, sky["solar_azimuth"], sky["apparent_elevation"],
                        saz, sel, c.width, c.height, band_edges if c.is_rectangle else (),
                        table, None if c.is_rectangle else c.outline_m())
    behind = np.zeros(len(saz), dtype=bool)
    if plant.slope_tilt > 0:                # the ground beyond the plant hides the sun
        behind = sky["apparent_elevation"] <= horizon_elevation(
            sky["solar_azimuth"], plant.slope_azimuth, plant.slope_tilt)
        shade.fraction[behind] = 1.0
    return shade, behind


def _power(plant: Plant, sky: dict[str, FloatArray], saz: FloatArray, sel: FloatArray,
           table: BinTable | None = None, tracker: int | None = None) -> dict[str, Any]:
    """Shade, POA and DC power of every collector for one orientation series (and of
    collector ``tracker`` alone, ``p_tracker``, when given)."""
    from pvlib.pvsystem import pvwatts_dc
    from pvlib.temperature import sapm_cell

    c = plant.collector
    shade, behind = field_shade(plant, sky, saz, sel, c.string_boundaries(), table)
    f_area, f_elec = beam_factors(shade, c)
    f_area[behind] = 0.0
    f_elec[behind] = 0.0
    poa = poa_irradiance(90.0 - sel, saz, sky["apparent_zenith"], sky["solar_azimuth"],
                         sky["dni"], sky["ghi"], sky["dhi"], sky["dni_extra"],
                         sky["airmass_relative"], albedo=plant.albedo, model="perez")
    cos_aoi = sum_columns(_enu(saz, sel) * _enu(sky["solar_azimuth"], sky["apparent_elevation"]))
    aoi = np.degrees(np.arccos(np.clip(cos_aoi, -1, 1)))
    beam = poa["poa_direct"] * np.where(aoi < 90, iam_physical(np.minimum(aoi, 89.999)), 0.0)
    diffuse = poa["poa_diffuse"]
    t_cell = sapm_cell(poa["poa_global"], sky["temp_air"], sky["wind_speed"], **_SAPM)
    pdc0 = c.power_stc

    def dc(g: FloatArray) -> FloatArray:
        return np.asarray(pvwatts_dc(g, t_cell, pdc0, c.gamma_pdc), dtype=float)

    # PVWatts DC is linear in the irradiance and every collector of a step has the same
    # cell temperature, so the plant's power is the power of the collectors' summed
    # irradiance: one (T,) call per model instead of a (T, N) array of powers
    n = plant.n_trackers
    beam_area = beam * _beam_sum(f_area)
    beam_elec = beam * _beam_sum(f_elec)
    out = {"shade": shade, "poa_global": poa["poa_global"],
           "p_unshaded": dc(beam + diffuse) * n,
           "p_area": dc(beam_area + n * diffuse), "p_elec": dc(beam_elec + n * diffuse)}
    if tracker is not None:
        out["p_tracker"] = dc(beam * np.nan_to_num(f_elec[:, tracker], nan=1.0) + diffuse)
    return out


def _beam_sum(factors: FloatArray) -> FloatArray:
    """Σ of the collectors' beam factors ``(T, N)`` per step, NaN (sun down) counted as 1;
    copied without NaN only when there is one (a run's daylight steps have none)."""
    return (np.nan_to_num(factors, nan=1.0) if np.isnan(factors).any() else factors).sum(axis=1)


def _ratio(a: FloatArray, b: FloatArray) -> FloatArray:
    """a / b, NaN where b is 0 (a day without extraterrestrial light)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(b != 0, a / b, np.nan)


def _enu(az: FloatArray, el: FloatArray) -> FloatArray:
    from vision.sphere import enu_from_sky

    return enu_from_sky(az, el)


@dataclass
class PlantResult:
    """A plant run: its per-step series and per-day table.

    ``series`` (UTC index): ``solar_azimuth``, ``apparent_elevation``, ``dni``,
    ``ghi``, ``surface_azimuth``, ``surface_elevation``, ``poa_global``,
    ``mean_shaded_fraction``, ``trackers_shaded``, ``power_w`` (electrical
    model), ``power_area_w``, ``power_unshaded_w``, ``fixed_power_w``.
    ``daily`` (local date): energies [Wh], ``clearness_index`` [-].
    """

    plant: Plant
    start: pd.Timestamp
    end: pd.Timestamp
    step_s: float
    strategy: str
    sky_source: str
    series: pd.DataFrame
    daily: pd.DataFrame
    any_shaded_steps: int
    daylight_steps: int
    #: Σ DNI · mean F / Σ DNI over the daylight steps; None without beam (a polar night), as
    #: the other fractions of an empty denominator (JSON has no NaN)
    dni_weighted_shaded_fraction: float | None
    tracker_dni_weighted_shaded_fraction: FloatArray | None = None
    #: the series' values at the instant closing the last step (one step after its last
    #: row, :func:`sim.energy.simulation_times`), by column
    closing: dict[str, float] = field(default_factory=dict)
    #: daylight minutes the wind held the plant flat (:mod:`sim.stow`); None when the plant
    #: does not stow or the run's sky has no wind speed
    stow_min: int | None = None

    def energy_wh(self, column: str) -> float:
        """The run's integral of a power column [Wh] (irradiance: [Wh m⁻²]) over
        ``[start, end)``, by :mod:`sim.energy`'s rule (:func:`sim.energy.run_energy_wh`)."""
        return run_energy_wh(np.append(self.series[column].to_numpy(), self.closing[column]),
                             self.step_s, (self.end - self.start).total_seconds())

    def summary(self) -> dict[str, Any]:
        """The CLI/HTTP summary (DESIGN.md contract), units in the keys."""
        s = self.series
        wh = self.energy_wh

        e, e_area, e_un, e_fix = (wh("power_w"), wh("power_area_w"), wh("power_unshaded_w"),
                                  wh("fixed_power_w"))
        day = s["apparent_elevation"] > 0

        def pct(x: float) -> float | None:
            return round(100.0 * (1.0 - x / e_un), 4) + 0.0 if e_un > 0 else None

        return {
            "plant_id": self.plant.plant_id,
            "trackers": self.plant.n_trackers,
            "start": self.start.isoformat(),
            "end": self.end.isoformat(),
            "step_s": self.step_s,
            "strategy": self.strategy,
            "sky": self.sky_source,
            "daylight_steps": self.daylight_steps,
            "fraction_of_daylight_any_shaded": (
                self.any_shaded_steps / self.daylight_steps if self.daylight_steps else None),
            "dni_weighted_shaded_fraction": self.dni_weighted_shaded_fraction,
            "mean_shaded_fraction": (float(s["mean_shaded_fraction"][day].mean())
                                     if day.any() else None),
            "plant_energy_wh": round(e, 3),
            "plant_energy_area_model_wh": round(e_area, 3),
            "plant_energy_unshaded_wh": round(e_un, 3),
            "shading_loss_area_pct": pct(e_area),
            "shading_loss_electrical_pct": pct(e),
            "fixed_energy_wh": round(e_fix, 3),
            "gain_vs_fixed_pct": None if (g := gain_pct(e, e_fix)) is None else round(g, 4),
            "plant_peak_w": round(float(s["power_w"].max()), 3),
            "poa_insolation_wh_m2": round(wh("poa_global"), 3),
            **({} if self.plant.wind_stow is None else {  # null: no wind in the run's sky
                "stow_wind_speed_m_s": self.plant.wind_stow.wind_speed_m_s,
                "stow_min": self.stow_min,
                "stow_loss_wh": None if self.stow_min is None else round(wh("stow_loss_w"), 3)}),
        }


def simulate_plant(plant: Plant, start: pd.Timestamp, end: pd.Timestamp, step_s: float = 60.0,
                   strategy: str = "sun", weather: pd.DataFrame | None = None,
                   progress: Callable[[float], None] | None = None,
                   sky: dict[str, FloatArray] | None = None, with_fixed: bool = True,
                   tracker: int | None = None) -> PlantResult:
    """Simulate a plant from ``start`` (inclusive) to ``end`` (exclusive).

    Parameters
    ----------
    plant : Plant
    start, end : pandas.Timestamp
        Tz-aware.
    step_s : float
        [s].
    strategy : {"sun", "backtrack", "sky_scan"}
    weather : pandas.DataFrame, optional
        Covering the range (e.g. :func:`sim.sky.typical_year_at_site`); clear sky when None.
    progress : callable, optional
        Called with the fraction done.
    sky : dict, optional
        :func:`sky_conditions` of the whole range at these steps, computed once by the
        caller (a sweep of many layouts at one place); ``weather`` then only names the
        sky (``sky_source``): pass the weather the sky was computed from.
    with_fixed : bool
        Simulate the fixed comparison plant too (``fixed_power_w``; zeros when False).
    tracker : int, optional
        Index of a collector whose own power is kept (series ``tracker_power_w``,
        bypass-diode model; NaN when not asked).

    Returns
    -------
    PlantResult
        Its ``tracker_dni_weighted_shaded_fraction`` (N,) is Σ DNI · F_i / Σ DNI over the
        daylight steps for each collector i.
    """
    if start.tz is None or end.tz is None:
        raise ValueError("start and end must be timezone-aware")
    check_step(start, end, step_s)
    times = simulation_times(start, end, step_s)  # the series' steps and the closing instant
    n_steps = len(times) - 1
    if sky is not None and any(len(v) != len(times) for v in sky.values()):
        raise ValueError(f"sky must hold the range's {len(times)} instants "
                         f"(sim.energy.simulation_times)")
    any_shaded, daylight, dni_f, dni_sum = 0, 0, 0.0, 0.0
    # the whole range's columns, filled chunk by chunk (night rows stay 0; NaN for the
    # shaded fraction, and for a tracker not asked for): no per-chunk frames, no concat
    col = {name: np.zeros(len(times)) for name in _SERIES_COLUMNS}
    col["trackers_shaded"] = np.zeros(len(times), dtype=np.int64)
    col["mean_shaded_fraction"][:] = np.nan
    if tracker is None:
        col["tracker_power_w"][:] = np.nan
    dni_f_tracker = np.zeros(plant.n_trackers)
    stowed = None  # the wind stow, on weather with a wind speed only (sim.stow)
    if plant.wind_stow is not None and weather is not None and "wind_speed" in weather.columns:
        wind = weather_at(times, weather, plant.temp_air, plant.wind_speed, True)["wind_speed"]
        stowed = plant.wind_stow.stowed(times.as_unit("ns").asi8 / 1e9, wind)
        col["stow_loss_w"] = np.zeros(len(times))
    table = BinTable()                       # sun bins recur every day: build each once
    for k0 in range(0, len(times), _CHUNK):
        tt = times[k0:k0 + _CHUNK]
        csky = (sky_conditions(plant, tt, weather, closing=k0 + len(tt) == len(times))
                if sky is None else {k: v[k0:k0 + _CHUNK] for k, v in sky.items()})
        saz, sel = orientations(strategy, plant, csky)
        up = csky["apparent_elevation"] > 0
        day = np.nonzero(up)[0]              # shade and power are computed by day only
        dsky = {k: v[day] for k, v in csky.items()}
        flat, unstowed_w = None, None
        if stowed is not None and (flat := np.nonzero(stowed[k0 + day])[0]).size:
            # the strategy's power in the stowed daylight steps, then every collector flat
            unstowed_w = _power(plant, {k: v[flat] for k, v in dsky.items()}, saz[day][flat],
                                sel[day][flat], table)["p_elec"]
            sel = np.where(stowed[k0:k0 + len(tt)], 90.0, sel)
        run = _power(plant, dsky, saz[day], sel[day], table, tracker)
        fixed_w = (_power(plant, dsky, np.full(len(day), plant.fixed_azimuth),
                          np.full(len(day), 90.0 - plant.fixed_tilt), table)["p_elec"]
                   if with_fixed else np.zeros(len(day)))
        frac = run["shade"].fraction
        # not BLAS: a product this size wakes OpenBLAS's threads, which then spin on the
        # other core (~0.35 s of CPU in a 1-min year, from these few calls)
        mean_f = frac.mean(axis=1)
        n_sh = (frac > 0).sum(axis=1)
        step = k0 + day < n_steps            # the statistics leave out the closing instant
        dni_f_tracker += np.einsum("t,tn->n", dsky["dni"][step], frac[step])
        any_shaded += int((n_sh[step] > 0).sum())
        daylight += int(step.sum())
        dni_f += float(np.sum(dsky["dni"][step] * mean_f[step]))
        dni_sum += float(np.sum(dsky["dni"][step]))
        rows, at = slice(k0, k0 + len(tt)), k0 + day
        for name in ("solar_azimuth", "apparent_elevation", "dni", "ghi"):
            col[name][rows] = csky[name]
        col["ghi_extra"][rows] = np.maximum(csky["dni_extra"] * np.cos(np.radians(csky["zenith"])),
                                            0.0)
        col["surface_azimuth"][rows], col["surface_elevation"][rows] = saz, sel
        col["mean_shaded_fraction"][at], col["trackers_shaded"][at] = mean_f, n_sh
        col["poa_global"][at], col["fixed_power_w"][at] = run["poa_global"], fixed_w
        col["power_w"][at], col["power_area_w"][at] = run["p_elec"], run["p_area"]
        col["power_unshaded_w"][at] = run["p_unshaded"]
        if flat is not None and unstowed_w is not None:
            col["stow_loss_w"][at[flat]] = unstowed_w - run["p_elec"][flat]
        if tracker is not None:
            col["tracker_power_w"][at] = run["p_tracker"]
        if progress is not None:
            progress(min(1.0, (k0 + len(tt)) / len(times)))
    closing = {name: float(v[n_steps]) for name, v in col.items()}
    series = pd.DataFrame({name: v[:n_steps] for name, v in col.items()}, index=times[:n_steps],
                          copy=False)
    # local days as integers (days since 1970-01-01 on the local calendar), summed with
    # bincount: pandas' groupby on ``.date`` made 525,600 date objects for a 1-min year
    local_day = series.index.tz_convert(plant.timezone).tz_localize(None).as_unit("s").asi8
    day_nums, day_of = np.unique(local_day // 86_400, return_inverse=True)
    dates = list(pd.to_datetime(day_nums, unit="D").date)
    edges = pd.DatetimeIndex([pd.Timestamp(d, tz=plant.timezone) for d in
                              [*dates, dates[-1] + pd.Timedelta(days=1)]])
    edges_s = np.minimum(edges.as_unit("ns").asi8, end.as_unit("ns").value) / 1e9
    ts_s = times.as_unit("ns").asi8 / 1e9  # the steps and the closing instant; steps < 1 s too

    def per_day_wh(column: str) -> np.ndarray:  # sim/energy.py's rule, split at local midnights
        return energy_per_period_wh(ts_s, col[column], 1.5 * step_s, edges_s)

    def per_day_sum(column: str) -> FloatArray:
        return np.bincount(day_of, series[column].to_numpy()).astype(float)

    daily = pd.DataFrame({
        "energy_wh": per_day_wh("power_w"),
        "energy_area_model_wh": per_day_wh("power_area_w"),
        "energy_unshaded_wh": per_day_wh("power_unshaded_w"),
        "fixed_energy_wh": per_day_wh("fixed_power_w"),
        "clearness_index": _ratio(per_day_sum("ghi"), per_day_sum("ghi_extra")),
    }, index=dates)
    stow_min = (None if stowed is None else daylight_minutes(
        stowed[:n_steps], series["apparent_elevation"].to_numpy() > 0, step_s,
        (end - start).total_seconds()))
    return PlantResult(plant, start, end, float(step_s), strategy,
                       "clearsky-ineichen" if weather is None else "weather", series, daily,
                       any_shaded, daylight, dni_f / dni_sum if dni_sum > 0 else None,
                       dni_f_tracker / dni_sum if dni_sum > 0 else None, closing, stow_min)





def compare_strategies(plant: Plant, start: pd.Timestamp, end: pd.Timestamp,
                       step_s: float = 600.0, weather: pd.DataFrame | None = None,
                       strategies: tuple[str, ...] = ("sun", "backtrack", "sky_scan"),
                       cloudy_kt: float = CLOUDY_KT) -> dict[str, Any]:
    """Every strategy over one range, and the gain of each over ``sun`` on cloudy days.

    Returns
    -------
    dict
        ``summaries`` (strategy → :meth:`PlantResult.summary`), ``cloudy_days``
        (days with daily clearness index < ``cloudy_kt``), ``cloudy_gain_pct``
        (strategy → gain over ``sun`` in plant energy on those days [%]),
        ``fixed_energy_wh``.
    """
    results = {s: simulate_plant(plant, start, end, step_s, s, weather) for s in strategies}
    out: dict[str, Any] = {"summaries": {s: r.summary() for s, r in results.items()}}
    base = results.get("sun")
    if base is not None:
        cloudy = base.daily["clearness_index"] < cloudy_kt
        out["cloudy_days"] = int(cloudy.sum())
        e_sun = float(base.daily["energy_wh"][cloudy].sum())
        out["cloudy_gain_pct"] = {
            s: (None if (g := gain_pct(float(r.daily["energy_wh"][cloudy].sum()), e_sun)) is None
                else round(g, 3))
            for s, r in results.items()}
    out["fixed_energy_wh"] = next(iter(results.values())).summary()["fixed_energy_wh"]
    return out


__all__ = ["CLOUDY_KT", "PlantResult", "compare_strategies", "field_shade", "local_day",
           "simulate_plant", "sky_conditions"]
