"""Kinematics of the dual-axis tracker as a 2-DOF serial manipulator.

The tracker is modelled with the Denavit–Hartenberg (D–H) convention of seed 000
(Acosta-Banda et al. 2025, eqs. 10–15, Table 2 and eq. 23): joint 1 is the
azimuth axis (vertical), joint 2 the elevation axis (horizontal), with link
parameters

======  ==========  ======  =====  ======
joint   θ           d       a      α
======  ==========  ======  =====  ======
1       θ1          d1      0      π/2
2       θ2          0       a2     0
======  ==========  ======  =====  ======

Seed 000's Table 2 sets ``a2 = 0``; the dimensions here are seed 002's
(Fernández-Pizarro et al. 2019, section II-A: d1 = 355 mm, a2 = 91 mm), whose
product ``A1 A2`` is its eq. 2.

Frames
------
The base frame {0} is East-North-Up (x0 = east, y0 = north, z0 = up) at the
foot of the azimuth axis. Frame {2}'s x axis, ``x2 = (c1 c2, s1 c2, s2)``, is the
panel normal: θ1 is its direction in the horizontal plane counter-clockwise from
east and θ2 its elevation above the horizon. The public joint angles (see
``docs/architecture.md``) are the azimuth of the normal clockwise from north and
its elevation; :func:`dh_from_joint_angles` / :func:`joint_angles_from_dh` are
the one place where the two conventions meet.

Joint limits
------------
Neither seed gives numeric joint limits (seed 000, Fig. 6b only draws the
elevation range; seed 002 simulates a 128.5° azimuth return at 9.9° elevation).
The defaults of :class:`TrackerGeometry` are assumptions, stated here:

- azimuth joint −90° … 450° (540° of travel with a cable wrap): every direction
  is reachable and the northern half of the sky has two equivalents, so a
  tracker in the tropics can follow the sun through north (summer noon) and
  south (winter noon) without a full turn when the previous angle is passed as
  ``reference_azimuth``;
- elevation joint 0° … 90° (panel vertical … panel horizontal), which includes
  seed 002's 9.9° end-of-day pose.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vision.sphere import sky_from_enu

_T = TypeVar("_T", float, NDArray[np.float64])

__all__ = [
    "TrackerGeometry",
    "dh_from_joint_angles",
    "joint_angles_from_dh",
    "dh_transform",
    "inverse_kinematics",
    "forward_kinematics",
    "panel_axes",
    "panel_axes_from_trig",
    "normal_to_tilt_azimuth",
    "joint_transforms",
    "PANEL_IN_FRAME2",
]


@dataclass(frozen=True)
class TrackerGeometry:
    """Dimensions and joint limits of a dual-axis tracker.

    Parameters
    ----------
    d1_m : float
        D–H offset of joint 1 along the azimuth axis [m] (seed 002, section II-A:
        355 mm; seed 000, Table 2 calls it ``l1``).
    a2_m : float
        D–H length of link 2 along the panel normal, from the elevation axis to
        the panel plane [m] (seed 002, section II-A: 91 mm).
    azimuth_min_deg, azimuth_max_deg : float
        Azimuth joint range, degrees clockwise from north [°]. May span more
        than 360° (cable wrap). Defaults are assumptions (module docstring).
    elevation_min_deg, elevation_max_deg : float
        Elevation joint range, elevation of the panel normal [°], within
        [0, 90]. Defaults are assumptions (module docstring).
    """

    d1_m: float = 0.355
    a2_m: float = 0.091
    azimuth_min_deg: float = -90.0
    azimuth_max_deg: float = 450.0
    elevation_min_deg: float = 0.0
    elevation_max_deg: float = 90.0

    def __post_init__(self) -> None:
        if not self.azimuth_min_deg < self.azimuth_max_deg:
            raise ValueError(
                f"azimuth_min_deg ({self.azimuth_min_deg}) must be below "
                f"azimuth_max_deg ({self.azimuth_max_deg})"
            )
        if not 0.0 <= self.elevation_min_deg < self.elevation_max_deg <= 90.0:
            raise ValueError(
                "elevation limits must satisfy 0 <= elevation_min_deg < "
                f"elevation_max_deg <= 90, got ({self.elevation_min_deg}, "
                f"{self.elevation_max_deg})"
            )
        if self.d1_m < 0 or self.a2_m < 0:
            raise ValueError(f"d1_m and a2_m must be >= 0, got {self.d1_m}, {self.a2_m}")


def dh_from_joint_angles(
    azimuth_joint_deg: ArrayLike, elevation_joint_deg: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Public joint angles → D–H joint variables (θ1, θ2) of seed 000, Table 2.

    With the base frame East-North-Up, θ1 is the direction of the panel normal
    counter-clockwise from east and θ2 its elevation:
    ``θ1 = 90° − azimuth_joint_deg``, ``θ2 = elevation_joint_deg``.

    Parameters
    ----------
    azimuth_joint_deg : array_like
        Azimuth of the panel normal, clockwise from north [°].
    elevation_joint_deg : array_like
        Elevation of the panel normal above the horizon [°].

    Returns
    -------
    theta1_rad, theta2_rad : ndarray
        D–H joint variables [rad].
    """
    az = np.asarray(azimuth_joint_deg, dtype=float)
    el = np.asarray(elevation_joint_deg, dtype=float)
    return np.radians(90.0 - az), np.radians(el)


