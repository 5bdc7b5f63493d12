"""Disturbances of a real tracker: why the pose a controller commands is not the pose it gets.

One frozen dataclass, :class:`Disturbances`, holds every disturbance as a named
parameter with its unit (all default 0, i.e. a perfect machine), and small pure
functions say how each enters the model. The twin (:mod:`sim.twin`) and the
controllers (:mod:`sim.control`) use only these functions, so every effect is
defined in one place:

======================================  ==========================================================
parameter                               enters the model as
======================================  ==========================================================
``pedestal_yaw_deg``                    rotation of the tracker's base frame about the vertical
                                        (azimuth misalignment of the pedestal): the joint angles
                                        the controller commands point the normal ``yaw`` further
                                        clockwise (seen from above) than intended
                                        (:func:`base_rotation`)
``pedestal_tilt_deg``,                  rotation of the base frame about a horizontal axis: the
``pedestal_tilt_azimuth_deg``           pedestal's vertical leans ``tilt`` towards the azimuth
                                        ``tilt_azimuth`` (:func:`base_rotation`)
``elevation_zero_deg``                  the elevation encoder's zero (issue 25's term of that
                                        name): the real elevation joint is the angle on the
                                        encoder's datum plus this — the motor side, the
                                        controller's readings and commands are on the datum,
                                        the panel and the camera at the real angle
                                        (:func:`real_elevation_deg`)
``encoder_drift_mrad_per_h``            the joint encoders' reading error grows linearly with the
                                        time since the start of the run, the same on both axes:
                                        reading = true angle + drift·t; the controller positions
                                        the readings, so the true joints lag by drift·t
                                        (:func:`encoder_error_deg`)
``clock_offset_s``                      the controller's clock runs ahead by this much: its
                                        ephemeris is evaluated at t + offset (seed 001's open loop
                                        trusts its clock; 4 min of error ≈ 1° of hour angle)
``backlash_deg``                        a dead zone in each gear train: on a reversal the first
                                        ``backlash`` of motor travel does not move the output; the
                                        output sits ``±backlash/2`` from the motor side's angle,
                                        on the flank the load presses (:func:`backlash_offset_deg`)
``gust_torque_nm``                      a disturbance torque on both axes, a seeded gust sequence
                                        of amplitude ``gust_torque_nm`` (:func:`gust_torque_nm`):
                                        it adds to the torque of every move (energy) and, with
                                        backlash, pushes the output to the gust's flank
``camera_offset_right_deg``,            the tracker camera's boresight relative to the panel
``camera_offset_up_deg``                normal, right/up in the panel frame (:func:`camera_axes`):
                                        a camera loop centres the sun on the *camera*, so the
                                        panel ends up off by the offset
======================================  ==========================================================

Frames: East-North-Up (ENU) for the world; the tracker's base frame is ENU
rotated by :func:`base_rotation`; joint angles are those of
``docs/architecture.md`` (azimuth of the normal clockwise from north, elevation
above the horizon) measured in the base frame.

Issue 25's pointing-model terms (:mod:`sim.pointing_model`, ``docs/pointing-model.md``)
in these disturbances: ``azimuth_zero_deg`` is ``pedestal_yaw_deg`` (a yaw turns the
base about the vertical before the tilt, as the zero turns the azimuth joint: the
same rotation); ``elevation_zero_deg`` is ``elevation_zero_deg``;
``pedestal_tilt_north_deg`` and ``pedestal_tilt_east_deg`` are the Euler angles of
the twin's lean (``pedestal_tilt_deg`` towards ``pedestal_tilt_azimuth_deg``), to
first order ``tilt·cos(tilt_azimuth)`` and ``tilt·sin(tilt_azimuth)``; the camera's
offset up is, to the camera, an elevation zero, and its offset right the collimation
(``tests/sim/test_pointing_model.py`` fits the twin's mount back to these terms).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.kinematics import panel_axes, panel_axes_from_trig

__all__ = [
    "Disturbances",
    "base_rotation",
    "real_elevation_deg",
    "normal_enu",
    "camera_axes",
    "sun_in_camera",
    "encoder_error_deg",
    "backlash_offset_deg",
    "gust_torque_nm",
    "GUST_WINDOW_S",
]

#: Length of one gust window of :func:`gust_torque_nm` [s].
GUST_WINDOW_S = 10.0


@dataclass(frozen=True)
class Disturbances:
    """Installation and machine errors of a tracker (all default 0: a perfect machine).

    Parameters
    ----------
    pedestal_yaw_deg : float
        Azimuth misalignment of the pedestal [°], positive clockwise seen from
        above (a positive yaw turns every pose towards larger azimuths).
    pedestal_tilt_deg : float
        Tilt of the pedestal's vertical axis from the zenith [°], ≥ 0.
    pedestal_tilt_azimuth_deg : float
        Azimuth the pedestal leans towards, clockwise from north [°].
    elevation_zero_deg : float
        The elevation encoder's zero error [°]: the real elevation joint angle is the
        encoder's (drift-free) reading plus this (issue 25's ``elevation_zero_deg``).
    encoder_drift_mrad_per_h : float
        Growth rate of the joint-reading error, both axes [mrad h⁻¹].
    clock_offset_s : float
        Controller clock minus true time [s].
    backlash_deg : float
        Gear backlash per axis (full width of the dead zone) [°], ≥ 0.
    gust_torque_nm : float
        Amplitude of the wind-gust torque on each axis [N m], ≥ 0.
    camera_offset_right_deg, camera_offset_up_deg : float
        Camera boresight relative to the panel normal, right/up [°].
    seed : int
        Seed of the gust sequence (deterministic runs).
    """

    pedestal_yaw_deg: float = 0.0
    pedestal_tilt_deg: float = 0.0
    pedestal_tilt_azimuth_deg: float = 0.0
    elevation_zero_deg: float = 0.0
    encoder_drift_mrad_per_h: float = 0.0
    clock_offset_s: float = 0.0
    backlash_deg: float = 0.0
    gust_torque_nm: float = 0.0
    camera_offset_right_deg: float = 0.0
    camera_offset_up_deg: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name != "seed" and not np.isfinite(v):
                raise ValueError(f"Disturbances.{f.name} must be finite, got {v}")
        for name in ("pedestal_tilt_deg", "backlash_deg", "gust_torque_nm"):
            if getattr(self, name) < 0:
                raise ValueError(f"Disturbances.{name} must be >= 0, got {getattr(self, name)}")
        if self.pedestal_tilt_deg > 45.0:
            raise ValueError(f"pedestal_tilt_deg must be <= 45, got {self.pedestal_tilt_deg}")
        for name in ("elevation_zero_deg", "camera_offset_right_deg", "camera_offset_up_deg"):
            if abs(getattr(self, name)) > 30.0:
                raise ValueError(f"|{name}| must be <= 30, got {getattr(self, name)}")

    @property
    def any(self) -> bool:
        """True when at least one disturbance is non-zero."""
        return any(v != 0 for k, v in asdict(self).items() if k != "seed")

    @property
    def moves_base(self) -> bool:
        """True when the base frame is rotated (pedestal yaw or tilt)."""
        return self.pedestal_yaw_deg != 0 or self.pedestal_tilt_deg != 0

    def to_dict(self) -> dict[str, float]:
        """JSON-ready, units in the names."""
        return {k: float(v) for k, v in asdict(self).items() if k != "seed"}


def _rot_z(angle_rad: float) -> NDArray[np.float64]:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@lru_cache(maxsize=32)
def base_rotation(d: Disturbances) -> NDArray[np.float64]:
    """Rotation from the tracker's base frame to ENU, ``v_enu = R v_base``.

    First the pedestal yaw: a rotation by ``−yaw`` about up (ENU angles are
    counter-clockwise, azimuths clockwise), so a base-frame azimuth ``A``
    points at ENU azimuth ``A + yaw``. Then the tilt: the up axis leans by
    ``tilt`` towards azimuth ``tilt_azimuth`` (Rodrigues rotation about the
    horizontal axis perpendicular to that azimuth). Rigid-body geometry, no
    seed equation; identity when both are 0.

    Returns
    -------
    ndarray, shape (3, 3)
        Read-only (cached per ``d``).
    """
    r = _rot_z(-np.radians(d.pedestal_yaw_deg))
    tilt = np.radians(d.pedestal_tilt_deg)
    if tilt != 0.0:
        a = np.radians(d.pedestal_tilt_azimuth_deg)
        lean = np.array([np.sin(a), np.cos(a), 0.0])  # where the top of the axis goes
        k = np.cross(np.array([0.0, 0.0, 1.0]), lean)  # up × lean: rotating up towards lean
        kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
        r_tilt = np.eye(3) + np.sin(tilt) * kx + (1.0 - np.cos(tilt)) * (kx @ kx)
        r = r_tilt @ r
    r.setflags(write=False)
    return r


def real_elevation_deg(elevation_joint_deg: ArrayLike, d: Disturbances) -> Any:
    """The real elevation joint angle [°] of an output-side angle on the encoder's datum:
    ``elevation + elevation_zero_deg`` (a float for a float)."""
    if d.elevation_zero_deg == 0.0:
        return elevation_joint_deg
    if isinstance(elevation_joint_deg, (int, float)):
        return float(elevation_joint_deg) + d.elevation_zero_deg
    return np.asarray(elevation_joint_deg, dtype=float) + d.elevation_zero_deg


def normal_enu(
    azimuth_joint_deg: ArrayLike, elevation_joint_deg: ArrayLike, d: Disturbances
) -> NDArray[np.float64]:
    """Panel unit normal in ENU for (true, output-side) joint angles on a disturbed base.

    ``R · n`` with ``n`` the normal of seed 000 eq. 23 in the base frame
    (:func:`sim.kinematics.panel_axes`) at the real elevation
    (:func:`real_elevation_deg`) and ``R`` :func:`base_rotation`.

    Returns
    -------
    ndarray, shape ``S + (3,)``
    """
    _, _, n = panel_axes(azimuth_joint_deg, real_elevation_deg(elevation_joint_deg, d))
    if not d.moves_base:
        return n
    return n @ base_rotation(d).T


def camera_axes(
    azimuth_joint_deg: float, elevation_joint_deg: float, d: Disturbances
) -> NDArray[np.float64]:
    """The tracker camera's (right, up, forward) unit axes in ENU, rows of a 3 × 3 matrix.

    Forward is the panel normal turned by the camera offset (right, then up,
    in the panel frame); right is horizontal in the base frame when the
    offsets are 0 (towards larger azimuth), up completes the frame. A sun
    direction ``s`` (ENU) is seen at camera coordinates ``M @ s`` — the
    (right, up, forward) convention of :class:`vision.cameras.PinholeCamera`.
    Scalar arithmetic: called once per camera frame.
    """
    x, y, normal = _panel_axes_scalar(azimuth_joint_deg,
                                      real_elevation_deg(elevation_joint_deg, d))
    n: tuple[float, ...] = normal
    r: tuple[float, ...] = (-x[0], -x[1], -x[2])  # the camera's right, looking along n
    u: tuple[float, ...] = y
    o_r, o_u = math.radians(d.camera_offset_right_deg), math.radians(d.camera_offset_up_deg)
    if o_r != 0.0 or o_u != 0.0:
        # turn right about u, then up about the new right axis
        cr, sr, cu, su = math.cos(o_r), math.sin(o_r), math.cos(o_u), math.sin(o_u)
        f1 = tuple(cr * n[k] + sr * r[k] for k in range(3))
        r = tuple(cr * r[k] - sr * n[k] for k in range(3))
        n = tuple(cu * f1[k] + su * u[k] for k in range(3))
        u = tuple(cu * u[k] - su * f1[k] for k in range(3))
    m = np.array([r, u, n])
    if d.moves_base:
        m = m @ base_rotation(d).T
    return m


def sun_in_camera(
    azimuth_joint_deg: float, elevation_joint_deg: float, d: Disturbances,
    sun_enu: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The sun's direction in camera coordinates (right, up, forward): ``camera_axes(...) @ s``.

    The same frames as :func:`camera_axes` in scalar arithmetic (called once per frame):
    the sun into the base frame (``Rᵀ s``), then onto the panel's and the camera's axes.
    """
    e, n_, u_ = (float(x) for x in sun_enu)
    if d.moves_base:
        r = _base_rotation_rows(d)  # s_base = Rᵀ s: the columns of R dotted with s
        e, n_, u_ = (r[0][k] * e + r[1][k] * n_ + r[2][k] * u_ for k in range(3))
    px, py, pn = _panel_axes_scalar(azimuth_joint_deg, elevation_joint_deg + d.elevation_zero_deg)
    x = -(px[0] * e + px[1] * n_)  # on the camera's right axis, −x (x is horizontal)
    y = py[0] * e + py[1] * n_ + py[2] * u_  # on the up axis
    z = pn[0] * e + pn[1] * n_ + pn[2] * u_  # on the normal
    if d.camera_offset_right_deg or d.camera_offset_up_deg:
        o_r, o_u = math.radians(d.camera_offset_right_deg), math.radians(d.camera_offset_up_deg)
        cr, sr, cu, su = math.cos(o_r), math.sin(o_r), math.cos(o_u), math.sin(o_u)
        f1, x = cr * z + sr * x, cr * x - sr * z
        z, y = cu * f1 + su * y, cu * y - su * f1
    return np.array([x, y, z])


