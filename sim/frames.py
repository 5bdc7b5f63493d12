"""Tracker-camera frames for the twin's camera loops: only the region around the sun.

The radiance model is :func:`vision.synth.tracker_frame`'s (the 0.53° disc, an
aureole falling as θ⁻² that saturates out to ``glare_deg``, a sky level
brightened by cloud, vignetting, shot and read noise, 8-bit BGR), evaluated
through the public :class:`vision.cameras.PinholeCamera` model but only on a
square region of interest (ROI) around the pixel where the sun falls: at
640 × 480 the rest of a clear frame is featureless sky below the detectors'
thresholds, so a detector finds the same centroid in the ROI as in the whole
frame (checked in tests/sim/test_control.py against ``vision.synth``). Left
out: vertical blooming (symmetric about the sun, it does not move a
centroid), flare streaks and lens ghosts.

Clouds are a :class:`CloudField` that drifts across the sun: a seeded sum of
plane waves in the sky angles around the sun, thresholded to the wanted
cover, moving at ``speed_deg_s``. Unlike ``vision.synth`` (one transmittance
for the whole sun, read at its centre pixel) the cloud dims each pixel by its
own optical depth, so a cloud edge crossing the sun cuts the glare — the case
a controller must not chase.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from statistics import NormalDist
from typing import NamedTuple

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.cameras import PinholeCamera
from vision.sphere import SUN_RADIUS_DEG  # the one value, for the renderers and the detector

__all__ = ["CloudField", "SunRoi", "render_sun_roi", "pointing_error_deg", "SUN_RADIUS_DEG"]

# vision.synth.tracker_frame's sensor tint, times the 8-bit full scale
_TINT_255 = np.array([1.0, 0.97, 0.93], np.float32) * np.float32(255.0)
#: the tint's grey (ITU-R BT.601 luma of B, G, R = 1.0, 0.97, 0.93), for grey frames
_LUMA_255 = np.float32((0.114 * 1.0 + 0.587 * 0.97 + 0.299 * 0.93) * 255.0)
_NOISE_BANK_SIZE = 1 << 20


@lru_cache(maxsize=1)
def _noise_bank() -> NDArray[np.float32]:
    """Standard-normal samples; each frame reads a slice at a random offset (cheaper than
    drawing 7 k normals per frame, and as random for a detector)."""
    return np.random.default_rng(20251).standard_normal(_NOISE_BANK_SIZE, dtype=np.float32)


@lru_cache(maxsize=64)
def _waves(seed: int, scale_deg: float) -> tuple[NDArray[np.float64], ...]:
    rng = np.random.default_rng(seed)
    n = 6
    angle = rng.uniform(0.0, 2 * np.pi, n)
    k = 2 * np.pi / (scale_deg * rng.uniform(1.0, 3.0, n))
    return k * np.cos(angle), k * np.sin(angle), rng.uniform(0.0, 2 * np.pi, n)


@lru_cache(maxsize=64)
def _level(cover: float) -> float:
    return NormalDist().inv_cdf(1.0 - min(cover, 0.999))


@dataclass(frozen=True)
class CloudField:
    """Drifting clouds in the sky around the sun (an assumption, seeded).

    Parameters
    ----------
    cover : float
        Fraction of the sky covered [-], 0…1.
    optical_depth : float
        Optical depth of a full cloud [-]: the sun is dimmed by ``exp(−τ c)``.
    scale_deg : float
        Typical cloud size [°].
    speed_deg_s : float
        Drift across the sky [° s⁻¹].
    seed : int
    """

    cover: float = 0.5
    optical_depth: float = 3.0
    scale_deg: float = 3.0
    speed_deg_s: float = 0.05
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0.0 <= self.cover <= 1.0:
            raise ValueError(f"cover must be in [0, 1], got {self.cover}")
        if self.optical_depth < 0 or self.scale_deg <= 0 or self.speed_deg_s < 0:
            raise ValueError("optical_depth, speed_deg_s must be >= 0 and scale_deg > 0")

    def density(self, x_deg: NDArray[np.float64], y_deg: NDArray[np.float64],
                t_s: float) -> NDArray[np.float64]:
        """Cloud density ``c`` in [0, 1] at sky offsets (x, y) from the sun [°] at ``t_s``."""
        if self.cover <= 0.0:
            return np.zeros(np.broadcast_shapes(np.shape(x_deg), np.shape(y_deg)))
        kx, ky, ph = _waves(self.seed, self.scale_deg)
        xx = np.asarray(x_deg, dtype=float) - self.speed_deg_s * t_s
        f = np.zeros(np.broadcast_shapes(np.shape(xx), np.shape(y_deg)))
        for i in range(len(kx)):
            f = f + np.sin(kx[i] * xx + ky[i] * np.asarray(y_deg) + ph[i])
        f = f / np.sqrt(len(kx) / 2.0)  # ~ unit variance
        # the sum of waves is ~ normal: threshold at the quantile that leaves `cover` of the sky
        level = _level(self.cover)
        return np.clip((f - level) * 1.5, 0.0, 1.0)

    def at_sun(self, t_s: float) -> float:
        """Cloud density on the sun's centre at ``t_s``."""
        return float(self.density(np.zeros(1), np.zeros(1), t_s)[0])


