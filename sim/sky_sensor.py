"""The fixed array as an irradiance sensor, and the weather-aware twin under that sky.

Three steps, each a plain vectorised function:

1. :func:`invert_poa` — the fixed array's measured power → plane-of-array
   irradiance [W m⁻²] by inverting the project's own PV model (:mod:`sim.pv`: the
   CEC single-diode model of the KD205GX-LP, Dobos 2012, through ``MppTable``; the
   SAPM cell temperature, King et al. 2004; the De Soto 2006 IAM on the beam part,
   :func:`sim.sky.effective_irradiance`). Array power rises monotonically with
   irradiance, so a vectorised bisection on G over every minute at once finds
   the one root. Minutes where the inversion is ill-posed are flagged, not guessed
   (:data:`FLAGS`): night, a missing reading, zero output in daylight, a stale
   (repeated) value, the logger's saturation, and power above what the clear sky
   (Ineichen 2002) can give even with cloud enhancement.
2. :func:`decompose` — POA → GHI/DNI/DHI by two physically different routes:
   ``"gti_dirint"``, pvlib's GTI-DIRINT (Marion 2015, doi:10.1016/j.solener.2015.03.016),
   the main estimate, and ``"clearsky_erbs"``, GHI from the clear-sky ratio of the
   plane (POA/POA_clear × GHI_clear) split by Erbs et al. (1982,
   doi:10.1016/0038-092X(82)90302-4), the second opinion whose spread widens the
   uncertainty band. Both are bounded by the clear sky: DNI ≤ DNI_clear,
   GHI ≤ 1.25·GHI_clear, DHI ≥ 0. Minutes that see the clear beam (:func:`_clear_beam`)
   take the clear-sky DNI; GTI-DIRINT runs on 10-minute means of the other minutes only
   (it iterates DIRINT per point, ~0.13 ms a point), its ratios interpolated back onto
   them; the diffuse is then solved so that the site's transposition gives back the
   measured POA (:func:`_closure`).
3. :func:`weather_from_fixed` — the minute weather frame (``ghi, dni, dhi,
   temp_air, wind_speed``) that :func:`sim.twin.simulate` takes as ``weather``,
   so the tracker's expected power comes from the same pipeline as the clear-sky
   twin. Flagged minutes with the sun up take the clear-sky index interpolated in time
   from their valid neighbours (the answer's ``valid`` column says which); a local day
   with too few valid minutes (:func:`measured_sky`) takes the clear sky's own
   GHI/DNI/DHI, so its expectation is the clear-sky twin's. Where the logger reports an
   irradiance sensor — a cell on the fixed plane, or a GHI pyranometer (a horizontal
   plane: GTI-DIRINT is then DIRINT, Perez et al. 1992) — its readings replace the
   inverted power on the days they cover, through the same two steps.

Nothing here reads files or keeps state; seeds: the tracker/fixed pair of seed 000
(Acosta-Banda et al. 2025), the small expected gain under diffuse skies of seed 004.
"""

from __future__ import annotations

import warnings
from typing import NamedTuple

import numpy as np
import pandas as pd

from sim import pv, sky, sun
from sim.sites import Site

__all__ = ["FLAGS", "SENSOR_SKIES", "Plane", "decompose", "fixed_clear_sky", "fixed_plane",
           "horizontal", "invert_poa", "measured_sky", "on_slow_days", "readings_fine",
           "sensor_flags", "tracker_blind_sd_w", "weather_aware_twin", "weather_from_fixed"]

#: Flags of :func:`invert_poa` (bit values, combined with ``|``).
FLAGS = {
    "night": 1,  # sun below 2° or clear-sky POA below 20 W m⁻²
    "missing": 2,  # no reading (NaN)
    "zero": 4,  # ≤ 0.5 % of STC power × clear-sky POA / 1000 while that POA is > 200 W m⁻²
    "stale": 8,  # the same value ≥ 5 readings (a coarse logger: an hour) running (_stale)
    "saturated": 16,  # at the logger's saturation power
    "above_clear_sky": 32,  # inverted POA > 1.25 × clear-sky POA + 50 W m⁻²
}

G_MAX = 1500.0  # upper end of the bisection [W m⁻²]
_BISECTIONS = 16  # 1500 / 2**16 = 0.023 W m⁻² (the logger's 0.1 W: 0.12 W m⁻²)
_STALE_MIN = 5
#: How long [min] a run of one value must last to be a frozen logger when the logger holds
#: its value from one minute to the next on at least :data:`_HELD_SHARE` of its live
#: minutes (a coarse resolution: 10 W or 0.01 kW steps; :func:`_stale`)
_STALE_COARSE_MIN = 60
#: A live 1-minute reading at a fine resolution changes on nearly every minute (the sun
#: moves, the sensor has noise); a share of held minutes above this is the resolution's
_HELD_SHARE = 0.1
#: A local day's sky is the fixed array's when at least this share of its daylight minutes
#: (clear-sky POA > 20 W m⁻²) inverted; else it is the clear sky of the clear-sky twin.
MIN_SENSOR_SHARE = 0.5
#: The fixed plane tells beam from diffuse where the sun is this far in front of it
#: (cos AOI; 0.3 = 72.5°): at grazing incidence its POA is nearly all diffuse.
BEAM_SEEN_COS = 0.3
#: Where the sun is behind or grazing the fixed plane (beyond :data:`BEAM_SEEN_COS`), a gap
#: in the clouds still shows on it when the clear beam is at least this share of its clear
#: POA (the gap lifts the POA from a deck's diffuse to the clear sky's: :func:`_clear_beam`);
#: below it the plane is blind to the beam (:func:`_unseen_beam`).
BEAM_SHARE_SPLIT = 0.8
#: How long a cloud state persists [min]: the beam the plane last saw (the mean of the seen
#: minutes within this of the nearest) carries over to a minute it cannot see with weight
#: exp(−lag / this), the day's seen mean with the rest (:func:`_unseen_beam`).
BEAM_PERSISTENCE_MIN = 30.0
#: A plane's clearness k = POA/POA_clear a clear sky can give: from this on (none below: the
#: plane is darker than a clear sky leaves it, so clouds hide the sun) …
CLEAR_K_MIN = 0.6
#: … fully from this on (a clear sky at low sun or in turbid air; :func:`_clear_beam`,
#: :func:`_unseen_beam`)
CLEAR_K_FULL = 0.75
#: A clear spell's plane clearness ranges less than this over 11 minutes (1 % logger noise
#: spans ~0.05; a cloud edge moves it by the beam's share, ≥ 0.3).
STEADY_RANGE = 0.06


class Plane(NamedTuple):
    """The plane an irradiance is measured on: tilt, azimuth [°] and the ground's albedo."""

    surface_tilt: float
    surface_azimuth: float
    albedo: float


def fixed_plane(site: Site) -> Plane:
    """The plane of the site's fixed array."""
    a = site.arrays["fixed"]
    return Plane(a.surface_tilt, a.surface_azimuth, a.albedo)


def horizontal(site: Site) -> Plane:
    """The plane of a pyranometer measuring GHI (the fixed array's albedo around it)."""
    return Plane(0.0, 180.0, site.arrays["fixed"].albedo)


