"""Tracker controllers: one small interface, seven controllers.

A controller sees what a real one sees — its own clock and ephemeris, the
joint encoders' readings and, for the camera loops, the sun detected in the
tracker camera's frame — and returns joint commands (degrees, the public joint
convention of ``docs/architecture.md``). It never sees the true sun or the
true pose; the world side (camera frames, motors, disturbances) is
:mod:`sim.tracking`.

Interface (:class:`Controller`): :meth:`Controller.plan` is given the tick
times of a chunk once (vectorised ephemeris), then :meth:`Controller.command`
is called at every tick with a :class:`Reading` and, when the controller asked
for a frame (:attr:`Controller.camera_interval_s`), a :class:`CameraMeasurement`.

======================  ======================================================================
name                    what it does
======================  ======================================================================
``ideal``               the sun exactly (today's :func:`sim.kinematics.tracking_angles`; no
                        motors, no disturbances reach it — the twin's reference)
``open_loop_spa``       NREL SPA ephemeris on its own clock, commands at every tick
``open_loop_duffie_     seed 001's Duffie–Beckman ephemeris (eqs. 1–4,
beckman``               ``sim.sun.solar_position(method="duffie-beckman")``)
``chronological``       a step every N minutes (seed 000's reference [34]: N = 5/30/60) to the
                        ephemeris at the middle of the coming interval
``closed_loop_camera``  seed 000 §3: the sun's centroid in the narrow camera (1 frame/s)
                        against the reference pixel, image-plane error → PID on the joints
``hybrid``              seed 001 §2.3 (Fig. 4): SPA ephemeris plus the camera's correction
                        angles (sun's joint angles seen by the camera minus the ephemeris's),
                        a fixed reference pixel, a correction every N s (default 60)
``open_loop_model``     issue 25: open loop on SPA through a fitted pointing model — the
                        encoder angles that put the mount's real axis on the sun
                        (:func:`sim.pointing_model.command_angles`); no camera
======================  ======================================================================

Shared behaviour (:class:`ControlSettings`): a dead band (an axis moves only
when its error exceeds it, so the motors run in short bursts — seed 000 §3.2:
"very short intervals"); joint limits and azimuth wrap (through
:func:`sim.kinematics.inverse_kinematics` with the day's reference, for every
controller's target, so that a midnight sun is unwound at its lowest); night stow
(elevation joint to its maximum, the panel flat, when the controller's ephemeris puts
the sun below ``stow_elevation_deg``) and morning wake-up; with no usable sun in the frame
(clouds) the camera loops fall back to the ephemeris — ``hybrid`` keeping its
last valid correction — and a detection that jumps away from the locked sun or
whose glare has lost its clear-sky size (a cloud edge eating the disc) is not
used.
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from sim import kinematics, sun
from sim.pointing_model import PointingModel, command_angles
from sim.sites import Site

__all__ = [
    "CONTROLLERS",
    "ControlSettings",
    "Reading",
    "CameraMeasurement",
    "Controller",
    "OpenLoop",
    "Chronological",
    "ClosedLoopCamera",
    "Hybrid",
    "OpenLoopModel",
    "make_controller",
    "noon_reference_azimuth",
    "ephemeris_joint_targets",
]

CONTROLLERS: tuple[str, ...] = (
    "ideal",
    "open_loop_spa",
    "open_loop_duffie_beckman",
    "chronological",
    "closed_loop_camera",
    "hybrid",
    "open_loop_model",
)


@dataclass(frozen=True)
class ControlSettings:
    """Parameters shared by the controllers (defaults are stated assumptions).

    Parameters
    ----------
    dead_band_deg : float
        An axis moves only when its error on the sky exceeds this [°]
        (azimuth errors are weighted by cos(elevation), the angle they make
        on the sky).
    stow_elevation_deg : float
        Below this sun elevation (the controller's ephemeris, apparent) the
        tracker stows; above it, it tracks [°].
    wake_lead_s : float
        The tracker wakes this long before the ephemeris sun rises above
        ``stow_elevation_deg`` and turns to the sunrise pose, so that it faces
        the sun when it rises [s]; :func:`sim.twin.simulate` lengthens it to the drives'
        slew (:meth:`sim.tracking.DriveLimits.wake_slew_s`) when that is longer.
    chronological_interval_min : float
        The chronological controller's period [min] (seed 000's ref. [34]:
        5, 30 or 60).
    update_interval_s : float
        How often the ephemeris controllers (and ``hybrid``) update their
        command [s]; each aims half an interval ahead. 30 s keeps the lag
        below 0.13° (the sun moves ≤ 0.25° min⁻¹).
    camera_interval_s : float, optional
        Frame interval [s]; default 1 for ``closed_loop_camera`` (seed 000),
        60 for ``hybrid``.
    kp, ki_per_s, kd_s : float
        ``closed_loop_camera``'s PID on the joint error per frame: increment =
        kp e + ki Σ e dt + kd de/dt [-, s⁻¹, s].
    hybrid_gain : float
        Fraction of the newly measured correction taken each frame [-].
    hybrid_max_offset_deg : float
        ``hybrid`` uses a frame only when the sun it shows is within this of the encoder
        azimuth (``h / cos E``) and the panel is below the zenith's singular cap (cos E at
        least the 0.05 that floors an azimuth error's weight): the small-angle conversion
        holds there [°]. At 30° sin Δ is within 5 % of Δ and the loop converges from
        there; a pedestal yaw of 28° is still removed (1.82 mrad RMS), one of 40° was not
        before this rule either (269 mrad).
    min_confidence : float
        Detections below this confidence are not used [-].
    max_jump_deg : float
        A locked camera loop ignores a detection this far from where it
        expects the sun [°] unless it persists ``reacquire_frames`` frames.
    reacquire_frames : int
    area_tolerance : float
        A detection whose glare area differs from the clear-sky reference by
        more than this factor is not used (a cloud cutting the disc) [-].
    min_peak_dn : int
        A frame whose brightest pixel is below this is not used: the clear
        sun saturates the sensor (seed 001's fixed exposure), a sun behind
        cloud or a cloud's bright edge does not [DN].
    reference_area_px : float, optional
        The clear sun's detected area [px] (a clear-sky calibration; the twin
        measures it on a clear frame of its camera). Default: learned, the
        90th percentile of the recent glares (cloud only shrinks them).
    detector : str, optional
        ``vision.detect`` method; default ``"robust"`` for
        ``"seed000_hsv"`` for ``closed_loop_camera`` (seed 000's Table 3
        pipeline) and ``"seed003_gray240"`` for ``hybrid`` (seed 001's grey →
        threshold → centroid, eq. 9, is this pipeline).
    """

    dead_band_deg: float = 0.1
    stow_elevation_deg: float = 0.0
    wake_lead_s: float = 300.0
    chronological_interval_min: float = 30.0
    update_interval_s: float = 30.0
    camera_interval_s: float | None = None
    kp: float = 0.7
    ki_per_s: float = 0.02
    kd_s: float = 0.0
    hybrid_gain: float = 0.7
    hybrid_max_offset_deg: float = 30.0
    min_confidence: float = 0.5
    max_jump_deg: float = 1.0
    reacquire_frames: int = 5
    area_tolerance: float = 1.2
    min_peak_dn: int = 250
    reference_area_px: float | None = None
    detector: str | None = None

    def __post_init__(self) -> None:
        if not self.dead_band_deg >= 0:
            raise ValueError(f"dead_band_deg must be >= 0, got {self.dead_band_deg}")
        if not self.chronological_interval_min > 0:
            raise ValueError("chronological_interval_min must be > 0")
        if not self.update_interval_s > 0:
            raise ValueError(f"update_interval_s must be > 0, got {self.update_interval_s}")
        if self.camera_interval_s is not None and not self.camera_interval_s > 0:
            raise ValueError(f"camera_interval_s must be > 0, got {self.camera_interval_s}")
        if not 0 < self.hybrid_gain <= 1:
            raise ValueError(f"hybrid_gain must be in (0, 1], got {self.hybrid_gain}")
        if not self.hybrid_max_offset_deg > 0:
            raise ValueError(f"hybrid_max_offset_deg must be > 0, got {self.hybrid_max_offset_deg}")
        if self.area_tolerance <= 1 or self.reacquire_frames < 1 or self.max_jump_deg <= 0:
            raise ValueError("area_tolerance must be > 1, reacquire_frames >= 1, max_jump_deg > 0")


class Reading(NamedTuple):
    """What the controller knows of the tracker at a tick (a NamedTuple: one per tick)."""

    t_s: float  #: time since the start of the run, on the true clock [s]
    azimuth_deg: float  #: azimuth encoder reading [°]
    elevation_deg: float  #: elevation encoder reading [°]
    azimuth_moving: bool = False
    elevation_moving: bool = False


@dataclass(frozen=True)
class CameraMeasurement:
    """One frame's detection, in the camera's angles from the reference pixel.

    ``right_deg``/``up_deg`` are :meth:`vision.cameras.PinholeCamera.pointing_error`'s
    horizontal and vertical angles (right, up positive); NaN when not found.
    """

    sun_found: bool
    right_deg: float = math.nan
    up_deg: float = math.nan
    confidence: float = 0.0
    area_px: int = 0
    peak_dn: int = 255  #: brightest grey level of the frame [DN]

    @classmethod
    def none(cls) -> CameraMeasurement:
        return cls(False)


def noon_reference_azimuth(times: pd.DatetimeIndex, site: Site) -> NDArray[np.float64]:
    """Azimuth joint reference for a continuous daily sweep [°].

    On days when the noon sun is north of the zenith the sweep east→north→west
    is kept continuous around 0°, otherwise east→south→west around 180°. The
    side is read from the SPA sun at each solar day's transit, which NREL SPA
    gives directly (``pvlib.solarposition.sun_rise_set_transit_spa``, Reda &
    Andreas 2004, appendix A.2); solar days are the calendar days of the zone
    whose offset is the longitude's nearest hour.
    """
    from pvlib import solarposition

    zone = dt.timezone(dt.timedelta(hours=round(site.longitude / 15.0)))
    local_days = times.tz_convert(zone).normalize()
    days, inverse = np.unique(local_days.asi8, return_inverse=True)
    day_index = pd.DatetimeIndex(days.astype(f"datetime64[{local_days.unit}]")).tz_localize(
        "UTC").tz_convert(zone)
    transit = solarposition.sun_rise_set_transit_spa(
        day_index + pd.Timedelta(hours=12), site.latitude, site.longitude)["transit"]
    noon = pd.DatetimeIndex(transit).tz_convert("UTC")
    noon_azimuth = sun.solar_position(noon, site.latitude, site.longitude)["azimuth"].to_numpy()
    side = np.where(np.cos(np.deg2rad(noon_azimuth)) > 0, 0.0, 180.0)
    return np.asarray(side[inverse.ravel()], dtype=float)


def ephemeris_joint_targets(
    times: pd.DatetimeIndex, site: Site, method: str = "spa",
    pointing_model: PointingModel | None = None,
) -> dict[str, NDArray[np.float64]]:
    """Ephemeris sun and the joint angles that face it, at ``times``.

    Returns ``{"solar_azimuth", "apparent_elevation", "azimuth_deg",
    "elevation_deg", "reference_azimuth_deg"}`` [°]: the sun by :func:`sim.sun.solar_position`
    (``method`` "spa" or "duffie-beckman", the site's pressure and air
    temperature) and :func:`sim.kinematics.inverse_kinematics` with the daily
    sweep reference of :func:`noon_reference_azimuth` (returned too: every controller's
    azimuth target is kept within it, :meth:`Controller.command`). With a ``pointing_model``
    the joint angles are the encoder angles that put that mount's real optical axis
    on the sun (:func:`sim.pointing_model.command_angles`, issue 25).
    """
    from pvlib import atmosphere

    pressure = float(atmosphere.alt2pres(site.altitude))
    pos = sun.solar_position(
        times, site.latitude, site.longitude, site.altitude, pressure, site.temp_air,
        method=method,
    )
    az = pos["azimuth"].to_numpy()
    el = pos["apparent_elevation"].to_numpy()
    aim_az, aim_el = (az, el) if pointing_model is None else command_angles(
        pointing_model, az, el)
    reference = noon_reference_azimuth(times, site)
    az_j, el_j = kinematics.inverse_kinematics(aim_az, aim_el, site.tracker,
                                               reference_azimuth=reference)
    return {"solar_azimuth": az, "apparent_elevation": el, "azimuth_deg": az_j,
            "elevation_deg": el_j, "reference_azimuth_deg": reference}


#: The floor of an azimuth error's weight cos(elevation) [-]: within 2.9° of the zenith.
_SKY_WEIGHT_FLOOR = 0.05


def _sky_weight(elevation_deg: float) -> float:
    """cos(elevation), floored so that near the zenith an azimuth error stays finite."""
    return max(math.cos(math.radians(elevation_deg)), _SKY_WEIGHT_FLOOR)


class Controller:
    """Base class: ephemeris, dead band, limits, stow and wake-up.

    Subclasses set :attr:`name`, :attr:`method` and override :meth:`_track`
    (the target while the sun is up). ``camera_interval_s`` is None for the
    controllers without a camera.
    """

    name = "controller"
    method = "spa"
    #: the mount's pointing model the ephemeris targets go through (None: a perfect mount)
    pointing_model: PointingModel | None = None
    gate: _CameraGate | None = None
    camera_interval_s: float | None = None
    detector: str | None = None

    def __init__(self, site: Site, settings: ControlSettings | None = None,
                 clock_offset_s: float = 0.0) -> None:
        self.site = site
        self.settings = settings or ControlSettings()
        self.clock_offset_s = float(clock_offset_s)
        self.geometry = site.tracker
        self.eph: dict[str, NDArray[Any]] = {}
        self.lists: dict[str, list[Any]] = {}
        self.command_deg = (math.nan, math.nan)
        self.stowed = False

    @property
    def frames_used(self) -> int:
        """Camera frames whose detection the controller used (0 without a camera)."""
        return 0 if self.gate is None else self.gate.accepted

    # -- planning ---------------------------------------------------------------------------
    def lead_s(self, tick_s: float) -> float:
        """How far ahead of the tick the ephemeris target is taken [s] (half an update)."""
        return 0.5 * tick_s

    def plan(self, times: pd.DatetimeIndex, tick_s: float) -> None:
        """Vectorised ephemeris for one chunk of ticks (on the controller's clock)."""
        clock = times + pd.Timedelta(seconds=self.clock_offset_s)
        now = ephemeris_joint_targets(clock, self.site, self.method, self.pointing_model)
        ahead = ephemeris_joint_targets(
            clock + pd.Timedelta(seconds=self.lead_s(tick_s)), self.site, self.method,
            self.pointing_model)
        self.eph = {"now_" + k: v for k, v in now.items()}
        self.eph.update({"ahead_" + k: v for k, v in ahead.items()})
        self._set_night(clock)

    def _set_night(self, clock: pd.DatetimeIndex) -> None:
        """``eph["night"]``: the sun below the stow elevation now and ``wake_lead_s`` later."""
        from pvlib import atmosphere

        s = self.settings
        el = self.eph["now_apparent_elevation"]
        if s.wake_lead_s > 0:
            later = sun.solar_position(
                clock + pd.Timedelta(seconds=s.wake_lead_s), self.site.latitude,
                self.site.longitude, self.site.altitude,
                float(atmosphere.alt2pres(self.site.altitude)), self.site.temp_air,
                method=self.method)["apparent_elevation"].to_numpy()
            el = np.maximum(el, later)
        self.eph["night"] = el <= s.stow_elevation_deg
        # plain lists for the per-tick lookups (numpy scalar indexing is ~5x slower)
        self.lists = {k: v.tolist() for k, v in self.eph.items()}

    # -- one tick ---------------------------------------------------------------------------
    def command(self, i: int, reading: Reading,
                measurement: CameraMeasurement | None = None) -> tuple[float, float]:
        """Joint commands (azimuth, elevation) [°] at tick ``i`` of the planned chunk."""
        g = self.geometry
        if self.lists["night"][i]:
            if not self.stowed:
                self._reset()
            self.stowed = True
            target = (reading.azimuth_deg, g.elevation_max_deg)
            self.command_deg = target
            return target
        waking = self.stowed
        self.stowed = False
        if waking or math.isnan(self.command_deg[0]):
            target = (self.lists["ahead_azimuth_deg"][i], self.lists["ahead_elevation_deg"][i])
            self.command_deg = target
            return target
        az_t, el_t = self._track(i, reading, measurement)
        el_t = min(max(el_t, g.elevation_min_deg), g.elevation_max_deg)
        az_t = self._in_daily_sweep(az_t, self.lists["now_reference_azimuth_deg"][i],
                                    self.lists["ahead_azimuth_deg"][i])
        return self._dead_band(az_t, el_t, reading)

    def _in_daily_sweep(self, azimuth_deg: float, reference_deg: float,
                        ephemeris_deg: float) -> float:
        """``azimuth_deg``'s equivalent (± k·360°) in the joint range nearest the day's
        reference [°]: the unwind rule, one for every controller.

        The ephemeris targets already obey it (:func:`ephemeris_joint_targets`, through
        :func:`sim.kinematics.inverse_kinematics` with :func:`noon_reference_azimuth`); a
        camera loop's target is the encoder reading plus a correction, which would follow
        a midnight sun round past the reference ± 180° into the joint limit and unwind
        there in daylight (Tromsø, June: 358° at 07:24 with the sun 25.6° up, a tester's
        finding). Kept within the reference ± 180°, every controller unwinds where the
        sun is farthest from its noon side — at its lowest (``docs/sites.md``).

        Where a correction (a camera's, a pointing model's) takes the target past a joint
        limit that the ephemeris's own target ``ephemeris_deg`` keeps within the sweep, it
        stays at the limit: its equivalent 360° away lies outside the sweep. At the equator
        on the equinox the sweep ends at the −90° limit at sunset; a 2° yaw's correction had
        sent ``hybrid`` round the other way at 1:50 pm, unwinding 360° in daylight (a
        tester's finding). Where the sun's path itself leaves the range (a ±180° range
        facing a southern sun), the target turns round with the ephemeris's.
        """
        g = self.geometry
        if (g.azimuth_min_deg <= azimuth_deg <= g.azimuth_max_deg
                and abs(azimuth_deg - reference_deg) <= 180.0):  # the common case, fast
            return azimuth_deg
        near = reference_deg + (azimuth_deg - reference_deg + 180.0) % 360.0 - 180.0
        if (not g.azimuth_min_deg <= near <= g.azimuth_max_deg
                and abs(ephemeris_deg - reference_deg) <= 180.0):
            return min(max(near, g.azimuth_min_deg), g.azimuth_max_deg)
        az, _ = kinematics.inverse_kinematics(azimuth_deg, 0.0, g, reference_deg)
        return float(az)

    def _dead_band(self, az_t: float, el_t: float, reading: Reading) -> tuple[float, float]:
        db = self.settings.dead_band_deg
        az_c, el_c = self.command_deg
        if abs(az_t - reading.azimuth_deg) * _sky_weight(el_t) > db or math.isnan(az_c):
            az_c = az_t
        if abs(el_t - reading.elevation_deg) > db or math.isnan(el_c):
            el_c = el_t
        self.command_deg = (az_c, el_c)
        return self.command_deg

    def _track(self, i: int, reading: Reading,
               measurement: CameraMeasurement | None) -> tuple[float, float]:
        return self.lists["ahead_azimuth_deg"][i], self.lists["ahead_elevation_deg"][i]

    def _reset(self) -> None:
        """Called when the tracker stows (end of a day)."""


class OpenLoop(Controller):
    """Ephemeris only (seed 001 §2.2's open loop): SPA or Duffie–Beckman."""

    def __init__(self, site: Site, settings: ControlSettings | None = None,
                 clock_offset_s: float = 0.0, method: str = "spa") -> None:
        super().__init__(site, settings, clock_offset_s)
        if method not in sun.METHODS:
            raise ValueError(f"method must be one of {sun.METHODS}, got {method!r}")
        self.method = method
        self.name = "open_loop_spa" if method == "spa" else "open_loop_duffie_beckman"


class OpenLoopModel(OpenLoop):
    """Open loop on SPA through a fitted pointing model (issue 25, item 4).

    The ephemeris sun goes through :func:`sim.pointing_model.command_angles` — the
    inverse the ``GET …/pointing-model/command`` route uses — so the commanded encoder
    angles put the *real* optical axis of a mount with ``model``'s terms (pedestal yaw,
    encoder zeros, pedestal tilts, collimation, non-perpendicularity) on the sun; with
    all terms 0 it is ``open_loop_spa``. No camera: it holds the sun through clouds as
    well as its model and clock do (``docs/control.md``).
    """

    def __init__(self, site: Site, settings: ControlSettings | None = None,
                 clock_offset_s: float = 0.0, model: PointingModel | None = None) -> None:
        super().__init__(site, settings, clock_offset_s, method="spa")
        self.name = "open_loop_model"
        self.pointing_model = model or PointingModel()


class Chronological(Controller):
    """A step every N minutes to the ephemeris at the middle of the coming interval.

    Seed 000, Table 1, ref. [34] (Arreola Gómez et al.: "time-based, 60/30/5-min
    intervals"); pointing at the interval's middle halves the largest error.
    No dead band: the tracker moves at every step.
    """

    name = "chronological"

    def __init__(self, site: Site, settings: ControlSettings | None = None,
                 clock_offset_s: float = 0.0) -> None:
        super().__init__(site, settings, clock_offset_s)
        self._last_step: int | None = None
        self._step_index: list[int] = []

    def plan(self, times: pd.DatetimeIndex, tick_s: float) -> None:
        clock = times + pd.Timedelta(seconds=self.clock_offset_s)
        period = pd.Timedelta(minutes=self.settings.chronological_interval_min)
        step_start = clock.floor(period) if period >= pd.Timedelta(seconds=1) else clock
        now = ephemeris_joint_targets(clock, self.site, self.method)
        ahead = ephemeris_joint_targets(step_start + period / 2, self.site, self.method)
        self.eph = {"now_" + k: v for k, v in now.items()}
        self.eph.update({"ahead_" + k: v for k, v in ahead.items()})
        self._set_night(clock)
        period_s = period.total_seconds()
        self._step_index = np.floor(
            sun._unix_seconds(clock) / period_s + 1e-9).astype(np.int64).tolist()

    def _dead_band(self, az_t: float, el_t: float, reading: Reading) -> tuple[float, float]:
        return self.command_deg

    def _track(self, i: int, reading: Reading,
               measurement: CameraMeasurement | None) -> tuple[float, float]:
        k = int(self._step_index[i])
        if k != self._last_step:
            self._last_step = k
            self.command_deg = (self.lists["ahead_azimuth_deg"][i],
                                self.lists["ahead_elevation_deg"][i])
        return self.command_deg


class _CameraGate:
    """Which detections a camera loop may use (clouds must not steer the tracker)."""

    def __init__(self, settings: ControlSettings) -> None:
        self.s = settings
        self.areas: list[int] = []
        self.rejected_in_a_row = 0
        self.accepted = 0
        self.ref_area: float | None = None

    def usable(self, m: CameraMeasurement | None, expected: tuple[float, float] | None) -> bool:
        """True when ``m`` is the clear sun: confident, of its clear-sky size, and (when the
        loop is locked on ``expected`` = (right, up) [°]) not a jump away from it."""
        if m is None or not m.sun_found or m.confidence < self.s.min_confidence:
            return False
        if not (math.isfinite(m.right_deg) and math.isfinite(m.up_deg)):
            return False
        if m.peak_dn < self.s.min_peak_dn:  # a sun dimmed by cloud, or no sun but a cloud edge
            return False
        # the clear sun's glare is the largest a frame shows (cloud only cuts or dims it): the
        # reference is the 90th percentile of the recent saturated glares' areas
        self.areas.append(int(m.area_px))
        if len(self.areas) > 300:
            del self.areas[0]
        if self.s.reference_area_px is not None:
            self.ref_area = float(self.s.reference_area_px)
        elif len(self.areas) < 5:
            return False
        elif self.ref_area is None or len(self.areas) % 10 == 0:
            self.ref_area = float(np.percentile(self.areas, 90))
        tol = self.s.area_tolerance
        if not self.ref_area / tol <= m.area_px <= self.ref_area * tol:
            return False
        if expected is not None:
            jump = math.hypot(m.right_deg - expected[0], m.up_deg - expected[1])
            if jump > self.s.max_jump_deg:
                self.rejected_in_a_row += 1
                if self.rejected_in_a_row < self.s.reacquire_frames:
                    return False
        self.rejected_in_a_row = 0
        self.accepted += 1
        return True


class ClosedLoopCamera(Controller):
    """Seed 000's vision loop: the sun's centroid vs the reference pixel → PID on the joints.

    Each frame (1 s): the image-plane error (right h, up v) [°] becomes a joint
    error ``(h / cos E, v)`` — a right error on the sky is an azimuth error
    times cos(elevation) — and a PID gives the joint increments, commanded
    through the dead band. Without a usable sun it follows the ephemeris and
    resets the PID's memory.
    """

    name = "closed_loop_camera"
    detector = "seed000_hsv"

    def __init__(self, site: Site, settings: ControlSettings | None = None,
                 clock_offset_s: float = 0.0) -> None:
        super().__init__(site, settings, clock_offset_s)
        s = self.settings
        self.camera_interval_s = s.camera_interval_s or 1.0
        self.detector = s.detector or "seed000_hsv"
        self._gate = self.gate = _CameraGate(s)
        self._reset()

    def lead_s(self, tick_s: float) -> float:
        return 0.0

    def _reset(self) -> None:
        self.integral = [0.0, 0.0]
        self.previous: tuple[float, float] | None = None
        self.locked = False

    def _track(self, i: int, reading: Reading,
               measurement: CameraMeasurement | None) -> tuple[float, float]:
        if measurement is None:  # no frame at this tick: hold the current command
            return self.command_deg
        expected = (0.0, 0.0) if self.locked else None
        if not self._gate.usable(measurement, expected):
            self._reset()
            return super()._track(i, reading, measurement)
        self.locked = True
        dt = float(self.camera_interval_s or 1.0)
        err = (measurement.right_deg / _sky_weight(reading.elevation_deg), measurement.up_deg)
        s = self.settings
        out = []
        for k in (0, 1):
            self.integral[k] = max(-2.0, min(2.0, self.integral[k] + err[k] * dt))
            de = 0.0 if self.previous is None else (err[k] - self.previous[k]) / dt
            out.append(s.kp * err[k] + s.ki_per_s * self.integral[k] + s.kd_s * de)
        self.previous = err
        return reading.azimuth_deg + out[0], reading.elevation_deg + out[1]


class Hybrid(Controller):
    """Seed 001's loop: SPA ephemeris plus the camera's correction angles.

    Every ``camera_interval_s`` (default 60 s) a frame gives the sun's
    position against the fixed reference pixel; with the encoder readings
    that is where the sun is in joint space, ``(A + h / cos E, E + v)``, and
    the correction is that minus the ephemeris's joint angles at the same
    instant (seed 001 §2.3: "correction angles ... added to those already
    calculated by the solar position algorithm"). The correction is low-pass
    filtered (``hybrid_gain``) and kept when the sun is not seen, and across
    the night (an installation error persists).
    """

    name = "hybrid"
    detector = "seed003_gray240"

    def __init__(self, site: Site, settings: ControlSettings | None = None,
                 clock_offset_s: float = 0.0) -> None:
        super().__init__(site, settings, clock_offset_s)
        s = self.settings
        self.camera_interval_s = s.camera_interval_s or 60.0
        self.detector = s.detector or "seed003_gray240"
        self._gate = self.gate = _CameraGate(s)
        self.correction = [0.0, 0.0]
        self.have_correction = False

    def _track(self, i: int, reading: Reading,
               measurement: CameraMeasurement | None) -> tuple[float, float]:
        if measurement is not None:
            az_e = self.lists["now_azimuth_deg"][i]
            el_e = self.lists["now_elevation_deg"][i]
            # where the camera expects the sun with the current correction
            w = _sky_weight(reading.elevation_deg)
            c = self.correction
            expected = None
            if self.have_correction:
                expected = ((az_e + c[0] - reading.azimuth_deg) * w,
                            el_e + c[1] - reading.elevation_deg)
            if self._in_small_angle(reading, el_e, measurement) and self._gate.usable(
                    measurement, expected):
                d_az = reading.azimuth_deg + measurement.right_deg / w - az_e
                if abs(d_az) > 180.0:  # the reading a turn from the ephemeris's branch
                    d_az -= 360.0 * round(d_az / 360.0)
                new = (d_az, reading.elevation_deg + measurement.up_deg - el_e)
                g = self.settings.hybrid_gain if self.have_correction else 1.0
                self.correction = [c[k] + g * (new[k] - c[k]) for k in (0, 1)]
                self.have_correction = True
        return (self.lists["ahead_azimuth_deg"][i] + self.correction[0],
                self.lists["ahead_elevation_deg"][i] + self.correction[1])

    def _in_small_angle(self, reading: Reading, elevation_deg: float,
                        m: CameraMeasurement) -> bool:
        """Whether the frame's ``(A + h / cos E, E + v)`` is where the sun is: the panel and
        the ephemeris sun outside the zenith's cap (cos E ≥ the weight's floor) and the sun
        within ``hybrid_max_offset_deg`` of the encoder azimuth. Elsewhere the correction
        was garbage and kept: a tracker slewing at 0.05° s⁻¹ through the equator's noon
        took 9° and then 99° of azimuth correction from frames 13° and 123° of azimuth
        behind the sun and lay flat at 3 pm, 772 mrad off (a tester's finding)."""
        cos_e = math.cos(math.radians(reading.elevation_deg))
        if min(cos_e, math.cos(math.radians(elevation_deg))) < _SKY_WEIGHT_FLOOR:
            return False
        return abs(m.right_deg) <= self.settings.hybrid_max_offset_deg * cos_e


def make_controller(name: str, site: Site, settings: ControlSettings | None = None,
                    clock_offset_s: float = 0.0, **kwargs: Any) -> Controller:
    """A controller by name (:data:`CONTROLLERS` except ``ideal``, which has no loop).

    ``chronological`` takes ``interval_min``; ``open_loop_model`` takes
    ``pointing_model_terms`` (:meth:`sim.pointing_model.PointingModel.from_terms`: the
    ``terms`` of ``GET …/pointing-model`` as they come, or ``{name: degrees}``; none is
    a perfect mount).
    """
    if name == "open_loop_spa":
        return OpenLoop(site, settings, clock_offset_s, method="spa")
    if name == "open_loop_duffie_beckman":
        return OpenLoop(site, settings, clock_offset_s, method="duffie-beckman")
    if name == "chronological":
        if "interval_min" in kwargs:
            settings = replace(settings or ControlSettings(),
                               chronological_interval_min=float(kwargs.pop("interval_min")))
        return Chronological(site, settings, clock_offset_s)
    if name == "closed_loop_camera":
        return ClosedLoopCamera(site, settings, clock_offset_s)
    if name == "hybrid":
        return Hybrid(site, settings, clock_offset_s)
    if name == "open_loop_model":
        terms = kwargs.pop("pointing_model_terms", None) or {}
        return OpenLoopModel(site, settings, clock_offset_s, PointingModel.from_terms(terms))
    if name == "ideal":
        raise ValueError("'ideal' has no control loop: the twin uses tracking_angles directly")
    raise ValueError(f"controller must be one of {', '.join(CONTROLLERS)}; got {name!r}")
