"""Realistic logger days for the diagnosis tests: a sky made independently of the inversion.

The sky is a two-state cloud process on the Ineichen clear sky, not any
decomposition model: in a clear spell the beam is the clear-sky beam (× an aerosol
factor of the day), behind a cloud the beam is 0 and the diffuse is the clear-sky
GHI × the cloud's transmittance; spell lengths are exponential (Markov). Each day
is ``clear``, ``partly`` or ``overcast`` at random; air temperature follows a daily
sine (22…33 °C) and the wind changes by the hour — neither is what the inversion
assumes (the site's 27 °C and 1 m/s). The arrays are then run through the twin
(:func:`sim.twin.simulate`), faults through the controllers/disturbances of
:mod:`sim.control` / :mod:`sim.disturbances` or the site's own wiring, and the
logger adds 1 % noise and 0.1 W resolution.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from sim import sky, sun, twin
from sim.disturbances import Disturbances
from sim.sites import Site

SKY_KINDS = ("clear", "partly", "overcast")


def cloud_weather(site: Site, first_day: pd.Timestamp, days: int, seed: int,
                  kinds: list[str] | None = None) -> tuple[pd.DataFrame, list[str]]:
    """Minute weather (UTC index) for ``days`` days from ``first_day``; each day's kind."""
    rng = np.random.default_rng(seed)
    start = first_day.tz_convert("UTC")
    times = pd.date_range(start, start + pd.Timedelta(days=days), freq="60s", inclusive="left")
    pos = sun.solar_position(times, site.latitude, site.longitude, site.altitude)
    zen = pos["apparent_zenith"].to_numpy()
    cs = sky.clearsky_ineichen(times, zen, site.latitude, site.longitude, site.altitude)
    cos_z = np.maximum(np.cos(np.radians(zen)), 0.0)
    ghi, dni, dhi = np.zeros(len(times)), np.zeros(len(times)), np.zeros(len(times))
    temp = np.zeros(len(times))
    wind = np.zeros(len(times))
    kinds = list(kinds) if kinds is not None else [
        str(rng.choice(SKY_KINDS, p=[0.4, 0.35, 0.25])) for _ in range(days)]
    for d in range(days):
        sl = slice(d * 1440, (d + 1) * 1440)
        kind = kinds[d]
        aerosol = rng.uniform(0.9, 1.02)
        if kind == "clear":
            cloudy = np.zeros(1440, dtype=bool)
        else:
            p_cloud = 0.45 if kind == "partly" else 0.97
            mean_len = rng.uniform(5, 40) if kind == "partly" else 120.0
            cloudy = np.zeros(1440, dtype=bool)
            i, state = 0, rng.random() < p_cloud
            while i < 1440:
                scale = mean_len * (p_cloud if state else 1 - p_cloud) / 0.5
                n = max(1, int(rng.exponential(max(scale, 1.0))))
                cloudy[i:i + n] = state
                i += n
                state = not state
        trans = np.clip(rng.normal(0.45 if kind == "partly" else 0.28, 0.08, 1440), 0.08, 0.8)
        trans = np.convolve(trans, np.ones(15) / 15, mode="same")
        b = cs["dni"][sl] * aerosol
        dni[sl] = np.where(cloudy, 0.0, b)
        dhi[sl] = np.where(cloudy, cs["ghi"][sl] * trans, cs["dhi"][sl] * rng.uniform(0.95, 1.3))
        ghi[sl] = dni[sl] * cos_z[sl] + dhi[sl]
        hour = (np.arange(1440) / 60.0 + site.longitude / 15.0) % 24.0  # solar hour
        temp[sl] = 27.5 + rng.uniform(-2, 2) + 5.5 * np.sin(2 * np.pi * (hour - 9.0) / 24.0)
        wind[sl] = np.repeat(rng.uniform(0.3, 4.0, 24), 60)
    weather = pd.DataFrame({"ghi": ghi, "dni": dni, "dhi": dhi, "temp_air": temp,
                            "wind_speed": wind}, index=times)
    return weather, kinds


@dataclass
class LoggerDays:
    """Minute readings of both arrays and what really happened."""

    times: pd.DatetimeIndex
    tracker_power_w: np.ndarray
    fixed_power_w: np.ndarray
    healthy_tracker_power_w: np.ndarray  # the truth a perfect tracker made under that sky
    kinds: list[str]
    fault: str | None
    fault_day: int | None
    ghi_w_m2: np.ndarray  # a pyranometer beside the arrays (±2 % gain of the seed, 1 % noise)
    fixed_poa_w_m2: np.ndarray  # a reference cell on the fixed plane (the same errors)
    temp_air_c: np.ndarray  # a shaded thermometer (±0.3 °C)

    def sensors(self, *columns: str) -> pd.DataFrame:
        """The named sensor columns as the ``sensors`` frame of
        :func:`sim.sky_sensor.weather_aware_twin`."""
        return pd.DataFrame({c: getattr(self, c) for c in columns}, index=self.times)