def fixed_clear_sky(site: Site, times: pd.DatetimeIndex, plane: Plane | None = None
                    ) -> pd.DataFrame:
    """Sun position and clear sky (Ineichen, :func:`sim.sky.clearsky_ineichen`) on the fixed
    plane (or on ``plane``).

    Returns
    -------
    pandas.DataFrame
        Indexed by ``times``: ``apparent_zenith``, ``azimuth``, ``apparent_elevation``
        [°], ``aoi`` [°] of the fixed plane, ``ghi_clear``, ``dni_clear``,
        ``dhi_clear``, ``poa_clear`` [W m⁻²], ``dni_extra`` [W m⁻²].
    """
    from pvlib import atmosphere

    fixed = plane or fixed_plane(site)
    pos = sun.solar_position(times, site.latitude, site.longitude, site.altitude,
                             float(atmosphere.alt2pres(site.altitude)), site.temp_air)
    zen = pos["apparent_zenith"].to_numpy()
    az = pos["azimuth"].to_numpy()
    cs = sky.clearsky_ineichen(times, zen, site.latitude, site.longitude, site.altitude)
    aoi = sky.angle_of_incidence(fixed.surface_tilt, fixed.surface_azimuth, zen, az)
    poa = sky.poa_irradiance(fixed.surface_tilt, fixed.surface_azimuth, zen, az, cs["dni"],
                             cs["ghi"], cs["dhi"], cs["dni_extra"], cs["airmass_relative"],
                             albedo=fixed.albedo, model=site.transposition_model)
    return pd.DataFrame({
        "apparent_zenith": zen, "azimuth": az, "apparent_elevation": 90.0 - zen, "aoi": aoi,
        "ghi_clear": cs["ghi"], "dni_clear": cs["dni"], "dhi_clear": cs["dhi"],
        "poa_clear": poa["poa_global"], "beam_clear": poa["poa_direct"],
        "dni_extra": cs["dni_extra"]}, index=times)


def _array_power(poa_global: np.ndarray, beam_fraction: np.ndarray, iam: np.ndarray,
                 temp_air: np.ndarray, wind_speed: np.ndarray, array: pv.ArrayConfig
                 ) -> np.ndarray:
    """The twin's power model of one array at POA ``poa_global`` [W m⁻²] [W]."""
    e_eff = poa_global * (beam_fraction * iam + 1.0 - beam_fraction)
    t_cell = pv.cell_temperature(poa_global, temp_air, wind_speed, array.temperature_model)
    return pv.array_mpp(e_eff, t_cell, array)["power_w"]


def invert_poa(power_w: np.ndarray, clear: pd.DataFrame, array: pv.ArrayConfig,
               temp_air: np.ndarray | float, wind_speed: np.ndarray | float,
               saturation_power_w: float | None = None) -> pd.DataFrame:
    """Plane-of-array irradiance [W m⁻²] behind the fixed array's measured power, per minute.

    The beam share of the POA (for the IAM) is taken from the clear sky scaled by
    the plane's clearness (all beam at POA_clear, none at 30 % of it) — a small
    correction: the IAM of the fixed plane is > 0.95 below 55° of incidence.

    Parameters
    ----------
    power_w : array_like
        Measured array power [W]; NaN = no reading.
    clear : pandas.DataFrame
        From :func:`fixed_clear_sky` on the same times.
    array : ArrayConfig
        The fixed array (modules, wiring, temperature model).
    temp_air, wind_speed : array_like or float
        Air temperature [°C] and wind speed [m s⁻¹] (site defaults when unmeasured).
    saturation_power_w : float, optional
        The most the array's readings can show [W] (its inverter's limit,
        ``inverter_limit_w``, or the logger's full scale); readings within 0.5 % of it are
        flagged ``saturated`` and their POA is the one that gives that much: a lower bound
        (:func:`_sky_from_plane`).

    Returns
    -------
    pandas.DataFrame
        ``poa_global`` [W m⁻²] (NaN where flagged), ``flag`` (bits of :data:`FLAGS`).
    """
    p = np.asarray(power_w, dtype=float)
    n = p.size
    t_air = np.broadcast_to(np.asarray(temp_air, dtype=float), (n,))
    wind = np.broadcast_to(np.asarray(wind_speed, dtype=float), (n,))
    poa_clear = clear["poa_clear"].to_numpy()
    iam = sky.iam_physical(np.minimum(clear["aoi"].to_numpy(), 90.0))
    beam_clear = np.divide(clear["beam_clear"].to_numpy(), poa_clear,
                           out=np.zeros(n), where=poa_clear > 0)
    stc_w = float(pv.cec_module_parameters(array.module)["STC"]) * array.modules
    # "zero": at most 0.5 % of what the array makes at the clear sky's POA (its rating scaled
    # by POA / 1000 W m⁻²): a share of the rating alone was 1.5 % of Reykjavík's December
    # clear sky, and a dark overcast day's 4.2 W on 820 W was refused as a tripped breaker
    # (a tester's finding); a breaker, kW or hours off still read far under it
    flag = _reading_flags(p, clear, 0.005 * stc_w * poa_clear / 1000.0)
    if saturation_power_w is not None:
        at = np.isfinite(p) & (p >= 0.995 * saturation_power_w)
        flag[at] |= FLAGS["saturated"]
        # an inverter holding its limit for hours is clipping, not a frozen logger
        flag[at] &= ~FLAGS["stale"]
    # a reading at the limit: the plane got at least the POA that gives the limit, solved
    # for here and kept beside its flag (_sky_from_plane: a lower bound, not a measurement)
    saturated = flag == FLAGS["saturated"]
    todo = (flag == 0) | saturated
    lo = np.zeros(int(todo.sum()))
    hi = np.full(lo.size, G_MAX)
    # (its flag's threshold: the modelled array clips at the limit itself, a plateau)
    target = np.where(saturated, 0.995 * (saturation_power_w or 0.0), p)[todo]
    args = (iam[todo], t_air[todo], wind[todo])
    ratio = np.ones(lo.size)
    for _ in range(2):  # beam share from the plane's clearness of the previous pass
        kt = np.clip(ratio, 0.0, 1.0)
        f_b = beam_clear[todo] * np.clip((kt - 0.3) / 0.7, 0.0, 1.0)
        lo, hi = np.zeros(lo.size), np.full(lo.size, G_MAX)
        for _ in range(_BISECTIONS):
            mid = 0.5 * (lo + hi)
            above = _array_power(mid, f_b, *args, array) > target
            hi = np.where(above, mid, hi)
            lo = np.where(above, lo, mid)
        ratio = 0.5 * (lo + hi) / np.maximum(poa_clear[todo], 1.0)
    g = np.full(n, np.nan)
    g[todo] = 0.5 * (lo + hi)
    too_high = todo & ~saturated & (g > 1.25 * poa_clear + 50.0)
    flag[too_high] |= FLAGS["above_clear_sky"]
    g[too_high] = np.nan
    return pd.DataFrame({"poa_global": g, "flag": flag}, index=clear.index)


def _reading_flags(values: np.ndarray, clear: pd.DataFrame,
                   zero_at: float | np.ndarray) -> np.ndarray:
    """:data:`FLAGS` a reading (power, or a measured irradiance) gets before any model:
    night (sun below 2° or clear-sky POA below 20 W m⁻²), missing (NaN), zero (≤
    ``zero_at`` while the clear sky gives > 200 W m⁻²), stale (:func:`_stale`)."""
    poa_clear = clear["poa_clear"].to_numpy()
    flag = np.zeros(values.size, dtype=np.int64)
    night = (clear["apparent_elevation"].to_numpy() < 2.0) | (poa_clear < 20.0)
    flag[night] |= FLAGS["night"]
    flag[~np.isfinite(values)] |= FLAGS["missing"]
    flag[~night & np.isfinite(values) & (values <= zero_at) & (poa_clear > 200.0)] |= \
        FLAGS["zero"]
    flag[~night & _stale(values)] |= FLAGS["stale"]
    return flag


