"""A second all-sky renderer, physically different from :mod:`vision.synth`.

Used only to evaluate the detector on frames its author did not draw with the
renderer the detector grew up on. Differences from :func:`vision.synth.fisheye_frame`:

* sky radiance from the CIE standard general sky (ISO 15469:2004 / CIE S 011,
  gradation × indicatrix; type 12 "clear, low turbidity" for a clear sky, with
  its circumsolar term lowered because the aureole is drawn separately, and
  type 3 for an overcast one) instead of an ad-hoc horizon term;
* the sun as a limb-darkened disc (linear law, u = 0.6) plus a Moffat
  (power-law) aureole ``I(θ) = (1 + (θ/α)²)^(−β)`` (Moffat 1969, A&A 3:455)
  instead of θ⁻², the exposure set so that the aureole saturates at
  ``glare_deg``;
* clouds of three kinds: fibrous cirrus (anisotropic noise, optical depth
  0.2–0.8, forward-scattering brightening toward the sun), broken cumulus
  (thresholded fractal noise with bright sunlit edges and dark bases) and a
  textured overcast deck that hides the sun;
* natural vignetting ``cos⁴``-like fall-off, lateral chromatic aberration
  (the red and blue planes radially scaled by ± ``fringe_px`` at the image
  circle's edge), Poisson–Gaussian sensor noise, JPEG at a given quality;
* trees at the horizon (a ragged dark skyline with crowns) and a lens-flare
  ghost on the line through the optical centre, opposite the sun;
* two tone curves: a sensor clipping at its full well (``tone="clip"``, the default), or
  an HDR camera's merge tone-mapped into 8 bits (``tone="reinhard"``: Reinhard et al.
  2002's global operator ``L(1 + L/L_w²)/(1 + L)`` per channel, the key 0.18 over the
  log-average of the sky inside the horizon, the white point ``L_w`` the frame's
  brightest value, then a display gamma of 1/2.2) — the sun is no larger clipped disc
  there, only the frame's brightest point, and the sky lies close under it.

The truth is the camera model's projection of the sun's direction
(:meth:`vision.cameras.FisheyeCamera.sky_to_pixel`); every pixel's radiance is
computed from its own viewing direction. Values are in units of the sensor's
full well (1.0 → 255) before quantisation.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.cameras import FisheyeCamera
from vision.sphere import SUN_RADIUS_DEG, enu_from_sky
from vision.synth import SynthFrame

SKIES: tuple[str, ...] = ("clear", "cirrus", "cumulus", "overcast")

# CIE standard general sky (ISO 15469): (a, b) gradation, (c, d, e) indicatrix
# type 12's gradation; its circumsolar term (c = 10) lowered to 2: the aureole is the
# Moffat term of _sun(), drawn separately
_CIE_CLEAR = (-1.0, -0.32, 2.0, -3.0, 0.45)
_CIE_OVERCAST = (4.0, -0.70, 0.0, -1.0, 0.0)  # type 3 (overcast, uniform in azimuth)


@dataclass(frozen=True)
class SkyScene:
    """Everything random about one frame, drawn by :func:`random_scene` from a seed."""

    azimuth_deg: float
    elevation_deg: float
    width_px: int
    height_px: int
    camera: FisheyeCamera
    sky: str = "clear"
    glare_deg: float = 3.0
    moffat_alpha_deg: float = 0.6
    moffat_beta: float = 1.4
    sky_level: float = 0.35
    cloud_optical_depth: float = 0.5
    vignetting: float = 0.25
    fringe_px: float = 0.8
    noise_dn: float = 1.5
    jpeg_quality: int = 90
    trees_deg: float = 8.0
    ghost: bool = True
    seed: int = 0
    tone: str = "clip"  # or "reinhard": an HDR merge tone-mapped (module docstring)


def _cie_gradation(cos_z: NDArray[np.float32], a: float, b: float) -> NDArray[np.float32]:
    return (1.0 + a * np.exp(b / np.maximum(cos_z, np.float32(0.02)))).astype(np.float32)


def _cie_indicatrix(gamma_rad: NDArray[np.float32], c: float, d: float, e: float
                    ) -> NDArray[np.float32]:
    return (1.0 + c * (np.exp(d * gamma_rad) - np.exp(d * np.pi / 2))
            + e * np.cos(gamma_rad) ** 2).astype(np.float32)


def _cie_sky(cos_z: NDArray[np.float32], gamma_rad: NDArray[np.float32], sun_zenith_rad: float,
             params: tuple[float, float, float, float, float]) -> NDArray[np.float32]:
    """Relative sky luminance L/L_zenith of the CIE general sky (ISO 15469, eq. 1)."""
    a, b, c, d, e = params
    num = _cie_gradation(cos_z, a, b) * _cie_indicatrix(gamma_rad, c, d, e)
    zen = (1.0 + a * np.exp(b)) * (1.0 + c * (np.exp(d * sun_zenith_rad) - np.exp(d * np.pi / 2))
                                   + e * np.cos(sun_zenith_rad) ** 2)
    return (num / np.float32(zen)).astype(np.float32)


def _fractal(rng: np.random.Generator, h: int, w: int, octaves: int = 5,
             stretch: float = 1.0, angle_deg: float = 0.0) -> NDArray[np.float32]:
    """Fractal value noise in [0, 1] (octaves of bicubic-upsampled noise, ``stretch`` ≥ 1
    elongates it along ``angle_deg``: fibrous cirrus)."""
    out: NDArray[Any] = np.zeros((h, w), np.float32)
    amp, total = 1.0, 0.0
    for o in range(octaves):
        cells = 3 * 2 ** o
        gh, gw = max(2, cells * h // max(h, w)), max(2, cells * w // max(h, w))
        coarse = rng.random((gh + 3, gw + 3)).astype(np.float32)
        layer = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
        out += np.float32(amp) * layer
        total += amp
        amp *= 0.55
    out /= np.float32(total)
    if stretch > 1.0:
        k = int(max(h, w) / 12) | 1
        kern = np.zeros((k, k), np.float32)
        c = k // 2
        t = np.radians(angle_deg)
        cv2.line(kern, (int(c - c * np.cos(t)), int(c - c * np.sin(t))),
                 (int(c + c * np.cos(t)), int(c + c * np.sin(t))), 1.0, 1)
        kern /= max(float(kern.sum()), 1e-6)
        out = cv2.filter2D(out, -1, kern, borderType=cv2.BORDER_REFLECT)
    lo, hi = float(out.min()), float(out.max())
    return ((out - lo) / max(hi - lo, 1e-6)).astype(np.float32)


def _sun(gamma_deg: NDArray[np.float32], s: SkyScene) -> NDArray[np.float32]:
    """Limb-darkened disc + Moffat aureole, scaled so that it reaches 1.0 at ``glare_deg``."""
    alpha, beta = np.float32(s.moffat_alpha_deg), np.float32(s.moffat_beta)
    moffat = (1.0 + (gamma_deg / alpha) ** 2) ** (-beta)
    scale = (1.0 + (s.glare_deg / s.moffat_alpha_deg) ** 2) ** s.moffat_beta
    aureole = moffat * np.float32(scale)
    mu2 = np.clip(1.0 - (gamma_deg / np.float32(SUN_RADIUS_DEG)) ** 2, 0.0, 1.0)
    disc = np.where(gamma_deg <= SUN_RADIUS_DEG, 1.0 - 0.6 * (1.0 - np.sqrt(mu2)), 0.0)
    return (aureole + np.float32(50.0 * scale) * disc.astype(np.float32)).astype(np.float32)


def _radial_scale(plane: NDArray[np.float32], cx: float, cy: float, k: float
                  ) -> NDArray[np.float32]:
    """``plane`` radially magnified by ``1 + k`` about (cx, cy) (lateral chromatic aberration)."""
    h, w = plane.shape
    m = np.array([[1.0 / (1.0 + k), 0.0, cx * (1 - 1.0 / (1.0 + k))],
                  [0.0, 1.0 / (1.0 + k), cy * (1 - 1.0 / (1.0 + k))]], np.float64)
    return np.asarray(cv2.warpAffine(plane, m, (w, h), flags=cv2.INTER_LINEAR,
                                     borderMode=cv2.BORDER_REPLICATE), np.float32)


def _upsample(coarse: NDArray[np.float32], step: int, h: int, w: int) -> NDArray[np.float32]:
    """Bilinear upsampling of a field sampled at pixels ``(i·step, j·step)`` to ``h × w``."""
    if step == 1:
        return coarse[:h, :w].astype(np.float32)
    mx = np.tile(np.arange(w, dtype=np.float32) / step, (h, 1))
    my = np.tile((np.arange(h, dtype=np.float32) / step)[:, None], (1, w))
    return np.asarray(cv2.remap(coarse.astype(np.float32), mx, my, cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_REPLICATE), np.float32)


def _sky_grid(cam: FisheyeCamera, x: NDArray[np.float64], y: NDArray[np.float64]
              ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``cam.pixel_to_sky`` for a levelled camera, fast: the zenith angle from a 1-D table
    of the camera's own ``theta_rad`` (the radial law depends on the radius only), the
    azimuth from the same camera without its radial terms (they do not change it)."""
    if cam.tilt_north_deg or cam.tilt_east_deg or not cam.radial_coeffs:
        return cam.pixel_to_sky(x, y)
    r = np.hypot(x - cam.cx_px, y - cam.cy_px)
    table_r = np.linspace(0.0, float(r.max()) + 1.0, 8192)
    table_t = cam.theta_rad(table_r)
    good = np.isfinite(table_t)
    theta = np.interp(r, table_r[good], table_t[good], right=np.nan)
    az, _ = replace(cam, radial_coeffs=()).pixel_to_sky(x, y)
    return az, 90.0 - np.degrees(theta)


