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
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from vision.cameras import FisheyeCamera
from vision.skyrender import SkyScene, random_scene, render
from vision.synth import SynthFrame, fisheye_frame

HELDOUT_SEED = 10_000


@dataclass(frozen=True)
class LabelledFrame:
    """A frame, the camera that drew it, the sun's true direction and where it came from."""

    frame: SynthFrame
    camera: FisheyeCamera
    azimuth_deg: float
    elevation_deg: float
    source: str
    seed: int


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
