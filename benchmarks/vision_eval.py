"""Vision evaluation sets and reports (issue 10), used by ``bench_vision.py``.

``bench_vision.py --evaluate [--quick]`` prints the development / held-out tables,
the reliability tables and the centre comparison of ``docs/validation-vision.md``;
``bench_vision.py --fit-confidence`` refits ``vision/confidence.json`` on the
development split only. References: the synthetic truth, the hand labels and
pvlib's SPA.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pvlib

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from vision import confidence as conf  # noqa: E402
from vision import metrics  # noqa: E402
from vision.calibrate import fit_fisheye  # noqa: E402
from vision.cameras import FisheyeCamera  # noqa: E402
from vision.candidates import _ring_values  # noqa: E402
from vision.detect import METHODS, detect_sun, to_gray  # noqa: E402
from vision.evalset import (  # noqa: E402
    LabelledFrame,
    fisheye_640_scenes,
    synth_frames,
    tracker_rois,
    varied_scenes,
)
from vision.radial import radial_symmetry_centre, sky_plane_gradient  # noqa: E402

REAL_SKY = ROOT / "tests" / "data" / "real-sky"


def real_rows() -> list[dict[str, object]]:
    """Real frames with metadata, split and the SPA sun (pvlib, apparent elevation)."""
    with (REAL_SKY / "metadata.csv").open(newline="") as fh:
        rows: list[dict[str, object]] = list(csv.DictReader(fh))
    with (REAL_SKY / "split.csv").open(newline="") as fh:
        split = {r["filename"]: r for r in csv.DictReader(fh)}
    for r in rows:
        r["image"] = cv2.imread(str(REAL_SKY / str(r["filename"])))
        r["split"] = split[str(r["filename"])]["split"]
        r["sun_visible"] = split[str(r["filename"])]["sun_visible"] == "1"
        sp = pvlib.solarposition.get_solarposition(
            pd.DatetimeIndex([pd.Timestamp(str(r["utc_time"]))]), float(str(r["lat"])),
            float(str(r["lon"])), method="nrel_numpy")
        r["sun_az"] = float(sp.azimuth.iloc[0])
        r["sun_el"] = float(sp.apparent_elevation.iloc[0])
    return rows


# --------------------------------------------------------------------------- evaluation


def synthetic_set(split: str, quick: bool = False) -> list[LabelledFrame]:
    """The labelled synthetic frames of ``split`` (both renderers, every sky)."""
    n = 6 if quick else 1
    return (list(varied_scenes(split, 60 // n, max_size_px=1920))
            + list(fisheye_640_scenes(split, 24 // n))
            + list(fisheye_640_scenes(split, 8 // n, overcast=True))
            + list(synth_frames(split, 30 // n)))


def correct_tol_px(px_per_deg: float) -> float:
    """A detection is correct within max(3 px, 0.5°)."""
    return max(3.0, 0.5 * px_per_deg)


def evaluate_synthetic(frames: list[LabelledFrame], use_ephemeris: bool, method: str = "robust"
                       ) -> list[dict[str, object]]:
    """One record per frame: features, confidence, found, correct, errors."""
    out = []
    for lf in frames:
        cam = lf.camera
        exp = None
        if use_ephemeris:
            ex, ey = cam.sky_to_pixel(lf.azimuth_deg, lf.elevation_deg)
            exp = (float(ex), float(ey))
        d = detect_sun(lf.frame.image, method=method,
                       camera=cam if method == "robust" else None, expected_px=exp)
        rec = _record(d, lf.frame.sun_px, lf.frame.sun_visible, cam, lf.azimuth_deg,
                      lf.elevation_deg)
        rec["source"] = lf.source
        out.append(rec)
    return out


def _record(d: object, truth_px: tuple[float, float], visible: bool, cam: FisheyeCamera,
            az: float, el: float) -> dict[str, object]:
    c = d.centroid_px  # type: ignore[attr-defined]
    err_px = err_deg = float("nan")
    if c is not None:
        err_px = float(np.hypot(c[0] - truth_px[0], c[1] - truth_px[1]))
        a2, e2 = cam.pixel_to_sky(*c)
        err_deg = float(metrics.angular_separation_deg(a2, e2, az, el))
    cand_ok = False
    cp = d.candidate_px  # type: ignore[attr-defined]
    if visible and cp is not None:
        r_eq = float(np.sqrt(max(d.area_px, 1) / np.pi))  # type: ignore[attr-defined]
        lim = max(3.0, 1.0 * cam.px_per_deg, r_eq)
        cand_ok = bool(np.hypot(cp[0] - truth_px[0], cp[1] - truth_px[1]) <= lim)
    feats = d.features  # type: ignore[attr-defined]
    return {"found": bool(d.sun_found), "confidence": float(d.confidence),  # type: ignore
            "visible": bool(visible), "err_px": err_px, "err_deg": err_deg,
            "reason": d.reason, "features": feats, "cand_ok": cand_ok,  # type: ignore
            "ppd": float(cam.px_per_deg)}



def roi_records(split: str, method: str = "robust", quick: bool = False
                ) -> list[dict[str, object]]:
    """Records for tracker-camera ROIs (:func:`vision.evalset.tracker_rois`), detected as the
    control loop does (no camera, no image circle)."""
    out = []
    for rf in tracker_rois(split, 60 // (6 if quick else 1)):
        kw = {"auto_fov": False} if method == "robust" else {}
        d = detect_sun(rf.image, method=method, **kw)
        c, cp = d.centroid_px, d.candidate_px
        err = (float(np.hypot(c[0] - rf.sun_px[0], c[1] - rf.sun_px[1])) if c is not None
               else float("nan"))
        r_eq = float(np.sqrt(max(d.area_px, 1) / np.pi))
        ok = bool(rf.sun_visible and cp is not None and np.hypot(
            cp[0] - rf.sun_px[0], cp[1] - rf.sun_px[1]) <= max(3.0, rf.px_per_deg, r_eq))
        out.append({"found": bool(d.sun_found), "confidence": float(d.confidence),
                    "visible": rf.sun_visible, "err_px": err, "err_deg": float("nan"),
                    "reason": d.reason, "features": d.features, "cand_ok": ok,
                    "ppd": rf.px_per_deg, "source": rf.source})
    return out


def real_records(rows: list[dict[str, object]], split: str | None, use_ephemeris: bool,
                 cam: FisheyeCamera | None, method: str = "robust") -> list[dict[str, object]]:
    """Records for the real frames of ``split`` (None: all). Without a camera (blind, as a
    new user would) the scale comes from the image circle; ``cam`` (a calibration fitted on
    the development frames) is needed for the ephemeris path."""
    out = []
    for r in rows:
        if split is not None and r["split"] != split:
            continue
        img = r["image"]
        c = cam if cam is not None and str(r["filename"]).startswith("Wettermast") else None
        exp = None
        if use_ephemeris and c is not None:
            ex, ey = c.sky_to_pixel(float(r["sun_az"]), float(r["sun_el"]))  # type: ignore
            exp = (float(ex), float(ey))
        d = detect_sun(img, method=method, camera=c if method == "robust" else None,
                       expected_px=exp)
        truth = ((float(str(r["sun_col_label"])), float(str(r["sun_row_label"])))
                 if r["sun_row_label"] else (float("nan"), float("nan")))
        ref_cam = c or FisheyeCamera(960.0, 960.0, 11.7)
        rec = _record(d, truth, bool(r["sun_visible"]), ref_cam, float(r["sun_az"]),  # type: ignore
                      float(r["sun_el"]))  # type: ignore[arg-type]
        if c is None:
            rec["err_deg"] = float("nan")
        rec["source"] = "real/" + str(r["filename"]).split("_")[0]
        rec["filename"] = r["filename"]
        out.append(rec)
    return out


def fit_confidence() -> dict[str, object]:
    """Fit the logistic confidence on the development split; returns the JSON to store."""
    cv2.setNumThreads(2)
    frames = synthetic_set("development")
    rows = real_rows()
    recs = []
    for eph in (False, True):
        recs += evaluate_synthetic(frames, eph)
        recs += real_records(rows, "development", eph, _dev_calibration(rows))
    n_frames = len(recs) // 2  # record i and i + n_frames: the same frame, blind and guided
    group_of = [i % n_frames for i in range(len(recs))]
    keep = [i for i, r in enumerate(recs) if r["features"]]
    x = np.array([[recs[i]["features"][k] for k in conf.FEATURES] for i in keep])  # type: ignore
    y = np.array([float(recs[i]["cand_ok"]) for i in keep])  # type: ignore[arg-type]
    groups = np.array([group_of[i] for i in keep])
    scores = {l2: grouped_cv_log_loss(x, y, groups, l2) for l2 in L2_GRID}
    l2 = min(scores, key=lambda k: scores[k])
    w, b = conf.fit_logistic(x, y, l2=l2)
    return {"features": list(conf.FEATURES), "weights": [round(float(v), 5) for v in w],
            "intercept": round(b, 5), "n_development": int(len(y)),
            "n_positive": int(y.sum()), "l2": l2,
            "cv_log_loss": {str(k): round(v, 4) for k, v in scores.items()},
            "fitted_by": "benchmarks/bench_vision.py --fit-confidence (development split only; "
                         "L2 penalty chosen by 5-fold cross-validation grouped by frame)"}


L2_GRID = (0.01, 0.03, 0.1, 0.3, 1.0)


def grouped_cv_log_loss(x: np.ndarray, y: np.ndarray, groups: np.ndarray, l2: float,
                        k: int = 5) -> float:
    """Mean held-out log loss of the logistic fit over ``k`` folds of whole frames
    (a frame's blind and guided records stay in the same fold)."""
    ids = np.random.default_rng(0).permutation(np.unique(groups))
    loss = 0.0
    for fold in np.array_split(ids, k):
        te = np.isin(groups, fold)
        w, b = conf.fit_logistic(x[~te], y[~te], l2=l2)
        p = np.clip(1.0 / (1.0 + np.exp(-(x[te] @ w + b))), 1e-6, 1 - 1e-6)
        loss -= float(np.sum(y[te] * np.log(p) + (1 - y[te]) * np.log(1 - p)))
    return loss / len(y)


def reliability_table(recs: list[dict[str, object]]) -> list[str]:
    """Markdown rows: confidence bin → fraction whose winning region is the sun, count."""
    edges = [0.0, 0.1, 0.3, 0.5, 0.7, 0.9, 1.0001]
    out = ["| confidence | frames | fraction correct | mean confidence |", "|---|---|---|---|"]
    conf_v = np.array([float(r["confidence"]) for r in recs])  # type: ignore[arg-type]
    ok = np.array([bool(r["cand_ok"]) for r in recs])
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        m = (conf_v >= lo) & (conf_v < hi)
        if m.sum() == 0:
            out.append(f"| {lo:.1f}–{min(hi, 1):.1f} | 0 | — | — |")
            continue
        out.append(f"| {lo:.1f}–{min(hi, 1):.1f} | {int(m.sum())} | {ok[m].mean():.2f} | "
                   f"{conf_v[m].mean():.2f} |")
    brier = float(np.mean((conf_v - ok) ** 2))
    out.append(f"| all | {len(recs)} | {ok.mean():.2f} | {conf_v.mean():.2f} (Brier "
               f"{brier:.3f}) |")
    return out


def summary(recs: list[dict[str, object]]) -> str:
    """found / visible, wrong suns, RMS and worst error [°] (or [px] when no camera)."""
    vis = [r for r in recs if r["visible"]]
    inv = [r for r in recs if not r["visible"]]
    found = [r for r in vis if r["found"]]
    invented = sum(1 for r in inv if r["found"])
    e = np.array([float(r["err_deg"]) for r in found])  # type: ignore[arg-type]
    p = np.array([float(r["err_px"]) for r in found])  # type: ignore[arg-type]
    txt = f"{len(found)}/{len(vis)} found"
    if inv:
        txt += f", {invented}/{len(inv)} no-sun frames given a sun"
    if e.size and np.isfinite(e).all():
        txt += f", {np.sqrt(np.mean(e**2)):.2f}° RMS (worst {e.max():.2f}°)"
    if p.size and np.isfinite(p).all():
        txt += f", median {np.median(p):.2f} px (worst {p.max():.1f} px)"
    return txt


def evaluation_report(quick: bool = False) -> list[str]:
    """The generalisation tables of docs/validation-vision.md (development and held-out)."""
    rows = real_rows()
    cal = _dev_calibration(rows)
    out: list[str] = []
    recs_by: dict[tuple[str, str, bool], list[dict[str, object]]] = {}
    for split in ("development", "heldout"):
        frames = synthetic_set(split, quick)
        for m in METHODS:
            for eph in ((False, True) if m == "robust" else (False,)):
                recs = evaluate_synthetic(frames, eph, m)
                recs += real_records(rows, split, eph, cal, m)
                if not eph:  # no ephemeris path for a tracker ROI
                    recs += roi_records(split, m, quick)
                recs_by[(split, m, eph)] = recs
    groups = ["skyrender/clear", "skyrender/cirrus", "skyrender/cumulus", "skyrender/overcast",
              "fisheye640/clear", "fisheye640/cirrus", "fisheye640/overcast", "synth/clear",
              "synth/thin-cloud", "synth/overcast", "real/Wettermast", "real/FE3", "real/UCEEB",
              "tracker-roi/clear", "tracker-roi/cloud"]
    cols = [("robust", False), ("robust", True), ("seed000_hsv", False),
            ("seed003_gray240", False)]
    for split in ("development", "heldout"):
        out += ["", f"**{split}** (every method given the same camera model; "
                "`robust+eph` also the ephemeris prediction)", "",
                "| set | robust | robust+eph | seed000_hsv | seed003_gray240 |",
                "|---|---|---|---|---|"]
        for g in groups:
            cells = []
            for m, eph in cols:
                sel = [r for r in recs_by[(split, m, eph)] if r["source"] == g]
                cells.append(summary(sel) if sel else "—")
            n = len([r for r in recs_by[(split, "robust", False)] if r["source"] == g])
            if n:
                out.append(f"| {g} ({n}) | " + " | ".join(cells) + " |")
    for split in ("development", "heldout"):
        recs = recs_by[(split, "robust", False)] + recs_by[(split, "robust", True)]
        out += ["", f"Reliability of `robust`'s confidence, {split} split (blind and "
                "ephemeris runs pooled; correct = the winning region is the visible sun):", ""]
        out += reliability_table(recs)
    out += ["", "Centre estimate, development split only (the choice of the reported centre "
            "is made here): RMS error against the truth", ""]
    out += centre_comparison(synthetic_set("development", quick))
    held_real = [r for r in recs_by[("heldout", "robust", False)]
                 if str(r["source"]).startswith("real/")]
    out += ["", "Held-out real frames, `robust` blind (distance to the hand label, "
            "confidence, reason):", "", "| frame | found | distance | confidence | reason |",
            "|---|---|---|---|---|"]
    for r in held_real:
        dist = f"{float(r['err_px']):.2f} px" if r["found"] and np.isfinite(
            float(r["err_px"])) else "—"  # type: ignore[arg-type]
        out.append(f"| {r['filename']} | {r['found']} | {dist} | {float(r['confidence']):.2f} | "  # type: ignore[arg-type]
                   f"{r['reason'] or ''} |")
    return out


def centre_comparison(frames: list[LabelledFrame]) -> list[str]:
    """Markdown rows: RMS error [°] of the reported centre against the radial-symmetry
    centre (Parthasarathy 2012, on the camera's tangent plane, started at the reported
    centre; window 2 R + 4 px, the detector's dark and glare levels), without and with
    the sky's plane gradient removed and the saturated limb left out, per set, on the
    frames where ``robust`` found the sun."""
    errs: dict[str, list[tuple[float, float, float]]] = {}
    for lf in frames:
        if not lf.frame.sun_visible:
            continue
        cam = lf.camera
        d = detect_sun(lf.frame.image, camera=cam)
        if not d.sun_found or d.centroid_px is None:
            continue
        g = to_gray(lf.frame.image)
        cx, cy = d.centroid_px
        r = d.radius_px
        ring = _ring_values(g, cx, cy, 2.0 * r + 3.0, None)  # as the detector's coherence
        bg = float(np.median(ring)) if ring.size else 0.0
        glare = bg + 0.3 * (float(g.max()) - bg)

        def sep(x: float, y: float, cam: FisheyeCamera = cam, lf: LabelledFrame = lf) -> float:
            a, e = cam.pixel_to_sky(x, y)
            return float(metrics.angular_separation_deg(a, e, lf.azimuth_deg, lf.elevation_deg))

        out = [sep(cx, cy)]
        for sat in (256.0, 250.0):
            grad = (0.0, 0.0) if sat > 255 else sky_plane_gradient(
                g, cx, cy, 1.5 * r + 2, 2.5 * r + 6, 0.6 * bg, sat)
            f = radial_symmetry_centre(g, (cx, cy), 2.0 * r + 4.0, dark_level=0.6 * bg,
                                       glare_level=glare, camera=cam, saturated_level=sat,
                                       sky_gradient=grad)
            out.append(sep(f.x_px, f.y_px) if f is not None else float("nan"))
        errs.setdefault(lf.source, []).append((out[0], out[1], out[2]))
    rows = ["| set (frames) | reported centre | radial symmetry | radial, sky gradient removed, "
            "saturated limb out |", "|---|---|---|---|"]
    for src in sorted(errs):
        e = np.array(errs[src])
        rms = np.sqrt(np.nanmean(e**2, axis=0))
        rows.append(f"| {src} ({len(e)}) | {rms[0]:.3f}° | {rms[1]:.3f}° | {rms[2]:.3f}° |")
    return rows


def _dev_calibration(rows: list[dict[str, object]]) -> FisheyeCamera | None:
    """Equidistant calibration from the blind detections on the development real frames."""
    dev = [r for r in rows if r["split"] == "development" and r["sun_row_label"]]
    xy, az, el = [], [], []
    for r in dev:
        d = detect_sun(r["image"], "robust")
        if d.centroid_px is not None:
            xy.append(d.centroid_px)
            az.append(r["sun_az"])
            el.append(r["sun_el"])
    if len(xy) < 3:
        return None
    a = np.array(xy)
    return fit_fisheye(a[:, 0], a[:, 1], np.array(az), np.array(el), (1920, 1920)).camera
