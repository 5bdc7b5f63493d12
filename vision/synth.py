"""Synthetic camera frames with a known sun, deterministic by seed.

* :func:`tracker_frame` — the tracker's pinhole camera (seed 000: 640 × 480,
  67°) looking near the sun with a given pointing error: the 0.53° solar disc,
  a circumsolar aureole falling as θ⁻² (the usual power-law aureole model),
  saturation at the sensor's full well with vertical blooming, vignetting,
  read and shot noise, optional clouds, a flare streak and a lens ghost.
* :func:`fisheye_frame` — a levelled all-sky camera (seed 003): black outside
  the horizon circle, a sky brighter toward the horizon and the sun, the sun
  placed through :class:`vision.cameras.FisheyeCamera`, its glare saturating a
  disc of ``glare_deg`` radius, optional clouds (which dim the sun and add
  white), an optional horizon skyline, and a flare ghost opposite the sun.

Radiance is computed per pixel from the angle to the sun along each pixel's
own viewing direction, so the truth is exactly the camera model's projection
of the sun's direction. Values are in units of the sensor's saturation level
(1.0 → 255) before quantisation to 8-bit BGR.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.cameras import FisheyeCamera, PinholeCamera
from vision.sphere import SUN_RADIUS_DEG, enu_from_sky


@dataclass(frozen=True)
class SynthFrame:
    """A rendered frame and its truth."""

    image: NDArray[np.uint8]
    sun_px: tuple[float, float]
    sun_visible: bool
    truth: dict[str, float] = field(default_factory=dict)


def _smooth_field(rng: np.random.Generator, h: int, w: int, cells: int) -> NDArray[np.float32]:
    """A smooth random field in [0, 1] (bicubic-upsampled noise, blurred)."""
    gh, gw = max(2, cells * h // max(h, w)), max(2, cells * w // max(h, w))
    coarse = rng.random((gh + 2, gw + 2)).astype(np.float32)
    big = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
    big = cv2.GaussianBlur(big, (0, 0), max(h, w) / (3.0 * cells))
    lo, hi = float(big.min()), float(big.max())
    return (big - lo) / max(hi - lo, 1e-6)


def _clouds(rng: np.random.Generator, h: int, w: int, cover: float) -> NDArray[np.float32]:
    """Cloud optical-depth map in [0, 1]: a thresholded multi-scale field, ``cover`` of the sky."""
    f = 0.65 * _smooth_field(rng, h, w, 6) + 0.35 * _smooth_field(rng, h, w, 18)
    if cover <= 0:
        return np.zeros((h, w), np.float32)
    level = float(np.quantile(f, 1.0 - min(cover, 1.0)))
    c = np.clip((f - level) / max(1e-6, 1.0 - level) * 3.0, 0.0, 1.0)
    return c.astype(np.float32)


def _sun_radiance(ang_deg: NDArray[np.float32], glare_deg: float) -> NDArray[np.float32]:
    """Disc + aureole: 1.0 (saturation) at ``glare_deg`` from the centre, ∝ θ⁻² outside."""
    a = np.maximum(ang_deg, np.float32(SUN_RADIUS_DEG))
    aureole = (np.float32(glare_deg) / a) ** 2
    disc = np.where(ang_deg <= SUN_RADIUS_DEG, np.float32(glare_deg / SUN_RADIUS_DEG) ** 2 * 4, 0)
    return (aureole + disc).astype(np.float32)


def _angle_to(dirs: NDArray[np.float32], sun: NDArray[np.float64]) -> NDArray[np.float32]:
    cosang = np.clip(dirs @ sun.astype(np.float32), -1.0, 1.0)
    return np.degrees(np.arccos(cosang)).astype(np.float32)


def _finish(lum: NDArray[np.float32], tint: NDArray[np.float32], rng: np.random.Generator,
            noise_dn: float) -> NDArray[np.uint8]:
    """Colour, shot + read noise, clip at full well, quantise to 8-bit BGR."""
    img = lum[..., None] * tint * 255.0
    if noise_dn > 0:
        img = img + rng.normal(0.0, 1.0, img.shape).astype(np.float32) * (
            noise_dn + 0.02 * np.sqrt(np.maximum(img, 0)) * noise_dn)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _bloom(lum: NDArray[np.float32], strength: float, length_px: float) -> NDArray[np.float32]:
    """Vertical blooming: charge above full well spills along the columns, both ways."""
    excess = np.maximum(lum - 1.0, 0.0)
    if strength <= 0 or not np.any(excess):
        return lum
    k = int(6 * length_px) | 1
    kernel = np.exp(-np.abs(np.arange(k) - k // 2) / length_px).astype(np.float32)
    kernel /= kernel.sum()
    spill = cv2.filter2D(excess, -1, kernel.reshape(-1, 1), borderType=cv2.BORDER_CONSTANT)
    return lum + np.float32(strength) * spill


def tracker_frame(
    horizontal_deg: float,
    vertical_deg: float,
    camera: PinholeCamera | None = None,
    seed: int = 0,
    glare_deg: float = 0.8,
    sky_level: float = 0.35,
    cloud_cover: float = 0.0,
    cloud_optical_depth: float = 1.0,
    flare: bool = False,
    ghost: bool = False,
    vignetting: float = 0.3,
    bloom: float = 0.02,
    noise_dn: float = 2.0,
) -> SynthFrame:
    """Tracker camera frame with the sun at a pointing error (right, up positive) [°].

    ``glare_deg`` sets the exposure: the aureole saturates out to that angle
    on a clear sky (0.8° ≈ a 15 px saturated disc at 640 px / 67°).
    ``cloud_optical_depth`` dims the sun by ``exp(−τ·c)`` where the cloud
    field ``c`` covers ``cloud_cover`` of the frame.
    """
    cam = camera or PinholeCamera()
    rng = np.random.default_rng(seed)
    h, w = cam.height_px, cam.width_px
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    dirs = cam.pixel_to_direction(xx, yy).astype(np.float32)
    sx, sy = cam.pixel_from_pointing_error(horizontal_deg, vertical_deg)
    sun = cam.pixel_to_direction(sx, sy)
    ang = _angle_to(dirs, sun)
    clouds = _clouds(rng, h, w, cloud_cover)
    ix, iy = int(np.clip(round(float(sx)), 0, w - 1)), int(np.clip(round(float(sy)), 0, h - 1))
    trans = float(np.exp(-cloud_optical_depth * clouds[iy, ix]))
    lum = _sun_radiance(ang, glare_deg) * np.float32(trans)
    lum += np.float32(sky_level) * (1.0 + 1.2 * clouds * min(1.0, cloud_optical_depth))
    if flare:
        theta = rng.uniform(0, np.pi)
        dx, dy = np.cos(theta), np.sin(theta)
        along = (xx - sx) * dx + (yy - sy) * dy
        across = -(xx - sx) * dy + (yy - sy) * dx
        lum += np.float32(0.5 * trans) * np.exp(-(across / 1.5) ** 2 - np.abs(along) / 120.0)
    if ghost:
        cx, cy = cam.centre_px
        gx, gy = 2 * cx - float(sx), 2 * cy - float(sy)
        lum += np.float32(0.9 * trans) * np.exp(-((xx - gx) ** 2 + (yy - gy) ** 2) / (2 * 2.0**2))
    cx, cy = cam.centre_px
    r2 = ((xx - cx) ** 2 + (yy - cy) ** 2) / (cx**2 + cy**2)
    lum = lum * (1.0 - np.float32(vignetting) * r2)
    lum = _bloom(lum, bloom, 25.0)
    tint = np.array([1.0, 0.97, 0.93], np.float32)
    img = _finish(lum, tint, rng, noise_dn)
    visible = bool(0 <= sx <= w - 1 and 0 <= sy <= h - 1)
    return SynthFrame(img, (float(sx), float(sy)), visible,
                      {"horizontal_deg": float(horizontal_deg), "vertical_deg": float(vertical_deg),
                       "transmittance": trans})


def fisheye_frame(
    azimuth_deg: float,
    elevation_deg: float,
    camera: FisheyeCamera | None = None,
    width_px: int = 640,
    height_px: int = 480,
    seed: int = 0,
    glare_deg: float = 3.0,
    cloud_cover: float = 0.0,
    cloud_optical_depth: float = 1.0,
    skyline_deg: float = 0.0,
    ghost: bool = False,
    noise_dn: float = 2.0,
) -> SynthFrame:
    """All-sky frame with the sun at (azimuth, elevation) [°].

    The default camera is seed 003's format: 640 × 480, equidistant, centre
    at the image centre, 2.6 px/deg (so the horizon circle fits the frame),
    north up, east left. ``skyline_deg`` > 0 adds a random horizon skyline up
    to that elevation (the sun behind it is hidden).
    """
    cam = camera or FisheyeCamera(cx_px=(width_px - 1) / 2, cy_px=(height_px - 1) / 2,
                                  px_per_deg=2.6)
    rng = np.random.default_rng(seed)
    h, w = height_px, width_px
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    az, el = cam.pixel_to_sky(xx, yy)
    inside = np.isfinite(el) & (el >= 0)
    el_safe = np.where(inside, el, 0.0)
    dirs = enu_from_sky(az, el_safe).astype(np.float32)
    sun = enu_from_sky(azimuth_deg, elevation_deg)
    ang = _angle_to(dirs, sun)
    clouds = _clouds(rng, h, w, cloud_cover)
    sx, sy = cam.sky_to_pixel(azimuth_deg, elevation_deg)
    ix, iy = int(np.clip(round(float(sx)), 0, w - 1)), int(np.clip(round(float(sy)), 0, h - 1))
    trans = float(np.exp(-cloud_optical_depth * clouds[iy, ix]))
    sky = 0.30 + 0.25 * (1.0 - np.sin(np.radians(el_safe))) ** 2
    lum = (_sun_radiance(ang, glare_deg) * np.float32(trans) + sky.astype(np.float32)
           + np.float32(0.55) * clouds * min(1.0, cloud_optical_depth))
    visible = bool(elevation_deg > 0 and 0 <= sx <= w - 1 and 0 <= sy <= h - 1)
    ground = ~inside
    if skyline_deg > 0:
        knots = rng.uniform(0.0, skyline_deg, 24)
        prof = np.interp(az % 360.0, np.linspace(0, 360, 25), np.append(knots, knots[0]))
        ground |= inside & (el < prof)
        sun_prof = float(np.interp(azimuth_deg % 360.0, np.linspace(0, 360, 25),
                                   np.append(knots, knots[0])))
        visible = visible and elevation_deg > sun_prof + SUN_RADIUS_DEG
    if ghost:
        gx, gy = 2 * cam.cx_px - float(sx), 2 * cam.cy_px - float(sy)
        lum += np.float32(0.9 * trans) * np.exp(-((xx - gx) ** 2 + (yy - gy) ** 2) / (2 * 2.5**2))
    lum = np.where(ground, np.float32(0.04), lum).astype(np.float32)
    tint = np.where(clouds[..., None] > 0.2, np.float32(1.0),
                    np.array([1.0, 0.8, 0.55], np.float32)).astype(np.float32)
    tint = np.where(lum[..., None] > 0.9, np.float32(1.0), tint).astype(np.float32)
    img = _finish(lum, tint, rng, noise_dn)
    return SynthFrame(img, (float(sx), float(sy)), visible,
                      {"azimuth_deg": float(azimuth_deg), "elevation_deg": float(elevation_deg),
                       "transmittance": trans})

