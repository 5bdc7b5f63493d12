"""The labelled synthetic evaluation sets, split by seed into development and held-out.

Development seeds are < 10 000, held-out seeds ≥ 10 000; the detector's
confidence model is fitted on the development frames only. Each frame comes
with its camera (the truth's model) and the ephemeris sun direction, so both
the blind and the ephemeris-guided paths can be evaluated.

* :func:`varied_scenes` — :mod:`vision.skyrender` scenes: 480–3000 px,
  2–15 px/°, clear, cirrus, broken cumulus and overcast skies.
* :func:`fisheye_640_scenes` — the issue's hard set: 640 × 480, ≈ 2.6 px/°,
  horizon brightening, trees, a flare ghost, JPEG, thin cirrus on every other
  frame (``overcast=True``: textured overcast, no sun).
* :func:`synth_frames` — :func:`vision.synth.fisheye_frame` frames (the first
  renderer), clear and thin cloud, 640 × 480.
* :func:`tracker_rois` — 48 × 48 px regions of :func:`vision.synth.tracker_frame`
  frames around the predicted sun, clear and under drifting cloud: what the
  control loop (``sim.tracking``) gives the detector.
* :func:`wrong_ephemeris_scenes` and :func:`wrong_ephemeris_discs` — a plainly
  visible sun while the ephemeris (a wrong place, time or zone) puts it
  20–70° away (``LabelledFrame.ephemeris_deg``): the detector must still report
  the sun, with its distance from the prediction, never "no sun" because of the
  distance. The discs are the public contract's case: a saturated disc on a
  flat sky (``../shared/tools/contract-check vision``).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.cameras import FisheyeCamera, PinholeCamera
from vision.skyrender import SkyScene, random_scene, render
from vision.sphere import angular_separation_deg
from vision.synth import SynthFrame, fisheye_frame, tracker_frame

HELDOUT_SEED = 10_000


@dataclass(frozen=True)
class LabelledFrame:
    """A frame, the camera that drew it, the sun's true direction and where it came from.

    ``ephemeris_deg`` (azimuth, elevation) is where a *wrong* ephemeris puts the sun
    (place, time or zone wrong); None when the ephemeris is right (the truth).
    """

    frame: SynthFrame
    camera: FisheyeCamera
    azimuth_deg: float
    elevation_deg: float
    source: str
    seed: int
    ephemeris_deg: tuple[float, float] | None = None

    @property
    def predicted_deg(self) -> tuple[float, float]:
        """Where the ephemeris given to the detector puts the sun (az, el) [°]."""
        if self.ephemeris_deg is not None:
            return self.ephemeris_deg
        return self.azimuth_deg, self.elevation_deg


def _seeds(split: str, n: int, offset: int) -> range:
    if split not in ("development", "heldout"):
        raise ValueError(f"split must be 'development' or 'heldout', got {split!r}")
    base = (HELDOUT_SEED if split == "heldout" else 0) + offset
    return range(base, base + n)


def _from_scene(s: SkyScene, source: str) -> LabelledFrame:
    return LabelledFrame(render(s), s.camera, s.azimuth_deg, s.elevation_deg, source, s.seed)


def varied_scenes(split: str, n: int, max_size_px: int = 3000) -> Iterator[LabelledFrame]:
    """``n`` random :mod:`vision.skyrender` scenes of ``split`` (short side ≤ ``max_size_px``)."""
    for seed in _seeds(split, n, 0):
        s = random_scene(seed)
        if min(s.width_px, s.height_px) > max_size_px:
            s = random_scene(seed, width_px=int(max_size_px * 4 / 3), height_px=max_size_px)
        yield _from_scene(s, f"skyrender/{s.sky}")


def hdr_scenes(split: str, n: int, max_size_px: int = 1920) -> Iterator[LabelledFrame]:
    """``n`` random :mod:`vision.skyrender` scenes of ``split`` from an HDR camera: the merge
    tone-mapped into 8 bits (``tone="reinhard"``), so the sun is the frame's brightest
    point rather than a clipped disc and the sky lies close under it (issue 24: "rooftop
    HDR cameras"); their own seeds, short side ≤ ``max_size_px``."""
    for seed in _seeds(split, n, 3_000):
        s = random_scene(seed)
        if min(s.width_px, s.height_px) > max_size_px:
            s = random_scene(seed, width_px=int(max_size_px * 4 / 3), height_px=max_size_px)
        yield _from_scene(replace(s, tone="reinhard"), f"skyrender-hdr/{s.sky}")


def fisheye_640_scenes(split: str, n: int, overcast: bool = False) -> Iterator[LabelledFrame]:
    """640 × 480 frames at ≈ 2.6 px/° with a ghost and JPEG; thin cirrus on odd seeds."""
    for k, seed in enumerate(_seeds(split, n, 5_000 if overcast else 2_000)):
        sky = "overcast" if overcast else ("cirrus" if k % 2 else "clear")
        s = random_scene(seed, sky=sky, width_px=640, height_px=480)
        rng = np.random.default_rng(seed)
        s = replace(s, ghost=True, jpeg_quality=int(rng.choice([70, 85])),
                    elevation_deg=float(rng.uniform(15, 80)),
                    trees_deg=float(rng.uniform(2, 10)),
                    cloud_optical_depth=float(rng.uniform(0.3, 0.7)))
        yield _from_scene(s, f"fisheye640/{sky}")


def synth_frames(split: str, n: int) -> Iterator[LabelledFrame]:
    """First-renderer frames (:func:`vision.synth.fisheye_frame`): clear on even seeds,
    40 % thin cloud on odd ones, overcast (cover 1, τ 4) on every fifth."""
    cam = FisheyeCamera(319.5, 239.5, 2.6)
    for seed in _seeds(split, n, 8_000):
        rng = np.random.default_rng(seed)
        az, el = float(rng.uniform(0, 360)), float(rng.uniform(10, 80))
        kw: dict[str, float | bool] = {"ghost": bool(rng.random() < 0.5),
                                       "glare_deg": float(rng.uniform(1.0, 5.0))}
        if seed % 5 == 4:
            kw.update(cloud_cover=1.0, cloud_optical_depth=4.0)
            src = "synth/overcast"
        elif seed % 2:
            kw.update(cloud_cover=0.4, cloud_optical_depth=0.6)
            src = "synth/thin-cloud"
        else:
            src = "synth/clear"
        fr = fisheye_frame(az, el, camera=cam, seed=seed, **kw)  # type: ignore[arg-type]
        if src == "synth/overcast":
            fr = replace(fr, sun_visible=fr.sun_visible and fr.truth["transmittance"] > 0.05)
        yield LabelledFrame(fr, cam, az, el, src, seed)


@dataclass(frozen=True)
class RoiFrame:
    """A tracker-camera region of interest and its truth (``sun_px`` in ROI pixels)."""

    image: NDArray[np.uint8]
    sun_px: tuple[float, float]
    sun_visible: bool
    px_per_deg: float
    source: str
    seed: int


def tracker_rois(split: str, n: int, half_px: int = 24) -> Iterator[RoiFrame]:
    """``n`` ROIs of ``(2 half_px)²`` px cut from 640 × 480 / 67° tracker frames, centred a
    few pixels off the true sun (the prediction's error); pointing errors up to ±3°, glare
    0.5–1.2° (the control loop renders 0.8°), cloud (cover 0.3–0.9, τ 0.3–4) on odd seeds.
    The sun counts as visible when the cloud passes more than 5 % of its light."""
    for seed in _seeds(split, n, 7_000):
        rng = np.random.default_rng(seed)
        h, v = (float(a) for a in rng.uniform(-3.0, 3.0, 2))
        kw: dict[str, float] = {"glare_deg": float(rng.uniform(0.5, 1.2))}
        if seed % 2:
            kw.update(cloud_cover=float(rng.uniform(0.3, 0.9)),
                      cloud_optical_depth=float(rng.uniform(0.3, 4.0)))
        fr = tracker_frame(h, v, seed=seed, **kw)  # type: ignore[arg-type]
        sx, sy = fr.sun_px
        rows, cols = fr.image.shape[:2]
        x0 = int(np.clip(round(sx + rng.uniform(-4, 4)) - half_px, 0, cols - 2 * half_px))
        y0 = int(np.clip(round(sy + rng.uniform(-4, 4)) - half_px, 0, rows - 2 * half_px))
        img = np.ascontiguousarray(fr.image[y0:y0 + 2 * half_px, x0:x0 + 2 * half_px])
        visible = fr.sun_visible and fr.truth["transmittance"] > 0.05
        ppd = float(PinholeCamera().focal_px * np.pi / 180.0)
        yield RoiFrame(img, (sx - x0, sy - y0), visible, ppd,
                       "tracker-roi/" + ("cloud" if seed % 2 else "clear"), seed)


def far_direction(rng: np.random.Generator, azimuth_deg: float, elevation_deg: float,
                  camera: FisheyeCamera, size_px: tuple[int, int], lo_deg: float = 20.0,
                  hi_deg: float = 70.0) -> tuple[float, float]:
    """A sky direction ``lo_deg``–``hi_deg`` from (azimuth, elevation), 5–85° high and
    inside the frame (``size_px`` = width, height): where a wrong place or time puts the
    sun (rejection sampling)."""
    w, h = size_px
    for _ in range(10_000):
        az, el = float(rng.uniform(0.0, 360.0)), float(rng.uniform(5.0, 85.0))
        sep = float(angular_separation_deg(az, el, azimuth_deg, elevation_deg))
        x, y = camera.sky_to_pixel(az, el)
        if lo_deg <= sep <= hi_deg and 0.0 <= float(x) <= w - 1 and 0.0 <= float(y) <= h - 1:
            return az, el
    raise ValueError("no direction at that distance inside the frame")


def wrong_ephemeris_scenes(split: str, n: int) -> Iterator[LabelledFrame]:
    """``n`` second-renderer scenes (640 × 480 and 960 × 960, clear, cirrus or cumulus, the
    sun visible) whose ephemeris is 20–70° off: a wrong place, time or zone."""
    for k, seed in enumerate(_seeds(split, n, 6_000)):
        rng = np.random.default_rng(seed)
        size = (640, 480) if k % 2 == 0 else (960, 960)
        sky = ("clear", "cirrus", "cumulus")[k % 3]
        s = random_scene(seed, sky=sky, width_px=size[0], height_px=size[1])
        fr = render(s)
        if not fr.sun_visible:
            continue
        eph = far_direction(rng, s.azimuth_deg, s.elevation_deg, s.camera, size)
        yield LabelledFrame(fr, s.camera, s.azimuth_deg, s.elevation_deg,
                            f"wrong-ephemeris/skyrender-{sky}", seed, eph)


def disc_frame(camera: FisheyeCamera, azimuth_deg: float, elevation_deg: float,
               radius_px: float, sky_level: int, size_px: tuple[int, int] = (640, 480),
               jpeg_quality: int = 95) -> SynthFrame:
    """A saturated white disc on a flat grey sky, JPEG-compressed: the public contract's
    frame (``contract-check vision``: radius 9 px, level 40) at any place and size."""
    w, h = size_px
    x, y = (float(v) for v in camera.sky_to_pixel(azimuth_deg, elevation_deg))
    drawn = np.full((h, w, 3), sky_level, np.uint8)
    cv2.circle(drawn, (int(round(x * 16)), int(round(y * 16))), int(round(radius_px * 16)),
               (255, 255, 255), -1, cv2.LINE_AA, 4)
    ok, jpg = cv2.imencode(".jpg", drawn, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
    img: NDArray[np.uint8] = (np.asarray(cv2.imdecode(jpg, cv2.IMREAD_COLOR), np.uint8)
                              if ok else drawn)
    return SynthFrame(img, (x, y), True, {"radius_px": float(radius_px)})


def wrong_ephemeris_discs(split: str, n: int) -> Iterator[LabelledFrame]:
    """``n`` contract-like frames (a saturated disc of 4–14 px on a flat sky of level 20–140,
    640 × 480, 2.6 px/°, any north offset and mirror) whose ephemeris is 20–70° off."""
    for seed in _seeds(split, n, 9_000):
        rng = np.random.default_rng(seed)
        cam = FisheyeCamera(319.5 + float(rng.uniform(-5, 5)), 239.5 + float(rng.uniform(-5, 5)),
                            float(rng.uniform(2.4, 2.8)),
                            north_offset_deg=float(rng.uniform(0, 360)),
                            east=str(rng.choice(["left", "right"])))
        for _ in range(1000):
            az, el = float(rng.uniform(0, 360)), float(rng.uniform(10, 85))
            x, y = cam.sky_to_pixel(az, el)
            if 20 <= float(x) <= 619 and 20 <= float(y) <= 459:
                break
        fr = disc_frame(cam, az, el, float(rng.uniform(4.0, 14.0)), int(rng.integers(20, 141)),
                        jpeg_quality=int(rng.choice([75, 90, 95])))
        eph = far_direction(rng, az, el, cam, (640, 480))
        yield LabelledFrame(fr, cam, az, el, "wrong-ephemeris/disc", seed, eph)
