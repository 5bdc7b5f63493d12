"""Scoring a detector on labelled frames (issue 10): records, summaries, reliability, the fit.

One *record* (a plain dict) per frame and run: whether the sun was found, the
confidence, the error against the truth [px, °], the confidence's features,
and whether the winning region *is* the visible sun (``cand_ok``: its centroid
within max(3 px, 1°, the region's own radius) of the truth — the event the
confidence is the probability of, found or not). ``benchmarks/bench_vision.py``
builds the tables of ``docs/validation-vision.md`` from these records and
fits ``vision/confidence.json`` on the development split's records only
(:func:`fit_confidence`).

References are never the detector: the synthetic truth (the camera model's
projection of the sun a frame was drawn around) or, for real frames, the hand
labels and pvlib's SPA (the caller's).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from vision import confidence as conf
from vision.cameras import FisheyeCamera
from vision.detect import detect_sun
from vision.detection import SunDetection
from vision.evalset import LabelledFrame, RoiFrame
from vision.sphere import angular_separation_deg

Record = dict[str, Any]

L2_GRID: tuple[float, ...] = (0.01, 0.03, 0.1, 0.3, 1.0)
"""Penalties tried by :func:`fit_confidence` (5-fold cross-validation grouped by frame)."""

RELIABILITY_EDGES: tuple[float, ...] = (0.0, 0.1, 0.3, 0.5, 0.7, 0.9, 1.0001)


def correct_limit_px(px_per_deg: float, area_px: int) -> float:
    """How far [px] the winning region's centroid may lie from the truth and still be the
    sun: max(3 px, 1°, the region's equivalent radius)."""
    return max(3.0, px_per_deg, float(np.sqrt(max(area_px, 1) / np.pi)))


def record(d: SunDetection, truth_px: tuple[float, float], visible: bool,
           camera: FisheyeCamera | None, azimuth_deg: float, elevation_deg: float,
           px_per_deg: float) -> Record:
    """One record of detection ``d`` against the truth (``camera`` None: no angles)."""
    c = d.centroid_px
    err_px = err_deg = float("nan")
    if c is not None:
        err_px = float(np.hypot(c[0] - truth_px[0], c[1] - truth_px[1]))
        if camera is not None:
            a2, e2 = camera.pixel_to_sky(*c)
            err_deg = float(angular_separation_deg(a2, e2, azimuth_deg, elevation_deg))
    cand_ok = False
    cp = d.candidate_px
    if visible and cp is not None and np.isfinite(truth_px[0]):
        cand_ok = bool(np.hypot(cp[0] - truth_px[0], cp[1] - truth_px[1])
                       <= correct_limit_px(px_per_deg, d.area_px))
    return {"found": bool(d.sun_found), "confidence": float(d.confidence),
            "visible": bool(visible), "err_px": err_px, "err_deg": err_deg,
            "reason": d.reason, "features": dict(d.features), "cand_ok": cand_ok,
            "ppd": float(px_per_deg), "distance_px": d.distance_from_ephemeris_px}


def evaluate(frames: Iterable[LabelledFrame], use_ephemeris: bool, method: str = "robust"
             ) -> list[Record]:
    """Records of ``method`` on ``frames``, blind or given the ephemeris prediction
    (``LabelledFrame.predicted_deg`` through the frame's camera — wrong on purpose for
    the wrong-ephemeris sets). Every method gets the same camera model."""
    out = []
    for lf in frames:
        cam = lf.camera
        exp = None
        if use_ephemeris:
            ex, ey = cam.sky_to_pixel(*lf.predicted_deg)
            exp = (float(ex), float(ey))
        d = detect_sun(lf.frame.image, method=method, camera=cam if method == "robust" else None,
                       expected_px=exp)
        rec = record(d, lf.frame.sun_px, lf.frame.sun_visible, cam, lf.azimuth_deg,
                     lf.elevation_deg, cam.px_per_deg)
        rec.update(source=lf.source, frame=f"{lf.source}#{lf.seed}", ephemeris=use_ephemeris,
                   wrong_ephemeris=use_ephemeris and lf.ephemeris_deg is not None)
        out.append(rec)
    return out


def roi_records(rois: Iterable[RoiFrame], method: str = "robust") -> list[Record]:
    """Records on tracker-camera ROIs, detected as the control loop does (``sim.tracking``:
    no camera, no image circle); errors in ROI pixels only."""
    out = []
    for rf in rois:
        kw: dict[str, Any] = {"auto_fov": False} if method == "robust" else {}
        d = detect_sun(rf.image, method=method, **kw)
        rec = record(d, rf.sun_px, rf.sun_visible, None, float("nan"), float("nan"),
                     rf.px_per_deg)
        rec.update(source=rf.source, frame=f"{rf.source}#{rf.seed}", ephemeris=False,
                   wrong_ephemeris=False)
        out.append(rec)
    return out


def summary(recs: list[Record]) -> str:
    """``found/visible``, suns given on no-sun frames, RMS and worst error [°] (when the
    camera is known), median and worst [px]."""
    vis = [r for r in recs if r["visible"]]
    inv = [r for r in recs if not r["visible"]]
    found = [r for r in vis if r["found"]]
    txt = f"{len(found)}/{len(vis)} found"
    if inv:
        txt += f", {sum(1 for r in inv if r['found'])}/{len(inv)} no-sun frames given a sun"
    e = np.array([float(r["err_deg"]) for r in found])
    p = np.array([float(r["err_px"]) for r in found])
    if e.size and np.isfinite(e).all():
        txt += f", {np.sqrt(np.mean(e**2)):.2f}° RMS (worst {e.max():.2f}°)"
    if p.size and np.isfinite(p).all():
        txt += f", median {np.median(p):.2f} px (worst {p.max():.1f} px)"
    return txt


def brier(recs: list[Record]) -> float:
    """Mean squared difference between the confidence and the outcome (``cand_ok``)."""
    c = np.array([float(r["confidence"]) for r in recs])
    ok = np.array([float(r["cand_ok"]) for r in recs])
    return float(np.mean((c - ok) ** 2)) if c.size else float("nan")


def reliability_rows(recs: list[Record]) -> list[str]:
    """Markdown table: confidence bin → runs, fraction whose winning region is the visible
    sun, mean confidence; last row all runs with the Brier score."""
    out = ["| confidence | runs | fraction correct | mean confidence |", "|---|---|---|---|"]
    c = np.array([float(r["confidence"]) for r in recs])
    ok = np.array([bool(r["cand_ok"]) for r in recs])
    edges = RELIABILITY_EDGES
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        m = (c >= lo) & (c < hi)
        label = f"{lo:.1f}–{min(hi, 1.0):.1f}"
        if not m.any():
            out.append(f"| {label} | 0 | — | — |")
            continue
        out.append(f"| {label} | {int(m.sum())} | {ok[m].mean():.2f} | {c[m].mean():.2f} |")
    out.append(f"| all | {len(recs)} | {ok.mean():.2f} | {c.mean():.2f} (Brier "
               f"{brier(recs):.3f}) |")
    return out


def design(recs: list[Record]) -> tuple[NDArray[np.float64], NDArray[np.float64], list[str]]:
    """``(x, y, groups)`` of the records whose candidate is :func:`vision.confidence.admissible`
    (the model is fitted on those only: the others get probability 0)."""
    keep = [r for r in recs if r["features"] and conf.admissible(
        np.array([r["features"][k] for k in conf.FEATURES], dtype=float))]
    x = np.array([[r["features"][k] for k in conf.FEATURES] for r in keep], dtype=float)
    y = np.array([float(r["cand_ok"]) for r in keep])
    return x, y, [str(r["frame"]) for r in keep]


def grouped_cv_log_loss(x: NDArray[np.float64], y: NDArray[np.float64], groups: list[str],
                        l2: float, k: int = 5) -> float:
    """Mean held-out log loss of the logistic fit over ``k`` folds of whole frames (a
    frame's blind, guided and wrong-ephemeris runs stay in one fold)."""
    g = np.array(groups)
    ids = np.random.default_rng(0).permutation(np.unique(g))
    loss = 0.0
    for fold in np.array_split(ids, k):
        te = np.isin(g, fold)
        w, b = conf.fit_logistic(x[~te], y[~te], l2=l2)
        p = np.clip(1.0 / (1.0 + np.exp(-(x[te] @ w + b))), 1e-6, 1 - 1e-6)
        loss -= float(np.sum(y[te] * np.log(p) + (1 - y[te]) * np.log(1 - p)))
    return loss / len(y)


def fit_confidence(recs: list[Record], note: str, l2_grid: tuple[float, ...] = L2_GRID
                   ) -> dict[str, Any]:
    """The logistic confidence fitted on ``recs`` (development records only!), its L2
    penalty chosen by grouped cross-validation; the JSON of ``confidence.json``."""
    x, y, groups = design(recs)
    scores = {l2: grouped_cv_log_loss(x, y, groups, l2) for l2 in l2_grid}
    l2 = min(scores, key=lambda v: scores[v])
    w, b = conf.fit_logistic(x, y, l2=l2)
    return {"features": list(conf.FEATURES), "weights": [round(float(v), 5) for v in w],
            "intercept": round(b, 5), "n_development": int(len(y)),
            "n_positive": int(y.sum()), "n_frames": len(set(groups)), "l2": l2,
            "cv_log_loss": {str(k): round(v, 4) for k, v in scores.items()},
            "fitted_by": note}


CAMERAS: tuple[str, ...] = ("Wettermast", "Wolf", "FE3", "UCEEB", "EUROCONTROL")
"""The real cameras of ``tests/data/real-sky`` (``split.csv``'s ``camera``): the folds of
the leave-one-camera-out evaluation (issue 24 item 1)."""


def nearest_direction_px(azimuth_deg: NDArray[np.float64], zenith_deg: NDArray[np.float64],
                         sun_azimuth_deg: float, sun_zenith_deg: float
                         ) -> tuple[float, float, float]:
    """The pixel ``(x, y)`` whose sky direction — per-pixel maps of azimuth (clockwise from
    north) and zenith angle [°], NaN where the camera sees no sky — is nearest the sun's,
    and that nearest separation [°]: the truth of a camera that ships its own direction
    maps (EUROCONTROL's), the sun's direction from pvlib's SPA (the caller's)."""
    sep = angular_separation_deg(azimuth_deg, 90.0 - zenith_deg, sun_azimuth_deg,
                                 90.0 - sun_zenith_deg)
    sep = np.where(np.isfinite(sep), sep, np.inf)
    iy, ix = np.unravel_index(int(np.argmin(sep)), sep.shape)
    return float(ix), float(iy), float(sep[iy, ix])


def rescore(recs: list[Record], model: tuple[NDArray[np.float64], float],
            min_confidence: float = 0.5) -> list[Record]:
    """``recs`` (of detections run with ``min_confidence=0``, so every candidate has its
    refined centre) with the confidence of ``model`` and ``found`` at ``min_confidence``."""
    out = []
    for r in recs:
        new = dict(r)
        if r["features"]:
            x = np.array([r["features"][k] for k in conf.FEATURES], dtype=float)
            new["confidence"] = conf.probability(x, model)
        new["found"] = bool(r["features"]) and new["confidence"] >= min_confidence
        if not new["found"]:
            new["err_px"] = new["err_deg"] = float("nan")
        out.append(new)
    return out


def leave_one_camera_out(common: list[Record], real: list[Record], l2: float
                         ) -> dict[str, list[Record]]:
    """Per real camera (``record["camera"]``), its records scored by a confidence fitted on
    ``common`` (the synthetic development runs) and every *other* camera's records: nothing
    tuned on the camera it is tested on."""
    out = {}
    for cam in sorted({str(r["camera"]) for r in real}):
        train = common + [r for r in real if r["camera"] != cam]
        x, y, _ = design(train)
        model = conf.fit_logistic(x, y, l2=l2)
        out[cam] = rescore([r for r in real if r["camera"] == cam], model)
    return out


def per_camera_row(cam: str, recs: list[Record], width_px: int) -> dict[str, Any]:
    """The figures of one held-out camera: suns found of the visible ones, median and worst
    distance to the truth [px] and as a share of the image width [%], the highest confidence
    on a frame without a sun."""
    vis = [r for r in recs if r["visible"]]
    found = [r for r in vis if r["found"]]
    p = np.array([float(r["err_px"]) for r in found])
    nosun = [float(r["confidence"]) for r in recs if not r["visible"]]
    return {"camera": cam, "visible": len(vis), "found": len(found),
            "median_px": float(np.median(p)) if p.size else float("nan"),
            "worst_px": float(p.max()) if p.size else float("nan"),
            "worst_pct": float(100.0 * p.max() / width_px) if p.size else float("nan"),
            "no_sun": len(nosun), "no_sun_max_conf": max(nosun) if nosun else float("nan"),
            "min_conf_visible": min((float(r["confidence"]) for r in vis), default=float("nan"))}


FORMATS: dict[str, str] = {
    "880": "880 px wide, colour (a small webcam)",
    "mono": "monochrome, native size (an industrial camera without a colour filter)",
    "mono2840": "monochrome, 2840 px (an M12 fisheye on a large sensor)",
    "dslr6000": "6000 × 4000, the circle on a 3:2 sensor (a DSLR's circular fisheye)",
}
"""What users vary that the real frames do not (issue 24: "several makes, resolutions from
880 to 6000 px"): each labelled real frame made into another camera's format by
:func:`as_format`."""


def as_format(image: NDArray[np.uint8], truth_px: tuple[float, float], name: str
              ) -> tuple[NDArray[np.uint8], tuple[float, float]]:
    """A real frame (BGR) and its sun's truth (x, y) as camera format ``name`` of
    :data:`FORMATS`: resampled (area-averaged down, bicubic up, as a sensor of that size
    would sample the same optics, up to its own noise), converted to one channel (OpenCV's
    BT.601 luma: a monochrome sensor's broad response), or put in the middle of a 3:2
    sensor's black frame and scaled to 6000 × 4000. The truth moves with the pixels
    (pixel centres: x' = (x + 0.5)·s − 0.5)."""
    h, w = image.shape[:2]
    x, y = truth_px

    def scaled(img: NDArray[np.uint8], s: float) -> NDArray[np.uint8]:
        how = cv2.INTER_AREA if s < 1.0 else cv2.INTER_CUBIC
        return np.asarray(cv2.resize(img, None, fx=s, fy=s, interpolation=how), np.uint8)

    def moved(sx: float, dx: float = 0.0, sy: float | None = None) -> tuple[float, float]:
        return (x + dx + 0.5) * sx - 0.5, (y + 0.5) * (sx if sy is None else sy) - 0.5

    if name == "880":
        return scaled(image, 880 / w), moved(880 / w)
    grey = np.asarray(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY), np.uint8)
    if name == "mono":
        return grey, (x, y)
    if name == "mono2840":
        return scaled(grey, 2840 / w), moved(2840 / w)
    if name == "dslr6000":
        canvas = np.zeros((h, max(w, int(round(1.5 * h))), 3), np.uint8)
        off = (canvas.shape[1] - w) // 2
        canvas[:, off:off + w] = image
        big = cv2.resize(canvas, (6000, 4000), interpolation=cv2.INTER_CUBIC)
        return np.asarray(big, np.uint8), moved(6000 / canvas.shape[1], off, 4000 / h)
    raise ValueError(f"format must be one of {sorted(FORMATS)}; got {name!r}")