def logger_days(site: Site, first_day: pd.Timestamp, days: int, seed: int,
                fault: str | None = None, fault_day: int = 0, magnitude: float | None = None,
                kinds: list[str] | None = None, stop_local: str | None = None) -> LoggerDays:
    """Both arrays' logged power for ``days`` days; ``fault`` from ``fault_day`` on.

    ``fault``: ``"stuck"`` (joints frozen at azimuth 181°, elevation 35°: the
    array at that fixed orientation; with ``stop_local``, e.g. ``"10:00"``, the tracker
    tracks until that local time of ``fault_day`` and then holds the orientation it had
    there), ``"azimuth_offset"`` (pedestal yaw of
    ``magnitude`` [°], default 10, under the open-loop SPA controller),
    ``"clock_offset"`` (the tracker logger's clock ``magnitude`` [s] ahead,
    default 1800), ``"module_loss"`` (one string of four lost), ``"soiling"`` (the
    tracker's glass loses ``magnitude`` % of transmittance a day, default 0.5, from
    ``fault_day``: its irradiance scaled in a second twin run).
    """
    weather, kinds = cloud_weather(site, first_day, days, seed, kinds)
    start = first_day
    end = first_day + pd.Timedelta(days=days)
    result = twin.simulate(site, start, end, weather=weather)
    healthy = result.series
    tracker = healthy["tracker_power_w"].to_numpy().copy()
    on = np.arange(len(healthy)) >= fault_day * 1440
    if fault == "stuck":
        tilt, surf_az = 55.0, 181.0
        if stop_local is not None:
            stop = first_day + pd.Timedelta(days=fault_day) + pd.Timedelta(f"{stop_local}:00")
            on = healthy.index >= stop.tz_convert("UTC")
            i = int(np.argmax(on))
            tilt = 90.0 - float(result.normal_elevation[i])
            surf_az = float(result.normal_azimuth[i])
        fixed = replace(site.arrays["fixed"], surface_tilt=tilt, surface_azimuth=surf_az)
        stuck_site = replace(site, arrays={**site.arrays, "fixed": fixed})
        tracker[on] = twin.simulate(stuck_site, start, end, weather=weather).series[
            "fixed_power_w"].to_numpy()[on]
    elif fault == "azimuth_offset":
        d = Disturbances(pedestal_yaw_deg=10.0 if magnitude is None else magnitude)
        faulty = twin.simulate(site, start, end, weather=weather, controller="open_loop_spa",
                               disturbances=d).series["tracker_power_w"].to_numpy()
        tracker[on] = faulty[on]
    elif fault == "clock_offset":
        shift = int(round((1800.0 if magnitude is None else magnitude) / 60.0))
        late = np.r_[np.zeros(shift), tracker[:-shift]] if shift > 0 else tracker
        tracker[on] = late[on]  # the reading stamped t was taken at t − offset
    elif fault == "module_loss":
        lost = replace(site.arrays["tracker"], strings_in_parallel=3)
        lost_site = replace(site, arrays={**site.arrays, "tracker": lost})
        tracker[on] = twin.simulate(lost_site, start, end, weather=weather).series[
            "tracker_power_w"].to_numpy()[on]
    elif fault == "soiling":
        rate = (0.5 if magnitude is None else magnitude) / 100.0  # per day from fault_day
        days_on = np.maximum(np.arange(len(healthy)) / 1440.0 - fault_day, 0.0)
        dirty = weather.copy()
        for k in ("ghi", "dni", "dhi"):  # the dust's transmittance on the tracker's glass
            dirty[k] = weather[k].to_numpy() * (1.0 - rate * days_on)
        tracker = twin.simulate(site, start, end, weather=dirty).series[
            "tracker_power_w"].to_numpy()
    elif fault is not None:
        raise ValueError(f"unknown fault {fault!r}")
    if stop_local is not None and fault != "stuck":
        raise ValueError("stop_local is for the stuck fault")
    rng = np.random.default_rng(seed + 1)

    def logged(p: np.ndarray) -> np.ndarray:
        noisy = p * (1.0 + rng.normal(0.0, 0.01, p.size))
        return np.round(np.maximum(noisy, 0.0), 1)

    def irradiance(g: np.ndarray) -> np.ndarray:  # a class-A instrument, 1 W m⁻² steps
        noisy = g * rng.uniform(0.98, 1.02) * (1.0 + rng.normal(0.0, 0.01, g.size))
        return np.round(np.maximum(noisy, 0.0))

    return LoggerDays(healthy.index, logged(tracker),
                      logged(healthy["fixed_power_w"].to_numpy()),
                      healthy["tracker_power_w"].to_numpy(), kinds, fault,
                      None if fault is None else fault_day,
                      irradiance(weather["ghi"].to_numpy()),
                      irradiance(healthy["fixed_poa_global"].to_numpy()),
                      np.round(weather["temp_air"].to_numpy()
                               + rng.normal(0.0, 0.3, len(weather)), 1))
