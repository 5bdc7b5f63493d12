"""Vision benchmark: detection speed against a bare kernel, accuracy per method, HTTP latency.

Prints one Markdown section to stdout (progress on stderr):

1. Speed on one core (``cv2.setNumThreads(1)``, decode excluded), frames per
   second of ``detect_robust`` and of the seeds' pipelines, as a ratio to a
   bare grey + threshold + moments kernel timed on the same frames in the
   same run: 640 × 480 synthetic tracker and fisheye frames, 1920 × 1920 real
   all-sky frames (``../shared/real-sky``; synthetic 1920 × 1920 frames when
   absent).
2. Accuracy of the three methods side by side on the same sets: synthetic
   fisheye (clear, thin cloud), synthetic tracker, the six labelled real
   frames, the two overcast ones, and the calibration fitted from the labelled
   frames' detections. References: the synthetic truth and pvlib's SPA.
3. HTTP: median latency of ``POST /api/v1/vision/sun`` with a 640 × 480 JPEG
   against ``GET /healthz`` on the same running server (``heliotwin serve``
   on free ports, a throw-away SQLite file).

``--evaluate [--quick]`` and ``--fit-confidence`` run the issue-10 evaluation
(:mod:`vision_eval`) instead. Speed is CPU time (``time.process_time``).
"""

from __future__ import annotations

import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pvlib

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from _common import Figures, free_port, log  # noqa: E402  (bench scripts run from this folder)
from vision_eval import evaluation_report, fit_confidence, real_rows  # noqa: E402

from vision import metrics  # noqa: E402
from vision.calibrate import fit_fisheye  # noqa: E402
from vision.cameras import FisheyeCamera, PinholeCamera  # noqa: E402
from vision.detect import METHODS, detect_sun, threshold_moments, to_gray  # noqa: E402
from vision.synth import fisheye_frame, tracker_frame  # noqa: E402


def per_frame_s(fn: Callable[[np.ndarray], object], frames: list[np.ndarray],
                passes: int = 5) -> float:
    """Best (least disturbed) of ``passes`` runs over the frames, CPU seconds per frame.

    CPU time of this process (``time.process_time``), not wall time: on a shared machine
    the wall clock also counts the time other processes held the core. One OpenCV
    thread, so CPU time is one core's time."""
    fn(frames[0])
    best = float("inf")
    for _ in range(passes):
        t0 = time.process_time()
        for f in frames:
            fn(f)
        best = min(best, (time.process_time() - t0) / len(frames))
    return best


def kernel(img: np.ndarray) -> object:
    return threshold_moments(to_gray(img), 240)


# --------------------------------------------------------------------------- frames


def tracker_set(n: int, **kw: object) -> list[tuple[np.ndarray, float, float]]:
    rng = np.random.default_rng(11)
    out = []
    for i in range(n):
        h, v = rng.uniform(-10.0, 10.0, 2)
        out.append((tracker_frame(h, v, seed=i, **kw).image, float(h), float(v)))
    return out


def fisheye_set(**kw: object) -> list[tuple[np.ndarray, float, float]]:
    out = []
    for k, day in enumerate(("2018-03-02", "2018-06-21", "2018-12-21")):
        t = pd.date_range(f"{day} 07:00", f"{day} 18:30", freq="45min", tz="Etc/GMT+6")
        sp = pvlib.solarposition.get_solarposition(t, 20.8667, -103.05, method="nrel_numpy")
        sp = sp[sp.apparent_elevation > 8]
        for i, (a, e) in enumerate(zip(sp.azimuth, sp.apparent_elevation, strict=True)):
            out.append((fisheye_frame(a, e, seed=100 * k + i, **kw).image, float(a), float(e)))
    return out


# --------------------------------------------------------------------------- accuracy