def render(s: SkyScene) -> SynthFrame:
    """Render one frame of scene ``s``; ``truth`` carries the scene's parameters.

    Viewing directions are computed exactly on a grid every ``step`` pixels
    (``step`` = short side // 480) and interpolated bilinearly between (the
    sun's pixel moves by < 0.01 px: the map's curvature over a few pixels is
    tiny); smooth fields (sky, clouds, texture) are drawn on that grid too.
    """
    rng = np.random.default_rng(s.seed + 7_000_003)
    cam, h, w = s.camera, s.height_px, s.width_px
    step = max(1, min(h, w) // 480)
    ch, cw = (h - 1) // step + 2, (w - 1) // step + 2
    cy_, cx_ = np.mgrid[0:ch, 0:cw].astype(np.float64) * step
    az_c, el_c = _sky_grid(cam, cx_, cy_)
    ok_c = np.isfinite(el_c)
    dirs_c = enu_from_sky(np.nan_to_num(az_c), np.where(ok_c, el_c, -90.0)).astype(np.float32)
    dirs = np.stack([_upsample(dirs_c[..., i], step, h, w) for i in range(3)], axis=-1)
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    sun_v = enu_from_sky(s.azimuth_deg, s.elevation_deg).astype(np.float32)
    gamma_deg = np.degrees(np.arccos(np.clip(dirs @ sun_v, -1.0, 1.0))).astype(np.float32)
    el = np.degrees(np.arcsin(np.clip(dirs[..., 2], -1.0, 1.0))).astype(np.float32)
    del dirs
    inside = el >= 0
    # smooth fields on the coarse grid
    cos_zc = np.clip(dirs_c[..., 2], 0.0, 1.0)
    gam_c = np.arccos(np.clip(dirs_c @ sun_v, -1.0, 1.0)).astype(np.float32)
    gam_cd = np.degrees(gam_c).astype(np.float32)
    inside_c = dirs_c[..., 2] >= 0
    sun_z = float(np.radians(90.0 - s.elevation_deg))
    sx, sy = (float(v) for v in cam.sky_to_pixel(s.azimuth_deg, s.elevation_deg))
    ix, iy = int(np.clip(round(sx / step), 0, cw - 1)), int(np.clip(round(sy / step), 0, ch - 1))

    sky = np.float32(s.sky_level) * np.clip(_cie_sky(cos_zc, gam_c, sun_z, _CIE_CLEAR), 0, 1.6)
    trans = 1.0
    if s.sky == "overcast":
        tex = _fractal(rng, ch, cw, 6)
        sky = (np.float32(2.2 * s.sky_level) * _cie_sky(cos_zc, gam_c, sun_z, _CIE_OVERCAST)
               * (0.75 + 0.5 * tex)).astype(np.float32)
        # the sun's position only as a broad brighter patch (no disc, no aureole)
        sky *= (1.0 + 0.35 * np.exp(-gam_cd / 25.0)).astype(np.float32)
        trans = 0.0
    elif s.sky in ("cirrus", "cumulus"):
        if s.sky == "cirrus":
            fld = _fractal(rng, ch, cw, 5, stretch=3.0, angle_deg=float(rng.uniform(0, 180)))
            tau = np.float32(s.cloud_optical_depth) * np.clip((fld - 0.35) / 0.4, 0, 1)
            # forward scattering: thin ice cloud is brightest near the sun
            bright = tau * np.float32(0.5) * (1.0 + 4.0 * np.exp(-gam_cd / 12.0))
        else:
            fld = _fractal(rng, ch, cw, 6)
            cover = float(rng.uniform(0.3, 0.6))
            level = float(np.quantile(fld[inside_c], 1.0 - cover)) if inside_c.any() else 0.5
            tau = np.clip((fld - level) / 0.05, 0, 1) * np.float32(12.0)
            edge = np.clip(1.0 - (fld - level) / 0.15, 0, 1)
            bright = np.clip(tau, 0, 1) * (np.float32(0.35) + np.float32(0.8) * edge
                                           * np.exp(-gam_cd / 30.0))
        tau = tau.astype(np.float32)
        trans = float(np.exp(-tau[iy, ix]))
        sky = (sky * np.exp(-tau) + bright.astype(np.float32) * np.float32(s.sky_level * 2.0)
               ).astype(np.float32)
        tau_full = _upsample(tau, step, h, w)
    lum = _upsample(sky, step, h, w)
    if s.sky != "overcast":
        sun = _sun(gamma_deg, s)
        lum += sun * (np.exp(-tau_full) if s.sky != "clear" else np.float32(1.0))
    xx = np.arange(w, dtype=np.float32)[None, :]
    yy = np.arange(h, dtype=np.float32)[:, None]
    if s.ghost and s.sky != "overcast":
        gx, gy = 2 * cam.cx_px - sx, 2 * cam.cy_px - sy
        rad = max(1.5, 0.35 * cam.px_per_deg)
        rr = np.sqrt((xx - np.float32(gx)) ** 2 + (yy - np.float32(gy)) ** 2)
        ghost = np.clip((rad + 1.0 - rr) / 2.0, 0, 1) * np.float32(rng.uniform(0.4, 1.3))
        lum += (ghost * np.float32(trans)).astype(np.float32)
    ground = ~inside
    visible = bool(s.elevation_deg > 0 and 0 <= sx <= w - 1 and 0 <= sy <= h - 1)
    if s.trees_deg > 0:
        knots = rng.uniform(0.0, s.trees_deg, 48) * (rng.random(48) < 0.6)
        grid = np.linspace(0, 360, 49)
        prof_c = np.interp(np.nan_to_num(az_c) % 360.0, grid, np.append(knots, knots[0]))
        ragged = _fractal(rng, ch, cw, 4) * np.float32(0.4 * s.trees_deg)
        margin = _upsample((el_c - prof_c - ragged).astype(np.float32), step, h, w)
        ground |= inside & (margin < 0)
        if visible:  # the sun's own pixel is behind a tree or it is not
            visible = not bool(ground[int(round(sy)), int(round(sx))])
    # visible: the dimmed sun still saturates its disc (a sun behind cloud can show)
    glare_scale = (1.0 + (s.glare_deg / s.moffat_alpha_deg) ** 2) ** s.moffat_beta
    visible = visible and trans * glare_scale >= 2.0 and s.sky != "overcast"
    lum = np.where(ground, np.float32(0.03) + np.float32(0.03) * inside, lum).astype(np.float32)
    r2 = ((xx - np.float32(cam.cx_px)) ** 2 + (yy - np.float32(cam.cy_px)) ** 2) / np.float32(
        cam.horizon_radius_px ** 2)
    lum *= (1.0 - np.float32(s.vignetting) * np.minimum(r2, 1.2)).astype(np.float32)
    # colour: blue sky, white sun and cloud; planes in BGR
    white = np.clip(lum - 0.6, 0, 0.4) / 0.4
    b = lum * (1.0 + 0.25 * (1 - white))
    g = lum * (0.92 + 0.08 * white)
    r = lum * (0.62 + 0.38 * white)
    k = s.fringe_px / max(cam.horizon_radius_px, 1.0)
    r = _radial_scale(r.astype(np.float32), cam.cx_px, cam.cy_px, k)
    b = _radial_scale(b.astype(np.float32), cam.cx_px, cam.cy_px, -k)
    img = np.stack([b, g, r], axis=-1) * np.float32(255.0)
    if s.noise_dn > 0:
        sd = np.sqrt(np.float32(s.noise_dn) ** 2 + np.float32(0.08) * np.clip(img, 0, 255))
        img += rng.standard_normal(img.shape, dtype=np.float32) * sd
    if s.tone == "reinhard":
        img = _reinhard(img / np.float32(255.0), inside & ~ground) * np.float32(255.0)
    elif s.tone != "clip":
        raise ValueError(f"tone must be 'clip' or 'reinhard', got {s.tone!r}")
    out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if s.jpeg_quality < 100:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(s.jpeg_quality)])
        if ok:
            out = np.asarray(cv2.imdecode(buf, cv2.IMREAD_COLOR), np.uint8)
    truth = {"azimuth_deg": float(s.azimuth_deg), "elevation_deg": float(s.elevation_deg),
             "transmittance": float(trans), "glare_deg": float(s.glare_deg),
             "px_per_deg": float(cam.px_per_deg)}
    return SynthFrame(out, (sx, sy), visible, truth)