@lru_cache(maxsize=8)
def _pinhole(camera: PinholeCamera) -> tuple[float, float, float, float, float]:
    """Focal length, optical centre and the reference pixel's angles of ``camera``."""
    cx, cy = camera.centre_px
    rx, ry = camera.reference_px
    h0, v0 = camera.pixel_angles_deg(rx, ry)
    return camera.focal_px, cx, cy, float(h0), float(v0)


def pointing_error_deg(camera: PinholeCamera, x_px: float, y_px: float) -> tuple[float, float]:
    """Horizontal and vertical pointing error [°] of the sun seen at ``(x, y)``.

    :meth:`vision.cameras.PinholeCamera.pointing_error`'s first two values
    (``h = atan2(X, Z)``, ``v = atan2(Y, √(X² + Z²))`` minus the reference
    pixel's), in scalar arithmetic for the once-a-frame call.
    """
    f, cx, cy, h0, v0 = _pinhole(camera)
    x, y = (x_px - cx) / f, -(y_px - cy) / f
    h = math.degrees(math.atan2(x, 1.0))
    v = math.degrees(math.atan2(y, math.hypot(x, 1.0)))
    return h - h0, v - v0


class _Optics(NamedTuple):
    """What every frame of one camera, lens and sky reuses (cached by :func:`_optics`)."""

    f: float  #: focal length [px]
    cx: float  #: optical centre [px]
    cy: float
    w: int  #: frame size [px]
    h: int
    dirs: NDArray[np.float32]  #: unit viewing direction of every pixel, H × W × 3
    vig: NDArray[np.float32]  #: vignetting factor, H × W
    vl: NDArray[np.float32]  #: vignetting × the grey full scale [DN], H × W
    svl: NDArray[np.float32]  #: the clear sky's grey level [DN], H × W


@lru_cache(maxsize=8)
def _optics(camera: PinholeCamera, vignetting: float, sky_level: float) -> _Optics:
    """The pixel grid of ``camera``: viewing directions (float32 right, up, forward, from
    :meth:`vision.cameras.PinholeCamera.pixel_to_direction`), the vignetting factor
    ``1 − vignetting r²`` (as ``vision.synth``) and the grey scales; read-only."""
    h, w = camera.height_px, camera.width_px
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    dirs = camera.pixel_to_direction(xx, yy).astype(np.float32)
    cx, cy = camera.centre_px
    r2 = ((xx - cx) ** 2 + (yy - cy) ** 2) / (cx**2 + cy**2)
    vig = (1.0 - vignetting * r2).astype(np.float32)
    vl = vig * _LUMA_255
    svl = (np.float32(sky_level) * vl).astype(np.float32)
    for a in (dirs, vig, vl, svl):
        a.setflags(write=False)
    return _Optics(camera.focal_px, cx, cy, w, h, dirs, vig, vl, svl)


@dataclass(frozen=True)
class SunRoi:
    """A rendered region of a tracker-camera frame: ``image`` starts at pixel (x0, y0)."""

    image: NDArray[np.uint8]  #: H × W grey or H × W × 3 BGR
    x0_px: int
    y0_px: int
    sun_px: tuple[float, float]
    sun_in_frame: bool


_R2_SUN = math.radians(SUN_RADIUS_DEG) ** 2  #: the disc's angular radius squared [rad²]
_R2_SUN_F32 = np.float32(_R2_SUN)


