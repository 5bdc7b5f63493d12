"""The world side of a control loop: the tracker's axes, its camera and its disturbances.

:func:`run_loop` steps a :class:`sim.control.Controller` through the ticks of
a run. At each tick the *true* pose (the motor-side angles, the gear backlash,
the pedestal's rotation) gives the panel normal; the controller gets only the
encoder readings (with their drift) and, when it asked for one, a camera frame
rendered from the true pose (:func:`sim.frames.render_sun_roi`) and detected by
:func:`vision.detect.detect_sun`. A command moves an idle axis along a speed-
and acceleration-limited profile (the trapezoid of
:func:`sim.dynamics.trapezoid_motion`); while it moves, later commands to that
axis wait. Nights are skipped in one step once the tracker is stowed.

Each move is logged (:class:`Move`); :func:`move_energies_wh` costs them
afterwards in one vectorised pass: the profile's rates and accelerations
through the inverse dynamics (seed 002, eq. 24, :func:`sim.dynamics.inverse_dynamics`)
plus the gust torque give the output torque, and :func:`sim.motors.electrical_power_w`
the power drawn, integrated over the move's samples only — the dynamics are
evaluated only while an axis moves. The servo is taken to follow its profile
(torque = inverse dynamics), so no forward integration is needed for the
energy; the axis not moving is held by its self-locking gear at no power.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import cv2
import numpy as np
import pandas as pd
from numpy.typing import NDArray

from sim import disturbances as dist
from sim.control import CameraMeasurement, Controller, Reading
from sim.frames import CloudField, pointing_error_deg, render_sun_roi
from vision.cameras import PinholeCamera

__all__ = ["DriveLimits", "CameraSetup", "Move", "LoopResult", "LoopState", "run_loop",
           "move_energies_wh", "MoveEnergies", "trapezoid_duration_s", "clear_sky_area_px",
           "SUNSHINE_DNI_W_M2"]

#: The camera sees the sun only when the beam is at least this [W m⁻²]: the WMO's
#: threshold of bright sunshine (direct normal irradiance ≥ 120 W m⁻², WMO-No. 8, *Guide
#: to Meteorological Instruments and Methods of Observation*, ch. 8 "Measurement of
#: sunshine duration", 8.1.2). Below it the sun's disc is hidden or too faint to cast a
#: shadow — to the tracker camera, an overcast sky with no sun to find.
SUNSHINE_DNI_W_M2 = 120.0


@dataclass(frozen=True)
class DriveLimits:
    """Speed and acceleration limits of the two axes (output side).

    Defaults: 0.05 rad s⁻¹ (2.86° s⁻¹) and 0.1 rad s⁻² (5.73° s⁻²) on both
    axes, the slew limits :func:`sim.motors.tracking_motion_energy` assumes
    (no seed gives them; the drives' own limit is 0.2 rad s⁻¹,
    ``AxisDrive.max_output_speed_rad_s``). A twin run takes :meth:`for_drives` of its
    site: these, with a rate no faster than the site's drive.
    """

    azimuth_rate_deg_s: float = math.degrees(0.05)
    azimuth_accel_deg_s2: float = math.degrees(0.1)
    elevation_rate_deg_s: float = math.degrees(0.05)
    elevation_accel_deg_s2: float = math.degrees(0.1)

    def __post_init__(self) -> None:
        for k, v in self.__dict__.items():
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"DriveLimits.{k} must be a positive number, got {v}")

    @classmethod
    def for_drives(cls, azimuth: Any, elevation: Any) -> DriveLimits:
        """The default profile with each axis's rate capped at its drive's rated output
        speed (``AxisDrive.max_output_speed_rad_s``, a site's ``tracker.drives``).

        A site's slow drive (a heavy tracker at 0.05° s⁻¹) had moved at 2.86° s⁻¹, with
        every move counted beyond the drive and no lag in the pointing (a tester's
        finding). The cap sits 1e-9 under the rating so that the trip through degrees
        never reads a move at the rated speed as over it.
        """
        d = cls()
        az = math.degrees(azimuth.max_output_speed_rad_s) * (1 - 1e-9)
        el = math.degrees(elevation.max_output_speed_rad_s) * (1 - 1e-9)
        return cls(min(d.azimuth_rate_deg_s, az), d.azimuth_accel_deg_s2,
                   min(d.elevation_rate_deg_s, el), d.elevation_accel_deg_s2)

    def wake_slew_s(self) -> float:
        """The longest slew from the night stow to a sunrise pose [s]: a full turn of
        azimuth (the daily sweep keeps the joint within its reference ± 180°) and 90° of
        elevation, the axes moving together."""
        return max(trapezoid_duration_s(360.0, *self.axis(0)),
                   trapezoid_duration_s(90.0, *self.axis(1)))

    def axis(self, k: int) -> tuple[float, float]:
        """(rate [° s⁻¹], acceleration [° s⁻²]) of axis ``k`` (0 azimuth, 1 elevation)."""
        if k == 0:
            return self.azimuth_rate_deg_s, self.azimuth_accel_deg_s2
        return self.elevation_rate_deg_s, self.elevation_accel_deg_s2


@dataclass(frozen=True)
class CameraSetup:
    """The tracker camera and its sky, for the camera loops.

    ``camera`` is seed 000's narrow camera (640 × 480, 67°) by default;
    ``glare_deg``, ``sky_level`` and ``noise_dn`` as :func:`vision.synth.tracker_frame`;
    ``clouds`` optional drifting clouds; ``roi_half_px`` half the rendered ROI.
    """

    camera: PinholeCamera = field(default_factory=PinholeCamera)
    roi_half_px: int = 16
    glare_deg: float = 0.8
    sky_level: float = 0.35
    noise_dn: float = 2.0
    clouds: CloudField | None = None
    seed: int = 0


class Move(NamedTuple):
    """One axis move: ``axis`` 0 azimuth / 1 elevation, start time since the run's start [s],
    signed displacement and start angle [°], the elevation joint at the start [°], the gust
    torque on the axis [N m]."""

    axis: int
    t0_s: float
    delta_deg: float
    start_deg: float
    elevation_deg: float
    gust_nm: float


def trapezoid_duration_s(delta_deg: float, rate: float, accel: float) -> float:
    """Duration of a trapezoidal move [s]: :func:`sim.dynamics.trapezoid_duration` in degrees
    (``rate`` [° s⁻¹], ``accel`` [° s⁻²])."""
    from sim.dynamics import trapezoid_duration

    return float(trapezoid_duration(delta_deg, rate, accel))


def _trapezoid_position(delta_deg: float, rate: float, accel: float, tt: float) -> float:
    """Displacement after ``tt`` seconds of a trapezoidal move [°]
    (:func:`sim.dynamics.trapezoid_motion` in degrees)."""
    from sim.dynamics import trapezoid_motion

    return float(trapezoid_motion(delta_deg, rate, accel, tt)[0])


class _Axis:
    """Motor-side angle, the gear flank in contact, and the move under way."""

    def __init__(self, angle_deg: float, rate: float, accel: float) -> None:
        self.motor = angle_deg
        self.rate, self.accel = rate, accel
        self.side = 1.0
        self.t0 = 0.0
        self.delta = 0.0
        self.t_end = -math.inf

    def moving(self, t: float) -> bool:
        return t < self.t_end

    def settle(self, t: float) -> None:
        if self.delta != 0.0 and t >= self.t_end:
            self.motor += self.delta
            self.delta = 0.0

    def position(self, t: float) -> float:
        if self.delta == 0.0:
            return self.motor
        return self.motor + _trapezoid_position(self.delta, self.rate, self.accel, t - self.t0)

    def start(self, t: float, delta: float) -> None:
        self.t0, self.delta = t, delta
        self.t_end = t + trapezoid_duration_s(delta, self.rate, self.accel)
        self.side = 1.0 if delta > 0 else -1.0


@dataclass
class LoopState:
    """What carries over from one chunk of ticks to the next."""

    axes: list[_Axis]
    last_frame_s: float = -math.inf
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))
    frames: int = 0
    frames_found: int = 0
    #: the end of the slew from stow to the sun after the last wake-up [s since the run's start]
    wake_until_s: float = -math.inf


@dataclass
class LoopResult:
    """Per-sample arrays of one chunk [°]: commands, true output-side joint angles (base
    frame), the true panel normal (ENU); the moves started in the chunk; and ``tracking``,
    whether the tracker is tracking at the sample: the controller not stowed and its slew
    from stow to the sun after waking over."""

    azimuth_command_deg: NDArray[np.float64]
    elevation_command_deg: NDArray[np.float64]
    azimuth_joint_deg: NDArray[np.float64]
    elevation_joint_deg: NDArray[np.float64]
    moves: list[Move]
    tracking: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))


def _detector(name: str):  # type: ignore[no-untyped-def]
    from vision.detect import detect_robust, detect_seed000, detect_seed003

    if name == "robust":
        return lambda img: detect_robust(img, auto_fov=False)
    if name == "seed003_gray240":
        return detect_seed003
    if name == "seed000_hsv":
        return detect_seed000
    raise ValueError(f"unknown detector {name!r}")


def run_loop(
    controller: Controller,
    ticks: pd.DatetimeIndex,
    t0_s: float,
    tick_s: float,
    sample_every: int,
    sun_enu: NDArray[np.float64],
    d: dist.Disturbances,
    limits: DriveLimits,
    camera: CameraSetup,
    state: LoopState | None,
    act_ticks: int | None = None,
    dni_w_m2: NDArray[np.float64] | None = None,
) -> tuple[LoopResult, LoopState]:
    """Run ``controller`` over one chunk of ``ticks`` (UTC, uniform ``tick_s``).

    Parameters
    ----------
    ticks : pandas.DatetimeIndex
        The chunk's tick times; ``t0_s`` is the first one's time since the run's start.
    sample_every : int
        Samples are taken at every ``sample_every``-th tick of the chunk,
        starting with its first (the chunk must start on a sample), before the
        controller acts at that tick.
    sun_enu : ndarray, shape (n_ticks, 3)
        True (apparent) sun direction at the ticks, ENU.
    state : LoopState, optional
        From the previous chunk; None to start with the tracker stowed.
    act_ticks : int, optional
        The ticks from this index on are only sampled: the controller neither looks nor
        acts (the instant closing a run's last step, :func:`sim.energy.simulation_times`:
        what would happen at it belongs to the next range). Default: every tick acts.
    dni_w_m2 : ndarray, shape (n_ticks,), optional
        The run's weather's direct normal irradiance at the ticks [W m⁻²]: a frame taken
        when it is below :data:`SUNSHINE_DNI_W_M2` shows no sun (overcast). Default: a
        clear sky, the sun in every frame it faces.

    Returns
    -------
    (LoopResult, LoopState)
    """
    from sim import dynamics

    n = len(ticks)
    controller.plan(ticks, tick_s)
    g = controller.site.tracker
    if state is None:
        # a run starts in the steady state: stowed at night, on the ephemeris target by day
        stowed = bool(controller.eph["night"][0])
        az0 = float(controller.eph["ahead_azimuth_deg"][0])
        el0 = g.elevation_max_deg if stowed else float(controller.eph["ahead_elevation_deg"][0])
        state = LoopState(axes=[_Axis(az0, *limits.axis(0)), _Axis(el0, *limits.axis(1))],
                          rng=np.random.default_rng(camera.seed))
        controller.stowed = stowed
        controller.command_deg = (az0, el0)
    ax_az, ax_el = state.axes
    t_s = t0_s + tick_s * np.arange(n)
    gust = dist.gust_torque_nm(t_s, d)
    inertia = controller.site.inertia
    n_samples = (n + sample_every - 1) // sample_every
    out = {k: np.empty(n_samples) for k in ("az_cmd", "el_cmd", "az", "el")}
    tracking = np.zeros(n_samples, dtype=bool)  # False through the skipped nights
    moves: list[Move] = []
    night = np.asarray(controller.eph["night"], dtype=bool)
    # index of the next daylight tick from each tick (n when none): skips whole nights
    day_idx = np.flatnonzero(~night)
    next_day = np.searchsorted(day_idx, np.arange(n))
    if day_idx.size:
        next_day = np.where(next_day < len(day_idx),
                            day_idx[np.minimum(next_day, len(day_idx) - 1)], n)
    else:
        next_day = np.full(n, n)
    # plain lists for the per-tick lookups (numpy scalar indexing is ~5x slower)
    t_list, night_list, next_list = t_s.tolist(), night.tolist(), next_day.tolist()
    gust_list = gust.tolist()
    dni_list = None if dni_w_m2 is None else np.asarray(dni_w_m2, dtype=float).tolist()
    sun_list = sun_enu
    half_b = 0.5 * d.backlash_deg
    enc_rate = float(dist.encoder_error_deg(1.0, d))
    detect = None
    if controller.camera_interval_s and controller.detector:
        detect = _detector(controller.detector)
    cam = camera.camera
    interval = controller.camera_interval_s or math.inf

    def output(t: float, i: int) -> tuple[float, float]:
        """True output-side joint angles (motor angle minus the backlash offset)."""
        a, e = ax_az.position(t), ax_el.position(t)
        if half_b:
            side_az = ax_az.side
            if gust_list[i][0] != 0.0 and not ax_az.moving(t):
                side_az = -math.copysign(1.0, gust_list[i][0])
            side_el = ax_el.side
            if not ax_el.moving(t):  # held: the flank the load presses (gravity minus gust)
                hold = float(dynamics.gravity(math.radians(e), inertia)[1]) - gust_list[i][1]
                side_el = 1.0 if hold >= 0 else -1.0
            a -= side_az * half_b
            e -= side_el * half_b
        return a, e

    # the axes' state inline (the hot path: ~10⁶ ticks a year); _Axis's methods, unrolled
    i = 0
    while i < n:
        t = t_list[i]
        if ax_az.delta != 0.0 and t >= ax_az.t_end:  # settle a finished move
            ax_az.motor += ax_az.delta
            ax_az.delta = 0.0
        if ax_el.delta != 0.0 and t >= ax_el.t_end:
            ax_el.motor += ax_el.delta
            ax_el.delta = 0.0
        az_moving, el_moving = t < ax_az.t_end, t < ax_el.t_end
        if night_list[i] and controller.stowed and not (az_moving or el_moving):
            j = next_list[i]  # the pose holds until the next daylight tick
            a, e = output(t, i)
            k0, k1 = -(-i // sample_every), -(-j // sample_every)
            out["az"][k0:k1], out["el"][k0:k1] = a, e
            out["az_cmd"][k0:k1], out["el_cmd"][k0:k1] = controller.command_deg
            i = j
            continue
        if i % sample_every == 0:
            k = i // sample_every
            out["az"][k], out["el"][k] = output(t, i)
            out["az_cmd"][k], out["el_cmd"][k] = controller.command_deg
            tracking[k] = not controller.stowed and t >= state.wake_until_s
        if act_ticks is not None and i >= act_ticks:
            i = (i // sample_every + 1) * sample_every  # on to the next sample's tick
            continue
        enc = enc_rate * t
        r_az = (ax_az.position(t) if az_moving else ax_az.motor) + enc
        r_el = (ax_el.position(t) if el_moving else ax_el.motor) + enc
        meas = None
        if detect is not None and not night_list[i] and t - state.last_frame_s >= interval - 1e-6:
            state.last_frame_s = t
            if dni_list is not None and dni_list[i] < SUNSHINE_DNI_W_M2:
                state.frames += 1  # overcast: the frame shows no sun
                meas = CameraMeasurement.none()
            else:
                meas = _frame(output(t, i), sun_list[i], d, camera, cam, detect, state, t)
        was_stowed = controller.stowed
        c_az, c_el = controller.command(i, Reading(t, r_az, r_el, az_moving, el_moving), meas)
        delta = c_az - r_az
        if not az_moving and abs(delta) > 1e-9 and math.isfinite(delta):
            moves.append(Move(0, t, delta, ax_az.motor, ax_el.motor, gust_list[i][0]))
            ax_az.start(t, delta)
        delta = c_el - r_el
        if not el_moving and abs(delta) > 1e-9 and math.isfinite(delta):
            moves.append(Move(1, t, delta, ax_el.motor, ax_el.motor, gust_list[i][1]))
            ax_el.start(t, delta)
        if was_stowed and not controller.stowed:  # waking: tracking once the slew is over
            state.wake_until_s = max(ax_az.t_end, ax_el.t_end)
        i += 1
    res = LoopResult(out["az_cmd"], out["el_cmd"], out["az"], out["el"], moves, tracking)
    return res, state


def clear_sky_area_px(setup: CameraSetup, detector: str) -> float:
    """Area of the clear sun as ``detector`` sees it on ``setup``'s camera [px]: the mean of
    a few clear, noisy frames around the boresight (a clear-sky calibration)."""
    rng = np.random.default_rng(setup.seed + 1)
    detect = _detector(detector)
    cam = setup.camera
    areas = []
    for h, v in ((0.0, 0.0), (0.3, -0.2), (-0.2, 0.4), (0.5, 0.5)):
        sx, sy = cam.pixel_from_pointing_error(h, v)
        roi = render_sun_roi(cam.pixel_to_direction(sx, sy), cam, setup.roi_half_px,
                             setup.glare_deg, setup.sky_level, None, 0.0,
                             noise_dn=setup.noise_dn, rng=rng)
        det = detect(roi.image)
        if det.sun_found:
            areas.append(det.area_px)
    if not areas:
        raise ValueError("the camera setup shows no sun on a clear sky: check glare_deg")
    return float(np.mean(areas))


def _frame(pose: tuple[float, float], sun_enu: NDArray[np.float64], d: dist.Disturbances,
           setup: CameraSetup, cam: PinholeCamera, detect,  # type: ignore[no-untyped-def]
           state: LoopState, t: float) -> CameraMeasurement:
    """Render the ROI seen from ``pose``, detect the sun, return its angles from the
    reference pixel."""
    if sun_enu[2] <= 0.0:  # the sun below the horizon: the Earth hides it
        state.frames += 1
        return CameraMeasurement.none()
    s_cam = dist.sun_in_camera(pose[0], pose[1], d, sun_enu)
    roi = render_sun_roi(s_cam, cam, setup.roi_half_px, setup.glare_deg, setup.sky_level,
                         setup.clouds, t, noise_dn=setup.noise_dn, rng=state.rng)
    state.frames += 1
    if not roi.sun_in_frame:
        return CameraMeasurement.none()
    peak = int(cv2.minMaxLoc(roi.image)[1])  # the brightest grey level (cheaper than max)
    det = detect(roi.image)
    if not det.sun_found or det.centroid_px is None:
        return CameraMeasurement.none()
    state.frames_found += 1
    x = det.centroid_px[0] + roi.x0_px
    y = det.centroid_px[1] + roi.y0_px
    h, v = pointing_error_deg(cam, x, y)
    return CameraMeasurement(True, float(h), float(v), float(det.confidence), int(det.area_px),
                             peak)


class MoveEnergies(NamedTuple):
    """:func:`move_energies_wh`'s answer."""

    energies_wh: NDArray[np.float64]  #: each move's bus energy [Wh]
    total_wh: float  #: their sum [Wh]
    #: each move: True where some sample asks more than its drive gives —
    #: :func:`sim.motors.duty_for`'s ``feasible`` is False (output torque above
    #: ``max_output_torque_nm``, speed above ``max_output_speed_rad_s``, or an armature
    #: voltage above the bus): its energy is what a drive that could would draw
    beyond_drive: NDArray[np.bool_]


def move_energies_wh(moves: list[Move], limits: DriveLimits, dt_s: float = 0.01,
                     drives: tuple[Any, Any] | None = None, inertia: Any = None,
                     ) -> MoveEnergies:
    """Electrical energy of each move [Wh], the total [Wh], and which moves ask more than
    their drive gives (:class:`MoveEnergies`).

    Each move's trapezoid (:func:`sim.dynamics.trapezoid_motion`) is sampled every
    ``dt_s`` (its samples before the end, as :func:`sim.dynamics.move_profile`'s); the
    moving joint's torque is seed 002's eq. 24 along it with the other joint at rest —
    for an azimuth move τ1 = M11(q2) q̈1 (V1 ∝ q̇2 and G1 vanish), for an elevation move
    τ2 = M22 q̈2 + G2(q2(t)) (V2 ∝ q̇1² vanishes), with M and G from :mod:`sim.dynamics`
    — minus the gust torque on the axis; :func:`sim.motors.electrical_power_w` of that
    torque and rate, summed over the samples (left Riemann sum; 0.01 s is within 0.5 %
    of 1 ms for 0.1°–1° moves, tests/sim/test_control.py). All samples of all moves of
    one axis go through in one
    flat vectorised pass.
    """
    from sim import dynamics, motors

    if not dt_s > 0:
        raise ValueError(f"dt_s must be > 0, got {dt_s}")
    inertia = dynamics.TrackerInertia.seed002() if inertia is None else inertia
    energies = np.zeros(len(moves))
    beyond = np.zeros(len(moves), dtype=bool)
    if drives is None:
        drives = (motors.AxisDrive.azimuth_default(), motors.AxisDrive.elevation_default())
    for axis in (0, 1):
        idx = np.array([k for k, m in enumerate(moves) if m.axis == axis], dtype=np.int64)
        if idx.size == 0:
            continue
        rate_deg, acc_deg = limits.axis(axis)
        rate, acc = math.radians(rate_deg), math.radians(acc_deg)
        delta = np.radians([moves[k].delta_deg for k in idx])
        q2 = np.radians([moves[k].elevation_deg for k in idx])
        gust = np.array([moves[k].gust_nm for k in idx])
        nsamp = np.ceil(dynamics.trapezoid_duration(delta, rate, acc) / dt_s - 1e-9
                        ).astype(np.int64)
        per_move = mass_terms(q2, axis, inertia)
        for lo in range(0, idx.size, 20_000):  # bounded memory
            sl = slice(lo, lo + 20_000)
            ns = nsamp[sl]
            rep = np.repeat(np.arange(ns.size), ns)
            first = np.cumsum(ns) - ns
            tt = (np.arange(rep.size) - first[rep]) * dt_s
            q, qd, qdd = dynamics.trapezoid_motion(delta[sl][rep], rate, acc, tt)
            tau = per_move[sl][rep] * qdd
            if axis == 1:
                q_el = q2[sl][rep] + q
                tau = tau + dynamics.gravity(q_el, inertia)[..., 1]
            tau = tau - gust[sl][rep]
            p = np.asarray(motors.electrical_power_w(drives[axis], tau, qd), dtype=float)
            energies[idx[sl]] = np.bincount(rep, weights=p, minlength=ns.size) * dt_s / 3600.0
            over = ~motors.duty_for(drives[axis], tau, qd).feasible
            beyond[idx[sl]] = np.bincount(rep, weights=over, minlength=ns.size) > 0
    return MoveEnergies(energies, float(energies.sum()), beyond)


def mass_terms(q2_rad: NDArray[Any], axis: int, inertia: Any) -> NDArray[np.float64]:
    """M11(q2) (``axis`` 0) or M22 (``axis`` 1) of :func:`sim.dynamics.mass_matrix` [kg m²]."""
    from sim import dynamics

    m = dynamics.mass_matrix(np.asarray(q2_rad, dtype=float), inertia)
    return np.asarray(m[..., axis, axis], dtype=float)