def _stale(p: np.ndarray) -> np.ndarray:
    """True inside runs of identical non-zero values that only a frozen logger makes:
    :data:`_STALE_MIN` of its readings running (a slower logger's minutes are interpolated
    between readings, :func:`sim.energy.on_grid`: its cadence is the median spacing of the
    grid's kinks), and at least :data:`_STALE_COARSE_MIN` minutes of a logger that often
    holds its value — a coarse resolution holds a live value for minutes (10 W steps at
    300 W: a tester's overcast day lost 30 % of its minutes as stale, and with 50 W steps
    every day fell back to the clear sky; two equal readings of a 15-minute logger made
    16 equal minutes)."""
    if p.size == 0:
        return np.zeros(0, dtype=bool)
    new_run = np.r_[True, p[1:] != p[:-1]]
    run_id = np.cumsum(new_run) - 1
    length = np.bincount(run_id)[run_id]
    live = (p[1:] > 0) & (p[:-1] > 0)  # NaN compares False: only read minutes
    held = float(np.mean(p[1:][live] == p[:-1][live])) if live.any() else 0.0
    d2 = np.abs(p[2:] - 2.0 * p[1:-1] + p[:-2])
    kinks = np.flatnonzero(d2 > 1e-9 * max(float(np.nanmax(np.abs(p), initial=0.0)), 1.0))
    cadence = max(1, int(round(float(np.median(np.diff(kinks)))))) if kinks.size > 2 else 1
    need = max(_STALE_MIN * cadence, _STALE_COARSE_MIN if held >= _HELD_SHARE else 0)
    return (length >= need) & (p > 0)


