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
   GHI ≤ 1.25·GHI_clear, DHI ≥ 0. GTI-DIRINT runs on 10-minute means (it iterates
   DIRINT per point, ~0.13 ms a point); its clearness ratios are interpolated back
   onto the minutes.
3. :func:`weather_from_fixed` — the minute weather frame (``ghi, dni, dhi,
   temp_air, wind_speed``) that :func:`sim.twin.simulate` takes as ``weather``,
   so the tracker's expected power comes from the same pipeline as the clear-sky
   twin. Flagged daylight minutes take the clear-sky index interpolated in time
   from their valid neighbours (the answer's ``valid`` column says which).

Nothing here reads files or keeps state; seeds: the tracker/fixed pair of seed 000
(Acosta-Banda et al. 2025), the small expected gain under diffuse skies of seed 004.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from sim import pv, sky, sun
from sim.sites import Site

__all__ = ["FLAGS", "decompose", "fixed_clear_sky", "invert_poa", "weather_from_fixed"]

#: Flags of :func:`invert_poa` (bit values, combined with ``|``).
FLAGS = {
    "night": 1,  # sun below 2° or clear-sky POA below 20 W m⁻²
    "missing": 2,  # no reading (NaN)
    "zero": 4,  # ≤ 0.5 % of STC power while the clear sky gives > 200 W m⁻²
    "stale": 8,  # the same value ≥ 5 minutes running in daylight
    "saturated": 16,  # at the logger's saturation power
    "above_clear_sky": 32,  # inverted POA > 1.25 × clear-sky POA + 50 W m⁻²
}

G_MAX = 1500.0  # upper end of the bisection [W m⁻²]
_BISECTIONS = 22  # 1500 / 2**22 < 0.001 W m⁻²
_STALE_MIN = 5


def fixed_clear_sky(site: Site, times: pd.DatetimeIndex) -> pd.DataFrame:
    """Sun position and clear sky (Ineichen, :func:`sim.sky.clearsky_ineichen`) on the fixed plane.

    Returns
    -------
    pandas.DataFrame
        Indexed by ``times``: ``apparent_zenith``, ``azimuth``, ``apparent_elevation``
        [°], ``aoi`` [°] of the fixed plane, ``ghi_clear``, ``dni_clear``,
        ``dhi_clear``, ``poa_clear`` [W m⁻²], ``dni_extra`` [W m⁻²].
    """
    from pvlib import atmosphere

    fixed = site.arrays["fixed"]
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
        The logger's full scale [W]; readings within 0.5 % of it are flagged.

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
    flag = np.zeros(n, dtype=np.int64)
    night = (clear["apparent_elevation"].to_numpy() < 2.0) | (poa_clear < 20.0)
    flag[night] |= FLAGS["night"]
    flag[~np.isfinite(p)] |= FLAGS["missing"]
    flag[~night & np.isfinite(p) & (p <= 0.005 * stc_w) & (poa_clear > 200.0)] |= FLAGS["zero"]
    flag[~night & _stale(p)] |= FLAGS["stale"]
    if saturation_power_w is not None:
        flag[np.isfinite(p) & (p >= 0.995 * saturation_power_w)] |= FLAGS["saturated"]
    todo = flag == 0
    lo = np.zeros(int(todo.sum()))
    hi = np.full(lo.size, G_MAX)
    target = p[todo]
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
    too_high = todo & (g > 1.25 * poa_clear + 50.0)
    flag[too_high] |= FLAGS["above_clear_sky"]
    g[too_high] = np.nan
    return pd.DataFrame({"poa_global": g, "flag": flag}, index=clear.index)


def _stale(p: np.ndarray) -> np.ndarray:
    """True inside runs of ≥ 5 identical non-zero readings (a frozen logger)."""
    if p.size == 0:
        return np.zeros(0, dtype=bool)
    new_run = np.r_[True, p[1:] != p[:-1]]
    run_id = np.cumsum(new_run) - 1
    length = np.bincount(run_id)[run_id]
    return (length >= _STALE_MIN) & (p > 0)


def _bound(ghi: np.ndarray, dni: np.ndarray, clear: pd.DataFrame
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Clip a decomposition to the clear sky: DNI ≤ DNI_clear, GHI ≤ 1.25 GHI_clear, DHI ≥ 0."""
    cos_z = np.cos(np.radians(clear["apparent_zenith"].to_numpy()))
    ghi = np.clip(np.nan_to_num(ghi), 0.0, 1.25 * clear["ghi_clear"].to_numpy())
    dni = np.clip(np.nan_to_num(dni), 0.0, clear["dni_clear"].to_numpy())
    dni = np.minimum(dni, ghi / np.maximum(cos_z, 0.05))
    dhi = np.maximum(ghi - dni * np.maximum(cos_z, 0.0), 0.0)
    return ghi, dni, dhi


def _clear_beam(poa: np.ndarray, ghi: np.ndarray, dni: np.ndarray, dhi: np.ndarray,
                clear: pd.DataFrame, site: Site) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the plane sees (nearly) the clear-sky POA the beam is unobstructed: DNI moves
    to the clear-sky DNI (fully at ≥ 100 % of POA_clear, from 85 % on) and the rest of the
    POA is diffuse (isotropic view factors). DIRINT's DNI runs low in clear skies (its
    Kt′ bins average over turbid and clean air; Perez et al. 1992)."""
    fixed = site.arrays["fixed"]
    k = np.divide(poa, clear["poa_clear"].to_numpy(), out=np.zeros(poa.size),
                  where=clear["poa_clear"].to_numpy() > 1.0)
    w = np.clip((k - 0.85) / 0.15, 0.0, 1.0)
    cos_z = np.maximum(np.cos(np.radians(clear["apparent_zenith"].to_numpy())), 0.0)
    cos_aoi = np.maximum(np.cos(np.radians(clear["aoi"].to_numpy())), 0.0)
    tilt = np.radians(fixed.surface_tilt)
    sky_view, ground_view = (1 + np.cos(tilt)) / 2, fixed.albedo * (1 - np.cos(tilt)) / 2
    dni_c = clear["dni_clear"].to_numpy()
    # POA = b cosθ + d·sky_view + (b cosZ + d)·ground_view  →  d for the clear beam b
    d_c = (poa - dni_c * (cos_aoi + cos_z * ground_view)) / (sky_view + ground_view)
    ok = d_c > 0
    w = np.where(ok, w, 0.0)
    dni = (1 - w) * dni + w * dni_c
    dhi = (1 - w) * dhi + w * np.maximum(d_c, 0.0)
    ghi = dni * cos_z + dhi
    return ghi, dni, dhi


def decompose(poa_global: np.ndarray, clear: pd.DataFrame, site: Site,
              model: str = "gti_dirint") -> pd.DataFrame:
    """GHI, DNI, DHI [W m⁻²] behind a fixed plane's POA (no NaN in ``poa_global``).

    Parameters
    ----------
    poa_global : array_like
        POA of the fixed plane [W m⁻²] (0 at night).
    clear : pandas.DataFrame
        From :func:`fixed_clear_sky`.
    model : {"gti_dirint", "clearsky_erbs"}
        See the module docstring.
    """
    from pvlib import atmosphere, irradiance

    poa = np.asarray(poa_global, dtype=float)
    zen = clear["apparent_zenith"].to_numpy()
    day = (clear["apparent_elevation"].to_numpy() > 2.0) & (poa > 0)
    ghi = np.zeros(poa.size)
    dni = np.zeros(poa.size)
    if model == "clearsky_erbs":
        poa_clear = clear["poa_clear"].to_numpy()
        ghi[day] = poa[day] * clear["ghi_clear"].to_numpy()[day] / np.maximum(poa_clear[day], 1.0)
        e = irradiance.erbs(ghi[day], zen[day], clear.index[day])
        dni[day] = np.asarray(e["dni"], dtype=float)
    elif model == "gti_dirint":
        fixed = site.arrays["fixed"]
        frame = pd.DataFrame({"poa": poa, "zen": zen, "az": clear["azimuth"].to_numpy(),
                              "aoi": clear["aoi"].to_numpy(), "day": day.astype(float)},
                             index=clear.index)
        coarse = frame.resample("10min").mean()
        ok = (coarse["day"] > 0.5) & (coarse["zen"] < 87.0)
        c = coarse[ok]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out = irradiance.gti_dirint(
                c["poa"], c["aoi"], c["zen"], c["az"], c.index, fixed.surface_tilt,
                fixed.surface_azimuth, pressure=float(atmosphere.alt2pres(site.altitude)),
                albedo=fixed.albedo)
        ratio_g = (out["ghi"] / c["poa"].clip(lower=1.0)).to_numpy(float)
        cos_z = np.cos(np.radians(c["zen"].to_numpy()))
        frac_b = (out["dni"] * cos_z / out["ghi"].clip(lower=1.0)).to_numpy(float)
        t_c = sun._unix_seconds(c.index) + 300.0  # the middle of each 10-min mean
        t = sun._unix_seconds(clear.index)
        if len(t_c):
            rg = np.interp(t, t_c, np.nan_to_num(ratio_g, nan=1.0))
            fb = np.interp(t, t_c, np.clip(np.nan_to_num(frac_b), 0.0, 1.0))
        else:
            rg, fb = np.ones(t.size), np.zeros(t.size)
        ghi[day] = poa[day] * rg[day]
        cz = np.cos(np.radians(zen[day]))
        dni[day] = ghi[day] * fb[day] / np.maximum(cz, 0.05)
    else:
        raise ValueError(f"model must be 'gti_dirint' or 'clearsky_erbs'; got {model!r}")
    ghi, dni, dhi = _bound(ghi, dni, clear)
    if model == "gti_dirint":
        ghi, dni, dhi = _clear_beam(poa, ghi, dni, dhi, clear, site)
    return pd.DataFrame({"ghi": ghi, "dni": dni, "dhi": dhi}, index=clear.index)


def weather_from_fixed(site: Site, times: pd.DatetimeIndex, fixed_power_w: np.ndarray,
                       temp_air: np.ndarray | float | None = None,
                       wind_speed: np.ndarray | float | None = None,
                       models: tuple[str, ...] = ("gti_dirint", "clearsky_erbs"),
                       saturation_power_w: float | None = None,
                       ) -> tuple[dict[str, pd.DataFrame], pd.DataFrame]:
    """The sky the fixed array saw, as twin weather frames, one per decomposition model.

    Parameters
    ----------
    site : Site
    times : pandas.DatetimeIndex
        Tz-aware, regular (1 min) grid.
    fixed_power_w : array_like
        The fixed array's power on ``times`` [W]; NaN where no reading.
    temp_air, wind_speed : optional
        Measured [°C], [m s⁻¹]; default the site's.

    Returns
    -------
    weather : dict
        Model name → DataFrame (``ghi``, ``dni``, ``dhi`` [W m⁻²], ``temp_air``
        [°C], ``wind_speed`` [m s⁻¹]) for :func:`sim.twin.simulate`.
    sensor : pandas.DataFrame
        ``poa_global`` (inverted, gaps filled) and ``poa_clear`` [W m⁻²], ``flag``,
        ``valid`` (a measured, well-posed daylight minute), ``clearness``
        (POA / clear-sky POA [-]).
    """
    clear = fixed_clear_sky(site, times)
    t_air = site.temp_air if temp_air is None else temp_air
    wind = site.wind_speed if wind_speed is None else wind_speed
    inv = invert_poa(fixed_power_w, clear, site.arrays["fixed"], t_air, wind,
                     saturation_power_w)
    flag = inv["flag"].to_numpy()
    night = (flag & FLAGS["night"]) > 0
    valid = flag == 0
    poa_clear = clear["poa_clear"].to_numpy()
    k = np.divide(inv["poa_global"].to_numpy(), poa_clear, out=np.full(len(times), np.nan),
                  where=valid)
    t = sun._unix_seconds(times)
    if valid.any():
        k_filled = np.interp(t, t[valid], k[valid])
    else:
        k_filled = np.ones(len(times))  # nothing measured: the clear sky
    poa = np.where(night, 0.0, np.where(valid, inv["poa_global"].to_numpy(),
                                        k_filled * poa_clear))
    n = len(times)
    extra = {"temp_air": np.broadcast_to(np.asarray(t_air, dtype=float), (n,)),
             "wind_speed": np.broadcast_to(np.asarray(wind, dtype=float), (n,))}
    weather = {}
    for m in models:
        w = decompose(poa, clear, site, m)
        for key, v in extra.items():
            w[key] = v
        weather[m] = w
    sensor = pd.DataFrame({"poa_global": poa, "poa_clear": poa_clear, "flag": flag,
                           "valid": valid, "clearness": np.where(night, np.nan, k_filled)},
                          index=times)
    return weather, sensor


def weather_aware_twin(site: Site, start: pd.Timestamp, end: pd.Timestamp,
                       fixed_power_w: np.ndarray,
                       temp_air: np.ndarray | float | None = None,
                       wind_speed: np.ndarray | float | None = None,
                       saturation_power_w: float | None = None) -> pd.DataFrame:
    """Both arrays' expected power per minute under the sky the fixed array saw.

    The twin (:func:`sim.twin.simulate`, ideal tracking) is run once per
    decomposition model of :func:`weather_from_fixed`.

    Parameters
    ----------
    start, end : pandas.Timestamp
        Tz-aware, end exclusive; ``fixed_power_w`` holds one value per minute of it.

    Returns
    -------
    pandas.DataFrame
        UTC minute index: ``tracker_power_w`` and ``fixed_power_w`` (GTI-DIRINT sky),
        ``tracker_power_alt_w`` / ``fixed_power_alt_w`` (clear-sky-ratio + Erbs sky)
        [W], ``tracker_clear_power_w`` (clear-sky twin) [W], ``solar_azimuth``,
        ``apparent_elevation`` [°], ``ghi``, ``dni``, ``dhi``, ``poa_global`` [W m⁻²],
        ``clearness`` [-], ``valid``, ``flag``.
    """
    from sim import twin

    times = pd.date_range(start.tz_convert("UTC"), end.tz_convert("UTC"), freq="60s",
                          inclusive="left")
    p = np.asarray(fixed_power_w, dtype=float)
    if p.shape != (len(times),):
        raise ValueError(f"fixed_power_w has {p.size} values for {len(times)} minutes")
    weather, sensor = weather_from_fixed(site, times, p, temp_air, wind_speed,
                                         saturation_power_w=saturation_power_w)
    main = twin.simulate(site, start, end, weather=weather["gti_dirint"]).series
    alt = twin.simulate(site, start, end, weather=weather["clearsky_erbs"]).series
    out = pd.DataFrame({
        "tracker_power_w": main["tracker_power_w"].to_numpy(),
        "fixed_power_w": main["fixed_power_w"].to_numpy(),
        "tracker_power_alt_w": alt["tracker_power_w"].to_numpy(),
        "fixed_power_alt_w": alt["fixed_power_w"].to_numpy(),
        "solar_azimuth": main["solar_azimuth"].to_numpy(),
        "apparent_elevation": main["apparent_elevation"].to_numpy(),
    }, index=times)
    for k in ("ghi", "dni", "dhi"):
        out[k] = weather["gti_dirint"][k].to_numpy()
    for k in ("poa_global", "poa_clear", "clearness", "valid", "flag"):
        out[k] = sensor[k].to_numpy()
    return out
