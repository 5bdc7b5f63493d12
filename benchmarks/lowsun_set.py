"""An independent low-sun fisheye set (not the repo's vision/synth or vision/skyrender) and
its blind evaluation through the CLI, as a new user runs it (``--camera fisheye`` only).

    .venv/bin/python benchmarks/lowsun_set.py render build/lowsun/open --n 30 --seed 5000
    .venv/bin/python benchmarks/lowsun_set.py render build/lowsun/cut --n 24 --seed 7000 --cut
    .venv/bin/python benchmarks/lowsun_set.py evaluate build/lowsun/open

Each frame: a lens projection (equidistant, equisolid, orthographic, stereographic, a radial
polynomial), 880-3000 px, a tilt up to 6° and a principal point up to 4 % off-centre, a
skyline of buildings and trees, haze, a sun 0-25° high. ``--cut`` puts an obstacle edge at
the sun: even frames 0-0.5° below the disc's centre (visible, cut), odd ones 1.2-4° above
it (the disc hidden, its aureole above the edge). The truth is the sun's direction through
the same lens (where a person puts the disc's centre). Made for issue 24's low-sun check;
the figures are quoted by hand in docs/validation-vision.md (not a bench section).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np

SUN_RADIUS_DEG = 0.2665
LENSES = ("equidistant", "equisolid", "orthographic", "stereographic", "poly")


def radius_of(kind: str, f_px: float, theta: np.ndarray, k: tuple[float, float]) -> np.ndarray:
    """The lens's image radius [px] at zenith angle ``theta`` [rad]."""
    if kind == "equidistant":
        return f_px * theta
    if kind == "equisolid":
        return 2 * f_px * np.sin(theta / 2)
    if kind == "orthographic":
        return f_px * np.sin(np.minimum(theta, np.pi / 2))
    if kind == "stereographic":
        return 2 * f_px * np.tan(theta / 2)
    return f_px * (theta + k[0] * theta**3 + k[1] * theta**5)


def _rotation(tilt_deg: float, tilt_az_deg: float, north_deg: float) -> np.ndarray:
    a = np.radians(north_deg)
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    t, b = np.radians(tilt_deg), np.radians(tilt_az_deg)
    ax = np.array([np.cos(b), np.sin(b), 0.0])
    k = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
    return (np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * k @ k) @ rz


def _skyline(rng: np.random.Generator, kind: str) -> tuple[np.ndarray, np.ndarray]:
    az = np.arange(0, 360, 0.05)
    h = np.zeros_like(az)
    if kind in ("buildings", "mixed"):
        a = 0.0
        while a < 360:
            w = rng.uniform(5, 30)
            hh = rng.uniform(0, 12) if rng.random() < 0.7 else 0.0
            sel = (az >= a) & (az < a + w)
            h[sel] = np.maximum(h[sel], hh)
            a += w
    if kind in ("trees", "mixed"):
        for _ in range(int(rng.integers(4, 10))):
            c, w, hh = rng.uniform(0, 360), rng.uniform(4, 25), rng.uniform(3, 18)
            d = np.abs((az - c + 180) % 360 - 180)
            prof = hh * np.sqrt(np.clip(1 - (d / w) ** 2, 0, 1))
            prof = prof + (prof > 0) * rng.normal(0, 0.6, az.size)  # ragged crowns
            h = np.maximum(h, prof)
        h = cv2.GaussianBlur(h.reshape(1, -1).astype(np.float32), (0, 0), 2).ravel()
    return az, np.maximum(h, rng.uniform(0, 1.5))