def _panel_axes_scalar(azimuth_joint_deg: float, elevation_joint_deg: float
                       ) -> tuple[tuple[float, float, float], ...]:
    """:func:`sim.kinematics.panel_axes_from_trig` (x, y, n) in scalar arithmetic (per frame)."""
    az, el = math.radians(azimuth_joint_deg), math.radians(elevation_joint_deg)
    return panel_axes_from_trig(math.sin(az), math.cos(az), math.sin(el), math.cos(el))


@lru_cache(maxsize=32)
def _base_rotation_rows(d: Disturbances) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(float(v) for v in row) for row in base_rotation(d))


def encoder_error_deg(t_s: ArrayLike, d: Disturbances) -> NDArray[np.float64]:
    """Joint-reading error after ``t_s`` seconds of run [°]: ``drift · t`` (both axes).

    Parameters
    ----------
    t_s : array_like
        Time since the start of the run [s].
    """
    return np.degrees(1e-3 * d.encoder_drift_mrad_per_h * np.asarray(t_s, dtype=float) / 3600.0)


def backlash_offset_deg(side: ArrayLike, d: Disturbances) -> NDArray[np.float64]:
    """Output minus motor-side angle for the flank ``side`` (+1/−1) the load presses [°].

    A motor that last moved in the + direction drives the output on its +
    flank: the output trails by half the dead zone, ``−side · backlash / 2``.
    ``side`` is the direction of the last move, or the sign of the static load
    (gravity on elevation, a gust) when that presses the gear harder.
    """
    return -np.asarray(side, dtype=float) * 0.5 * d.backlash_deg


