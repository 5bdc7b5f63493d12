"""Camera models: pixel ↔ direction for the tracker's pinhole camera and a fisheye sky camera.

Pixel coordinates are ``(x, y)`` = (column, row) with the origin at the top-left
pixel's centre, so the centre of a ``W × H`` image is ``((W − 1)/2, (H − 1)/2)``.
Angles are in degrees at every boundary; azimuth is clockwise from true north.

* :class:`PinholeCamera` — the tracker camera of seed 000 (640 × 480, 67°
  horizontal field of view, optical axis along the panel normal) and the
  webcam of seed 001 (64°), which compares the sun's centroid with a fixed
  reference pixel (seed 001, Fig. 4 and Eq. 9).
* :class:`FisheyeCamera` — a levelled all-sky camera as in seed 003
  (eqs. 9–11: ``x = τ z sin(A − Δ) + h``, ``y = τ z cos(A − Δ) + k``) with the
  equidistant projection by default and the equisolid, stereographic and
  orthographic projections of the standard fisheye lens models.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vision.sphere import enu_from_sky, sky_from_enu

Projection = Literal["equidistant", "equisolid", "stereographic", "orthographic"]
PROJECTIONS: tuple[str, ...] = ("equidistant", "equisolid", "stereographic", "orthographic")
EAST_SIDES: tuple[str, ...] = ("left", "right")

FloatArray = NDArray[np.float64]


def _as_float(a: ArrayLike) -> FloatArray:
    return np.asarray(a, dtype=float)


# --------------------------------------------------------------------------- pinhole


@dataclass(frozen=True)
class PinholeCamera:
    """Ideal pinhole camera looking along the panel normal.

    Parameters
    ----------
    width_px, height_px : image size [px].
    fov_deg : horizontal field of view [°]; the focal length is
        ``f = (W / 2) / tan(fov / 2)`` [px].
    cx_px, cy_px : optical centre [px]; default the image centre.
    reference_x_px, reference_y_px : the fixed reference pixel the centroid is
        compared with (seed 001); default the optical centre.
    """

    width_px: int = 640
    height_px: int = 480
    fov_deg: float = 67.0
    cx_px: float | None = None
    cy_px: float | None = None
    reference_x_px: float | None = None
    reference_y_px: float | None = None

    def __post_init__(self) -> None:
        if not (0.0 < self.fov_deg < 180.0):
            raise ValueError(f"fov_deg must be in (0, 180), got {self.fov_deg}")
        if self.width_px <= 0 or self.height_px <= 0:
            raise ValueError("width_px and height_px must be positive")

    @property
    def focal_px(self) -> float:
        """Focal length [px] from the horizontal field of view."""
        return 0.5 * self.width_px / float(np.tan(np.radians(self.fov_deg) / 2.0))

    @property
    def centre_px(self) -> tuple[float, float]:
        cx = (self.width_px - 1) / 2.0 if self.cx_px is None else float(self.cx_px)
        cy = (self.height_px - 1) / 2.0 if self.cy_px is None else float(self.cy_px)
        return cx, cy

    @property
    def reference_px(self) -> tuple[float, float]:
        cx, cy = self.centre_px
        rx = cx if self.reference_x_px is None else float(self.reference_x_px)
        ry = cy if self.reference_y_px is None else float(self.reference_y_px)
        return rx, ry

    def pixel_to_direction(self, x_px: ArrayLike, y_px: ArrayLike) -> FloatArray:
        """Unit vectors ``[..., 3]`` in the camera frame (right, up, forward = optical axis)."""
        cx, cy = self.centre_px
        f = self.focal_px
        x = (_as_float(x_px) - cx) / f
        y = -(_as_float(y_px) - cy) / f
        v = np.stack([x, y, np.ones_like(x)], axis=-1)
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    def direction_to_pixel(self, direction: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Pixel ``(x, y)`` of camera-frame directions ``[..., 3]``; NaN behind the camera."""
        d = _as_float(direction)
        cx, cy = self.centre_px
        f = self.focal_px
        z = np.where(d[..., 2] > 1e-12, d[..., 2], np.nan)
        return cx + f * d[..., 0] / z, cy - f * d[..., 1] / z

    def pixel_angles_deg(self, x_px: ArrayLike, y_px: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Horizontal and vertical angle [°] of a pixel's direction, right and up positive.

        Horizontal first (as the tracker's azimuth joint), then vertical:
        ``h = atan2(X, Z)``, ``v = atan2(Y, √(X² + Z²))``.
        """
        d = self.pixel_to_direction(x_px, y_px)
        h = np.degrees(np.arctan2(d[..., 0], d[..., 2]))
        v = np.degrees(np.arctan2(d[..., 1], np.hypot(d[..., 0], d[..., 2])))
        return h, v

    def pointing_error(
        self, x_px: ArrayLike, y_px: ArrayLike
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Pointing error of the sun seen at ``(x, y)`` against the reference pixel.

        Returns ``(horizontal_deg, vertical_deg, total_mrad)``: right and up
        positive, the total being the angle between the two directions
        (seed 001 reports drift in mrad).
        """
        rx, ry = self.reference_px
        h, v = self.pixel_angles_deg(x_px, y_px)
        h0, v0 = self.pixel_angles_deg(rx, ry)
        d = self.pixel_to_direction(x_px, y_px)
        d0 = self.pixel_to_direction(rx, ry)
        cosang = np.clip(np.sum(d * d0, axis=-1), -1.0, 1.0)
        return h - h0, v - v0, 1000.0 * np.arccos(cosang)

    def pixel_from_pointing_error(
        self, horizontal_deg: ArrayLike, vertical_deg: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """Inverse of :meth:`pointing_error`: where the sun appears for a given error."""
        rx, ry = self.reference_px
        h0, v0 = self.pixel_angles_deg(rx, ry)
        h = np.radians(_as_float(horizontal_deg) + h0)
        v = np.radians(_as_float(vertical_deg) + v0)
        d = np.stack([np.cos(v) * np.sin(h), np.sin(v), np.cos(v) * np.cos(h)], axis=-1)
        return self.direction_to_pixel(d)


# --------------------------------------------------------------------------- fisheye


def _project_rad(theta_rad: FloatArray, projection: str) -> FloatArray:
    """Normalised radial mapping g(θ) with g'(0) = 1 (r = f·g(θ))."""
    if projection == "equidistant":
        return theta_rad
    if projection == "equisolid":
        return 2.0 * np.sin(theta_rad / 2.0)
    if projection == "stereographic":
        return 2.0 * np.tan(theta_rad / 2.0)
    if projection == "orthographic":
        return np.where(theta_rad <= np.pi / 2, np.sin(theta_rad), np.nan)
    raise ValueError(f"projection must be one of {PROJECTIONS}, got {projection!r}")


def _project_slope(theta_rad: ArrayLike, projection: str) -> FloatArray:
    """The derivative g'(θ) of :func:`_project_rad` (NaN outside the lens's domain)."""
    t = _as_float(theta_rad)
    if projection == "equidistant":
        return np.ones_like(t)
    if projection == "equisolid":
        return np.cos(t / 2.0)
    if projection == "stereographic":
        return 1.0 / np.cos(t / 2.0) ** 2
    if projection == "orthographic":
        return np.where(t <= np.pi / 2, np.cos(t), np.nan)
    raise ValueError(f"projection must be one of {PROJECTIONS}, got {projection!r}")


def _unproject_rad(rho: FloatArray, projection: str) -> FloatArray:
    """Inverse of :func:`_project_rad` (NaN outside the lens's domain)."""
    if projection == "equidistant":
        return rho
    with np.errstate(invalid="ignore"):
        if projection == "equisolid":
            return 2.0 * np.arcsin(np.where(rho <= 2.0, rho / 2.0, np.nan))
        if projection == "stereographic":
            return 2.0 * np.arctan(rho / 2.0)
        if projection == "orthographic":
            return np.arcsin(np.where(rho <= 1.0, rho, np.nan))
    raise ValueError(f"projection must be one of {PROJECTIONS}, got {projection!r}")


def _tilt_rotations(tilt_north_deg: float, tilt_east_deg: float
                    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The two rotations of :func:`_tilt_matrix`, ``rx`` about the east axis and ``ry``
    about the north axis, and their derivatives on their angles [rad⁻¹]."""
    a = np.radians(tilt_north_deg)
    b = np.radians(tilt_east_deg)
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    # axis tipped toward north: camera "up" = (0, sin a, cos a); R maps it to (0, 0, 1)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])
    ry = np.array([[cb, 0.0, -sb], [0.0, 1.0, 0.0], [sb, 0.0, cb]])
    drx = np.array([[0.0, 0.0, 0.0], [0.0, -sa, -ca], [0.0, ca, -sa]])
    dry = np.array([[-sb, 0.0, -cb], [0.0, 0.0, 0.0], [cb, 0.0, -sb]])
    return rx, ry, drx, dry


def _tilt_matrix(tilt_north_deg: float, tilt_east_deg: float) -> FloatArray:
    """Rotation taking ENU vectors into the (tilted) camera frame.

    ``tilt_north_deg`` tips the optical axis toward north (rotation about the
    east axis), ``tilt_east_deg`` toward east (rotation about the north axis).
    """
    rx, ry, _, _ = _tilt_rotations(tilt_north_deg, tilt_east_deg)
    return ry @ rx


def _seq(v: object) -> list[float]:
    return [float(c) for c in v] if isinstance(v, (list, tuple)) else []


@dataclass(frozen=True)
class FisheyeCamera:
    """Levelled fisheye all-sky camera looking up (seed 003, eqs. 9–11).

    Parameters
    ----------
    cx_px, cy_px : optical centre (the zenith's pixel) [px].
    px_per_deg : radial scale at the zenith [px °⁻¹] (seed 003 assumed 3.365);
        ``r = f·g(θ)`` with ``f = px_per_deg·180/π`` and ``g`` the projection:
        equidistant ``θ``, equisolid ``2 sin(θ/2)``, stereographic
        ``2 tan(θ/2)``, orthographic ``sin θ`` (θ the zenith angle).
    north_offset_deg : where north lies in the image, clockwise from image-up
        (seed 003's Δ).
    east : ``"left"`` — the raw view from below the sky (east to the left of
        north, the default) — or ``"right"`` (a mirrored image).
    projection : one of :data:`PROJECTIONS`.
    radial_coeffs : optional polynomial ``(c2, c3, …)`` added to the mapping:
        ``r = f·(g(θ) + c2·θ² + c3·θ³ + …)`` with θ in radians.
    tilt_north_deg, tilt_east_deg : optional small tilt of the optical axis
        away from the zenith toward north / east [°].
    """

    cx_px: float
    cy_px: float
    px_per_deg: float
    north_offset_deg: float = 0.0
    east: str = "left"
    projection: str = "equidistant"
    radial_coeffs: tuple[float, ...] = field(default_factory=tuple)
    tilt_north_deg: float = 0.0
    tilt_east_deg: float = 0.0

    def __post_init__(self) -> None:
        if self.projection not in PROJECTIONS:
            raise ValueError(f"projection must be one of {PROJECTIONS}, got {self.projection!r}")
        if self.east not in EAST_SIDES:
            raise ValueError(f"east must be 'left' or 'right', got {self.east!r}")
        if not (self.px_per_deg > 0 and np.isfinite(self.px_per_deg)):
            raise ValueError(f"px_per_deg must be positive, got {self.px_per_deg}")

    @property
    def focal_px(self) -> float:
        """Radial scale at the zenith [px rad⁻¹]."""
        return float(self.px_per_deg) * 180.0 / np.pi

    @property
    def horizon_radius_px(self) -> float:
        """Radius of the horizon circle (θ = 90°) [px]."""
        return float(self.radius_px(np.radians(90.0)))

    def radius_px(self, theta_rad: ArrayLike) -> FloatArray:
        """Radial distance from the centre [px] for zenith angle θ [rad]."""
        t = _as_float(theta_rad)
        rho = _project_rad(t, self.projection)
        for i, c in enumerate(self.radial_coeffs):
            rho = rho + c * t ** (i + 2)
        return self.focal_px * rho

    def _mapping_slope(self, theta_rad: ArrayLike) -> FloatArray:
        """dρ/dθ of the normalised mapping ρ(θ) = g(θ) + c2·θ² + … (:meth:`radius_px` / f)."""
        t = _as_float(theta_rad)
        slope = _project_slope(t, self.projection)
        for i, c in enumerate(self.radial_coeffs):
            slope = slope + (i + 2) * c * t ** (i + 1)
        return slope

    def theta_rad(self, r_px: ArrayLike) -> FloatArray:
        """Zenith angle [rad] for a radial distance [px] (Newton steps with a polynomial)."""
        rho = _as_float(r_px) / self.focal_px
        t = _unproject_rad(rho, self.projection)
        if self.radial_coeffs:
            t = np.where(np.isfinite(t), t, rho)
            for _ in range(30):
                g = self.radius_px(t) / self.focal_px - rho
                # a central difference, not :meth:`_mapping_slope`: beyond the mapping's
                # largest radius the steps never converge and what they leave is garbage
                # that depends on the slope's rounding — vision.skyrender's frames (its
                # table reaches past the lens) moved with the analytic slope, one held-out
                # HDR frame 0.09 → 0.23° (a bug of its own: NaN is the answer there)
                h = 1e-6
                dg = (self.radius_px(t + h) - self.radius_px(t - h)) / (2 * h * self.focal_px)
                step = g / np.where(np.abs(dg) > 1e-9, dg, 1e-9)
                t = t - step
                if np.all(np.abs(step[np.isfinite(step)]) < 1e-12):
                    break
        return t

    def radial_scales(self, theta_rad: float) -> tuple[float, float]:
        """The normalised mapping's scales at zenith angle θ [per rad, × focal_px for px]:
        along the radius ρ'(θ) (:meth:`_mapping_slope`) and across it ρ(θ)/sin θ (its limit
        at the zenith g'(0) = 1)."""
        along = float(self._mapping_slope(theta_rad))
        sin_t = float(np.sin(theta_rad))
        across = float(self.radius_px(theta_rad)) / self.focal_px / sin_t if sin_t > 1e-9 \
            else float(_project_slope(0.0, self.projection))
        return along, across

    def local_px_per_deg(self, x_px: float, y_px: float) -> tuple[float, float]:
        """The scale at pixel (x, y) [px/°], largest and smallest over the directions of the
        sky there: along the radius r'(θ), across it r(θ)/sin θ (the lens maps the
        meridian and the small circle of a point to the image's radius and its normal, so
        these are the singular values of the projection's Jacobian; a tilt turns the sky
        before the projection and changes neither). ``(0, 0)`` beyond the lens's domain."""
        theta = float(self.theta_rad(float(np.hypot(x_px - self.cx_px, y_px - self.cy_px))))
        if not math.isfinite(theta):
            return 0.0, 0.0
        along, across = self.radial_scales(theta)
        scales = (self.px_per_deg * abs(along), self.px_per_deg * abs(across))
        if not (math.isfinite(scales[0]) and math.isfinite(scales[1])):
            return 0.0, 0.0
        return float(max(scales)), float(min(scales))

    @property
    def _azimuth_sign(self) -> float:
        """+1 where the image angle grows with azimuth (east right, mirrored), −1 (east left)."""
        return -1.0 if self.east == "left" else 1.0

    def _image_angle_rad(self, azimuth_deg: FloatArray) -> FloatArray:
        """Image angle φ, clockwise from image-up, of a camera-frame azimuth."""
        return np.radians(self.north_offset_deg + self._azimuth_sign * azimuth_deg)

    def _camera_sky(
        self, azimuth_deg: ArrayLike, elevation_deg: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        if self.tilt_north_deg == 0.0 and self.tilt_east_deg == 0.0:
            return _as_float(azimuth_deg), _as_float(elevation_deg)
        v = enu_from_sky(azimuth_deg, elevation_deg)
        r = _tilt_matrix(self.tilt_north_deg, self.tilt_east_deg)
        return sky_from_enu(v @ r.T)

    def sky_to_pixel(
        self, azimuth_deg: ArrayLike, elevation_deg: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """Pixel ``(x, y)`` of a sky direction (azimuth clockwise from north, elevation) [°]."""
        az, el = self._camera_sky(azimuth_deg, elevation_deg)
        r = self.radius_px(np.radians(90.0 - el))
        phi = self._image_angle_rad(az)
        return self.cx_px + r * np.sin(phi), self.cy_px - r * np.cos(phi)

    def sky_to_pixel_jacobian(self, azimuth_deg: ArrayLike, elevation_deg: ArrayLike,
                              tilt: bool = True) -> FloatArray:
        """The derivatives of :meth:`sky_to_pixel`'s ``(x, y)`` on the camera's parameters,
        shape ``(2, …, P)`` (``[0]`` of x, ``[1]`` of y [px per unit]), in the columns
        ``cx_px``, ``cy_px``, ``px_per_deg``, ``north_offset_deg``, each of
        ``radial_coeffs``, and with ``tilt`` ``tilt_north_deg``, ``tilt_east_deg``.

        The chain rule through ``x = cx + r sin φ``, ``y = cy − r cos φ`` with
        ``r = f·ρ(θ)`` (:meth:`radius_px`), ``φ = Δ ∓ A`` (:meth:`_image_angle_rad`) and, for
        the tilt, θ and A of the tilted direction ``e = R v`` (:func:`_tilt_matrix`):
        ``dθ = −de_z / sin θ``, ``dA = (e_y de_x − e_x de_y) / sin² θ``. NaN where the pixel
        is (beyond an orthographic lens's horizon), and in the tilt's columns on the optical
        axis itself (θ = 0, where A is undefined).
        """
        az, el = self._camera_sky(azimuth_deg, elevation_deg)
        theta = np.radians(90.0 - el)
        phi = self._image_angle_rad(az)
        r = self.radius_px(theta)
        f = self.focal_px
        n_rad = len(self.radial_coeffs)
        # each parameter's dr [px] and dφ [rad] (after cx_px and cy_px)
        d_r = np.zeros((*r.shape, 2 + n_rad + (2 if tilt else 0)))
        d_phi = np.zeros_like(d_r)
        d_r[..., 0] = r / self.px_per_deg
        d_phi[..., 1] = np.pi / 180.0
        for i in range(n_rad):
            d_r[..., 2 + i] = f * theta ** (i + 2)
        if tilt:
            rx, ry, drx, dry = _tilt_rotations(self.tilt_north_deg, self.tilt_east_deg)
            v = enu_from_sky(azimuth_deg, elevation_deg)
            e = v @ (ry @ rx).T
            horiz2 = e[..., 0] ** 2 + e[..., 1] ** 2  # sin² θ
            slope = f * self._mapping_slope(theta)
            with np.errstate(divide="ignore", invalid="ignore"):
                for j, d_rot in enumerate((ry @ drx, dry @ rx), start=2 + n_rad):
                    de = v @ (d_rot * (np.pi / 180.0)).T  # per degree of tilt
                    d_r[..., j] = slope * -de[..., 2] / np.sqrt(horiz2)
                    d_phi[..., j] = self._azimuth_sign * (e[..., 1] * de[..., 0]
                                                          - e[..., 0] * de[..., 1]) / horiz2
        sin_p, cos_p, r = np.sin(phi)[..., None], np.cos(phi)[..., None], r[..., None]
        out = np.zeros((2, *d_r.shape[:-1], 2 + d_r.shape[-1]))
        out[0, ..., 0] = out[1, ..., 1] = 1.0
        out[0, ..., 2:] = d_r * sin_p + r * d_phi * cos_p
        out[1, ..., 2:] = -d_r * cos_p + r * d_phi * sin_p
        return out

    def pixel_to_sky(self, x_px: ArrayLike, y_px: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Azimuth [0, 360) and elevation [°] seen at pixel ``(x, y)`` (NaN outside the lens)."""
        dx = _as_float(x_px) - self.cx_px
        dy = _as_float(y_px) - self.cy_px
        r = np.hypot(dx, dy)
        theta = self.theta_rad(r)
        phi_deg = np.degrees(np.arctan2(dx, -dy))
        az = (self._azimuth_sign * (phi_deg - self.north_offset_deg)) % 360.0
        el = 90.0 - np.degrees(theta)
        if self.tilt_north_deg == 0.0 and self.tilt_east_deg == 0.0:
            return az, el
        v = enu_from_sky(az, el)
        rot = _tilt_matrix(self.tilt_north_deg, self.tilt_east_deg)
        return sky_from_enu(v @ rot)

    def pixel_to_direction(self, x_px: ArrayLike, y_px: ArrayLike) -> FloatArray:
        """ENU unit vectors ``[..., 3]`` seen at pixel ``(x, y)``."""
        az, el = self.pixel_to_sky(x_px, y_px)
        return enu_from_sky(az, el)

    def direction_to_pixel(self, direction: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Pixel ``(x, y)`` of ENU directions ``[..., 3]``."""
        az, el = sky_from_enu(direction)
        return self.sky_to_pixel(az, el)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready parameters with units in the names."""
        return {
            "projection": self.projection,
            "cx_px": float(self.cx_px),
            "cy_px": float(self.cy_px),
            "px_per_deg": float(self.px_per_deg),
            "north_offset_deg": float(self.north_offset_deg) % 360.0,
            "east": self.east,
            "radial_coeffs": [float(c) for c in self.radial_coeffs],
            "tilt_north_deg": float(self.tilt_north_deg),
            "tilt_east_deg": float(self.tilt_east_deg),
        }

    @classmethod
    def from_dict(cls, d: dict[str, object]) -> FisheyeCamera:
        """Inverse of :meth:`to_dict`."""
        return cls(
            cx_px=float(d["cx_px"]),  # type: ignore[arg-type]
            cy_px=float(d["cy_px"]),  # type: ignore[arg-type]
            px_per_deg=float(d["px_per_deg"]),  # type: ignore[arg-type]
            north_offset_deg=float(d.get("north_offset_deg", 0.0)),  # type: ignore[arg-type]
            east=str(d.get("east", "left")),
            projection=str(d.get("projection", "equidistant")),
            radial_coeffs=tuple(float(c) for c in _seq(d.get("radial_coeffs"))),
            tilt_north_deg=float(d.get("tilt_north_deg", 0.0)),  # type: ignore[arg-type]
            tilt_east_deg=float(d.get("tilt_east_deg", 0.0)),  # type: ignore[arg-type]
        )


# --------------------------------------------------------------------------- from parameters

PINHOLE_FIELDS: tuple[str, ...] = ("fov_deg", "cx_px", "cy_px", "reference_x_px",
                                   "reference_y_px")
FISHEYE_FIELDS: tuple[str, ...] = ("projection", "px_per_deg", "cx_px", "cy_px",
                                   "north_offset_deg", "east")


def px_per_deg_for_horizon(horizon_radius_px: float, projection: str = "equidistant") -> float:
    """The zenith scale [px/°] of a fisheye whose horizon (θ = 90°) lies at ``horizon_radius_px``.

    Inverts ``r(90°) = f·g(90°)`` with ``f = px_per_deg·180/π`` (the projections of
    :class:`FisheyeCamera`): equidistant gives ``r/90``, the others differ by
    ``g(90°)/(π/2)``. For a camera whose scale nobody measured: the image
    circle of a 180° lens is its horizon.
    """
    if projection not in PROJECTIONS:
        raise ValueError(f"projection: must be one of {', '.join(PROJECTIONS)}, got {projection!r}")
    g90 = float(_project_rad(np.array([np.pi / 2]), projection)[0])
    return float(horizon_radius_px) / (g90 * 180.0 / np.pi)


def _number(params: dict[str, object], name: str, default: float | None = None,
            positive: bool = False, bounds: tuple[float, float] | None = None
            ) -> float | None:
    raw = params.get(name)
    if raw is None or (isinstance(raw, str) and raw.strip() == ""):
        return default
    try:
        value = float(raw)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"{name}: {raw!r} is not a number") from None
    if not np.isfinite(value):
        raise ValueError(f"{name}: must be finite, got {raw!r}")
    if positive and value <= 0:
        raise ValueError(f"{name}: must be positive, got {raw!r}")
    if bounds is not None and not bounds[0] <= value <= bounds[1]:
        raise ValueError(f"{name}: {value:g} is outside [{bounds[0]:g}, {bounds[1]:g}]")
    return value


def camera_from_params(camera: str, params: dict[str, object], width_px: int,
                       height_px: int) -> PinholeCamera | FisheyeCamera:
    """A camera from the public parameter names (DESIGN.md, ``POST /api/v1/vision/sun``).

    ``camera="pinhole"``: ``fov_deg`` (default 67, seed 000), ``cx_px``,
    ``cy_px``, ``reference_x_px``, ``reference_y_px`` (default the image centre).
    ``camera="fisheye"``: ``px_per_deg`` (required), ``projection`` (default
    equidistant), ``cx_px``/``cy_px`` (default the image centre),
    ``north_offset_deg`` (default 0), ``east`` (default left). Values may be
    strings (form fields). A ValueError names the offending field. Pixel
    positions must lie on the image (−0.5 … size − 0.5) and ``px_per_deg`` in
    [0.01, 1000].
    """
    xs, ys = (-0.5, width_px - 0.5), (-0.5, height_px - 0.5)
    # the other kind's parameters are refused, not ignored: a fisheye's fov_deg (even NaN)
    # was accepted and read by nothing (a tester's finding)
    own = {"pinhole": PINHOLE_FIELDS, "fisheye": FISHEYE_FIELDS}.get(camera, ())
    stray = [n for n in dict.fromkeys((*PINHOLE_FIELDS, *FISHEYE_FIELDS))
             if own and n not in own and params.get(n) not in (None, "")]
    if stray:
        raise ValueError(f"{stray[0]}: a {camera} camera does not take it (it takes "
                         f"{', '.join(own)})")
    if camera == "pinhole":
        fov = _number(params, "fov_deg", 67.0, positive=True)
        if fov is None or not 0 < fov < 180:
            raise ValueError(f"fov_deg: must be between 0 and 180, got {fov}")
        return PinholeCamera(width_px, height_px, fov,
                             _number(params, "cx_px", bounds=xs),
                             _number(params, "cy_px", bounds=ys),
                             _number(params, "reference_x_px", bounds=xs),
                             _number(params, "reference_y_px", bounds=ys))
    if camera == "fisheye":
        k = _number(params, "px_per_deg", positive=True, bounds=(0.01, 1000.0))
        if k is None:
            raise ValueError("px_per_deg: required for a fisheye camera (or give calibration_id)")
        projection = str(params.get("projection") or "equidistant")
        if projection not in PROJECTIONS:
            raise ValueError(f"projection: must be one of {', '.join(PROJECTIONS)}, "
                             f"got {projection!r}")
        east = str(params.get("east") or "left")
        if east not in EAST_SIDES:
            raise ValueError(f"east: must be 'left' or 'right', got {east!r}")
        cx = _number(params, "cx_px", (width_px - 1) / 2.0, bounds=xs)
        cy = _number(params, "cy_px", (height_px - 1) / 2.0, bounds=ys)
        off = _number(params, "north_offset_deg", 0.0, bounds=(-360.0, 360.0))
        return FisheyeCamera(float(cx), float(cy), float(k), float(off), east,  # type: ignore[arg-type]
                             projection)
    raise ValueError(f"camera: must be 'pinhole' or 'fisheye', got {camera!r}")