def render(spec: dict[str, Any]) -> tuple[np.ndarray, dict[str, Any]]:
    """One BGR frame and its truth."""
    rng = np.random.default_rng(spec["seed"])
    w = spec["width"]
    h = spec.get("height", w)
    kind, k = spec["lens"], tuple(spec.get("k", (0.0, 0.0)))
    half_fov = np.radians(spec["fov_deg"] / 2)
    circle_px = spec["circle_frac"] * min(w, h)
    f_px = circle_px / float(radius_of(kind, 1.0, np.array(half_fov), k))
    cx, cy = w / 2 - 0.5 + spec["dx"], h / 2 - 0.5 + spec["dy"]
    rot = _rotation(spec["tilt"], spec["tilt_az"], spec["north"])
    saz, sel = np.radians(spec["sun_az"]), np.radians(spec["sun_el"])
    sun = np.array([np.sin(saz) * np.cos(sel), np.cos(saz) * np.cos(sel), np.sin(sel)])
    s_cam = rot.T @ sun
    th_s, ph_s = np.arccos(np.clip(s_cam[2], -1, 1)), np.arctan2(s_cam[1], s_cam[0])
    rs = float(radius_of(kind, f_px, np.array(th_s), k))
    truth = (cx + rs * np.cos(ph_s), cy - rs * np.sin(ph_s))
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    dx, dy = xx - cx, cy - yy
    r = np.hypot(dx, dy)
    grid = np.linspace(0, half_fov, 4000)
    th = np.interp(r, radius_of(kind, f_px, grid, k), grid, right=np.nan)
    inside = np.isfinite(th) & (r <= circle_px)
    th = np.nan_to_num(th)
    ph = np.arctan2(dy, dx)
    v = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1) @ rot.T
    el = np.degrees(np.arcsin(np.clip(v[..., 2], -1, 1)))
    az = np.degrees(np.arctan2(v[..., 0], v[..., 1])) % 360
    gam = np.degrees(np.arccos(np.clip(v @ sun, -1, 1)))
    sky_az, sky_h = _skyline(rng, spec["skyline"])
    if "edge_deg" in spec:  # an obstacle edge at the sun's azimuth
        d = np.abs((sky_az - spec["sun_az"] + 180) % 360 - 180)
        sky_h = np.where(d < 12, spec["edge_deg"], sky_h)
    ground = el < np.interp(az, sky_az, sky_h)
    edge_at_sun = float(np.interp(spec["sun_az"], sky_az, sky_h))
    haze = spec["haze"]
    zen = np.radians(90 - np.clip(el, 0, 90))
    sky = (0.08 + 0.2 * (1 - np.exp(-0.5 / np.maximum(np.cos(zen), 0.05)))) * (1 + 1.5 * haze)
    aureole = ((1 + 4 * haze) * 0.6 * np.exp(-gam / (3 + 8 * haze))
               + 0.6 * (1 + haze) / (1 + gam**2))
    disc = 1e4 * np.clip((SUN_RADIUS_DEG - gam) / spec["deg_per_px"] + 0.5, 0, 1) * ~ground
    shows = float(np.clip((spec["sun_el"] - edge_at_sun) / (2 * SUN_RADIUS_DEG) + 0.5, 0, 1))
    lens = shows * spec["glare"] * 6.0 / (1 + (gam / 1.2) ** 2.2)  # the lens's veiling glare
    base = np.where(ground, 0.12 + 0.05 * rng.random(), sky + aureole)
    lum = base + disc + lens
    tint = np.where(ground, 0.7, 1.0)[..., None] * np.array([1.0, 0.72 + 0.15 * haze,
                                                             0.45 + 0.3 * haze])
    white = np.clip((aureole + lens + disc) / np.maximum(base + lens + disc, 1e-6), 0, 1)
    col = lum[..., None] * (tint * (1 - white[..., None]) + white[..., None])
    img = 255 * np.clip(spec["gain"] * col, 0, None) ** (1 / 2.2) + rng.normal(0, 1.5, col.shape)
    img[~inside] = rng.uniform(0, 6)
    above = spec["sun_el"] - edge_at_sun
    return np.clip(img, 0, 255).astype(np.uint8), {
        "truth": [float(truth[0]), float(truth[1])], "sun_el": spec["sun_el"],
        "skyline_at_sun": edge_at_sun, "visible": bool(above >= 0.0),
        "hidden": bool(above <= -2 * SUN_RADIUS_DEG - 0.5)}