def _bound(ghi: np.ndarray, dni: np.ndarray, clear: pd.DataFrame
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Clip a decomposition to the clear sky: DNI ≤ DNI_clear, GHI ≤ 1.25 GHI_clear, DHI ≥ 0."""
    cos_z = np.cos(np.radians(clear["apparent_zenith"].to_numpy()))
    ghi = np.clip(np.nan_to_num(ghi), 0.0, 1.25 * clear["ghi_clear"].to_numpy())
    dni = np.clip(np.nan_to_num(dni), 0.0, clear["dni_clear"].to_numpy())
    dni = np.minimum(dni, ghi / np.maximum(cos_z, 0.05))
    dhi = np.maximum(ghi - dni * np.maximum(cos_z, 0.0), 0.0)
    return ghi, dni, dhi


#: Readings at most this far apart [s] show a clear spell (:func:`_clear_beam`: steady over
#: 11 minutes, two or three readings or more); coarser readings, interpolated onto the minute
#: grid, look steady whatever the clouds did between them (an hourly mean's smooth POA)
SPELL_SEEN_MAX_SPACING_S = 300.0


def readings_fine(ts_s: np.ndarray, values: np.ndarray, grid_s: np.ndarray) -> np.ndarray:
    """Per minute of ``grid_s`` [s] (and per column of a 2-D ``values``): whether it lies
    between two finite readings at most :data:`SPELL_SEEN_MAX_SPACING_S` apart, or on one —
    where the readings can show a clear spell (:func:`decompose`, ``spells_seen``). The
    energy rule's bridging (:func:`sim.energy.on_grid`) with that gap."""
    from sim.energy import on_grid

    v = np.asarray(values, np.float64)
    return np.isfinite(on_grid(ts_s, np.where(np.isfinite(v), 1.0, np.nan), grid_s,
                               SPELL_SEEN_MAX_SPACING_S))


def _clear_beam(k: np.ndarray, clear: pd.DataFrame
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the plane sees a clear line to the sun: the clear beam's weight per minute,
    its DNI [W m⁻²] and the clear-spell mask.

    With ``k`` = POA/POA_clear the plane's clearness (:func:`_clearness`), the DNI there is
    the clear-sky DNI (Ineichen) × min(k, 1); elsewhere GTI-DIRINT's, which runs low in
    clear skies (its
    Kt′ bins average over turbid and clean air; Perez et al. 1992), by up to 40 % at low
    sun on the fixed plane's grazing incidence. Two rules, the larger weight wins:

    - any minute at k ≥ 0.85 (fully at 1): a gap in the clouds shows the beam whatever
      its neighbours — a gap of a few minutes is never steady, and missing it put the
      overcast days' expected energy 2–5 % low with a shape error of 0.1–0.25;
    - in a *clear spell* (k ranging < :data:`STEADY_RANGE` over 11 minutes, no cloud
      edge passing, and k ≥ :data:`CLEAR_K_FULL`) from k = :data:`CLEAR_K_MIN` on, fully at
      :data:`CLEAR_K_FULL`: a clear sky whose plane clearness sits below 0.85 (low sun,
      turbid air).

    The diffuse follows from :func:`_closure`.
    """
    roll = pd.Series(k).rolling(11, center=True, min_periods=1)
    steady = (roll.max() - roll.min()).to_numpy() < STEADY_RANGE
    w = np.maximum(np.clip((k - 0.85) / 0.15, 0.0, 1.0), np.where(steady, _clear_sky_can(k), 0.0))
    return w, np.minimum(k, 1.0) * clear["dni_clear"].to_numpy(), steady & (k >= CLEAR_K_FULL)


def _clearness(poa: np.ndarray, clear: pd.DataFrame) -> np.ndarray:
    """The plane's clearness k = POA/POA_clear [-] (0 where the clear sky gives ≤ 1 W m⁻²)."""
    poa_clear = clear["poa_clear"].to_numpy()
    return np.divide(poa, poa_clear, out=np.zeros(poa.size), where=poa_clear > 1.0)


def _clear_sky_can(k: np.ndarray) -> np.ndarray:
    """0–1: how plainly a plane at clearness ``k`` can be under a clear sky, from
    :data:`CLEAR_K_MIN` (0) to :data:`CLEAR_K_FULL` (1)."""
    return np.clip((k - CLEAR_K_MIN) / (CLEAR_K_FULL - CLEAR_K_MIN), 0.0, 1.0)


def _unseen_beam(dni: np.ndarray, clear: pd.DataFrame, seen: np.ndarray, up: np.ndarray,
                 k: np.ndarray, gap_dni: np.ndarray, site: Site
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``(dni, sd)`` [W m⁻²]: ``dni`` with each minute the plane is blind to the beam in — the
    sun up but not ``seen`` (behind the plane, grazing it, or no reading) and the clear beam
    under :data:`BEAM_SHARE_SPLIT` of the plane's clear POA (where it is not, the plane still
    shows a gap in the clouds: ``gap_dni``, :func:`_clear_beam`'s clear beam) — given the beam's
    clear-sky index DNI/DNI_clear that the seen minutes make likely there: that of the seen
    minutes within :data:`BEAM_PERSISTENCE_MIN` of the nearest seen one, weighted
    exp(−lag / :data:`BEAM_PERSISTENCE_MIN`) by the lag from it, and the mean of the seen
    minutes of the ``site``'s local day with the rest — a two-state cloud process's
    expectation (clear or clouded spells, Markov: the state's memory fades with the lag toward the
    day's share of clear sky; the generated skies are such a process,
    tests/sim/realistic_sky.py) — where the plane's clearness ``k`` lets a clear sky be
    (:func:`_clear_sky_can`: a plane darker than a clear sky leaves it is under cloud, and
    its sun is too). ``sd``: that guess's standard deviation, the day's spread of the seen
    minutes' index × √(1 − weight²) (the Markov state's variance given the last seen one;
    a day without a seen minute takes the run's mean and spread), also on a minute without
    a reading whose grazing or frontal sun keeps ``gap_dni``; 0 where the plane sees.
    Without a seen minute in the run the decomposition stands, its sd half the clear beam.

    There the plane's POA is (nearly) diffuse only, and its decomposition says nothing of
    the beam either way: an overcast deck's diffuse can be as bright as the clear sky's,
    which :func:`_clear_beam`'s k ≥ 0.85 and GTI-DIRINT read as a beam (summer dawns and
    dusks behind the plane put cloudy days up to 28.5 % high at Golden, Madrid, Freiburg and
    Alice Springs, generated held-out skies, 36 of 120 healthy days called underperforming
    or soiled), and a clear dusk's grazing POA, whose clearness wavers off a clear spell's,
    read as no beam at all (Palmer, December: a clear evening's tracker expected at 5 % of
    what it made for a quarter of an hour). The first rule, a cap at the seen minutes' mean
    alone where the clear beam was under half the plane's clear-sky POA, left a gap in the
    clouds by the last seen minute to the whole evening behind the plane, and a grazing
    sun's minutes uncapped (a tester's Hobart and Palmer, December, facing north: overcast
    days 6–26 % high, underperformance at confidence 1.0; ``docs/diagnosis.md``, "Any
    site")."""
    idx = np.flatnonzero(seen)
    dni_clear = clear["dni_clear"].to_numpy()
    if idx.size == 0:  # nothing seen: the decomposition stands, as unsure as a beam can be
        return dni, np.where(up, 0.5 * dni_clear, 0.0)
    pos = np.arange(dni.size)
    after = np.clip(np.searchsorted(idx, pos), 0, idx.size - 1)
    before = np.maximum(after - 1, 0)
    near = np.where(np.abs(idx[before] - pos) <= np.abs(idx[after] - pos), idx[before],
                    idx[after])
    k_b = pd.Series(np.where(seen, np.divide(dni, dni_clear, out=np.zeros(dni.size),
                                             where=dni_clear > 0), np.nan))
    window = 2 * int(BEAM_PERSISTENCE_MIN) + 1  # minutes, centred
    last_seen = k_b.rolling(window, center=True, min_periods=1).mean().to_numpy()[near]
    by_day = k_b.groupby(_local_days(site, clear.index.as_unit("s").asi8))
    # a day without a seen minute of its own takes the run's (a reviewer's finding: the
    # last seen index at full weight, half a day on, with no spread)
    day_mean = np.nan_to_num(by_day.transform("mean").to_numpy(), nan=float(k_b.mean()))
    var_day = np.nan_to_num(by_day.transform("var", ddof=0).to_numpy(),
                            nan=float(k_b.var(ddof=0)))
    w = np.exp(-np.abs(near - pos) / BEAM_PERSISTENCE_MIN)
    k_likely = w * last_seen + (1.0 - w) * day_mean
    sd_likely = np.sqrt(np.maximum(var_day * (1.0 - w * w), 0.0)) * dni_clear
    cos_aoi = np.cos(np.radians(clear["aoi"].to_numpy()))
    blind = up & ~seen & (dni_clear * np.maximum(cos_aoi, 0.0)
                          < BEAM_SHARE_SPLIT * clear["poa_clear"].to_numpy())
    can = _clear_sky_can(k)
    out = np.where(blind, k_likely * can * dni_clear, np.where(up & ~seen, gap_dni, dni))
    # a minute without a reading, the sun in front of the plane: its beam is the clear-beam
    # evidence of the clearness filled in across the gap, no more sure than a blind one's (a
    # reviewer's finding: a midday dropout narrowed nothing, 14 of 48 healthy Golden days
    # under their band)
    unread = up & ~seen & ~blind & (cos_aoi >= BEAM_SEEN_COS)
    sd = np.where(blind, sd_likely * can, np.where(unread, sd_likely, 0.0))
    return out, sd


def _closure(poa: np.ndarray, dni: np.ndarray, clear: pd.DataFrame, site: Site,
             fixed: Plane) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """GHI, DNI, DHI whose transposition onto the plane ``fixed`` by the site's own model
    (the twin's, :func:`sim.sky.poa_irradiance`) gives back ``poa``: DHI solved for the given
    DNI (Hay-Davies and isotropic are linear in DHI at fixed DNI, so the secant step is
    exact; one more step for Perez); where the beam alone would exceed ``poa`` the DNI is
    scaled down to it and DHI is 0. Without this the twin's fixed array ran ~1 % below its
    own readings (GTI-DIRINT transposes with Perez, the twin with the site's model)."""
    from pvlib import atmosphere

    zen = clear["apparent_zenith"].to_numpy()
    cos_z = np.maximum(np.cos(np.radians(zen)), 0.0)
    am = np.asarray(atmosphere.get_relative_airmass(np.minimum(zen, 90.0)), dtype=float)

    def onto_plane(b: np.ndarray, d: np.ndarray) -> np.ndarray:
        return sky.poa_irradiance(fixed.surface_tilt, fixed.surface_azimuth, zen,
                                  clear["azimuth"].to_numpy(), b, b * cos_z + d, d,
                                  clear["dni_extra"].to_numpy(), np.nan_to_num(am, nan=40.0),
                                  albedo=fixed.albedo, model=site.transposition_model
                                  )["poa_global"]

    beam_only = onto_plane(dni, np.zeros(poa.size))
    per_dhi = np.maximum(onto_plane(dni, np.ones(poa.size)) - beam_only, 1e-6)
    dhi = (poa - beam_only) / per_dhi
    dhi = dhi + (poa - onto_plane(dni, np.maximum(dhi, 0.0))) / per_dhi
    over = dhi < 0.0
    dni = np.where(over, dni * np.divide(poa, beam_only, out=np.zeros(poa.size),
                                         where=beam_only > 0), dni)
    dhi = np.maximum(dhi, 0.0)
    return dni * cos_z + dhi, dni, dhi


def decompose(poa_global: np.ndarray, clear: pd.DataFrame, site: Site,
              model: str = "gti_dirint", beam_seen: np.ndarray | None = None,
              plane: Plane | None = None, spells_seen: np.ndarray | bool = True
              ) -> pd.DataFrame:
    """GHI, DNI, DHI [W m⁻²] behind a fixed plane's POA (no NaN in ``poa_global``).

    Parameters
    ----------
    poa_global : array_like
        POA of the fixed plane [W m⁻²] (0 at night).
    clear : pandas.DataFrame
        From :func:`fixed_clear_sky`.
    model : {"gti_dirint", "clearsky_erbs"}
        See the module docstring.
    beam_seen : array_like of bool, optional
        Minutes whose POA can tell beam from diffuse (a measured minute with the sun well
        in front of the plane); the others, when in a clear spell (:func:`_clear_beam`),
        take the beam's clear-sky index (DNI/DNI_clear) of the nearest such minutes of a
        clear spell in time. Default: every minute.
    plane : Plane, optional
        The plane ``poa_global`` is on (``clear`` computed for it); default the fixed
        array's. On a horizontal plane GTI-DIRINT is plain DIRINT on a GHI.
    spells_seen : array_like of bool, or bool
        Per minute (or for all): whether the readings behind ``poa_global`` are fine enough
        to show a clear spell (:func:`readings_fine`); there ``"clearsky_erbs"`` too takes
        the clear beam in the clear spells.

    The result reproduces ``poa_global`` on the plane through the site's transposition
    model (:func:`_closure`). Its columns: ``ghi``, ``dni``, ``dhi``, ``dni_blind_sd``,
    the standard deviation of the DNI guessed where the plane cannot see the beam (0 where
    it can) [W m⁻²], and ``beam_seen``, where it can.
    """
    from pvlib import atmosphere, irradiance

    fixed = plane or fixed_plane(site)
    poa = np.asarray(poa_global, dtype=float)
    zen = clear["apparent_zenith"].to_numpy()
    day = (clear["apparent_elevation"].to_numpy() > 2.0) & (poa > 0)
    ghi = np.zeros(poa.size)
    dni = np.zeros(poa.size)
    k = _clearness(poa, clear)
    w_clear, dni_clear_beam, spell = _clear_beam(k, clear)
    if model == "clearsky_erbs":
        poa_clear = clear["poa_clear"].to_numpy()
        ghi[day] = poa[day] * clear["ghi_clear"].to_numpy()[day] / np.maximum(poa_clear[day], 1.0)
        e = irradiance.erbs(ghi[day], zen[day], clear.index[day])
        dni[day] = np.asarray(e["dni"], dtype=float)
    elif model == "gti_dirint":
        t = sun._unix_seconds(clear.index)
        # DIRINT sees the 10-min means of the minutes without the clear beam only: a mean
        # over clear and cloudy minutes would give the cloudy ones a beam they do not have
        cloudy = day & (w_clear < 1.0)
        frame = pd.DataFrame({"poa": poa, "zen": zen, "az": clear["azimuth"].to_numpy(),
                              "aoi": clear["aoi"].to_numpy(), "t": t},
                             index=clear.index)[cloudy]
        c = frame.resample("10min").mean()
        c = c[c["poa"].notna() & (c["zen"] < 87.0)]
        rg, fb = np.ones(t.size), np.zeros(t.size)  # no cloudy block: all diffuse
        if (c["aoi"] < 90.0).any():  # GTI-DIRINT needs one block facing the plane
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out = irradiance.gti_dirint(
                    c["poa"], c["aoi"], c["zen"], c["az"], c.index, fixed.surface_tilt,
                    fixed.surface_azimuth, pressure=float(atmosphere.alt2pres(site.altitude)),
                    albedo=fixed.albedo)
            ratio_g = (out["ghi"] / c["poa"].clip(lower=1.0)).to_numpy(float)
            cos_z = np.cos(np.radians(c["zen"].to_numpy()))
            frac_b = (out["dni"] * cos_z / out["ghi"].clip(lower=1.0)).to_numpy(float)
            t_c = c["t"].to_numpy()  # the mean time of each block's minutes
            rg = np.interp(t, t_c, np.nan_to_num(ratio_g, nan=1.0))
            fb = np.interp(t, t_c, np.clip(np.nan_to_num(frac_b), 0.0, 1.0))
        ghi[day] = poa[day] * rg[day]
        cz = np.cos(np.radians(zen[day]))
        dni[day] = ghi[day] * fb[day] / np.maximum(cz, 0.05)
    else:
        raise ValueError(f"model must be 'gti_dirint' or 'clearsky_erbs'; got {model!r}")
    ghi, dni, dhi = _bound(ghi, dni, clear)
    if model == "clearsky_erbs":
        # the second opinion takes the clear beam only in a clear spell the readings show:
        # Erbs runs low in a clear sky at low sun (its k_t falls with the air mass), and its
        # sky had put the band's lower edge at 0.21 × the expected energy on a clear December
        # day at 60° N, 0.85 in Madrid in November (a tester's finding); in a gap between
        # clouds, or where coarse readings hide the clouds, the two routes' spread is the
        # band's (healthy hourly partly cloudy days, whose main sky runs 7–10 % high, need it)
        w_clear = np.where(spell & np.asarray(spells_seen, bool), w_clear, 0.0)
    dni = (1.0 - w_clear) * dni + w_clear * dni_clear_beam
    dni_clear = clear["dni_clear"].to_numpy()
    up = clear["apparent_elevation"].to_numpy() > 0.0
    seen = up & (dni_clear > 0) & (True if beam_seen is None else np.asarray(beam_seen, bool))
    dni, blind_sd = _unseen_beam(dni, clear, seen, up, k, w_clear * dni_clear_beam, site)
    out = pd.DataFrame(0.0, index=clear.index, columns=["ghi", "dni", "dhi"])
    out.loc[up, :] = np.column_stack(_closure(poa[up], dni[up], clear[up], site, fixed))
    out["dni_blind_sd"] = blind_sd  # the diagnosis's band widens by it (faults.band_uncertainty)
    out["beam_seen"] = seen
    return out


def measured_sky(site: Site, times: pd.DatetimeIndex, valid: np.ndarray,
                 poa_clear: np.ndarray, now: pd.Timestamp | None = None) -> np.ndarray:
    """Per minute: True where its local day (the site's time zone) has a measured sky, at
    least :data:`MIN_SENSOR_SHARE` of the day's daylight minutes (``poa_clear`` > 20 W m⁻²)
    ``valid``; a day without one takes the clear sky (:func:`weather_from_fixed`). Minutes
    from ``now`` on are still to come: not missing, so not counted (a day in progress is
    judged on its minutes so far)."""
    # the local wall clock's dates (normalize() on the zone raises where a change of
    # clock skips midnight: Santiago, the Azores)
    day_id = pd.factorize(times.tz_convert(site.timezone).tz_localize(None).normalize())[0]
    daylight = np.asarray(poa_clear) > 20.0
    if now is not None:
        daylight &= np.asarray(times < now)
    n_day = np.bincount(day_id, weights=daylight.astype(float))
    n_ok = np.bincount(day_id, weights=(daylight & np.asarray(valid, bool)).astype(float))
    share = np.divide(n_ok, n_day, out=np.zeros(n_day.size), where=n_day > 0)
    return (share >= MIN_SENSOR_SHARE)[day_id]


def measurable(sky: pd.DataFrame) -> np.ndarray:
    """The minutes of a frame of :func:`weather_from_fixed`'s sensor columns whose sky a
    reading can give: not :data:`FLAGS` ``night`` (the sun at 2° or more and a clear-sky
    POA over 20 W m⁻²). The one daylight of a day's sky source, its share of valid minutes
    and its refusals: counting the minutes with the sun under 2° (a clear-sky POA over
    20 W m⁻² all the same, on a steep plane), which no reading can ever make valid, put
    Reykjavík's December days — the sun under 4.5° at noon — on the clear sky, and a dark
    one was ``sky_unusable`` (a tester's finding)."""
    return (sky["flag"].to_numpy().astype(np.int64) & FLAGS["night"]) == 0


def main_sky_source(sky: pd.DataFrame) -> str:
    """What most of the :func:`measurable` minutes of a frame of :func:`weather_from_fixed`'s
    sensor columns rest on: the most common ``sky_source``
    (``"sensor_poa"``, ``"sensor_ghi"``, ``"fixed_array"`` or ``"clear_sky"``);
    ``"clear_sky"`` without such minutes. The one rule for a day's source: the diagnosis
    reports it and widens the day's band by it."""
    src = sky["sky_source"].to_numpy()[measurable(sky)]
    if src.size == 0:
        return "clear_sky"
    names, counts = np.unique(src, return_counts=True)
    return str(names[np.argmax(counts)])


#: Sensor columns :func:`weather_from_fixed` reads from its ``sensors`` frame, in rising
#: priority: a GHI pyranometer (only where the fixed array's power gives no sky), then a
#: reference cell or pyranometer on the fixed plane (wherever it reads).
SENSOR_SKIES = (("sensor_ghi", "ghi_w_m2"), ("sensor_poa", "fixed_poa_w_m2"))


def sensor_flags(irradiance_w_m2: np.ndarray, clear: pd.DataFrame) -> np.ndarray:
    """:data:`FLAGS` of a measured irradiance on the plane of ``clear``: those of any
    reading (:func:`_reading_flags`, zero at ≤ 2 W m⁻²) and above the clear sky (as
    :func:`invert_poa` flags an inverted POA)."""
    g = np.asarray(irradiance_w_m2, dtype=float)
    flag = _reading_flags(g, clear, 2.0)
    flag[np.isfinite(g) & (g > 1.25 * clear["poa_clear"].to_numpy() + 50.0)] |= \
        FLAGS["above_clear_sky"]
    return flag


def _sky_from_plane(site: Site, times: pd.DatetimeIndex, poa_measured: np.ndarray,
                    flag: np.ndarray, clear: pd.DataFrame, plane: Plane,
                    models: tuple[str, ...], extra: dict[str, np.ndarray],
                    now: pd.Timestamp | None = None, spells_seen: np.ndarray | bool = True
                    ) -> tuple[dict[str, pd.DataFrame], pd.DataFrame]:
    """The weather frames and the sensor frame of :func:`weather_from_fixed` from one
    plane's measured irradiance ``poa_measured`` (valid where ``flag`` is 0; ``spells_seen``:
    :func:`decompose`)."""
    valid = flag == 0
    at_limit = flag == FLAGS["saturated"]  # at the array's limit: a lower bound (below)
    night = (flag & FLAGS["night"]) > 0
    poa_clear = clear["poa_clear"].to_numpy()
    k = np.divide(poa_measured, poa_clear, out=np.full(len(times), np.nan), where=valid)
    # a day clipping for hours is read all the same (its clipped minutes count among its
    # readings: a clear day at DC/AC 1.4 clips for half its daylight)
    measured = measured_sky(site, times, valid | at_limit, poa_clear, now)
    src = valid & measured
    t = sun._unix_seconds(times)
    # up but not usable (low, or behind the plane, or a flagged reading): the clear-sky
    # index of the valid neighbours; a day without a measured sky: the clear sky
    k_filled = np.where(measured, np.interp(t, t[src], k[src]) if src.any() else 1.0, 1.0)
    # a reading at the array's limit (its inverter clips): at least the clearness that gives
    # the limit (invert_poa), not the neighbours' alone — clipping is the sun out, and on a
    # broken-cloud day the neighbours are the clouds (their index gave such minutes a fifth
    # of their beam)
    if at_limit.any():
        k_limit = np.divide(poa_measured, poa_clear, out=np.zeros(len(times)),
                            where=at_limit & (poa_clear > 0) & np.isfinite(poa_measured))
        k_filled = np.where(at_limit & measured, np.maximum(k_filled, k_limit), k_filled)
    sun_down = clear["apparent_elevation"].to_numpy() <= 0.0
    poa = np.where(sun_down, 0.0, np.where(src, poa_measured, k_filled * poa_clear))
    beam_seen = src & (np.cos(np.radians(clear["aoi"].to_numpy())) >= BEAM_SEEN_COS)
    # the clear-sky twin's own weather (Ineichen GHI/DNI/DHI), not a decomposition of it
    clear_sky = clear[["ghi_clear", "dni_clear", "dhi_clear"]].to_numpy()[~measured]
    weather = {}
    for m in models:
        w = decompose(poa, clear, site, m, beam_seen, plane, spells_seen)
        w.loc[~measured, ["ghi", "dni", "dhi"]] = clear_sky
        w.loc[~measured, "dni_blind_sd"] = 0.0  # the clear-sky twin's own day
        w.loc[~measured, "beam_seen"] = True
        for key, v in extra.items():
            w[key] = v
        weather[m] = w
    sensor = pd.DataFrame({"poa_global": poa, "poa_clear": poa_clear, "flag": flag,
                           "valid": valid, "measured_sky": measured,
                           "clearness": np.where(night, np.nan, k_filled),
                           "dni_extra": clear["dni_extra"].to_numpy()},
                          index=times)
    return weather, sensor


def _measured_or(value: np.ndarray | float | None, sensors: pd.DataFrame | None,
                 column: str, default: float, n: int) -> np.ndarray:
    """``value`` (or the site's ``default``), replaced by the ``sensors[column]`` readings
    where there are any."""
    out = np.broadcast_to(np.asarray(default if value is None else value, dtype=float),
                          (n,)).copy()
    if sensors is not None and column in sensors:
        m = sensors[column].to_numpy(dtype=float)
        out = np.where(np.isfinite(m), m, out)
    return out


def module_air_temperature(site: Site, clear: pd.DataFrame, fixed_power_w: np.ndarray,
                           temp_air: np.ndarray, wind_speed: np.ndarray,
                           sensors: pd.DataFrame | None,
                           saturation_power_w: float | None = None) -> np.ndarray:
    """``temp_air`` [°C], replaced where the fixed array's back-of-module temperature
    (``sensors["fixed_temp_module_c"]``) reads by the air temperature that gives it
    (:func:`sim.pv.air_temperature_from_module`) at the fixed plane's POA — its sensor's where
    it reads, else the one behind the array's power under ``temp_air`` (:func:`invert_poa`;
    a cell's temperature moves that POA by 0.4 %/°C, the air temperature it gives by a few
    hundredths of a degree per W m⁻²). The SAPM module model put a utility array's modules
    3–4 °C warmer than its sensor read on January days (tests/data/loggers/snow_data.csv, air
    temperature measured, 1 m s⁻¹): 1.3–1.6 % of its expected power."""
    if sensors is None or "fixed_temp_module_c" not in sensors:
        return temp_air
    t_mod = sensors["fixed_temp_module_c"].to_numpy(dtype=float)
    if not np.isfinite(t_mod).any():
        return temp_air
    fixed = site.arrays["fixed"]
    poa = np.full(len(t_mod), np.nan)
    if "fixed_poa_w_m2" in sensors:
        poa = sensors["fixed_poa_w_m2"].to_numpy(dtype=float)
    if not np.isfinite(poa[np.isfinite(t_mod)]).all():
        inverted = invert_poa(fixed_power_w, clear, fixed, temp_air, wind_speed,
                              saturation_power_w)["poa_global"].to_numpy()
        poa = np.where(np.isfinite(poa), poa, inverted)
    air = pv.air_temperature_from_module(t_mod, np.maximum(poa, 0.0), wind_speed,
                                         fixed.temperature_model)
    return np.where(np.isfinite(air), air, temp_air)


def weather_from_fixed(site: Site, times: pd.DatetimeIndex, fixed_power_w: np.ndarray,
                       temp_air: np.ndarray | float | None = None,
                       wind_speed: np.ndarray | float | None = None,
                       models: tuple[str, ...] = ("gti_dirint", "clearsky_erbs"),
                       saturation_power_w: float | None = None,
                       sensors: pd.DataFrame | None = None,
                       now: pd.Timestamp | None = None,
                       fine: dict[str, np.ndarray] | None = None,
                       ) -> tuple[dict[str, pd.DataFrame], pd.DataFrame]:
    """The sky the site's instruments saw, as twin weather frames, one per decomposition model.

    Each local day's sky comes from the first of: a reference cell/pyranometer on the
    fixed plane (``sensors["fixed_poa_w_m2"]``), the fixed array's power (inverted,
    :func:`invert_poa`), a GHI pyranometer (``sensors["ghi_w_m2"]``, decomposed on the
    horizontal plane), the clear sky — a source counts on a day when
    :func:`measured_sky` says it covers that day. The cell reads the fixed plane's
    irradiance without the PV model, its temperature or the array's faults in between, so
    it comes first. A tilted plane tells beam from diffuse far better than a horizontal
    one (the premise of GTI-DIRINT, Marion 2015), so the fixed array's power comes before
    a GHI pyranometer: on the real RMIS days the GHI path erred by up to 6.7 % on clear
    days and 18.3 % on a broken-cloud one against 3.7 % and 1.1 % from the fixed array's
    power (``docs/diagnosis.md``, "Real skies"), and its band (:data:`backend.diagnosis.
    faults.GHI_UNCERTAINTY`, 16 %) hid a tracker 15 % down that the fixed array's found
    on every day (a tester's finding: adding a pyranometer made the diagnosis blind). A
    GHI pyranometer gives the sky where the fixed array's power does not (no fixed array,
    or its logger down). A cell on the *tracker* is not a sky sensor here: it shares the
    tracker's pointing, the thing the diagnosis checks.

    Parameters
    ----------
    site : Site
    times : pandas.DatetimeIndex
        Tz-aware, regular (1 min) grid.
    fixed_power_w : array_like
        The fixed array's power on ``times`` [W]; NaN where no reading.
    temp_air, wind_speed : optional
        Air temperature [°C], wind speed [m s⁻¹]; default the site's.
    sensors : pandas.DataFrame, optional
        Measured on ``times`` (NaN where not): ``fixed_poa_w_m2``, ``ghi_w_m2`` [W m⁻²],
        ``temp_air_c`` [°C] and ``wind_speed_m_s`` [m s⁻¹] (replace ``temp_air`` and
        ``wind_speed`` where they read: the cells' temperature, SAPM, in the inversion
        and the twin), ``fixed_temp_module_c`` [°C], the fixed array's back-of-module
        temperature (where it reads, the air temperature is the one that gives it,
        :func:`module_air_temperature`); any may be absent.
    now : pandas.Timestamp, optional
        The minutes from it on are still to come (a day in progress): a day's share of
        measured minutes (:func:`measured_sky`) is of its minutes before it.
    fine : dict, optional
        Per minute, whether the readings behind a sky's source are fine enough to show a
        clear spell (:func:`readings_fine`), by source: ``"fixed_power_w"``, and the sensor
        columns ``"fixed_poa_w_m2"``, ``"ghi_w_m2"``; a source not in it is taken as read
        every minute (default: all). Elsewhere the second sky takes no clear beam
        (:func:`decompose`, ``spells_seen``).

    Returns
    -------
    weather : dict
        Model name → DataFrame (``ghi``, ``dni``, ``dhi`` [W m⁻²], ``temp_air``
        [°C], ``wind_speed`` [m s⁻¹]) for :func:`sim.twin.simulate`.
    sensor : pandas.DataFrame
        ``poa_global`` and ``poa_clear`` [W m⁻²]: the irradiance measured (or inverted,
        gaps filled) and its clear-sky value on the plane of the day's source (the
        fixed plane; horizontal for a GHI sensor); ``flag``, ``valid`` (a measured,
        well-posed daylight minute), ``measured_sky`` (:func:`measured_sky`; where False
        the weather is the clear sky's Ineichen GHI, DNI and DHI — the clear-sky twin's
        — and ``poa_global`` is ``poa_clear``), ``clearness`` (``poa_global`` /
        ``poa_clear`` [-]), ``sky_source`` (``"sensor_poa"``, ``"sensor_ghi"``,
        ``"fixed_array"`` or ``"clear_sky"``).
    """
    n = len(times)
    if saturation_power_w is None:  # its inverter's limit: a clipped reading shows no sky
        saturation_power_w = site.arrays["fixed"].inverter_limit_w
    clear = fixed_clear_sky(site, times)
    t_air = _measured_or(temp_air, sensors, "temp_air_c", site.temp_air, n)
    # an anemometer's zero offset reads a calm a little below 0: a calm
    wind = np.maximum(_measured_or(wind_speed, sensors, "wind_speed_m_s", site.wind_speed, n),
                      0.0)
    t_air = module_air_temperature(site, clear, fixed_power_w, t_air, wind, sensors,
                                   saturation_power_w)
    inv = invert_poa(fixed_power_w, clear, site.arrays["fixed"], t_air, wind,
                     saturation_power_w)
    extra = {"temp_air": t_air, "wind_speed": wind}
    fine = fine or {}
    weather, sensor = _sky_from_plane(site, times, inv["poa_global"].to_numpy(),
                                      inv["flag"].to_numpy(), clear, fixed_plane(site),
                                      models, extra, now, fine.get("fixed_power_w", True))
    source = np.where(sensor["measured_sky"].to_numpy(), "fixed_array", "clear_sky")
    for name, column in SENSOR_SKIES:  # rising priority: a later one replaces
        if sensors is None or column not in sensors or not sensors[column].notna().any():
            continue
        plane = horizontal(site) if column == "ghi_w_m2" else fixed_plane(site)
        c = clear if column == "fixed_poa_w_m2" else fixed_clear_sky(site, times, plane)
        g = sensors[column].to_numpy(dtype=float)
        flag = sensor_flags(g, c)
        w_s, s_s = _sky_from_plane(site, times, np.where(flag == 0, g, np.nan), flag, c,
                                   plane, models, extra, now, fine.get(column, True))
        take = s_s["measured_sky"].to_numpy()
        if column == "ghi_w_m2":  # behind the fixed array's power (see above)
            take = take & (source == "clear_sky")
        for m in models:
            weather[m].loc[take] = w_s[m].loc[take]
        sensor.loc[take] = s_s.loc[take]
        source = np.where(take, name, source)
    sensor["sky_source"] = source
    return weather, sensor


def tracker_blind_sd_w(series: pd.DataFrame, weather: pd.DataFrame) -> np.ndarray:
    """The standard deviation [W] of the tracker's expected power from the beam guessed where
    the fixed plane is blind (``weather["dni_blind_sd"]``, :func:`decompose`): the tracker
    faces the sun, so a W m⁻² of beam more is the array's power per W m⁻² of its plane's
    irradiance more (the run's mean over ``series``, :func:`sim.twin.simulate`'s; an
    uncertainty's scale)."""
    poa_tr = float(series["tracker_poa_global"].sum())
    per_w_m2 = float(series["tracker_power_w"].sum()) / poa_tr if poa_tr > 0 else 0.0
    return per_w_m2 * weather["dni_blind_sd"].to_numpy()


def weather_aware_twin(site: Site, start: pd.Timestamp, end: pd.Timestamp,
                       fixed_power_w: np.ndarray,
                       temp_air: np.ndarray | float | None = None,
                       wind_speed: np.ndarray | float | None = None,
                       saturation_power_w: float | None = None,
                       sensors: pd.DataFrame | None = None,
                       now: pd.Timestamp | None = None,
                       fine: dict[str, np.ndarray] | None = None) -> pd.DataFrame:
    """Both arrays' expected power per minute under the sky the site's instruments saw
    (irradiance sensors where they read, else the fixed array: :func:`weather_from_fixed`).

    The twin (:func:`sim.twin.simulate`, ideal tracking) is run once per
    decomposition model of :func:`weather_from_fixed`.

    Parameters
    ----------
    start, end : pandas.Timestamp
        Tz-aware, end exclusive; ``fixed_power_w`` (and ``sensors``, if given) hold one
        value per minute of it.
    now : pandas.Timestamp, optional
        Minutes from it on are still to come (:func:`weather_from_fixed`).
    fine : dict, optional
        Where each sky source's readings are fine enough to show a clear spell
        (:func:`weather_from_fixed`).

    Returns
    -------
    pandas.DataFrame
        UTC minute index: ``tracker_power_w`` and ``fixed_power_w`` (GTI-DIRINT sky),
        ``tracker_power_alt_w`` / ``fixed_power_alt_w`` (clear-sky-ratio + Erbs sky)
        [W], ``tracker_voltage_v`` and ``fixed_voltage_v`` (GTI-DIRINT sky: the arrays'
        maximum power point) [V], ``solar_azimuth``, ``apparent_elevation``, ``normal_azimuth``,
        ``normal_elevation`` [°] (the twin's tracker normal: the orientation a tracker that
        stops there holds), ``ghi``, ``dni``, ``dhi``,
        ``poa_global``, ``poa_clear``, ``dni_extra`` [W m⁻²], ``temp_air`` [°C] and
        ``wind_speed`` [m s⁻¹] (measured where the loggers read them, else the site's),
        ``clearness`` [-], ``valid``, ``measured_sky``, ``flag``, ``sky_source``,
        ``tracker_blind_sd_w`` [W]: the standard deviation of the tracker's expected power
        from the beam guessed where the fixed plane cannot see it (0 elsewhere), and
        ``beam_seen``: where it sees it (the clear-sky fallback's days: everywhere).
    """
    from sim import twin

    times = pd.date_range(start.tz_convert("UTC"), end.tz_convert("UTC"), freq="60s",
                          inclusive="left")
    p = np.asarray(fixed_power_w, dtype=float)
    if p.shape != (len(times),):
        raise ValueError(f"fixed_power_w has {p.size} values for {len(times)} minutes")
    if sensors is not None and len(sensors) != len(times):
        raise ValueError(f"sensors has {len(sensors)} rows for {len(times)} minutes")
    weather, sensor = weather_from_fixed(site, times, p, temp_air, wind_speed,
                                         saturation_power_w=saturation_power_w,
                                         sensors=sensors, now=now, fine=fine)
    run = twin.simulate(site, start, end, weather=weather["gti_dirint"])
    main = run.series
    alt = twin.simulate(site, start, end, weather=weather["clearsky_erbs"]).series
    out = pd.DataFrame({
        "tracker_power_w": main["tracker_power_w"].to_numpy(),
        "fixed_power_w": main["fixed_power_w"].to_numpy(),
        "tracker_power_alt_w": alt["tracker_power_w"].to_numpy(),
        "fixed_power_alt_w": alt["fixed_power_w"].to_numpy(),
        "tracker_voltage_v": main["tracker_voltage_v"].to_numpy(),
        "fixed_voltage_v": main["fixed_voltage_v"].to_numpy(),
        "solar_azimuth": main["solar_azimuth"].to_numpy(),
        "apparent_elevation": main["apparent_elevation"].to_numpy(),
        "normal_azimuth": run.normal_azimuth,
        "normal_elevation": run.normal_elevation,
    }, index=times)
    for k in ("ghi", "dni", "dhi", "temp_air", "wind_speed"):
        out[k] = weather["gti_dirint"][k].to_numpy()
    out["tracker_blind_sd_w"] = tracker_blind_sd_w(main, weather["gti_dirint"])
    out["beam_seen"] = weather["gti_dirint"]["beam_seen"].to_numpy(bool)
    for k in ("poa_global", "poa_clear", "clearness", "valid", "measured_sky", "flag",
              "dni_extra", "sky_source"):
        out[k] = sensor[k].to_numpy()
    return out


#: A logger whose readings are this far apart [s] or farther has what its stamps mark read
#: from its readings (:func:`inferred_stamped`) when the site leaves it at ``"instant"``: half
#: its interval (10 min) lies well beyond a healthy day's shape against the clear sky (1–3 min,
#: :func:`backend.diagnosis.faults.sky_clock`), and under it the stamp moves a day's expected
#: energy by little (docs/diagnosis.md, "Cadence")
STAMP_INFER_MIN_SPACING_S = 1200.0
#: A day shows its readings' stamp when the best convention fits the clear sky's shape this
#: well (relative RMS) [-]: clear days; a cloudy day's shape is the clouds'
STAMP_CLEAR_RESIDUAL = 0.08


def slow_logger(ts_s: np.ndarray, max_gap_s: float) -> bool:
    """Whether readings stamped ``ts_s`` [s] are :data:`STAMP_INFER_MIN_SPACING_S` or more
    apart (the median of the spacings the energy rule bridges): a logger whose stamps'
    meaning :func:`inferred_stamped` reads."""
    step = np.diff(np.asarray(ts_s, np.float64).reshape(-1))
    bridged = step[step <= max_gap_s]
    return bridged.size > 0 and float(np.median(bridged)) >= STAMP_INFER_MIN_SPACING_S


def on_slow_days(site: Site, ts_s: np.ndarray, max_gap_s: float) -> np.ndarray:
    """Per reading stamped ``ts_s`` [s]: whether its local day's readings are
    :data:`STAMP_INFER_MIN_SPACING_S` or more apart (:func:`slow_logger` of that day's) —
    a logger may change its cadence (a replaced logger, a back-fill), and only its slow
    days say what its slow stamps mark."""
    ts = np.asarray(ts_s, np.float64).reshape(-1)
    return _on_slow_days(ts, _local_days(site, ts), max_gap_s)


def _on_slow_days(ts: np.ndarray, day: np.ndarray, max_gap_s: float) -> np.ndarray:
    """:func:`on_slow_days` of stamps ``ts`` [s] whose local days ``day`` are known."""
    return np.isin(day, [d for d in np.unique(day) if slow_logger(ts[day == d], max_gap_s)])


def _local_days(site: Site, ts_s: np.ndarray) -> np.ndarray:
    """The local wall date of each stamp ``ts_s`` [s] in the site's zone, as int64 ns
    (normalize() on the zone itself raises where a clock change skips midnight)."""
    local = pd.to_datetime(ts_s, unit="s", utc=True).tz_convert(site.timezone)
    return np.asarray(local.tz_localize(None).normalize().asi8)


def inferred_stamped(site: Site, ts_s: np.ndarray, values: np.ndarray, max_gap_s: float,
                     stamped: str = "instant") -> str:
    """What the stamps ``ts_s`` [s] of a logger's readings ``values`` (the fixed array's
    power, or its plane's POA: any reading proportional to the fixed plane's irradiance on a
    clear day) mark, read from the readings: ``stamped`` (the site's word) unless the
    readings are at least :data:`STAMP_INFER_MIN_SPACING_S` apart (the median bridged
    spacing, per local day: only such days are read) and ``stamped`` is ``"instant"``, the
    default a site may never have set.

    Each convention of :data:`sim.energy.READING_STAMPS` is tried as the readings' meaning:
    the fixed plane's clear-sky POA at the instant, or its mean over the interval the
    reading would average (:func:`sim.energy.interval_middles`: ending, or starting, at the
    stamp), fitted to the readings with a free scale per local day. On the days whose best
    fit is under :data:`STAMP_CLEAR_RESIDUAL` (clear days) the convention with the smallest
    sum of residuals is the answer; without such a day, or when instants a whole interval
    early or late fit better still (a clock off), ``stamped``. An hourly mean stamped
    at its hour's end and an hourly sample from a clock 30 minutes late are the same
    readings and get the same answer (``"interval_end"``); a clock an hour off is none of
    them and stays the sky clock's finding (docs/diagnosis.md, "Cadence")."""
    from sim.energy import READING_STAMPS, interval_middles

    if stamped != "instant":
        return stamped
    ts = np.asarray(ts_s, np.float64).reshape(-1)
    v = np.asarray(values, np.float64).reshape(-1)
    ok = np.isfinite(ts) & np.isfinite(v)
    ts, v = ts[ok], v[ok]
    # only the days the logger was slow on say what its slow stamps mark: a site whose
    # logger logged every 5 minutes ten days before its hourly day read that day's hourly
    # means as instants (a tester's finding: a sky_clock_offset of +32 min at 0.90)
    day = _local_days(site, ts)
    slow = _on_slow_days(ts, day, max_gap_s)
    ts, v, day = ts[slow], v[slow], day[slow]
    if ts.size < 8:
        return stamped
    step = np.diff(ts)
    bridged = step <= max_gap_s
    # the clear sky on the fixed plane, minute by minute over the readings and an interval
    # around them, and its running integral: the mean over any interval is a difference
    reach = float(np.median(step[bridged])) + max_gap_s
    t0, t1 = np.floor((ts[0] - reach) / 60.0) * 60.0, np.ceil((ts[-1] + reach) / 60.0) * 60.0
    grid = np.arange(t0, t1 + 60.0, 60.0)
    clear = fixed_clear_sky(site, pd.DatetimeIndex(pd.to_datetime(grid, unit="s", utc=True))
                            )["poa_clear"].to_numpy()
    clear = np.nan_to_num(np.maximum(clear, 0.0))
    cum = np.concatenate(([0.0], np.cumsum(0.5 * (clear[1:] + clear[:-1]) * 60.0)))

    def mean_over(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        ca, cb = np.interp(a, grid, cum), np.interp(b, grid, cum)
        return np.where(b > a, (cb - ca) / np.maximum(b - a, 1e-9), np.interp(a, grid, clear))

    shapes = {}
    for conv in READING_STAMPS:
        mid = interval_middles(ts, conv, max_gap_s)
        shapes[conv] = mean_over(np.minimum(ts, 2 * mid - ts), np.maximum(ts, 2 * mid - ts))
    # a whole interval early or late: a clock off, not a convention (a 30-minute logger's
    # samples 30 minutes late are nearer its end-stamped means than its instants)
    typical = float(np.median(step[bridged]))
    for sign in (-1.0, 1.0):
        shapes[f"clock{sign:+.0f}"] = np.interp(ts + sign * typical, grid, clear)
    lit = np.max(np.column_stack(list(shapes.values())), axis=1) > 50.0
    total = dict.fromkeys(shapes, 0.0)
    clear_days = 0
    for d in np.unique(day[lit]):
        sel = lit & (day == d)
        if sel.sum() < 4 or float(np.mean(v[sel])) <= 0:
            continue
        res = {}
        for conv, x in shapes.items():
            xs, m = x[sel], v[sel]
            s = float(np.dot(m, xs) / np.dot(xs, xs)) if np.dot(xs, xs) > 0 else 0.0
            res[conv] = float(np.sqrt(np.mean((m - s * xs) ** 2)) / np.mean(m))
        if min(res.values()) < STAMP_CLEAR_RESIDUAL:
            clear_days += 1
            for conv in shapes:
                total[conv] += res[conv]
    best = min(shapes, key=lambda c: total[c]) if clear_days else stamped
    return best if best in READING_STAMPS else stamped