def render_sun_roi(
    sun_camera: NDArray[np.float64],
    camera: PinholeCamera,
    half_px: int = 24,
    glare_deg: float = 0.8,
    sky_level: float = 0.35,
    clouds: CloudField | None = None,
    t_s: float = 0.0,
    vignetting: float = 0.3,
    noise_dn: float = 2.0,
    rng: np.random.Generator | None = None,
    colour: bool = False,
) -> SunRoi:
    """Render the ``(2 half_px)²`` ROI of a tracker frame centred on the sun's pixel.

    Parameters
    ----------
    sun_camera : ndarray, shape (3,)
        Sun direction in camera coordinates (right, up, forward), unit.
    camera : PinholeCamera
    half_px : int
        Half the ROI side [px]; the ROI is clipped to the frame.
    glare_deg, sky_level, vignetting, noise_dn : float
        As :func:`vision.synth.tracker_frame` (exposure, sky, lens, sensor).
    clouds : CloudField, optional
        Clouds drifting over the sun (none by default).
    t_s : float
        Time for the cloud drift [s].
    colour : bool
        8-bit BGR with ``vision.synth``'s tint (True), or 8-bit grey (default:
        seed 001's camera works in grey; the detectors take either).
    rng : numpy.random.Generator, optional
        Picks the noise (default: a fresh generator seeded 0). The noise is
        ``vision.synth``'s (read + shot), its normal deviates read at a random
        offset from a fixed bank of 2²⁰ samples.

    Returns
    -------
    SunRoi
        ``sun_in_frame`` False (and an empty image) when the sun is behind the
        camera or outside the frame.
    """
    if half_px < 4:
        raise ValueError(f"half_px must be >= 4, got {half_px}")
    s0, s1, s2 = float(sun_camera[0]), float(sun_camera[1]), float(sun_camera[2])
    o = _optics(camera, vignetting, sky_level)
    if not s2 > 1e-12:  # behind the camera
        return SunRoi(np.zeros((0, 0, 3), np.uint8), 0, 0, (math.nan, math.nan), False)
    # PinholeCamera.direction_to_pixel, in scalars
    sxf, syf = o.cx + o.f * s0 / s2, o.cy - o.f * s1 / s2
    if not (0 <= sxf <= o.w - 1 and 0 <= syf <= o.h - 1):
        return SunRoi(np.zeros((0, 0, 3), np.uint8), 0, 0, (sxf, syf), False)
    xc, yc = int(round(sxf)), int(round(syf))
    x0, y0 = max(0, xc - half_px), max(0, yc - half_px)
    x1, y1 = min(o.w, xc + half_px), min(o.h, yc + half_px)
    # squared angle to the sun from the chord, θ² = |d − s|² = 2 − 2 d·s [rad²], in one
    # affine cv2.transform (to < 1e-3 relative inside a 5° ROI; no float32 arccos near 1)
    m = np.array([[-2.0 * s0, -2.0 * s1, -2.0 * s2, 2.0]], np.float32)
    theta2 = cv2.transform(o.dirs[y0:y1, x0:x1], m)
    # vision.synth._sun_radiance: aureole (glare/θ)², the disc's plateau inside SUN_RADIUS
    lum = np.maximum(theta2, _R2_SUN_F32)
    np.divide(np.float32(math.radians(glare_deg) ** 2), lum, out=lum)
    cloudy = clouds is not None and clouds.cover > 0
    if cloudy or (glare_deg / SUN_RADIUS_DEG) ** 2 * (1.0 - vignetting) < 2.0:
        # the disc's plateau shows only through cloud or at a short exposure: otherwise
        # the aureole already saturates the disc many times over
        lum[theta2 <= _R2_SUN] += np.float32((glare_deg / SUN_RADIUS_DEG) ** 2 * 4)
    if clouds is not None and cloudy:
        sky = np.float32(sky_level)
        xx, yy = np.meshgrid(np.arange(x0, x1, dtype=float), np.arange(y0, y1, dtype=float))
        c = clouds.density(np.degrees((xx - sxf) / o.f), np.degrees(-(yy - syf) / o.f), t_s)
        c = c.astype(np.float32)
        lum *= np.exp(-np.float32(clouds.optical_depth) * c)
        lum += sky * (1.0 + 1.2 * c * min(1.0, clouds.optical_depth))
        lum *= o.vig[y0:y1, x0:x1]
        img = lum[..., None] * _TINT_255 if colour else lum * _LUMA_255
    elif colour:
        lum += np.float32(sky_level)
        lum *= o.vig[y0:y1, x0:x1]
        img = lum[..., None] * _TINT_255
    else:
        # (sun + sky) · vignetting · grey scale, with the constant sky term precomputed
        lum *= o.vl[y0:y1, x0:x1]
        lum += o.svl[y0:y1, x0:x1]
        img = lum
    if noise_dn > 0:
        gen = rng if rng is not None else np.random.default_rng(0)
        bank = _noise_bank()
        n = img.size
        k = int(gen.random() * (bank.size - n))
        shot = np.sqrt(img)
        shot *= np.float32(0.02 * noise_dn)
        shot += np.float32(noise_dn)
        shot *= bank[k:k + n].reshape(img.shape)
        img += shot
    out = np.asarray(cv2.convertScaleAbs(img), dtype=np.uint8)  # round, saturate to 0…255
    return SunRoi(out, x0, y0, (sxf, syf), True)