def specs(n: int, seed0: int, cut: bool) -> list[dict[str, Any]]:
    """The frames' parameters (seeded: the same set every time)."""
    out = []
    rng = np.random.default_rng(seed0)
    edges = np.random.default_rng(1)
    for i in range(n):
        w = int(rng.choice([880, 1280, 1536, 1920, 2464, 3000]))
        s: dict[str, Any] = {
            "seed": seed0 + i, "width": w, "lens": LENSES[i % len(LENSES)],
            "fov_deg": float(rng.uniform(178, 192)), "circle_frac": float(rng.uniform(0.44, 0.5)),
            "dx": float(rng.uniform(-0.04, 0.04) * w), "dy": float(rng.uniform(-0.04, 0.04) * w),
            "tilt": float(rng.uniform(0, 6)), "tilt_az": float(rng.uniform(0, 360)),
            "north": float(rng.uniform(0, 360)), "sun_az": float(rng.uniform(0, 360)),
            "sun_el": float(rng.uniform(0, 25)), "haze": float(rng.uniform(0, 0.6)),
            "gain": float(rng.uniform(0.6, 1.4)), "glare": float(rng.uniform(0.5, 1.5)),
            "skyline": str(rng.choice(["buildings", "trees", "mixed"])),
            "deg_per_px": 180.0 / w * 1.1}
        if s["lens"] == "poly":
            s["k"] = (float(rng.uniform(-0.08, 0.02)), float(rng.uniform(-0.01, 0.01)))
        if w == 2464:
            s["height"] = 2056
        if cut:
            if i % 2 == 0:
                s["edge_deg"] = max(s["sun_el"] - float(edges.uniform(0.0, 0.5)), 0.0)
            else:
                s["edge_deg"] = s["sun_el"] + float(edges.uniform(1.2, 4))
            s["sun_el"] = max(s["sun_el"], 2.0)
        out.append(s)
    return out


def cmd_render(args: argparse.Namespace) -> int:
    out = Path(args.outdir)
    out.mkdir(parents=True, exist_ok=True)
    meta = []
    for s in specs(args.n, args.seed, args.cut):
        img, m = render(s)
        name = f"{'cut' if args.cut else 'ls'}_{s['seed']}_{s['lens']}_{s['width']}.png"
        cv2.imwrite(str(out / name), img)
        meta.append({"name": name, "spec": s, **m})
        print(name, m, flush=True)
    (out / "meta.json").write_text(json.dumps(meta, indent=1))
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    d = Path(args.outdir)
    cli = os.environ.get("HELIOTWIN", str(Path(sys.executable).with_name("heliotwin")))
    vis, hid = [], []
    for m in json.loads((d / "meta.json").read_text()):
        p = subprocess.run([cli, "vision", "detect", str(d / m["name"]), "--camera", "fisheye",
                            "--json"], capture_output=True, text=True, check=False)
        w = m["spec"]["width"]
        if p.returncode:
            print(f"{m['name']}: error {p.stderr.strip()[-200:]}")
            (vis if m["visible"] else hid).append((False, 0.0, float("nan")))
            continue
        j = json.loads(p.stdout)
        err = float("nan")
        if j["sun_found"]:
            err = 100 * float(np.hypot(j["centroid_px"][0] - m["truth"][0],
                                       j["centroid_px"][1] - m["truth"][1])) / w
        state = "visible" if m["visible"] else "hidden" if m["hidden"] else "ambiguous"
        print(f"{m['name']:36s} {state:9s} el {m['sun_el']:5.1f}° edge {m['skyline_at_sun']:5.1f}° "
              f"found {j['sun_found']!s:5s} conf {j['confidence']:.2f} err {err:.2f} % "
              f"{j['reason'] or ''}")
        if m["visible"]:
            vis.append((j["sun_found"], j["confidence"], err))
        elif m["hidden"]:
            hid.append((j["sun_found"], j["confidence"], err))
    ok = sum(f and c >= 0.5 and e <= 1.0 for f, c, e in vis)
    errs = [e for f, _, e in vis if f]
    print(f"visible {len(vis)}: {ok} found with confidence >= 0.5 within 1 % of the width; "
          f"found {sum(f for f, _, _ in vis)}; median {np.median(errs) if errs else np.nan:.2f} %"
          f", worst {max(errs) if errs else np.nan:.2f} %")
    print(f"hidden {len(hid)}: {sum(c >= 0.3 for _, c, _ in hid)} at confidence >= 0.3")
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("render")
    r.add_argument("outdir")
    r.add_argument("--n", type=int, default=30)
    r.add_argument("--seed", type=int, default=5000)
    r.add_argument("--cut", action="store_true")
    e = sub.add_parser("evaluate")
    e.add_argument("outdir")
    args = ap.parse_args()
    return cmd_render(args) if args.cmd == "render" else cmd_evaluate(args)


if __name__ == "__main__":
    sys.exit(main())