def tracker_accuracy(frames: list[tuple[np.ndarray, float, float]], method: str) -> str:
    cam = PinholeCamera()
    errs, missed = [], 0
    for img, h, v in frames:
        d = detect_sun(img, method=method, camera=cam if method == "robust" else None)
        if d.centroid_px is None:
            missed += 1
            continue
        hh, vv, _ = cam.pointing_error(*d.centroid_px)
        errs.append(1000.0 * np.radians(np.hypot(float(hh) - h, float(vv) - v)))
    if not errs:
        return f"none found of {len(frames)}"
    e = np.asarray(errs)
    return (f"{np.sqrt(np.mean(e**2)):.3f} mrad RMS (max {e.max():.3f}), "
            f"{len(frames) - missed}/{len(frames)} found")


def fisheye_accuracy(frames: list[tuple[np.ndarray, float, float]], method: str) -> str:
    cam = FisheyeCamera(319.5, 239.5, 2.6)
    ra, re, a, e = [], [], [], []
    for img, az, el in frames:
        d = detect_sun(img, method=method, camera=cam if method == "robust" else None)
        if d.centroid_px is None:
            continue
        a2, e2 = cam.pixel_to_sky(*d.centroid_px)
        ra.append(az)
        re.append(el)
        a.append(float(a2))
        e.append(float(e2))
    if not a:
        return f"none found of {len(frames)}"
    t = metrics.error_table(ra, re, a, e)
    return (f"az {t['azimuth']['rmse_deg']:.3f}° / el {t['elevation']['rmse_deg']:.3f}° RMSE, "
            f"separation {t['separation']['rmse_deg']:.3f}° RMS (max "
            f"{t['separation']['max_deg']:.2f}°), {len(a)}/{len(frames)} found")


def real_accuracy(rows: list[dict[str, object]], method: str) -> tuple[str, str, str]:
    lab = [r for r in rows if r["sun_row_label"]]
    dists, xy = [], []
    for r in lab:
        d = detect_sun(r["image"], method=method)
        if d.centroid_px is None:
            dists.append(float("inf"))
            xy.append(None)
            continue
        x, y = d.centroid_px
        xy.append((x, y))
        dists.append(float(np.hypot(x - float(r["sun_col_label"]), y - float(r["sun_row_label"]))))
    d = np.asarray(dists)
    labelled = f"median {np.median(d):.2f} px, worst {d.max():.2f} px"
    over = [detect_sun(r["image"], method=method) for r in rows
            if str(r["filename"]).startswith("UCEEB")]
    overcast = ", ".join(f"{'sun' if o.sun_found else 'no sun'} ({o.confidence:.2f})"
                         for o in over)
    ok = [i for i, p in enumerate(xy) if p is not None]
    if len(ok) < 3:
        return labelled, overcast, "too few detections"
    times = pd.DatetimeIndex([pd.Timestamp(lab[i]["utc_time"]) for i in ok])
    sp = pvlib.solarposition.get_solarposition(times, float(lab[0]["lat"]),
                                               float(lab[0]["lon"]), method="nrel_numpy")
    arr = np.array([xy[i] for i in ok])
    cal = fit_fisheye(arr[:, 0], arr[:, 1], sp.azimuth.values, sp.apparent_elevation.values,
                      (1920, 1920))
    c = cal.camera
    calib = (f"{cal.rms_px:.2f} px / {cal.rms_deg:.3f}° RMS ({c.px_per_deg:.2f} px/°, "
             f"centre {c.cx_px:.0f},{c.cy_px:.0f}, east {c.east})")
    return labelled, overcast, calib


# --------------------------------------------------------------------------- HTTP


