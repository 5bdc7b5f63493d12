"""The side-by-side run: a dual-axis tracker and a fixed array at one site.

For every step of ``[start, end)``: sun position (NREL SPA, :mod:`sim.sun`),
tracker joint angles (ideal tracking within the joint limits,
:mod:`sim.kinematics`, seed 000 eqs. 10–15 and 23), the panel normal and its
pvlib orientation, then for both arrays the angle of incidence, plane-of-array
irradiance (clear sky or given weather, :mod:`sim.sky`), cell temperature and
the current, voltage and power at the maximum power point (CEC single-diode,
:mod:`sim.pv`). Energies are left Riemann sums of the power samples (each
sample stands for one step).

Speed: the sun is computed once for both arrays; the irradiance and electrics
only for steps with the sun above the horizon; the single-diode model goes
through :class:`sim.pv.MppTable`. Work is done in chunks so that a
``progress`` callback can report.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from sim import kinematics, pv, sky, sun
from sim.sites import Site

CONTROLLERS = ("ideal",)
"""Controllers :func:`simulate` knows (others come with the controller issue)."""

SERIES_COLUMNS = [
    "solar_azimuth",
    "apparent_elevation",
    "azimuth_joint_deg",
    "elevation_joint_deg",
    "tracker_aoi",
    "fixed_aoi",
    "tracker_poa_global",
    "fixed_poa_global",
    "tracker_temp_cell",
    "fixed_temp_cell",
    "tracker_current_a",
    "tracker_voltage_v",
    "tracker_power_w",
    "fixed_current_a",
    "fixed_voltage_v",
    "fixed_power_w",
]

_CHUNK_STEPS = 1 << 16  # ~45 days at 1 min: bounded memory and progress granularity


@dataclass
class TwinResult:
    """Result of :func:`simulate`: the per-step series and its summary.

    ``series`` is indexed by UTC time with :data:`SERIES_COLUMNS` (angles [°],
    irradiance [W m⁻²], temperature [°C], current [A], voltage [V], power [W]);
    night rows are present with zero power.
    """

    site: Site
    start: pd.Timestamp
    end: pd.Timestamp
    step_s: float
    controller: str
    sky: str
    series: pd.DataFrame

    def energy_wh(self, array: str) -> float:
        """Energy of ``array`` (``"tracker"``/``"fixed"``) over the run [Wh]."""
        return float(self.series[f"{array}_power_w"].sum() * self.step_s / 3600.0)

    def summary(self) -> dict[str, Any]:
        """The CLI/HTTP summary (DESIGN.md ``heliotwin simulate`` contract), JSON-ready."""
        s = self.series
        tracker_wh = self.energy_wh("tracker")
        fixed_wh = self.energy_wh("fixed")
        out: dict[str, Any] = {
            "site_id": self.site.site_id,
            "start": self.start.isoformat(),
            "end": self.end.isoformat(),
            "step_s": self.step_s,
            "controller": self.controller,
            "sky": self.sky,
            "steps": int(len(s)),
            "tracker_energy_wh": tracker_wh,
            "fixed_energy_wh": fixed_wh,
            "gain_pct": 100.0 * (tracker_wh / fixed_wh - 1.0) if fixed_wh > 0 else None,
        }
        for name in ("tracker", "fixed"):
            p = s[f"{name}_power_w"]
            peak = float(p.max()) if len(p) else 0.0
            out[f"{name}_peak_w"] = peak
            out[f"{name}_peak_time"] = (
                p.idxmax().tz_convert(self.site.timezone).isoformat() if peak > 0 else None
            )
        out["tracker_modules"] = self.site.arrays["tracker"].modules
        out["fixed_modules"] = self.site.arrays["fixed"].modules
        out["wiring"] = {k: a.wiring for k, a in self.site.arrays.items()}
        out["timezone"] = self.site.timezone
        return out


def _as_timestamp(value: Any) -> Any:
    """``datetime``/``Timestamp`` → ``pd.Timestamp`` (other types are left for the check)."""
    try:
        return pd.Timestamp(value)
    except (TypeError, ValueError):
        return value


def _check_inputs(
    site: Site, start: pd.Timestamp, end: pd.Timestamp, step_s: float, controller: str
) -> None:
    if controller not in CONTROLLERS:
        raise ValueError(f"controller must be one of {', '.join(CONTROLLERS)}; got {controller!r}")
    for name, t in (("start", start), ("end", end)):
        if not isinstance(t, pd.Timestamp) or t.tz is None:
            raise ValueError(f"{name} must be a timezone-aware pandas.Timestamp, got {t!r}")
    if not end > start:
        raise ValueError(f"end ({end.isoformat()}) must be after start ({start.isoformat()})")
    if not step_s > 0:
        raise ValueError(f"step_s must be positive, got {step_s}")
    for name in ("tracker", "fixed"):
        arr = site.arrays.get(name)
        if arr is None:
            raise ValueError(f"site {site.site_id!r} has no {name!r} array to simulate")
    if site.arrays["tracker"].mount != "tracker" or site.arrays["fixed"].mount != "fixed":
        raise ValueError(
            f"site {site.site_id!r}: array 'tracker' must be mount tracker, 'fixed' fixed"
        )


def _weather_on(
    times: pd.DatetimeIndex, weather: pd.DataFrame, site: Site
) -> dict[str, np.ndarray]:
    """Weather interpolated (linear in time) onto ``times``; must cover them."""
    missing = [c for c in ("ghi", "dni", "dhi") if c not in weather.columns]
    if missing:
        raise ValueError(f"weather lacks columns {missing}")
    if weather.index.tz is None:
        raise ValueError("weather index must be timezone-aware")
    w = weather.copy()
    w.index = w.index.tz_convert("UTC")
    if times[0] < w.index[0] or times[-1] > w.index[-1]:
        raise ValueError(
            f"weather covers {w.index[0].isoformat()}..{w.index[-1].isoformat()}, "
            f"not the run {times[0].isoformat()}..{times[-1].isoformat()}"
        )
    t_w = sun._unix_seconds(w.index)
    t = sun._unix_seconds(times)
    out = {c: np.interp(t, t_w, w[c].to_numpy(float)) for c in ("ghi", "dni", "dhi")}
    out["temp_air"] = (
        np.interp(t, t_w, w["temp_air"].to_numpy(float))
        if "temp_air" in w
        else np.full(len(t), site.temp_air)
    )
    out["wind_speed"] = (
        np.interp(t, t_w, w["wind_speed"].to_numpy(float))
        if "wind_speed" in w
        else np.full(len(t), site.wind_speed)
    )
    return out


def _noon_reference_azimuth(times: pd.DatetimeIndex, site: Site) -> np.ndarray:
    """Azimuth joint reference for a continuous daily sweep [°].

    On days when the noon sun is north of the zenith the sweep east→north→west
    is kept continuous around 0°, otherwise east→south→west around 180°. The
    side is read from the SPA sun at each local solar day's noon (12:00 mean
    solar time corrected by the equation of time, seed 001's D&B step), so it
    is exact even on the days the sun passes within a degree of the zenith.
    """
    shift = pd.Timedelta(hours=site.longitude / 15.0)
    solar_days = (times + shift).normalize()
    days, inverse = np.unique(solar_days.asi8, return_inverse=True)
    day_index = pd.DatetimeIndex(days.astype(f"datetime64[{solar_days.unit}]")).tz_localize("UTC")
    eot_min = sun.equation_of_time_spencer(np.asarray(day_index.day_of_year, dtype=float))
    noon = day_index + pd.Timedelta(hours=12) - shift - pd.to_timedelta(eot_min, unit="min")
    noon_azimuth = sun.solar_position(noon, site.latitude, site.longitude)["azimuth"].to_numpy()
    side = np.where(np.cos(np.deg2rad(noon_azimuth)) > 0, 0.0, 180.0)
    return side[inverse.ravel()]


def _arrays_step(
    site: Site, times: pd.DatetimeIndex, pos: pd.DataFrame, weather: dict[str, np.ndarray] | None
) -> dict[str, np.ndarray]:
    """All series columns for one chunk of steps."""
    from pvlib import atmosphere

    n = len(times)
    out = {c: np.zeros(n) for c in SERIES_COLUMNS}
    app_zen = pos["apparent_zenith"].to_numpy()
    azimuth = pos["azimuth"].to_numpy()
    app_el = pos["apparent_elevation"].to_numpy()
    out["solar_azimuth"] = azimuth
    out["apparent_elevation"] = app_el

    az_joint, el_joint = kinematics.tracking_angles(
        azimuth,
        app_el,
        site.tracker,
        reference_azimuth=_noon_reference_azimuth(times, site),
    )
    out["azimuth_joint_deg"], out["elevation_joint_deg"] = az_joint, el_joint
    tilt, surf_az = kinematics.normal_to_tilt_azimuth(
        kinematics.forward_kinematics(az_joint, el_joint, site.tracker)
    )
    fixed = site.arrays["fixed"]
    out["tracker_aoi"] = sky.angle_of_incidence(tilt, surf_az, app_zen, azimuth)
    out["fixed_aoi"] = sky.angle_of_incidence(
        fixed.surface_tilt, fixed.surface_azimuth, app_zen, azimuth
    )

    if weather is None:
        temp_air = np.full(n, site.temp_air)
        wind = np.full(n, site.wind_speed)
    else:
        temp_air, wind = weather["temp_air"], weather["wind_speed"]
    out["tracker_temp_cell"] = temp_air.copy()
    out["fixed_temp_cell"] = temp_air.copy()

    day = app_el > 0
    if not np.any(day):
        return out
    d_times = times[day]
    if weather is None:
        irr = sky.clearsky_ineichen(
            d_times, app_zen[day], site.latitude, site.longitude, site.altitude
        )
    else:
        irr = {k: weather[k][day] for k in ("ghi", "dni", "dhi")}
        irr["dni_extra"] = sky.extra_radiation(d_times)
        irr["airmass_relative"] = np.asarray(
            atmosphere.get_relative_airmass(app_zen[day], "kastenyoung1989"), dtype=float
        )
    orientation = {
        "tracker": (tilt[day], surf_az[day]),
        "fixed": (fixed.surface_tilt, fixed.surface_azimuth),
    }
    for name, (s_tilt, s_az) in orientation.items():
        arr = site.arrays[name]
        poa = sky.poa_irradiance(
            s_tilt,
            s_az,
            app_zen[day],
            azimuth[day],
            irr["dni"],
            irr["ghi"],
            irr["dhi"],
            irr["dni_extra"],
            irr["airmass_relative"],
            albedo=arr.albedo,
            model=site.transposition_model,
        )
        t_cell = pv.cell_temperature(
            poa["poa_global"], temp_air[day], wind[day], arr.temperature_model
        )
        e_eff = sky.effective_irradiance(
            poa["poa_direct"], poa["poa_diffuse"], out[f"{name}_aoi"][day]
        )
        mpp = pv.array_mpp(e_eff, t_cell, arr)
        out[f"{name}_poa_global"][day] = poa["poa_global"]
        out[f"{name}_temp_cell"][day] = t_cell
        for q in ("current_a", "voltage_v", "power_w"):
            out[f"{name}_{q}"][day] = mpp[q]
    return out


def simulate(
    site: Site,
    start: pd.Timestamp,
    end: pd.Timestamp,
    step_s: float = 60,
    controller: str = "ideal",
    weather: pd.DataFrame | None = None,
    progress: Callable[[float], None] | None = None,
) -> TwinResult:
    """Run the tracker and the fixed array side by side.

    Parameters
    ----------
    site : Site
        Needs arrays ``"tracker"`` (mount tracker) and ``"fixed"``.
    start, end : pandas.Timestamp
        Timezone-aware; ``start`` inclusive, ``end`` exclusive.
    step_s : float
        Step [s] (default 60).
    controller : {"ideal"}
        Ideal tracking: the panel normal on the apparent sun within the
        joint limits and a flat night stow (:func:`sim.kinematics.tracking_angles`).
    weather : pandas.DataFrame, optional
        Tz-aware index; ``ghi``, ``dni``, ``dhi`` [W m⁻²], optional
        ``temp_air`` [°C] and ``wind_speed`` [m s⁻¹]; interpolated linearly onto
        the steps. Default: clear sky (Ineichen) with the site's air
        temperature and wind speed.
    progress : callable, optional
        Called with the fraction done (0…1) after each chunk.

    Returns
    -------
    TwinResult
    """
    start, end = _as_timestamp(start), _as_timestamp(end)
    _check_inputs(site, start, end, step_s, controller)
    from pvlib import atmosphere

    start_utc, end_utc = start.tz_convert("UTC"), end.tz_convert("UTC")
    times = pd.date_range(start_utc, end_utc, freq=pd.Timedelta(seconds=step_s), inclusive="left")
    weather_on = None if weather is None else _weather_on(times, weather, site)
    pressure = float(atmosphere.alt2pres(site.altitude))
    # one (column, step) block, filled chunk by chunk and handed to pandas without a copy
    block = np.empty((len(SERIES_COLUMNS), len(times)))
    for i0 in range(0, len(times), _CHUNK_STEPS):
        chunk = times[i0 : i0 + _CHUNK_STEPS]
        pos = sun.solar_position(
            chunk, site.latitude, site.longitude, site.altitude, pressure, site.temp_air
        )
        w = (
            None
            if weather_on is None
            else {k: v[i0 : i0 + _CHUNK_STEPS] for k, v in weather_on.items()}
        )
        part = _arrays_step(site, chunk, pos, w)
        for k, c in enumerate(SERIES_COLUMNS):
            block[k, i0 : i0 + len(chunk)] = part[c]
        if progress is not None:
            progress(min(1.0, (i0 + len(chunk)) / len(times)))
    series = pd.DataFrame(block.T, index=times, columns=SERIES_COLUMNS, copy=False)
    return TwinResult(
        site=site,
        start=start,
        end=end,
        step_s=float(step_s),
        controller=controller,
        sky="clearsky-ineichen" if weather is None else "weather",
        series=series,
    )
