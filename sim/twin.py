"""The side-by-side run: a dual-axis tracker and a fixed array at one site.

For every step of ``[start, end)``: sun position (NREL SPA, :mod:`sim.sun`),
tracker joint angles (ideal tracking within the joint limits,
:mod:`sim.kinematics`, seed 000 eqs. 10–15 and 23), the panel normal and its
pvlib orientation, then for both arrays the angle of incidence, plane-of-array
irradiance (clear sky or given weather, :mod:`sim.sky`), cell temperature and
the current, voltage and power at the maximum power point (CEC single-diode,
:mod:`sim.pv`). The instant that closes the last step is computed too
(:func:`sim.energy.simulation_times`) but not shown: energies are
:mod:`sim.energy`'s rule over every step of the range (:func:`sim.energy.run_energy_wh`).

Controllers other than ``"ideal"`` (:mod:`sim.control`) run in
:func:`sim.tracking.run_loop` on a tick grid (1 s for the camera loop, the
step or 60 s otherwise): their joint commands go through the motors'
profiles and the disturbances (:mod:`sim.disturbances`), and the tracker's
power comes from the *actual* panel normal. The pointing error is the angle
between that normal and the apparent sun, defined only while the tracker means
to track (the controller is not stowed) and the sun stands above
:data:`POINTING_MIN_ELEVATION_DEG`; elsewhere the series holds NaN and the
statistics leave the step out (a stowed panel is not "pointing" at a sun on the
horizon). The pointing loss is the energy an ideal tracker makes minus the
actual one (same PV model), or, with ``receiver="cpv"``, a concentrator that
converts only the beam inside its acceptance angle.

Speed: the sun is computed once for both arrays; the irradiance and electrics
only for steps with the sun above the horizon; the single-diode model goes
through :class:`sim.pv.MppTable`. Work is done in chunks so that a
``progress`` callback can report.

The tracker's shade on the fixed array: when the site config places both
arrays (``position_east_m``/``position_north_m``, :class:`sim.sites.Site`
``placements``), the fixed array loses the shaded fraction of its area
(:func:`sim.array_shade.fixed_shade`) from its plane-of-array beam —
area-proportional, a lower bound (a shaded cell row drops its bypass-diode
substring) — and the series gains ``fixed_shaded_fraction`` [-], the summary
``fixed_shade_loss_wh`` (the fixed array's energy unshaded minus shaded, same
PV model). Without positions nothing changes.

Wind stow: a site whose tracker has ``stow_wind_speed_m_s`` (:class:`sim.stow.WindStow`), on a
run whose weather has a ``wind_speed`` column, lies flat (the night stow's elevation, on its
base) in the steps :meth:`sim.stow.WindStow.stowed` marks; its power there is the flat
plane's, through the same sky, temperature and PV chain. The ideal tracker of the pointing
loss stows too (the stow is not a pointing error) and the stowed steps are not tracking. The
series gains ``stow_loss_power_w`` [W] (the tracker's power had it not stowed minus its
power), the summary ``stow_min`` (daylight minutes stowed) and ``stow_loss_wh``, each day
``stow_loss_wh``. The control loop and its motors do not see the stow (no move to it costed).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pandas as pd

from sim import array_shade, kinematics, pv, sky, sun
from sim import disturbances as dist
from sim.control import CONTROLLERS, ControlSettings, make_controller, noon_reference_azimuth
from sim.energy import (
    check_step,
    energy_per_period_wh,
    gain_pct,
    run_energy_wh,
    simulation_times,
)
from sim.sites import Site
from sim.stow import daylight_minutes
from sim.tracking import (
    CameraSetup,
    DriveLimits,
    LoopState,
    clear_sky_area_px,
    move_energies_wh,
    run_loop,
)
from vision.sphere import angular_separation_deg, enu_from_sky, sky_from_enu

__all__ = ["CONTROLLERS", "POINTING_MIN_ELEVATION_DEG", "RECEIVERS", "SERIES_COLUMNS",
           "TwinResult", "has_twin_arrays", "simulate"]

#: The pointing error is stated only with the sun above this apparent elevation [°]: below it
#: refraction and the horizon make the sun's place uncertain by tenths of a degree, the
#: camera loops have no usable disc, and a tracker's energy is negligible.
POINTING_MIN_ELEVATION_DEG = 5.0

RECEIVERS = ("flat", "cpv")
"""Receivers: flat PV modules, or a concentrator (beam inside the acceptance angle only)."""

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
    "azimuth_command_deg",
    "elevation_command_deg",
    "pointing_error_mrad",
]

_CHUNK_STEPS = 1 << 16  # ~45 days at 1 min: bounded memory and progress granularity


@dataclass
class TwinResult:
    """Result of :func:`simulate`: the per-step series and its summary.

    ``series`` is indexed by UTC time with :data:`SERIES_COLUMNS` (angles [°],
    irradiance [W m⁻²], temperature [°C], current [A], voltage [V], power [W]);
    night rows are present with zero power; ``pointing_error_mrad`` is NaN where the
    pointing error is not defined (stowed, or the sun below
    :data:`POINTING_MIN_ELEVATION_DEG`).
    """

    site: Site
    start: pd.Timestamp
    end: pd.Timestamp
    step_s: float
    controller: str
    sky: str
    series: pd.DataFrame
    receiver: str = "flat"
    acceptance_angle_deg: float = 0.5
    spot_distance_m: float = 1.5
    disturbances: dist.Disturbances = field(default_factory=dist.Disturbances)
    ideal_tracker_energy_wh: float | None = None
    moves: int = 0
    actuator_move_energy_wh: float = 0.0
    actuator_standby_energy_wh: float = 0.0
    #: moves that ask more than their drive gives (:class:`sim.tracking.MoveEnergies`)
    actuator_moves_beyond_drive: int = 0
    camera_frames: int = 0
    camera_frames_found: int = 0
    camera_frames_used: int = 0
    normal_azimuth: np.ndarray = field(default_factory=lambda: np.zeros(0))
    normal_elevation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    fixed_shade_loss_wh: float | None = None
    #: the ideal tracker's plane-of-array irradiance per step [W m⁻²] (the beam for CPV):
    #: the weight of the energy-weighted pointing error
    ideal_poa_global: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: ``open_loop_model``'s mount terms [°] by name (None for the other controllers)
    pointing_model_terms: dict[str, float] | None = None
    #: each array's power [W] at the instant closing the last step (one step after the
    #: series' last row, :func:`sim.energy.simulation_times`), by array name
    closing_power_w: dict[str, float] = field(default_factory=dict)
    #: a weather file's shift from the sun [min] (:func:`sim.weather_clock.irradiance_shift`)
    #: and the words when it is too large (:func:`sim.weather_clock.shift_warning`)
    weather_shift_min: float | None = None
    weather_warning: str | None = None
    #: daylight minutes the wind held the tracker stowed (:mod:`sim.stow`); None when the
    #: run's weather has no wind speed
    stow_min: int | None = None

    def _power_to_close(self, array: str) -> np.ndarray:
        """``array``'s power [W] at every step and at the instant closing the last."""
        return np.append(self.series[f"{array}_power_w"].to_numpy(),
                         self.closing_power_w[array])

    def energy_wh(self, array: str) -> float:
        """Energy of ``array`` (``"tracker"``/``"fixed"``) over the run [Wh]."""
        return run_energy_wh(self._power_to_close(array), self.step_s,
                             (self.end - self.start).total_seconds())

    def daily_energy(self) -> list[dict[str, Any]]:
        """Energy [Wh] and gain [%] per local calendar day of the run (the site's zone), by
        :mod:`sim.energy`'s rule split at local midnights: the days add up to the run's
        totals. Days are ``date`` (local ISO date), ``tracker_energy_wh``,
        ``fixed_energy_wh``, ``gain_pct``."""
        s = self.series
        if s.empty:
            return []
        zone = self.site.timezone

        def midnight(day: pd.Timestamp) -> pd.Timestamp:  # a missing one: the first instant
            return pd.Timestamp(day.date()).tz_localize(  # after (Santiago, Havana: normalize
                zone, ambiguous=True, nonexistent="shift_forward")  # raised on those days)

        first = s.index[0].tz_convert(zone).date()
        last = s.index[-1].tz_convert(zone).date()
        dates = pd.date_range(first, last, freq="D")
        edges = [midnight(d) for d in dates]
        edges.append(min(midnight(dates[-1] + pd.Timedelta(days=1)), self.end))
        edges_s = np.array([e.timestamp() for e in edges])
        t = s.index.as_unit("ns").asi8 / 1e9  # not whole seconds: a step may be 0.5 s
        t = np.append(t, t[-1] + self.step_s)  # the instant closing the last step
        gap = 1.5 * self.step_s
        per = {a: energy_per_period_wh(t, self._power_to_close(a), gap, edges_s)
               for a in ("tracker", "fixed", "stow_loss") if a in self.closing_power_w}
        return [{"date": d.date().isoformat(), "tracker_energy_wh": float(per["tracker"][k]),
                 "fixed_energy_wh": float(per["fixed"][k]),
                 "gain_pct": gain_pct(float(per["tracker"][k]), float(per["fixed"][k]),
                                      self.site.gain_ratings_w()),
                 **({"stow_loss_wh": float(per["stow_loss"][k])} if "stow_loss" in per else {})}
                for k, d in enumerate(dates)]

    def summary(self) -> dict[str, Any]:
        """The CLI/HTTP summary (DESIGN.md ``heliotwin simulate`` contract), JSON-ready."""
        s = self.series
        tracker_wh = self.energy_wh("tracker")
        fixed_wh = self.energy_wh("fixed")
        out: dict[str, Any] = {
            "site_id": self.site.site_id,
            # in the site's zone, both (an instant given with an offset came back in UTC
            # beside a bare end date in local time)
            "start": self.start.tz_convert(self.site.timezone).isoformat(),
            "end": self.end.tz_convert(self.site.timezone).isoformat(),
            "step_s": self.step_s,
            "controller": self.controller,
            "sky": self.sky,
            "steps": int(len(s)),
            "tracker_energy_wh": tracker_wh,
            "fixed_energy_wh": fixed_wh,
            "gain_pct": gain_pct(tracker_wh, fixed_wh, self.site.gain_ratings_w()),
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
        out["days"] = self.daily_energy()
        out.update(self._pointing_summary(tracker_wh, fixed_wh))
        if self.pointing_model_terms is not None:
            out["pointing_model_terms"] = dict(self.pointing_model_terms)
        if self.fixed_shade_loss_wh is not None:
            out["fixed_shade_loss_wh"] = self.fixed_shade_loss_wh
        if self.site.wind_stow is not None:  # null: the run's sky has no wind to stow for
            out["stow_wind_speed_m_s"] = self.site.wind_stow.wind_speed_m_s
            out["stow_min"] = self.stow_min
            out["stow_loss_wh"] = (self.energy_wh("stow_loss") if self.stow_min is not None
                                   else None)
        if self.sky == "weather":
            out["weather_shift_min"] = self.weather_shift_min
            out["weather_warning"] = self.weather_warning
        return out

    def _pointing_summary(self, tracker_wh: float, fixed_wh: float) -> dict[str, Any]:
        """Pointing statistics, actuators, losses.

        The pointing statistics cover the steps where the series states a pointing error
        (the tracker meant to track, the sun above :data:`POINTING_MIN_ELEVATION_DEG`):
        ``pointing_error_minutes`` says how long that is. Beside the plain RMS,
        ``pointing_error_energy_weighted_rms_mrad`` weights each step by the ideal
        tracker's plane-of-array irradiance (the beam for CPV) — the error when there is
        energy to lose counts, the error at a dim low sun barely.
        """
        s = self.series
        day = s["apparent_elevation"].to_numpy() > 0
        err_all = s["pointing_error_mrad"].to_numpy()
        on = np.isfinite(err_all)
        err = err_all[on]
        az_err, el_err = _error_components_mrad(s, self.normal_azimuth, self.normal_elevation)
        az_err, el_err = az_err[on], el_err[on]
        weight = self.ideal_poa_global[on] if len(self.ideal_poa_global) == len(s) else (
            np.zeros(0))

        def rms(x: np.ndarray) -> float | None:
            return float(np.sqrt(np.mean(x**2))) if x.size else None

        weighted = (float(np.sqrt(np.sum(weight * err**2) / np.sum(weight)))
                    if weight.size and np.sum(weight) > 0 else None)

        # each sample stands for its step; the last only up to the run's end (a step that
        # does not divide the run is cut there: it counted whole)
        step_s = np.full(len(s), self.step_s)
        if len(s):
            step_s[-1] = min(self.step_s, (self.end - s.index[-1]).total_seconds())
        actuator_wh = self.actuator_move_energy_wh + self.actuator_standby_energy_wh
        ideal_wh = tracker_wh if self.ideal_tracker_energy_wh is None else (
            self.ideal_tracker_energy_wh)
        f = self.spot_distance_m
        spot_x = f * np.tan(az_err / 1000.0)
        spot_y = f * np.tan(el_err / 1000.0)
        return {
            "daylight_steps": int(day.sum()),
            "pointing_error_rms_mrad": rms(err),
            "pointing_error_p95_mrad": float(np.percentile(err, 95)) if err.size else None,
            "pointing_error_max_mrad": float(err.max()) if err.size else None,
            "pointing_error_energy_weighted_rms_mrad": weighted,
            "pointing_error_minutes": int(round(float(step_s[on].sum()) / 60.0)),
            "pointing_min_elevation_deg": POINTING_MIN_ELEVATION_DEG,
            "azimuth_error_rms_mrad": rms(az_err),
            "elevation_error_rms_mrad": rms(el_err),
            "moves": int(self.moves),
            "actuator_energy_wh": actuator_wh,
            "actuator_move_energy_wh": self.actuator_move_energy_wh,
            "actuator_standby_energy_wh": self.actuator_standby_energy_wh,
            "actuator_moves_beyond_drive": int(self.actuator_moves_beyond_drive),
            "actuator_warning": self._actuator_warning(),
            "net_gain_pct": gain_pct(tracker_wh - actuator_wh, fixed_wh,
                                     self.site.gain_ratings_w()),
            "pointing_loss_wh": ideal_wh - tracker_wh,
            "receiver": self.receiver,
            "acceptance_angle_deg": self.acceptance_angle_deg if self.receiver == "cpv" else None,
            "spot_distance_m": f,
            "spot_displacement_rms_m": rms(np.hypot(spot_x, spot_y)),
            "spot_x_rms_m": rms(spot_x),
            "spot_y_rms_m": rms(spot_y),
            "camera_frames": int(self.camera_frames),
            "camera_frames_found": int(self.camera_frames_found),
            "camera_frames_used": int(self.camera_frames_used),
            "disturbances": self.disturbances.to_dict(),
        }

    def _actuator_warning(self) -> str | None:
        """Words for moves beyond the drives, None when there are none. The twin takes each
        axis to follow its profile (torque = inverse dynamics), so a move the drive cannot
        make is still costed as made: past the gearbox's rating, or the bus voltage, that
        energy is not one this machine would draw (a 1,000 N m gust read 4,926 W per axis
        where a 24 V bus through a 1.5 Ω winding gives at most 404 W, a tester's finding)."""
        n = self.actuator_moves_beyond_drive
        if not n:
            return None
        drives = self.site.drives.values()
        torque = "/".join(sorted({f"{d.max_output_torque_nm:g}" for d in drives}))
        volts = "/".join(sorted({f"{d.supply_voltage_v:g}" for d in drives}))
        speed = "/".join(sorted({f"{d.max_output_speed_rad_s:g}" for d in drives}))
        return (f"{n:,} of {self.moves:,} moves ask more than the drives give (output torque "
                f"over their {torque} N m rating, a speed over their {speed} rad/s, or a "
                f"voltage over the {volts} V bus: "
                f"sim.motors.duty_for); the twin costs them as if made, so "
                f"actuator_energy_wh is not what this machine would draw: it would stall "
                f"or slip (gust_torque_nm {self.disturbances.gust_torque_nm:g} N m)")


def _error_components_mrad(
    s: pd.DataFrame, n_az: np.ndarray, n_el: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Pointing error split on the sky: across (azimuth, × cos elevation) and along
    (elevation) [mrad], normal minus sun."""
    sun_az = s["solar_azimuth"].to_numpy()
    sun_el = s["apparent_elevation"].to_numpy()
    d_az = (n_az - sun_az + 180.0) % 360.0 - 180.0
    az = np.radians(d_az) * np.cos(np.radians(sun_el)) * 1000.0
    el = np.radians(n_el - sun_el) * 1000.0
    return az, el


def _as_timestamp(value: Any) -> Any:
    """``datetime``/``Timestamp`` → ``pd.Timestamp`` (other types are left for the check)."""
    try:
        return pd.Timestamp(value)
    except (TypeError, ValueError):
        return value


def has_twin_arrays(mounts: Mapping[str, Any]) -> bool:
    """Whether a site of these arrays (name → mount) can be simulated: arrays named
    ``tracker`` and ``fixed``, so mounted (the rule :func:`_check_inputs` enforces)."""
    return all(mounts.get(name) == name for name in ("tracker", "fixed"))


def _check_inputs(
    site: Site, start: pd.Timestamp, end: pd.Timestamp, step_s: float, controller: str
) -> None:
    if controller not in CONTROLLERS:
        raise ValueError(f"controller must be one of {', '.join(CONTROLLERS)}; got {controller!r}")
    for name, t in (("start", start), ("end", end)):
        if not isinstance(t, pd.Timestamp) or t.tz is None:
            raise ValueError(f"{name} must be a timezone-aware pandas.Timestamp, got {t!r}")
    check_step(start, end, step_s)
    for name in ("tracker", "fixed"):
        arr = site.arrays.get(name)
        if arr is None:
            raise ValueError(f"site {site.site_id!r} has no {name!r} array to simulate")
    if site.arrays["tracker"].mount != "tracker" or site.arrays["fixed"].mount != "fixed":
        raise ValueError(
            f"site {site.site_id!r}: array 'tracker' must be mount tracker, 'fixed' fixed"
        )


def _noon_reference_azimuth(times: pd.DatetimeIndex, site: Site) -> np.ndarray:
    """Azimuth joint reference for a continuous daily sweep [°] (see
    :func:`sim.control.noon_reference_azimuth`)."""
    return noon_reference_azimuth(times, site)


def _beam_transmission(aoi: np.ndarray, acceptance_angle_deg: float) -> np.ndarray:
    """CPV receiver: the beam is converted inside the acceptance half-angle, lost outside."""
    return np.where(aoi <= acceptance_angle_deg, 1.0, 0.0)


def _arrays_step(
    site: Site,
    times: pd.DatetimeIndex,
    pos: pd.DataFrame,
    weather: dict[str, np.ndarray] | None,
    pose: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    receiver: str = "flat",
    acceptance_angle_deg: float = 0.5,
    layout: array_shade.Layout | None = None,
    base: np.ndarray | None = None,
    stowed: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """All series columns for one chunk of steps.

    ``pose`` = (azimuth joint, elevation joint [°], actual normal ENU) of a
    controlled tracker; None: ideal tracking (:func:`sim.kinematics.tracking_angles`).
    The extra key ``ideal_tracker_power_w`` is the ideal tracker's power when
    a pose or the CPV receiver is given. With a ``layout`` (the arrays' places,
    :func:`sim.array_shade.layout_of`; ``base`` the tracker's disturbed base rotation)
    the extra keys ``fixed_shaded_fraction`` [-] and ``fixed_shade_loss_w`` [W]. With
    ``stowed`` (bool per step, :meth:`sim.stow.WindStow.stowed`) the tracker and the ideal
    tracker lie flat in those steps and the series key ``stow_loss_power_w`` [W] is the
    tracker's power in its pose before the stow minus its power.
    """
    from pvlib import atmosphere

    n = len(times)
    out = {c: np.zeros(n) for c in SERIES_COLUMNS}
    app_zen = pos["apparent_zenith"].to_numpy()
    azimuth = pos["azimuth"].to_numpy()
    app_el = pos["apparent_elevation"].to_numpy()
    out["solar_azimuth"] = azimuth
    out["apparent_elevation"] = app_el

    az_ideal, el_ideal = kinematics.tracking_angles(
        azimuth,
        app_el,
        site.tracker,
        reference_azimuth=_noon_reference_azimuth(times, site),
        night_azimuth=kinematics.morning_azimuth(times, site.latitude, site.longitude),
    )
    ideal_normal = kinematics.forward_kinematics(az_ideal, el_ideal, site.tracker)
    if pose is None:
        az_joint, el_joint, normal = az_ideal, el_ideal, ideal_normal
    else:
        az_joint, el_joint, normal = pose
    unstowed = None
    if stowed is not None and np.any(stowed):
        # flat as at night (elevation joint at its maximum, azimuth kept), on its base
        unstowed = kinematics.normal_to_tilt_azimuth(normal)
        el_joint = np.where(stowed, site.tracker.elevation_max_deg, el_joint)
        flat = kinematics.forward_kinematics(az_joint, el_joint, site.tracker)
        normal = np.where(stowed[:, None], flat if base is None else flat @ base.T, normal)
        # the ideal tracker stows as this one does (on its base): a stow is not a pointing
        # error, and a level ideal beside a leaning pedestal's stow had put its tilt there
        ideal_normal = np.where(stowed[:, None], normal, ideal_normal)
    out["azimuth_joint_deg"], out["elevation_joint_deg"] = az_joint, el_joint
    tilt, surf_az = kinematics.normal_to_tilt_azimuth(normal)
    fixed = site.arrays["fixed"]
    out["tracker_aoi"] = sky.angle_of_incidence(tilt, surf_az, app_zen, azimuth)
    out["fixed_aoi"] = sky.angle_of_incidence(
        fixed.surface_tilt, fixed.surface_azimuth, app_zen, azimuth
    )
    n_az, n_el = sky_from_enu(normal)
    out["pointing_error_mrad"] = 1000.0 * np.radians(
        angular_separation_deg(n_az, n_el, azimuth, app_el)
    )
    out["normal_azimuth"], out["normal_elevation"] = n_az, n_el

    if weather is None:
        temp_air = np.full(n, site.temp_air)
        wind = np.full(n, site.wind_speed)
    else:
        temp_air, wind = weather["temp_air"], weather["wind_speed"]
    out["tracker_temp_cell"] = temp_air.copy()
    out["fixed_temp_cell"] = temp_air.copy()
    want_ideal = pose is not None or receiver == "cpv"
    if want_ideal:
        out["ideal_tracker_power_w"] = np.zeros(n)
        out["ideal_tracker_poa_global"] = np.zeros(n)
    if layout is not None:
        out["fixed_shaded_fraction"], out["fixed_shade_loss_w"] = np.zeros(n), np.zeros(n)
    if stowed is not None:
        out["stow_loss_power_w"], out["tracker_unstowed_power_w"] = np.zeros(n), np.zeros(n)

    day = app_el > 0
    if not np.any(day):
        return out
    shade = None
    if layout is not None:
        frames = array_shade.tracker_panel_frames(layout, site.tracker, az_joint[day],
                                                  el_joint[day], base)
        shade = array_shade.fixed_shade(
            layout, frames, enu_from_sky(azimuth[day], app_el[day])).fraction
        out["fixed_shaded_fraction"][day] = shade
    d_times = times[day]
    if weather is None:
        irr = sky.clearsky_ineichen(
            d_times, app_zen[day], site.latitude, site.longitude, site.altitude
        )
    else:
        dni_extra = sky.extra_radiation(d_times)
        irr = sky.limit_to_extraterrestrial(weather["ghi"][day], weather["dni"][day],
                                            weather["dhi"][day], app_zen[day], dni_extra)
        irr["dni_extra"] = dni_extra
        irr["airmass_relative"] = np.asarray(
            atmosphere.get_relative_airmass(app_zen[day], "kastenyoung1989"), dtype=float
        )
    orientation = {
        "tracker": (tilt[day], surf_az[day], out["tracker_aoi"][day]),
        "fixed": (fixed.surface_tilt, fixed.surface_azimuth, out["fixed_aoi"][day]),
    }
    if want_ideal:
        i_tilt, i_az = kinematics.normal_to_tilt_azimuth(ideal_normal[day])
        i_aoi = sky.angle_of_incidence(i_tilt, i_az, app_zen[day], azimuth[day])
        orientation["ideal_tracker"] = (i_tilt, i_az, i_aoi)
    if unstowed is not None:  # the stow's loss: the same chain in the pose before it
        u_tilt, u_az = unstowed[0][day], unstowed[1][day]
        orientation["tracker_unstowed"] = (
            u_tilt, u_az, sky.angle_of_incidence(u_tilt, u_az, app_zen[day], azimuth[day]))
    unshaded_w = None
    for name, (s_tilt, s_az, aoi) in orientation.items():
        arr = site.arrays["fixed" if name == "fixed" else "tracker"]
        if name != "fixed" and receiver == "cpv":
            # a concentrator converts the beam inside its acceptance angle only
            beam = irr["dni"] * _beam_transmission(aoi, acceptance_angle_deg)
            poa_global, e_eff = beam, beam
        else:
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
            poa_global = poa["poa_global"]
            e_eff = sky.effective_irradiance(poa["poa_direct"], poa["poa_diffuse"], aoi)
            if name == "fixed" and shade is not None and np.any(shade > 0):
                # area-proportional: the shaded share of the array gets no beam
                unshaded_w = _fixed_power_w(poa_global, e_eff, temp_air[day], wind[day], arr,
                                            shade)
                poa_global = poa["poa_global"] - shade * poa["poa_direct"]
                e_eff = sky.effective_irradiance(poa["poa_direct"] * (1.0 - shade),
                                                 poa["poa_diffuse"], aoi)
        t_cell = pv.cell_temperature(poa_global, temp_air[day], wind[day], arr.temperature_model)
        mpp = pv.array_mpp(e_eff, t_cell, arr)
        if unshaded_w is not None and shade is not None:
            out["fixed_shade_loss_w"][day] = np.where(shade > 0, unshaded_w - mpp["power_w"], 0)
            unshaded_w = None
        if name == "ideal_tracker":
            out["ideal_tracker_power_w"][day] = mpp["power_w"]
            out["ideal_tracker_poa_global"][day] = poa_global
            continue
        if name == "tracker_unstowed":
            out["tracker_unstowed_power_w"][day] = mpp["power_w"]
            continue
        out[f"{name}_poa_global"][day] = poa_global
        out[f"{name}_temp_cell"][day] = t_cell
        for q in ("current_a", "voltage_v", "power_w"):
            out[f"{name}_{q}"][day] = mpp[q]
    if unstowed is not None and stowed is not None:
        out["stow_loss_power_w"] = np.where(
            stowed, out["tracker_unstowed_power_w"] - out["tracker_power_w"], 0.0)
    return out


def _fixed_power_w(poa_global: np.ndarray, e_eff: np.ndarray, temp_air: np.ndarray,
                   wind: np.ndarray, arr: pv.ArrayConfig, shade: np.ndarray) -> np.ndarray:
    """The array's maximum power [W] at the steps with ``shade`` > 0 (0 elsewhere)."""
    out = np.zeros(len(shade))
    k = shade > 0
    t_cell = pv.cell_temperature(poa_global[k], temp_air[k], wind[k], arr.temperature_model)
    out[k] = pv.array_mpp(e_eff[k], t_cell, arr)["power_w"]
    return out


def _tick_s(controller: str, step_s: float, settings: ControlSettings) -> float:
    """The control loop's tick [s]: the frame interval for ``closed_loop_camera``, else the
    update interval (and the frame interval if shorter), never longer than the step, and
    dividing it."""
    if controller == "closed_loop_camera":
        want = settings.camera_interval_s or 1.0
    elif controller == "hybrid":
        want = min(settings.update_interval_s, settings.camera_interval_s or 60.0)
    else:
        want = settings.update_interval_s
    want = min(want, step_s)
    return step_s / math.ceil(step_s / want - 1e-9)


def simulate(
    site: Site,
    start: pd.Timestamp,
    end: pd.Timestamp,
    step_s: float = 60,
    controller: str = "ideal",
    weather: pd.DataFrame | None = None,
    progress: Callable[[float], None] | None = None,
    disturbances: dist.Disturbances | None = None,
    receiver: str = "flat",
    acceptance_angle_deg: float = 0.5,
    settings: ControlSettings | None = None,
    limits: DriveLimits | None = None,
    camera: CameraSetup | None = None,
    spot_distance_m: float = 1.5,
    pointing_model_terms: Mapping[str, Any] | None = None,
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
    controller : str
        One of :data:`CONTROLLERS` (:mod:`sim.control`). ``"ideal"``: the
        panel normal on the apparent sun within the joint limits and a flat
        night stow (:func:`sim.kinematics.tracking_angles`), no motors, and no
        disturbance reaches it. The others run their control loop with the
        motors and ``disturbances``.
    weather : pandas.DataFrame, optional
        Tz-aware index; ``ghi``, ``dni``, ``dhi`` [W m⁻²], optional
        ``temp_air`` [°C] and ``wind_speed`` [m s⁻¹]; interpolated linearly onto
        the steps. Default: clear sky (Ineichen) with the site's air
        temperature and wind speed. With weather, the camera loops' frames show the
        sun only while its ``dni`` (interpolated to each frame's time) is at least
        :data:`sim.tracking.SUNSHINE_DNI_W_M2` (the WMO's sunshine threshold).
    progress : callable, optional
        Called with the fraction done (0…1) after each chunk.
    disturbances : Disturbances, optional
        Installation and machine errors (:mod:`sim.disturbances`); default none.
    receiver : {"flat", "cpv"}
        Flat PV modules (the site's), or a concentrator with the same
        electrics that converts only the beam (DNI) within
        ``acceptance_angle_deg`` of its axis [°].
    settings : ControlSettings, optional
        Dead band, stow, PID and camera-loop parameters.
    limits : DriveLimits, optional
        Axis speed and acceleration limits; default :meth:`DriveLimits.for_drives` of the
        site's drives (0.05 rad s⁻¹, slower when a drive's rated speed is).
    camera : CameraSetup, optional
        The tracker camera, exposure and clouds for the camera loops.
    spot_distance_m : float
        Distance from the optics to the receiver for the spot displacement
        ``f tan θ`` [m] (seed 001: the Fresnel concentrator's focal distance, 1.5 m).
    pointing_model_terms : mapping, optional
        ``open_loop_model`` only: the fitted mount terms its commands go through
        (:meth:`sim.pointing_model.PointingModel.from_terms`: the ``terms`` object of
        ``GET /api/v1/sites/{id}/pointing-model`` as it comes, or ``{name: degrees}``);
        default none, a perfect mount.

    Returns
    -------
    TwinResult
    """
    start, end = _as_timestamp(start), _as_timestamp(end)
    _check_inputs(site, start, end, step_s, controller)
    if receiver not in RECEIVERS:
        raise ValueError(f"receiver must be one of {', '.join(RECEIVERS)}; got {receiver!r}")
    if not 0 < acceptance_angle_deg < 90:
        raise ValueError(f"acceptance_angle_deg must be in (0, 90), got {acceptance_angle_deg}")
    if not spot_distance_m > 0:
        raise ValueError(f"spot_distance_m must be > 0, got {spot_distance_m}")
    if pointing_model_terms is not None and controller != "open_loop_model":
        raise ValueError(f"pointing_model_terms: only the open_loop_model controller uses "
                         f"them, not {controller!r}")
    d = disturbances if disturbances is not None else dist.Disturbances()
    settings = settings or ControlSettings()
    limits = limits or DriveLimits.for_drives(site.drives["azimuth"], site.drives["elevation"])
    if limits.wake_slew_s() > settings.wake_lead_s:
        # wake early enough to face the sun as it rises: a 0.05° s⁻¹ drive's 176° from the
        # evening's stow took the first hour of sun (a tester's finding)
        settings = replace(settings, wake_lead_s=limits.wake_slew_s())
    camera = camera or CameraSetup()
    from pvlib import atmosphere

    start_utc, end_utc = start.tz_convert("UTC"), end.tz_convert("UTC")
    grid = simulation_times(start_utc, end_utc, step_s)
    n_steps = len(grid) - 1  # the range's steps (the series); grid[n_steps] closes the last
    weather_on = (None if weather is None else
                  sky.weather_at(grid, weather, site.temp_air, site.wind_speed, closing=True))
    pressure = float(atmosphere.alt2pres(site.altitude))
    stowed = None  # the wind stow, on weather with a wind speed only (sim.stow)
    if (site.wind_stow is not None and weather is not None and weather_on is not None
            and "wind_speed" in weather.columns):
        stowed = site.wind_stow.stowed(sun._unix_seconds(grid), weather_on["wind_speed"])
    ctl = None
    if controller != "ideal":
        if controller in ("closed_loop_camera", "hybrid") and settings.reference_area_px is None:
            detector = settings.detector or (
                "seed000_hsv" if controller == "closed_loop_camera" else "seed003_gray240")
            settings = replace(settings, reference_area_px=clear_sky_area_px(camera, detector))
        ctl = make_controller(controller, site, settings, clock_offset_s=d.clock_offset_s,
                              pointing_model_terms=pointing_model_terms)
        tick_s = _tick_s(controller, float(step_s), settings)
        every = int(round(step_s / tick_s))
    layout = array_shade.layout_of(site)
    base = dist.base_rotation(d) if ctl is not None and d.moves_base else None
    state: LoopState | None = None
    moves: list = []
    # one (column, step) block, filled chunk by chunk and handed to pandas without a copy
    block = np.empty((len(SERIES_COLUMNS), len(grid)))
    extra = {k: np.zeros(len(grid)) for k in ("ideal_tracker_power_w", "normal_azimuth",
                                             "normal_elevation", "ideal_tracker_poa_global")}
    tracking = np.zeros(len(grid), dtype=bool)
    if layout is not None:
        extra.update({k: np.zeros(len(grid)) for k in ("fixed_shaded_fraction",
                                                     "fixed_shade_loss_w")})
    if stowed is not None:
        extra["stow_loss_power_w"] = np.zeros(len(grid))
    # the camera loops' frames see the sun only in the weather's beam (tracking.run_loop)
    grid_s = (sun._unix_seconds(grid) if weather_on is not None and ctl is not None
              and ctl.camera_interval_s else None)
    chunk_steps = _CHUNK_STEPS if ctl is None else max(1, min(_CHUNK_STEPS, (1 << 17) // every))
    for i0 in range(0, len(grid), chunk_steps):
        chunk = grid[i0 : i0 + chunk_steps]
        pos = sun.solar_position(
            chunk, site.latitude, site.longitude, site.altitude, pressure, site.temp_air
        )
        w = (
            None
            if weather_on is None
            else {k: v[i0 : i0 + chunk_steps] for k, v in weather_on.items()}
        )
        pose = None
        if ctl is not None:
            # the closing instant is one tick, sampled only: nothing at it is the run's
            closes = i0 + len(chunk) == len(grid)
            ticks = pd.date_range(chunk[0], periods=(len(chunk) - closes) * every + closes,
                                  freq=pd.Timedelta(seconds=tick_s))
            # only the ticks before the run's end act: a last step that the end cuts (a
            # step not dividing the range) ran the controller and the motors past it
            act = int(np.searchsorted(ticks.as_unit("ns").asi8, end_utc.as_unit("ns").value))
            act_ticks = act if act < len(ticks) else None
            if every == 1:
                t_pos = pos
            else:
                t_pos = sun.solar_position(ticks, site.latitude, site.longitude, site.altitude,
                                           pressure, site.temp_air)
            sun_enu = enu_from_sky(t_pos["azimuth"].to_numpy(),
                                   t_pos["apparent_elevation"].to_numpy())
            t0_s = (chunk[0] - grid[0]).total_seconds()
            dni = None  # a clear sky: the camera sees the sun whenever it faces it
            if grid_s is not None and weather_on is not None:
                # the run's weather at each frame's time (linear, as at the steps)
                near = slice(i0, i0 + len(chunk) + 1)
                dni = np.interp(sun._unix_seconds(ticks), grid_s[near], weather_on["dni"][near])
            res, state = run_loop(ctl, ticks, t0_s, tick_s, every, sun_enu, d, limits, camera,
                                  state, act_ticks, dni_w_m2=dni)
            moves.extend(res.moves)
            normal = dist.normal_enu(res.azimuth_joint_deg, res.elevation_joint_deg, d)
            # the series' joints are the real ones (an encoder zero moves the elevation)
            pose = (res.azimuth_joint_deg,
                    dist.real_elevation_deg(res.elevation_joint_deg, d), normal)
        part = _arrays_step(site, chunk, pos, w, pose, receiver, acceptance_angle_deg, layout,
                            base, None if stowed is None else stowed[i0 : i0 + len(chunk)])
        if ctl is not None:
            part["azimuth_command_deg"] = res.azimuth_command_deg
            part["elevation_command_deg"] = res.elevation_command_deg
            tracking[i0 : i0 + len(chunk)] = res.tracking
        else:
            part["azimuth_command_deg"] = part["azimuth_joint_deg"]
            part["elevation_command_deg"] = part["elevation_joint_deg"]
            # the ideal tracker tracks whenever the sun is up and lies flat otherwise
            tracking[i0 : i0 + len(chunk)] = part["apparent_elevation"] > 0
        for k, c in enumerate(SERIES_COLUMNS):
            block[k, i0 : i0 + len(chunk)] = part[c]
        for name, arr in extra.items():
            if name in part:
                arr[i0 : i0 + len(chunk)] = part[name]
        if progress is not None:
            progress(min(1.0, (i0 + len(chunk)) / len(grid)))
    series = pd.DataFrame(block[:, :n_steps].T, index=grid[:n_steps], columns=SERIES_COLUMNS,
                          copy=False)
    closing_power_w = {a: float(block[SERIES_COLUMNS.index(f"{a}_power_w"), n_steps])
                       for a in ("tracker", "fixed")}
    duration_s = (end - start).total_seconds()
    tracking = tracking[:n_steps]
    stow_min = None
    if stowed is not None:
        tracking &= ~stowed[:n_steps]  # a stowed tracker is not pointing
        series["stow_loss_power_w"] = extra["stow_loss_power_w"][:n_steps]
        closing_power_w["stow_loss"] = float(extra["stow_loss_power_w"][n_steps])
        stow_min = daylight_minutes(stowed[:n_steps],
                                    series["apparent_elevation"].to_numpy() > 0, step_s,
                                    duration_s)
    pointing = tracking & (series["apparent_elevation"].to_numpy() > POINTING_MIN_ELEVATION_DEG)
    series.loc[~pointing, "pointing_error_mrad"] = np.nan
    shade_loss_wh = None
    if layout is not None:
        series["fixed_shaded_fraction"] = extra["fixed_shaded_fraction"][:n_steps]
        shade_loss_wh = run_energy_wh(extra["fixed_shade_loss_w"], step_s, duration_s)
    move_wh = standby_wh = 0.0
    beyond_drive = 0
    if ctl is not None:
        costs = move_energies_wh(
            moves, limits, drives=(site.drives["azimuth"], site.drives["elevation"]),
            inertia=site.inertia)
        move_wh, beyond_drive = costs.total_wh, int(costs.beyond_drive.sum())
        standby_wh = _standby_energy_wh(site, duration_s)
    ideal_wh = None
    if ctl is not None or receiver == "cpv":
        ideal_wh = run_energy_wh(extra["ideal_tracker_power_w"], step_s, duration_s)
    return TwinResult(
        site=site,
        start=start,
        end=end,
        step_s=float(step_s),
        controller=controller,
        sky="clearsky-ineichen" if weather is None else "weather",
        series=series,
        receiver=receiver,
        acceptance_angle_deg=float(acceptance_angle_deg),
        spot_distance_m=float(spot_distance_m),
        disturbances=d,
        ideal_tracker_energy_wh=ideal_wh,
        moves=len(moves),
        actuator_move_energy_wh=move_wh,
        actuator_standby_energy_wh=standby_wh,
        actuator_moves_beyond_drive=beyond_drive,
        camera_frames=0 if state is None else state.frames,
        camera_frames_found=0 if state is None else state.frames_found,
        camera_frames_used=0 if ctl is None else ctl.frames_used,
        normal_azimuth=extra["normal_azimuth"][:n_steps],
        normal_elevation=extra["normal_elevation"][:n_steps],
        fixed_shade_loss_wh=shade_loss_wh,
        ideal_poa_global=(extra["ideal_tracker_poa_global"][:n_steps] if ideal_wh is not None
                          else series["tracker_poa_global"].to_numpy()),
        pointing_model_terms=(None if ctl is None or ctl.pointing_model is None
                              else ctl.pointing_model.as_dict()),
        closing_power_w=closing_power_w,
        stow_min=stow_min,
    )


def _standby_energy_wh(site: Site, duration_s: float) -> float:
    """Both drives' standby electronics over the run [Wh] (``AxisDrive.standby_power_w``)."""
    p = sum(d.standby_power_w for d in site.drives.values())
    return float(p) * duration_s / 3600.0