def http_latency(n: int = 200) -> tuple[float, float, float] | None:
    """Median ms of POST /api/v1/vision/sun (640×480 JPEG) and GET /healthz, and p90 of POST."""
    import httpx

    port = free_port()
    tmp = tempfile.mkdtemp(prefix="bench-vision-")
    env = {k: v for k, v in os.environ.items() if not k.startswith("HELIOTWIN_")}
    env.update({"HELIOTWIN_DATABASE_URL": f"sqlite:///{tmp}/bench.sqlite",
                "HELIOTWIN_VISER": "false", "HELIOTWIN_LIVE_TWIN": "false"})
    proc = subprocess.Popen([sys.executable, "-m", "backend", "serve", "--host", "127.0.0.1",
                             "--port", str(port), "--viser-port", str(free_port()),
                             "--no-demo"], cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    base = f"http://127.0.0.1:{port}"
    try:
        for _ in range(300):
            try:
                if httpx.get(base + "/healthz", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.1)
        else:
            return None
        fr = fisheye_frame(150.0, 50.0, seed=1).image
        ok, jpg = cv2.imencode(".jpg", fr, [cv2.IMWRITE_JPEG_QUALITY, 90])
        body = jpg.tobytes()
        data = {"camera": "fisheye", "px_per_deg": "2.6", "timestamp": "2024-03-15T12:00:00-06:00",
                "site_id": "tehuantepec"}
        post, get = [], []
        with httpx.Client(base_url=base, timeout=30) as c:
            for i in range(n + 10):
                t0 = time.perf_counter()
                r = c.post("/api/v1/vision/sun", files={"file": ("f.jpg", body, "image/jpeg")},
                           data=data)
                dt_post = time.perf_counter() - t0
                assert r.status_code == 200, r.text
                t0 = time.perf_counter()
                c.get("/healthz")
                dt_get = time.perf_counter() - t0
                if i >= 10:
                    post.append(dt_post)
                    get.append(dt_get)
        return (1000 * statistics.median(post), 1000 * statistics.median(get),
                1000 * float(np.percentile(post, 90)))
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()


# --------------------------------------------------------------------------- main


def main() -> int:
    cv2.setNumThreads(1)
    log("rendering synthetic frames")
    tr_clear = tracker_set(24)
    tr_flare = tracker_set(12, flare=True, ghost=True)
    tr_bloom = tracker_set(12, bloom=1.0, glare_deg=2.0)
    fe_clear = fisheye_set()
    fe_cloud = fisheye_set(cloud_cover=0.4, cloud_optical_depth=0.6)
    rows = real_rows()
    big = [r["image"] for r in rows if r["image"] is not None and r["image"].shape[0] == 1920]
    big_note = f"{len(big)} real all-sky frames (Wettermast, FE3)"
    if not big:
        cam = FisheyeCamera(959.5, 959.5, 10.4)
        big = [fisheye_frame(a, 40.0, camera=cam, width_px=1920, height_px=1920, seed=i,
                             glare_deg=4.0).image for i, a in enumerate((100.0, 200.0))]
        big_note = "2 synthetic fisheye frames (real-sky folder absent)"

    sets = [("640×480 synthetic tracker (clear)", [f[0] for f in tr_clear]),
            ("640×480 synthetic fisheye (clear + thin cloud)",
             [f[0] for f in fe_clear + fe_cloud]),
            (f"1920×1920, {big_note}", big)]
    fig = Figures("vision")
    keys = ["tracker_640_fps", "fisheye_640_fps", "allsky_1920_fps"]
    targets = [1000.0, 1000.0, 60.0]
    speed_rows = []
    for (name, frames), key, target in zip(sets, keys, targets, strict=True):
        log(f"timing {name}")
        base = per_frame_s(kernel, frames)
        rob = per_frame_s(lambda f: detect_sun(f, "robust"), frames)
        s3 = per_frame_s(lambda f: detect_sun(f, "seed003_gray240"), frames)
        s0 = per_frame_s(lambda f: detect_sun(f, "seed000_hsv"), frames, passes=2)
        rob_text = fig.add(key, 1 / rob, "fps", f"{1 / rob:,.0f} fps", f"≥ {target:,.0f} fps",
                           1 / rob >= target)
        speed_rows.append(
            f"| {name} | {1 / base:,.0f} fps | **{rob_text}** ({rob / base:.1f}×) "
            f"{fig.verdict(key)} | "
            f"{1 / s3:,.0f} fps ({s3 / base:.1f}×) | {1 / s0:,.0f} fps ({s0 / base:.1f}×) |")

    log("accuracy per method")
    acc = {m: {} for m in METHODS}
    for m in METHODS:
        acc[m]["fe_clear"] = fisheye_accuracy(fe_clear, m)
        acc[m]["fe_cloud"] = fisheye_accuracy(fe_cloud, m)
        acc[m]["tr_clear"] = tracker_accuracy(tr_clear, m)
        acc[m]["tr_flare"] = tracker_accuracy(tr_flare, m)
        acc[m]["tr_bloom"] = tracker_accuracy(tr_bloom, m)
        if rows:
            acc[m]["real"], acc[m]["overcast"], acc[m]["calib"] = real_accuracy(rows, m)
    log("HTTP latency")
    lat = http_latency()

    out = ["## vision — sun detection (speed, accuracy per method, HTTP)", ""]
    out.append("Speed on one core (`cv2.setNumThreads(1)`, CPU time of the process), decode "
               "excluded, best of 5 passes; "
               "the ratio is the time per frame over the bare kernel's (grey + threshold 240 "
               "+ moments) on the same frames in the same run. Targets: ≥ 1,000 fps at "
               "640×480 and ≥ 60 fps at 1920×1920 for `robust`.")
    out += ["", "| frames | bare kernel | robust | seed003_gray240 | seed000_hsv |",
            "|---|---|---|---|---|", *speed_rows, ""]
    out.append("Accuracy of the three methods on the same sets (references: the synthetic "
               "truth; pvlib SPA and the hand labels for the real frames).")
    labels = [("fe_clear", f"synthetic fisheye 640×480, clear ({len(fe_clear)} frames, "
                           "seed 003 site, 3 days)"),
              ("fe_cloud", "synthetic fisheye 640×480, thin cloud (40 % cover, τ 0.6)"),
              ("tr_clear", f"synthetic tracker 640×480 / 67°, clear ({len(tr_clear)} frames)"),
              ("tr_flare", f"synthetic tracker, flare streak + ghost ({len(tr_flare)} frames)"),
              ("tr_bloom", f"synthetic tracker, strong blooming, 2° glare ({len(tr_bloom)} "
                           "frames)")]
    if rows:
        labels += [("real", "six labelled real frames: distance to the hand label"),
                   ("overcast", "two overcast UCEEB frames (confidence)"),
                   ("calib", "equidistant calibration fitted from the six detections")]
    out += ["", "| set | " + " | ".join(METHODS) + " |", "|---|" + "---|" * len(METHODS)]
    for key, label in labels:
        out.append(f"| {label} | " + " | ".join(acc[m][key] for m in METHODS) + " |")
    out.append("")
    if lat is None:
        out.append("HTTP: the server did not start; no latency measured.")
    else:
        post, get, p90 = lat
        out.append("HTTP (`heliotwin serve`, SQLite, keep-alive, 200 requests): "
                   "`POST /api/v1/vision/sun` with a 640×480 JPEG (fisheye, time + site, "
                   "stored) **" + fig.add("http_sun_ms", post, "ms", f"{post:.1f} ms", "≤ 15 ms",
                                           post <= 15.0)
                   + f" median** (p90 {p90:.1f} ms) vs `GET /healthz` "
                   f"{get:.1f} ms on the same server ({post / get:.1f}×). Target ≤ 15 ms: "
                   + fig.verdict("http_sun_ms") + ".")
    print("\n".join(out))
    fig.write()
    return 0


if __name__ == "__main__":
    if "--evaluate" in sys.argv:
        cv2.setNumThreads(2)
        print("\n".join(evaluation_report(quick="--quick" in sys.argv)))
        sys.exit(0)
    if "--fit-confidence" in sys.argv:
        import json

        model = fit_confidence()
        (ROOT / "vision" / "confidence.json").write_text(json.dumps(model, indent=1) + "\n")
        log(f"wrote vision/confidence.json: {model}")
        sys.exit(0)
    sys.exit(main())
