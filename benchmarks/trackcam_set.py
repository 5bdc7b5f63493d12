"""An independent tracker-camera set (not vision/synth): the sun behind a neutral-density
filter (unclipped, limb darkened) and the sub-pixel bias of a clipped disc, drawn after a
tester's own renderer (/work/mount-research/mymount.py: disc with limb darkening 0.4 + 0.6 μ,
a glare halo 1 / (1 + (r / 3ρ)²), noise), supersampled 8 × 8. Figures quoted by hand in
docs/validation-vision.md (not a bench section).

    .venv/bin/python benchmarks/trackcam_set.py nd --seeds 101,102,103,104   # held out
    .venv/bin/python benchmarks/trackcam_set.py phase --phases 5 --offset 0.1

``nd``: peaks 120-254 of 255 at five cameras (disc 4.5-109 px across), sky 5-40, halo 0-5 %
of the disc's contrast, noise 0.5-3 DN; found and the error [mrad]. ``phase``: noise-free
clipped suns (the disc 4000 grey levels at its centre, as the tester's) at ``phases`` ×
``phases`` sub-pixel positions and discs 4.5-42 px across; the bias [mrad]. Development seeds
were 11 and 12 and phases 4 at offset 0.
"""

from __future__ import annotations

import argparse

import numpy as np

from vision import detect
from vision.cameras import PinholeCamera

SUN_RADIUS_DEG = 0.2666


def frame(width: int, height: int, fov_deg: float, x: float, y: float, peak: float,
          sky: float, halo: float, noise_dn: float, rng: np.random.Generator,
          clip: bool = False) -> np.ndarray:
    """A BGR frame: the disc centred at (x, y) [px]; ``peak`` its centre's grey level over
    ``sky`` (4000 with ``clip``: clipped as an unfiltered camera's)."""
    f = 0.5 * width / np.tan(np.radians(fov_deg) / 2)
    rpx = f * np.tan(np.radians(SUN_RADIUS_DEG))
    ss, r = 8, int(np.ceil(rpx)) + 3
    x0, y0, n = int(np.floor(x)) - r, int(np.floor(y)) - r, 2 * r + 1
    yy, xx = np.mgrid[0:n * ss, 0:n * ss].astype(np.float64)
    rho = np.hypot(x0 + (xx + 0.5) / ss - 0.5 - x, y0 + (yy + 0.5) / ss - 0.5 - y) / rpx
    mu = np.sqrt(np.clip(1 - rho * rho, 0, 1))
    d = np.where(rho <= 1, 0.4 + 0.6 * mu, 0.0).reshape(n, ss, n, ss).mean((1, 3))
    disc = np.zeros((height, width))
    disc[y0:y0 + n, x0:x0 + n] = d
    rr = np.hypot(*np.meshgrid(np.arange(width) - x, np.arange(height) - y)) / rpx
    level = peak - sky
    img = sky + level * disc + (255.0 if clip else level) * halo / (1 + (rr / 3.0) ** 2)
    img = img + rng.normal(0, noise_dn, img.shape)
    g = np.clip(np.rint(img), 0, 255).astype(np.int64)
    return np.stack([np.clip(g + 6, 0, 255), g, np.clip(g - 4, 0, 255)], -1).astype(np.uint8)


CAMERAS = [(640, 480, 67.0), (1280, 960, 20.0), (1280, 960, 67.0), (640, 480, 30.0),
           (2048, 1536, 10.0)]


def nd(seeds: list[int]) -> None:
    for w, h, fov in CAMERAS:
        cam = PinholeCamera(w, h, fov_deg=fov)
        errs, refused = [], []
        for s in seeds:
            rng = np.random.default_rng(s)
            for p in (120, 160, 200, 240, 254):
                x = w / 2 + rng.uniform(-w / 4, w / 4)
                y = h / 2 + rng.uniform(-h / 4, h / 4)
                img = frame(w, h, fov, x, y, p, rng.uniform(5, 40), rng.uniform(0, 0.05),
                            rng.uniform(0.5, 3), rng)
                d = detect.detect_robust(img, camera=cam)
                if d.sun_found and d.centroid_px is not None:
                    errs.append(1000 * np.hypot(d.centroid_px[0] - x, d.centroid_px[1] - y)
                                / cam.focal_px)
                else:
                    refused.append(d.reason)
        e = np.array(errs)
        diam = 2 * cam.focal_px * np.tan(np.radians(SUN_RADIUS_DEG))
        line = f"{w}x{h} {fov:g}° (disc {diam:.1f} px): found {len(e)}/{len(e) + len(refused)}"
        if e.size:
            line += f", error RMS {np.sqrt((e ** 2).mean()):.3f} max {e.max():.3f} mrad"
        print(line, *sorted(set(map(str, refused)))[:2], sep="\n  " if refused else "")


def phase(phases: int, offset: float) -> None:
    allerr = []
    for w, h, fov in [(640, 480, 67.0), (640, 480, 40.0), (640, 480, 25.0), (1280, 960, 30.0),
                      (1280, 960, 20.0), (1280, 960, 16.0)]:
        cam = PinholeCamera(w, h, fov_deg=fov)
        errs = []
        for i in range(phases):
            for j in range(phases):
                x = (w - 1) / 2 + 37 + (i + offset) / phases
                y = (h - 1) / 2 - 23 + (j + offset) / phases
                img = frame(w, h, fov, x, y, 4000.0, 60.0, 0.25, 0.0,
                            np.random.default_rng(0), clip=True)
                d = detect.detect_robust(img, camera=cam)
                c = d.centroid_px if d.centroid_px is not None else (np.nan, np.nan)
                errs.append((1000 * (c[0] - x) / cam.focal_px, 1000 * (c[1] - y) / cam.focal_px))
        e = np.array(errs)
        allerr.append(e)
        diam = 2 * cam.focal_px * np.tan(np.radians(SUN_RADIUS_DEG))
        print(f"{w}x{h} {fov:g}° (disc {diam:.1f} px): bias max {np.nanmax(np.abs(e)):.3f}, "
              f"RMS {np.sqrt(np.nanmean((e ** 2).sum(1))):.3f} mrad, "
              f"missed {int(np.isnan(e[:, 0]).sum())}")
    a = np.concatenate(allerr)
    rms = np.sqrt(np.nanmean((a ** 2).sum(1)))
    print(f"all: RMS {rms:.3f}, max {np.nanmax(np.abs(a)):.3f} mrad")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="what", required=True)
    a = sub.add_parser("nd")
    a.add_argument("--seeds", default="101,102,103,104")
    b = sub.add_parser("phase")
    b.add_argument("--phases", type=int, default=5)
    b.add_argument("--offset", type=float, default=0.1)
    args = ap.parse_args()
    if args.what == "nd":
        nd([int(s) for s in args.seeds.split(",")])
    else:
        phase(args.phases, args.offset)


if __name__ == "__main__":
    main()
