"""Equivalence check (not a timed test): ``detect_robust``'s answers of this tree against
those of another git revision, on every frame the vision evaluations use.

    .venv/bin/python benchmarks/vision_equivalence.py [--against REV] [--quick]

The frames are rendered once (by this tree's renderers) and cached under
``build/vision-equivalence/``; the detector of ``REV`` (default ``main``) runs in a
subprocess on ``git archive REV vision``, this tree's in another, each writing its answers;
then every run is compared: the sun found or refused and the reason, the centre (to less
than 0.01 px), the winning region's centroid and the confidence. The runs: the speed
bench's frames (tracker and fisheye 640 × 480, flare and bloom, blind and with the camera),
the development and held-out synthetic sets with the HDR scenes (blind and guided), the
tracker ROIs (no image circle), and the real frames (blind, ``min_confidence=0``, guided
by the development calibration with the right clock and one 3 h off).

Exit status 0 when every run agrees.
"""

from __future__ import annotations

import argparse
import pickle
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "build" / "vision-equivalence"
TOL_PX = 0.01

Run = tuple[str, str, dict[str, Any]]  # (name, frame key, detect_sun keyword arguments)


def _camera_spec(cam: Any) -> tuple[str, dict[str, Any]] | None:
    """A camera as (class name, constructor fields), so that either tree rebuilds it."""
    if cam is None:
        return None
    import dataclasses

    return type(cam).__name__, {f.name: getattr(cam, f.name) for f in dataclasses.fields(cam)}