def joint_angles_from_dh(
    theta1_rad: ArrayLike, theta2_rad: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """D–H joint variables (θ1, θ2) → public joint angles; inverse of
    :func:`dh_from_joint_angles` (no wrapping applied).

    Returns
    -------
    azimuth_joint_deg, elevation_joint_deg : ndarray
        [°], azimuth clockwise from north.
    """
    t1 = np.asarray(theta1_rad, dtype=float)
    t2 = np.asarray(theta2_rad, dtype=float)
    return 90.0 - np.degrees(t1), np.degrees(t2)


def dh_transform(theta_rad: ArrayLike, d_m: float, a_m: float, alpha_rad: float) -> NDArray:
    """Homogeneous D–H link transform ``A_i`` (seed 000, eqs. 10–15).

    ``A_i = Rot(z, θ_i) · Trans(z, d_i) · Trans(x, a_i) · Rot(x, α_i)``.

    Parameters
    ----------
    theta_rad : array_like
        Joint angle θ_i [rad]; any shape ``S``.
    d_m, a_m : float
        Link offset and length [m].
    alpha_rad : float
        Link twist [rad].

    Returns
    -------
    ndarray, shape ``S + (4, 4)``
    """
    th = np.asarray(theta_rad, dtype=float)
    ct, st = np.cos(th), np.sin(th)
    ca, sa = np.cos(alpha_rad), np.sin(alpha_rad)
    out = np.zeros(th.shape + (4, 4))
    # seed 000, eq. 15
    out[..., 0, 0] = ct
    out[..., 0, 1] = -st * ca
    out[..., 0, 2] = st * sa
    out[..., 0, 3] = a_m * ct
    out[..., 1, 0] = st
    out[..., 1, 1] = ct * ca
    out[..., 1, 2] = -ct * sa
    out[..., 1, 3] = a_m * st
    out[..., 2, 1] = sa
    out[..., 2, 2] = ca
    out[..., 2, 3] = d_m
    out[..., 3, 3] = 1.0
    return out


def _wrap_azimuth_into_range(
    azimuth_deg: NDArray, lo: float, hi: float, reference_deg: NDArray
) -> NDArray:
    """Equivalent of ``azimuth_deg`` (mod 360°) inside ``[lo, hi]``, nearest to
    ``reference_deg``; when no equivalent is inside, the nearer limit (by
    angular distance)."""
    a = np.mod(azimuth_deg, 360.0)
    k_min = np.ceil((lo - a) / 360.0)
    k_max = np.floor((hi - a) / 360.0)
    k_ref = np.round((reference_deg - a) / 360.0)
    k = np.clip(k_ref, k_min, np.maximum(k_max, k_min))
    inside = a + 360.0 * k
    dist_lo = np.abs((a - lo + 180.0) % 360.0 - 180.0)
    dist_hi = np.abs((a - hi + 180.0) % 360.0 - 180.0)
    nearest_limit = np.where(dist_lo <= dist_hi, lo, hi)
    wrapped = np.where(k_min <= k_max, inside, nearest_limit)
    return np.where(np.isnan(a), np.nan, wrapped)


def inverse_kinematics(
    solar_azimuth: ArrayLike,
    solar_elevation: ArrayLike,
    geometry: TrackerGeometry,
    reference_azimuth: ArrayLike | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Joint angles that point the panel normal at the sun (ideal tracking).

    The inverse of seed 000, eq. 23 (seed 002, eq. 2) for the orientation of
    x2: the normal ``(c1 c2, s1 c2, s2)`` equals the sun vector when θ1 is the
    sun's direction counter-clockwise from east and θ2 its elevation, mapped to
    the public angles by :func:`joint_angles_from_dh`. The azimuth is moved to
    its equivalent (± k·360°) inside the joint range, the one nearest
    ``reference_azimuth`` (default: the range's centre; pass the previous joint
    angle for continuous motion through the ±180° or 0/360° crossings); a
    direction outside a range narrower than 360° goes to the nearer limit. The
    elevation is clipped to the elevation limits, so a sun below the horizon
    gives ``elevation_min_deg``. NaN inputs give NaN outputs.

    Parameters
    ----------
    solar_azimuth : array_like
        Sun azimuth, clockwise from north [°]; any real value (e.g. −170° or
        190° are the same direction).
    solar_elevation : array_like
        Sun elevation (apparent or true, the caller's choice) [°].
    geometry : TrackerGeometry
    reference_azimuth : array_like, optional
        Azimuth joint angle to stay near [°].

    Returns
    -------
    azimuth_joint_deg, elevation_joint_deg : ndarray
        Broadcast shape of the inputs [°].
    """
    az, el = np.broadcast_arrays(
        np.asarray(solar_azimuth, dtype=float), np.asarray(solar_elevation, dtype=float)
    )
    lo, hi = geometry.azimuth_min_deg, geometry.azimuth_max_deg
    ref = (
        np.full(az.shape, 0.5 * (lo + hi))
        if reference_azimuth is None
        else np.broadcast_to(np.asarray(reference_azimuth, dtype=float), az.shape)
    )
    az_joint = _wrap_azimuth_into_range(az, lo, hi, ref)
    el_joint = np.clip(el, geometry.elevation_min_deg, geometry.elevation_max_deg)
    return az_joint, el_joint


_MORNING_MARGIN_S = 3 * 3600


def morning_azimuth(
    times: ArrayLike, latitude: float, longitude: float
) -> NDArray[np.float64]:
    """Sun azimuth at the coming sunrise of each of ``times`` [°] (clockwise from N).

    Sunrise by NREL SPA (Reda & Andreas 2004, appendix A.2, through
    ``pvlib.solarposition.sun_rise_set_transit_spa``: the topocentric sun's
    upper limb at the horizon with standard refraction), its azimuth by
    :func:`sim.sun.solar_position` (SPA). Solar days are the calendar days of
    the zone whose offset is the longitude's nearest hour. "Coming" is the
    first sunrise later than three hours before the time, so that the
    minutes between SPA's sunrise and an apparent elevation of 0° still hold
    that morning's azimuth. NaN where no sunrise follows within two days
    (polar day or night).

    Parameters
    ----------
    times : array_like of timezone-aware datetimes
    latitude, longitude : float
        [°].
    """
    import datetime as dt

    import pandas as pd
    from pvlib import solarposition

    from sim import sun

    t = pd.DatetimeIndex(times)
    if t.tz is None:
        raise ValueError("times must be timezone-aware")
    if not len(t):
        return np.zeros(0)
    zone = dt.timezone(dt.timedelta(hours=round(longitude / 15.0)))
    local = t.tz_convert(zone)
    days = pd.date_range(local.min().normalize() - pd.Timedelta(days=1),
                         local.max().normalize() + pd.Timedelta(days=2), freq="D")
    rises = pd.DatetimeIndex(solarposition.sun_rise_set_transit_spa(
        days + pd.Timedelta(hours=12), latitude, longitude)["sunrise"]).dropna()
    out = np.full(len(t), np.nan)
    if not len(rises):
        return out
    rises = rises.tz_convert("UTC").sort_values()
    rise_s = rises.as_unit("s").asi8
    t_s = t.tz_convert("UTC").as_unit("s").asi8
    # the coming morning's sunrise: the first later than 3 h before t, so that the minutes
    # between SPA's sunrise (upper limb on the horizon, −0.83°) and the apparent elevation
    # reaching 0° still hold that morning's azimuth (days are longer than 3 h below ~65°)
    k = np.searchsorted(rise_s, t_s - _MORNING_MARGIN_S, side="left")
    ok = k < len(rise_s)
    ok[ok] = rise_s[k[ok]] - t_s[ok] <= 2 * 86400
    rise_az = sun.solar_position(rises, latitude, longitude)["azimuth"].to_numpy(float)
    out[ok] = rise_az[k[ok]]
    return out


def tracking_angles(
    solar_azimuth: ArrayLike,
    solar_elevation: ArrayLike,
    geometry: TrackerGeometry,
    reference_azimuth: ArrayLike | None = None,
    night_azimuth: ArrayLike | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Joint angles of ideal tracking with the night stow.

    While the sun is above the horizon this is :func:`inverse_kinematics`;
    with the sun at or below it the tracker is stowed flat (elevation joint at
    ``elevation_max_deg``, the panel facing the zenith as far as the joint
    allows) and its azimuth joint stays put all night at the *morning's*
    azimuth, ``night_azimuth`` (the sun's azimuth at the next sunrise,
    :func:`morning_azimuth`), wrapped into the joint range near
    ``reference_azimuth``: the one return move happens at dusk, when no energy
    is at stake, and at dawn the tracker already faces the rising sun — no
    swing through the night and no move at the start of the day. Where
    ``night_azimuth`` is not given (or NaN) the stowed azimuth is due east
    (90°), the morning side at any latitude. The twin (:mod:`sim.twin`) and
    the 3D scene both use this, so the pose they report at night is the same.

    Parameters
    ----------
    solar_azimuth, solar_elevation : array_like
        Sun azimuth clockwise from north and elevation [°].
    geometry : TrackerGeometry
    reference_azimuth : array_like, optional
        Azimuth joint angle to stay near [°] (see :func:`inverse_kinematics`).
    night_azimuth : array_like, optional
        Azimuth to hold while stowed [°], e.g. :func:`morning_azimuth` of the times.

    Returns
    -------
    azimuth_joint_deg, elevation_joint_deg : ndarray
        [°]; NaN where the inputs are NaN.
    """
    az_joint, el_joint = inverse_kinematics(
        solar_azimuth, solar_elevation, geometry, reference_azimuth=reference_azimuth
    )
    elevation = np.broadcast_to(np.asarray(solar_elevation, dtype=float), el_joint.shape)
    sun_down = elevation <= 0.0
    hold = np.broadcast_to(
        np.asarray(90.0 if night_azimuth is None else night_azimuth, dtype=float), az_joint.shape
    )
    hold = np.where(np.isnan(hold), 90.0, hold)
    ref = (
        np.full(az_joint.shape, 0.5 * (geometry.azimuth_min_deg + geometry.azimuth_max_deg))
        if reference_azimuth is None
        else np.broadcast_to(np.asarray(reference_azimuth, dtype=float), az_joint.shape)
    )
    stow_az = _wrap_azimuth_into_range(hold, geometry.azimuth_min_deg,
                                       geometry.azimuth_max_deg, ref)
    az_joint = np.where(sun_down & ~np.isnan(elevation), stow_az, az_joint)
    el_joint = np.where(sun_down, geometry.elevation_max_deg, el_joint)
    return az_joint, el_joint


def forward_kinematics(
    azimuth_joint_deg: ArrayLike, elevation_joint_deg: ArrayLike, geometry: TrackerGeometry
) -> NDArray[np.float64]:
    """Panel unit normal in East-North-Up for given joint angles.

    The first column of the rotation of ``T = A1 A2`` (seed 000, eq. 23 with
    seed 002's parameters, seed 002 eq. 2): ``x2 = (c1 c2, s1 c2, s2)``.
    Joint angles are used as given (no limit check); use
    :func:`inverse_kinematics` to apply the limits.

    Parameters
    ----------
    azimuth_joint_deg, elevation_joint_deg : array_like
        Public joint angles [°].
    geometry : TrackerGeometry
        Unused by the orientation (lengths do not rotate), kept for a uniform
        signature with :func:`joint_transforms`.

    Returns
    -------
    ndarray, shape ``S + (3,)``
        Unit normal (east, north, up) [-].
    """
    t1, t2 = dh_from_joint_angles(azimuth_joint_deg, elevation_joint_deg)
    t1, t2 = np.broadcast_arrays(t1, t2)
    c1, s1, c2, s2 = np.cos(t1), np.sin(t1), np.cos(t2), np.sin(t2)
    return np.stack([c1 * c2, s1 * c2, s2], axis=-1)


def panel_axes_from_trig(
    sin_az: _T, cos_az: _T, sin_el: _T, cos_el: _T
) -> tuple[tuple[_T, _T, float], tuple[_T, _T, _T], tuple[_T, _T, _T]]:
    """The panel frame's axes from the sines and cosines of the public joint angles.

    The one rule for the panel's axes (every caller goes through it, directly or via
    :func:`panel_axes`): the columns of the rotation of :func:`joint_transforms`'s
    base → panel transform (``A1 A2 PANEL_IN_FRAME2``, seed 000 eq. 23 with seed
    002's D–H table), in closed form, with A the azimuth of the normal clockwise from
    north and E its elevation:

    * x = (−cos A, sin A, 0): horizontal, along the elevation axis and the
      collector's width; to the right of someone facing the panel's front (a
      camera looking along the normal has its right at −x);
    * y = (−sin A sin E, −cos A sin E, cos E) = ∂n/∂E: in the panel's plane, up
      its slope (the collector's height);
    * n = (sin A cos E, cos A cos E, sin E): the normal, x × y = n.

    Plain arithmetic on what it is given — floats or broadcastable arrays alike —
    so scalar hot paths (one camera frame) can call it with :mod:`math`'s
    results. Returns three (east, north, up) component triples; x's up component
    is the float 0.
    """
    x = (-cos_az, sin_az, 0.0)
    y = (-sin_az * sin_el, -cos_az * sin_el, cos_el)
    n = (sin_az * cos_el, cos_az * cos_el, sin_el)
    return x, y, n


def panel_axes(
    azimuth_joint_deg: ArrayLike, elevation_joint_deg: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Panel axes x (width, horizontal), y (up the slope) and n (normal) for joint angles.

    :func:`panel_axes_from_trig` on arrays. The vectors are in the tracker's base
    frame (ENU for a level pedestal); a plant's collectors (seed 004's u, v, n,
    :func:`sim.plant.shading.collector_axes`) and the tracker camera
    (:mod:`sim.disturbances`) use the same frame.

    Parameters
    ----------
    azimuth_joint_deg, elevation_joint_deg : array_like
        Public joint angles [°] (azimuth of the normal clockwise from north,
        elevation above the horizon); broadcast together.

    Returns
    -------
    x, y, n : ndarray, shape ``S + (3,)``
        Unit vectors (east, north, up) [-].
    """
    az = np.radians(np.asarray(azimuth_joint_deg, dtype=float))
    el = np.radians(np.asarray(elevation_joint_deg, dtype=float))
    az, el = np.broadcast_arrays(az, el)
    axes = panel_axes_from_trig(np.sin(az), np.cos(az), np.sin(el), np.cos(el))
    out = np.empty((3,) + az.shape + (3,))
    for k, triple in enumerate(axes):
        for c in range(3):
            out[k, ..., c] = triple[c]
    return out[0], out[1], out[2]


def normal_to_tilt_azimuth(
    normal_enu: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Panel normal (ENU) → pvlib's ``(surface_tilt, surface_azimuth)``.

    pvlib convention (pvlib.irradiance): ``surface_tilt`` from horizontal,
    0 = facing up, 90 = vertical; ``surface_azimuth`` of the direction the
    surface faces, clockwise from north in [0, 360). A horizontal panel
    (normal straight up) gets ``surface_azimuth = 180`` (pvlib's default).

    Parameters
    ----------
    normal_enu : array_like, shape ``S + (3,)``
        Panel normal, need not be unit length.

    Returns
    -------
    surface_tilt, surface_azimuth : ndarray, shape ``S``
        [°].
    """
    n = np.asarray(normal_enu, dtype=float)
    azimuth, elevation = sky_from_enu(n)  # the normal's sky direction; tilt = its zenith angle
    surface_tilt = 90.0 - elevation
    horizontal = np.hypot(n[..., 0], n[..., 1]) < 1e-12 * np.linalg.norm(n, axis=-1)
    surface_azimuth = np.where(horizontal, 180.0, azimuth)
    return surface_tilt, surface_azimuth


#: Fixed rotation from D–H frame {2} to the panel frame: panel z = x2 (the
#: normal), panel x = −z2 (along the elevation axis), panel y = y2 (up the
#: slope of the panel). A rotation of +90° about y2; the origin stays at o2.
PANEL_IN_FRAME2: NDArray[np.float64] = np.array(
    [
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ]
)


def joint_transforms(
    azimuth_joint_deg: ArrayLike, elevation_joint_deg: ArrayLike, geometry: TrackerGeometry
) -> list[NDArray[np.float64]]:
    """Homogeneous transforms from the base frame (ENU, metres) to each frame.

    Returns ``[T01, T02, T0p]``: base → frame {1} (after the azimuth joint,
    ``A1``), base → frame {2} (after the elevation joint, ``A1 A2`` = seed 000
    eq. 23 with seed 002's d1, a2, i.e. seed 002 eq. 2) and base → panel frame
    (``A1 A2 PANEL_IN_FRAME2``: origin at the panel centre, z along the normal,
    x along the elevation axis). Each is ``S + (4, 4)`` for inputs of shape
    ``S``.

    Parameters
    ----------
    azimuth_joint_deg, elevation_joint_deg : array_like
        Public joint angles [°].
    geometry : TrackerGeometry
        Provides d1_m and a2_m.
    """
    t1, t2 = dh_from_joint_angles(azimuth_joint_deg, elevation_joint_deg)
    t1, t2 = np.broadcast_arrays(t1, t2)
    a1 = dh_transform(t1, geometry.d1_m, 0.0, np.pi / 2.0)  # Table 2, joint 1
    a2 = dh_transform(t2, 0.0, geometry.a2_m, 0.0)  # Table 2, joint 2
    t02 = a1 @ a2
    return [a1, t02, t02 @ PANEL_IN_FRAME2]