def _reinhard(x: NDArray[np.float32], sky: NDArray[np.bool_]) -> NDArray[np.float32]:
    """An HDR frame (linear, 1 = a clipping sensor's full well; any range) tone-mapped to
    [0, 1]: Reinhard, Stark, Shirley & Ferwerda 2002 ("Photographic tone reproduction for
    digital images", eq. 4), per channel, the key 0.18 over the log-average of the ``sky``
    pixels, the white point the frame's brightest value, display gamma 1/2.2."""
    x = np.maximum(x, np.float32(0.0))
    log_avg = float(np.exp(np.mean(np.log(x[sky] + 1e-4)))) if sky.any() else 1.0
    scaled = x * np.float32(0.18 / log_avg)
    white = float(scaled.max())
    mapped = scaled * (1.0 + scaled / np.float32(white * white)) / (1.0 + scaled)
    return (np.clip(mapped, 0.0, 1.0) ** np.float32(1.0 / 2.2)).astype(np.float32)


def random_scene(seed: int, sky: str | None = None, width_px: int | None = None,
                 height_px: int | None = None) -> SkyScene:
    """A scene drawn from ``seed``: size 480–3000 px, 2–15 px/°, a random lens and sky.

    The camera: equidistant or equisolid, a small radial term, the image circle
    0.85–1.0 of the frame's short side, any north offset, either mirror. The
    sun: azimuth uniform, elevation 8–80°. ``sky`` (one of :data:`SKIES`)
    overrides the random choice.
    """
    rng = np.random.default_rng(seed)
    if width_px is None or height_px is None:
        short = int(rng.choice([480, 640, 960, 1200, 1536, 1920, 2400, 3000]))
        aspect = float(rng.choice([1.0, 1.0, 4.0 / 3.0]))
        height_px, width_px = short, int(round(short * aspect))
    short = min(width_px, height_px)
    projection = str(rng.choice(["equidistant", "equisolid"]))
    frac = float(rng.uniform(0.85, 1.0))
    g90 = np.pi / 2 if projection == "equidistant" else 2 * np.sin(np.pi / 4)
    px_per_deg = float(np.clip(frac * 0.5 * short / (g90 * 180 / np.pi), 2.0, 15.0))
    cam = FisheyeCamera(
        cx_px=(width_px - 1) / 2 + float(rng.uniform(-0.02, 0.02)) * short,
        cy_px=(height_px - 1) / 2 + float(rng.uniform(-0.02, 0.02)) * short,
        px_per_deg=px_per_deg, north_offset_deg=float(rng.uniform(0, 360)),
        east=str(rng.choice(["left", "right"])), projection=projection,
        radial_coeffs=(float(rng.uniform(-0.02, 0.02)),))
    if sky is None:
        sky = str(rng.choice(SKIES, p=[0.4, 0.3, 0.15, 0.15]))
    return SkyScene(
        azimuth_deg=float(rng.uniform(0, 360)), elevation_deg=float(rng.uniform(8, 80)),
        width_px=int(width_px), height_px=int(height_px), camera=cam, sky=sky,
        glare_deg=float(rng.uniform(1.0, 7.0)), moffat_alpha_deg=float(rng.uniform(0.3, 1.5)),
        moffat_beta=float(rng.uniform(1.0, 2.0)), sky_level=float(rng.uniform(0.2, 0.45)),
        cloud_optical_depth=float(rng.uniform(0.2, 0.8)), vignetting=float(rng.uniform(0.05, 0.4)),
        fringe_px=float(rng.uniform(0.0, 2.0)), noise_dn=float(rng.uniform(0.5, 3.0)),
        jpeg_quality=int(rng.choice([60, 75, 85, 95])), trees_deg=float(rng.uniform(0, 15)),
        ghost=bool(rng.random() < 0.7), seed=int(seed))