def build_runs(quick: bool) -> tuple[dict[str, np.ndarray], list[Run]]:
    """Every frame (by key) and every detection run on them."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    sys.path.insert(0, str(ROOT))
    import bench_vision as bv

    from vision.cameras import FisheyeCamera, PinholeCamera
    from vision.evalset import hdr_scenes, tracker_rois

    frames: dict[str, np.ndarray] = {}
    runs: list[Run] = []
    # the speed bench's frames: blind with no camera (what is timed), and with the camera
    # (its accuracy tables)
    fe_cam, tr_cam = FisheyeCamera(319.5, 239.5, 2.6), PinholeCamera()
    sets = {"bench/tracker": (bv.tracker_set(24), tr_cam),
            "bench/tracker-flare": (bv.tracker_set(12, flare=True, ghost=True), tr_cam),
            "bench/tracker-bloom": (bv.tracker_set(12, bloom=1.0, glare_deg=2.0), tr_cam),
            "bench/fisheye-clear": (bv.fisheye_set(), fe_cam),
            "bench/fisheye-cloud": (bv.fisheye_set(cloud_cover=0.4, cloud_optical_depth=0.6),
                                    fe_cam)}
    for name, (items, cam) in sets.items():
        for i, (img, _, _) in enumerate(items):
            key = f"{name}#{i}"
            frames[key] = img
            runs.append((key + " blind", key, {}))
            runs.append((key + " camera", key, {"camera": _camera_spec(cam)}))
    # the synthetic evaluation sets, both splits, blind and guided with each frame's camera
    for split in ("development", "heldout"):
        lfs = bv.synthetic_set(split, quick) + list(hdr_scenes(split, 40 // (6 if quick else 1)))
        for lf in lfs:
            key = f"{split}/{lf.source}#{lf.seed}"
            frames[key] = lf.frame.image
            cam = _camera_spec(lf.camera)
            ex, ey = lf.camera.sky_to_pixel(*lf.predicted_deg)
            runs.append((key + " blind", key, {"camera": cam}))
            runs.append((key + " guided", key,
                         {"camera": cam, "expected_px": (float(ex), float(ey))}))
            runs.append((key + " no-camera", key, {}))
        for rf in tracker_rois(split, 60 // (6 if quick else 1)):
            key = f"{split}/{rf.source}#{rf.seed}"
            frames[key] = rf.image
            runs.append((key + " roi", key, {"auto_fov": False}))
    # the real frames: blind, every winner (min_confidence 0), guided by the development
    # calibration (right clock, 3 h off)
    rows = bv.real_rows() if bv.REAL_SKY.exists() else []
    cal = bv._dev_calibration(rows) if rows else None
    for r in rows:
        if r["image"] is None:
            continue
        key = f"real/{r['filename']}"
        frames[key] = r["image"]
        runs.append((key + " blind", key, {}))
        runs.append((key + " min0", key, {"min_confidence": 0.0}))
        if cal is not None and str(r["filename"]).startswith("Wettermast"):
            for tag, az, el in (("guided", r["sun_az"], r["sun_el"]),
                                ("wrong-clock", r["wrong_az"], r["wrong_el"])):
                ex, ey = cal.sky_to_pixel(float(az), float(el))  # type: ignore[arg-type]
                runs.append((f"{key} {tag}", key, {"camera": _camera_spec(cal),
                                                   "expected_px": (float(ex), float(ey))}))
    return frames, runs


def detect_all(src: Path, data: Path, out: Path) -> None:
    """Run the detector of the tree at ``src`` on the cached runs; answers to ``out``."""
    sys.path.insert(0, str(src))
    import cv2

    import vision.cameras as cams
    from vision.detect import detect_sun

    assert Path(cams.__file__).resolve().is_relative_to(src.resolve()), cams.__file__
    cv2.setNumThreads(1)
    with data.open("rb") as fh:
        frames, runs = pickle.load(fh)
    answers = {}
    for name, key, kw in runs:
        kw = dict(kw)
        if kw.get("camera") is not None:
            cls, fields = kw["camera"]
            kw["camera"] = getattr(cams, cls)(**fields)
        d = detect_sun(frames[key], "robust", **kw)
        answers[name] = {"found": d.sun_found, "centre": d.centroid_px,
                         "candidate": d.candidate_px, "confidence": d.confidence,
                         "reason": d.reason, "fov": d.fov, "area": d.area_px,
                         "features": d.features}
    with out.open("wb") as fh:
        pickle.dump(answers, fh)


def _dist(a: tuple[float, float] | None, b: tuple[float, float] | None) -> float:
    if a is None or b is None:
        return 0.0 if a is b else float("inf")
    return float(np.hypot(a[0] - b[0], a[1] - b[1]))


def compare(old: dict[str, dict[str, Any]], new: dict[str, dict[str, Any]]) -> int:
    """Print the differences; returns the number of runs that differ."""
    bad = 0
    worst_c = worst_p = 0.0
    for name in old:
        a, b = old[name], new[name]
        dc = _dist(a["centre"], b["centre"])
        worst_c = max(worst_c, dc)
        worst_p = max(worst_p, abs(a["confidence"] - b["confidence"]))
        diffs = []
        if a["found"] != b["found"]:
            diffs.append(f"found {a['found']} → {b['found']}")
        if not dc < TOL_PX:
            diffs.append(f"centre {a['centre']} → {b['centre']}")
        if not _dist(a["candidate"], b["candidate"]) < TOL_PX:
            diffs.append(f"candidate {a['candidate']} → {b['candidate']}")
        if a["reason"] != b["reason"]:
            diffs.append(f"reason {a['reason']!r} → {b['reason']!r}")
        if abs(a["confidence"] - b["confidence"]) > 1e-4:
            diffs.append(f"confidence {a['confidence']} → {b['confidence']}")
        if a["fov"] != b["fov"]:
            diffs.append(f"fov {a['fov']} → {b['fov']}")
        if diffs:
            bad += 1
            print(f"DIFF {name}: " + "; ".join(diffs))
    found = sum(1 for v in new.values() if v["found"])
    print(f"{len(old)} runs ({found} suns found): {bad} differ; largest centre move "
          f"{worst_c:.2g} px, largest confidence change {worst_p:.2g}")
    return bad


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--against", default="main", help="the git revision to compare with")
    ap.add_argument("--quick", action="store_true", help="a sixth of the synthetic sets")
    ap.add_argument("--detect", nargs=3, metavar=("SRC", "DATA", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.detect:
        detect_all(*(Path(p) for p in args.detect))
        return 0
    CACHE.mkdir(parents=True, exist_ok=True)
    data = CACHE / f"runs{'-quick' if args.quick else ''}.pkl"
    if not data.exists():
        print("rendering the frames (once; cached in build/vision-equivalence/)",
              file=sys.stderr)
        runs = build_runs(args.quick)
        with data.with_suffix(".part").open("wb") as fh:
            pickle.dump(runs, fh)
        data.with_suffix(".part").replace(data)
    with tempfile.TemporaryDirectory(prefix="vision-equivalence-") as tmp:
        old_src = Path(tmp) / "old"
        old_src.mkdir()
        tar = Path(tmp) / "vision.tar"
        subprocess.run(["git", "-C", str(ROOT), "archive", "-o", str(tar), args.against,
                        "vision"], check=True)
        with tarfile.open(tar) as tf:
            tf.extractall(old_src, filter="data")
        outs = []
        for name, src in (("old", old_src), ("new", ROOT)):
            out = Path(tmp) / f"{name}.pkl"
            print(f"detecting with {name} ({args.against if name == 'old' else 'this tree'})",
                  file=sys.stderr)
            subprocess.run([sys.executable, __file__, "--detect", str(src), str(data),
                            str(out)], check=True)
            with out.open("rb") as fh:
                outs.append(pickle.load(fh))
    return 1 if compare(*outs) else 0


if __name__ == "__main__":
    sys.exit(main())