def gust_torque_nm(t_s: ArrayLike, d: Disturbances) -> NDArray[np.float64]:
    """Wind-gust torque on the axes at times ``t_s`` [N m], shape ``S + (2,)``.

    A seeded random telegraph: in each :data:`GUST_WINDOW_S` window each axis
    sees ``+A``, ``0`` or ``−A`` (probabilities ¼, ½, ¼), ``A`` =
    ``gust_torque_nm``; the windows are drawn from ``seed`` and the window
    index, so any time gives the same value in every call. An assumption (no
    seed gives a wind model); zero when ``gust_torque_nm`` is 0.
    """
    t = np.asarray(t_s, dtype=float)
    if d.gust_torque_nm == 0:
        return np.zeros(t.shape + (2,))
    k = np.floor(t / GUST_WINDOW_S).astype(np.int64)
    # a counter-based hash (SplitMix64 finaliser) of (seed, window, axis): reproducible anywhere
    out = np.empty(t.shape + (2,))
    for axis in (0, 1):
        z = (k * 2 + axis + (int(d.seed) << 32)).astype(np.uint64) + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z = z ^ (z >> np.uint64(31))
        u = (z >> np.uint64(11)).astype(float) / float(1 << 53)
        out[..., axis] = np.where(u < 0.25, 1.0, np.where(u < 0.75, 0.0, -1.0))
    return d.gust_torque_nm * out
