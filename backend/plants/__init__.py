"""Plants for the HTTP service: loaded configs (cached, reloaded when a file changes),
positions for a plant controller, the sky map and a day's shade (seed 004).

The routes in ``backend/api/routes/plants.py`` are thin: they parse and call
:class:`PlantService`. All physics is in :mod:`sim.plant`.

What a computation costs, before it runs (the price an anonymous caller pays from the
hourly allowance of ``backend/limits.py``, trued up to the CPU time it took) —
measured on 2026-12-04 (after the plant-year and sky-scan speed-ups; best of three, with
``time.process_time()`` around :meth:`PlantService.day` for the built-in Peñarroya, 29
trackers, on 21 March, 21 June and 21 December at 300, 900 and 3,600 s): a whole day
(three strategies, the fixed plant, the sun-tracking shade) 0.034–0.038 s at 3,600 s,
0.053–0.064 s at 900 s, 0.105–0.128 s at 300 s. :func:`day_cost_s` is the least-squares
fit (the largest day 1.09 × its price)

    cost_s = DAY_OVERHEAD_S + DAY_STEP_TRACKER_S × (86,400 s / step_s) × trackers,

linear in the trackers as the shade test is (each collector against its few
candidate shaders). :func:`sky_map_cost_s`: 0.044 s at 1° (32,760 orientations), 0.008 s
at 3° (3,720), the line through them. :func:`positions_cost_s`: one instant, 2.4–2.9 ms
of CPU for Peñarroya (5.3–8.8 ms on 2026-12-03, when its price was set; kept, as its
per-tracker part was not measured again on a larger plant).
"""

from __future__ import annotations

import builtins
import datetime as dt
import logging
import threading
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sim.plant import Collector, Plant, UnknownPlantError, default_plants_dir, load_plant
from sim.plant.layout import plant_file_problem
from sim.plant.simulate import field_shade, local_day, simulate_plant, sky_conditions
from sim.plant.strategies import STRATEGIES, orientations, sky_map, strategies_for

log = logging.getLogger(__name__)

__all__ = ["POLYGON_COST_FACTOR", "STRATEGIES", "PlantService", "UnknownPlantError",
           "cost_factor", "day_cost_s", "lambert_xy", "positions_cost_s", "simulate_summary",
           "sky_map_cost_s", "sky_map_png"]

#: A plant day's fixed cost [s]: the sun, backtrack and fixed runs, the sun's ephemeris.
DAY_OVERHEAD_S = 0.03
#: A plant day's cost per step of the day and tracker [s] (``sky_scan``'s shade test).
DAY_STEP_TRACKER_S = 1.05e-5
#: The positions of one instant: fixed cost and cost per tracker [s].
POSITIONS_OVERHEAD_S, POSITIONS_TRACKER_S = 0.002, 2.5e-4
#: How many times a rectangle's shade a polygon collector's costs per step and tracker, for
#: pricing work without a token: the worst of benchmarks/bench_plant_polygon.py (a 32-gon
#: field's year took up to 97 s where a 12 m x 5 m rectangle's takes about 1 s; the L 7-14 s:
#: GEOS clipping per shaded collector, RESULTS.md "plant_polygon").
POLYGON_COST_FACTOR = 100.0
#: A sky map's cost per orientation of its grid [s], and its fixed cost [s].
SKY_MAP_ORIENTATION_S, SKY_MAP_OVERHEAD_S = 1.24e-6, 0.0034
#: Days kept (clear sky: a plant, date and step always give the same day); the cache holds
#: at most this many shaded-fraction values in all (≈ 32 bytes each as Python floats in
#: lists: ≈ 16 MB), the least recently used day is dropped first. A Peñarroya day at
#: 300 s holds 5,162.
DAY_CACHE_VALUES = 500_000


def cost_factor(collector: Collector) -> float:
    """How many times the rectangle's the shade of ``collector`` costs (1 or
    :data:`POLYGON_COST_FACTOR`): what the prices below are multiplied by."""
    return 1.0 if collector.is_rectangle else POLYGON_COST_FACTOR


def day_cost_s(n_trackers: int, step_s: float, factor: float = 1.0) -> float:
    """The expected CPU time [s] of :meth:`PlantService.day` (module docstring); ``factor``:
    :func:`cost_factor` of the collector."""
    return DAY_OVERHEAD_S + factor * DAY_STEP_TRACKER_S * 86400.0 / step_s * n_trackers


def simulate_summary(plant: Plant, start: pd.Timestamp, end: pd.Timestamp, step_s: float,
                     strategy: str, weather: pd.DataFrame | None,
                     station: dict[str, Any] | None, clock: dict[str, Any],
                     progress: Any = None) -> dict[str, Any]:
    """The summary of a plant run (:meth:`sim.plant.simulate.PlantResult.summary`), on a
    weather file with its ``weather_station`` and clock check (``weather_shift_min``,
    ``weather_warning``: :func:`backend.twin.scenario.place_weather`): ``heliotwin plant
    simulate``'s JSON and ``POST /api/v1/plants/{plant_id}/weather``'s answer, one rule."""
    summary = simulate_plant(plant, start, end, step_s=step_s, strategy=strategy,
                             weather=weather, progress=progress).summary()
    if station is not None:
        summary["weather_station"] = station
        summary.update(clock)
    return summary


def positions_cost_s(n_trackers: int, factor: float = 1.0) -> float:
    """The expected CPU time [s] of :meth:`PlantService.positions` (module docstring)."""
    return POSITIONS_OVERHEAD_S + factor * POSITIONS_TRACKER_S * n_trackers


def sky_map_cost_s(resolution_deg: float) -> float:
    """The expected CPU time [s] of :meth:`PlantService.sky_map` (module docstring)."""
    orientations = (360.0 / resolution_deg) * (90.0 / resolution_deg + 1)
    return SKY_MAP_OVERHEAD_S + SKY_MAP_ORIENTATION_S * orientations


def lambert_xy(azimuth_deg: np.ndarray, elevation_deg: np.ndarray) -> tuple[np.ndarray, ...]:
    """Lambert azimuthal equal-area disk (seed 004 Fig. 6): unit radius at the horizon.

    r = √2 · sin(ζ/2), ζ the zenith angle; x east, y north.
    """
    zeta = np.radians(90.0 - np.asarray(elevation_deg, dtype=float))
    r = np.sqrt(2.0) * np.sin(zeta / 2)
    az = np.radians(np.asarray(azimuth_deg, dtype=float))
    return r * np.sin(az), r * np.cos(az)


class PlantService:
    """The plants of one directory, cached by file modification time."""

    def __init__(self, plants_dir: str | Path | None = None) -> None:
        self.plants_dir = Path(plants_dir) if plants_dir is not None else default_plants_dir()
        # one entry per plant file of the folder (the operator's files, not callers' input)
        self._cache: dict[str, tuple[float, Plant]] = {}
        self._lock = threading.Lock()
        self._days: OrderedDict[tuple[str, float, str, float], dict[str, Any]] = OrderedDict()
        self._day_values = 0

    def _day_key(self, plant_id: str, date: dt.date, step_s: float
                 ) -> tuple[str, float, str, float]:
        path = self.plants_dir / f"{plant_id}.json"
        try:
            mtime = path.stat().st_mtime
        except (OSError, ValueError):  # no file, a name too long, a NUL in it: load says
            mtime = -1.0
        return plant_id, mtime, date.isoformat(), float(step_s)

    def cached_day(self, plant_id: str, date: dt.date, step_s: float) -> dict[str, Any] | None:
        """:meth:`day` when it was computed before (for this file of the plant), else None."""
        key = self._day_key(plant_id, date, step_s)
        with self._lock:
            hit = self._days.get(key)
            if hit is not None:
                self._days.move_to_end(key)
            return hit

    def _keep_day(self, key: tuple[str, float, str, float], day: dict[str, Any]) -> None:
        values = len(day["times"]) * len(day["tracker_ids"])
        if values > DAY_CACHE_VALUES:
            return
        with self._lock:
            old = self._days.pop(key, None)
            if old is not None:
                self._day_values -= len(old["times"]) * len(old["tracker_ids"])
            self._days[key] = day
            self._day_values += values
            while self._day_values > DAY_CACHE_VALUES:
                _, dropped = self._days.popitem(last=False)
                self._day_values -= len(dropped["times"]) * len(dropped["tracker_ids"])

    @property
    def cached_day_values(self) -> int:
        """Shaded-fraction values the day cache holds (≤ :data:`DAY_CACHE_VALUES`)."""
        return self._day_values

    def ids(self) -> list[str]:
        """Plant ids (file stems), sorted."""
        return sorted(p.stem for p in self.plants_dir.glob("*.json"))

    def get(self, plant_id: str) -> Plant:
        """A plant; ``UnknownPlantError`` / ``ValueError`` as :func:`sim.plant.load_plant`."""
        path = self.plants_dir / f"{plant_id}.json"
        try:
            mtime = path.stat().st_mtime
        except (OSError, ValueError):  # no file, a name too long, a NUL in it: load says
            mtime = -1.0
        with self._lock:
            hit = self._cache.get(plant_id)
            if hit is not None and hit[0] == mtime:
                return hit[1]
        plant = load_plant(plant_id, self.plants_dir)
        with self._lock:
            self._cache[plant_id] = (mtime, plant)
        return plant

    def list(self) -> list[dict[str, Any]]:
        """Every loadable plant (summary); a bad file is left out (:meth:`skipped` names it)."""
        return self._scan()[0]

    def skipped(self) -> builtins.list[dict[str, str]]:
        """The plant files left out of :meth:`list`: ``{"file", "reason"}`` each."""
        return self._scan()[1]

    def _scan(self) -> tuple[builtins.list[dict[str, Any]], builtins.list[dict[str, str]]]:
        out, skipped = [], []
        for pid in self.ids():
            try:
                p = self.get(pid)
            except ValueError as exc:
                path = self.plants_dir / f"{pid}.json"
                reason = plant_file_problem(exc, path)
                log.warning("plant %s left out: %s", pid, reason)
                skipped.append({"file": path.name, "reason": reason})
                continue
            out.append({"plant_id": p.plant_id, "name": p.name, "trackers": p.n_trackers,
                        "latitude_deg": p.latitude, "longitude_deg": p.longitude,
                        "timezone": p.timezone})
        return out, skipped

    def positions(self, plant_id: str, time: dt.datetime, strategy: str = "sun"
                  ) -> dict[str, Any]:
        """What a plant controller polls: every tracker's orientation, shade and shaders."""
        plant = self.get(plant_id)
        ts = pd.Timestamp(time).tz_convert("UTC")
        sky = sky_conditions(plant, pd.DatetimeIndex([ts]))
        saz, sel = orientations(strategy, plant, sky)
        shade, _ = field_shade(plant, sky, saz, sel)
        up = bool(sky["apparent_elevation"][0] > 0)
        trackers = []
        for k, tid in enumerate(plant.tracker_ids):
            f = shade.fraction[0, k]
            trackers.append({
                "tracker_id": tid,
                "azimuth_deg": round(float(saz[0]), 4),
                "elevation_deg": round(float(sel[0]), 4),
                "shaded_fraction": round(float(f), 6) if up else None,
                "shaded_by": [plant.tracker_ids[b] for b in shade.shaded_by(0, k)],
            })
        fr = shade.fraction[0]
        return {
            "plant_id": plant.plant_id,
            "time": ts.isoformat(),
            "strategy": strategy,
            "sun": {"azimuth_deg": round(float(sky["solar_azimuth"][0]), 4),
                    "elevation_deg": round(float(sky["apparent_elevation"][0]), 4)},
            "sun_up": up,
            "trackers_shaded": int((np.nan_to_num(fr) > 0).sum()),
            "mean_shaded_fraction": round(float(fr.mean()), 6) if up else None,
            "trackers": trackers,
        }

    def sky_map(self, plant_id: str, time: dt.datetime, resolution_deg: float = 3.0,
                strategy: str = "sky_scan") -> dict[str, Any]:
        """The hemispheric POA map (clear sky) with the shaded region, the sun and the pick."""
        plant = self.get(plant_id)
        ts = pd.Timestamp(time).tz_convert("UTC")
        sky = sky_conditions(plant, pd.DatetimeIndex([ts]))
        m = sky_map(plant, sky, 0, resolution_deg)
        saz, sel = orientations(strategy, plant, sky)
        poa = np.where(m["shading"], np.nan, m["poa_global"])
        best = {"azimuth_deg": round(float(saz[0]), 3), "elevation_deg": round(float(sel[0]), 3)}

        def grid(a: np.ndarray, nd: int = 1) -> list[list[float | None]]:
            return [[None if not np.isfinite(v) else round(float(v), nd) for v in row]
                    for row in a]

        return {
            "plant_id": plant.plant_id,
            "time": ts.isoformat(),
            "projection": "lambert_azimuthal_equal_area",
            "sky": "clearsky-ineichen",
            "transposition_model": "perez",
            "sun": {"azimuth_deg": round(float(sky["solar_azimuth"][0]), 4),
                    "elevation_deg": round(float(sky["apparent_elevation"][0]), 4)},
            "strategy": strategy,
            "chosen": best,
            "azimuth_deg": [float(a) for a in m["azimuth"]],
            "elevation_deg": [float(e) for e in m["elevation"]],
            "poa_global_w_m2": grid(poa),
            "shading": [[bool(v) for v in row] for row in m["shading"]],
        }

    def day(self, plant_id: str, date: dt.date, step_s: float = 600.0) -> dict[str, Any]:
        """A clear-sky day: each tracker's shaded fraction (sun tracking) and strategy energies
        (kept for the next caller: :meth:`cached_day`)."""
        key = self._day_key(plant_id, date, step_s)
        plant = self.get(plant_id)
        start, end = local_day(date, plant.timezone)     # 23 or 25 h on a DST change day
        strategies: dict[str, Any] = {}
        shade_rows: list[list[float]] = []
        times: list[str] = []
        for strategy in strategies_for(plant.collector):
            r = simulate_plant(plant, start, end, step_s=step_s, strategy=strategy)
            s = r.summary()
            strategies[strategy] = {k: s[k] for k in (
                "plant_energy_wh", "plant_energy_area_model_wh", "plant_energy_unshaded_wh",
                "shading_loss_area_pct", "shading_loss_electrical_pct",
                "fraction_of_daylight_any_shaded", "fixed_energy_wh")}
            if strategy == "sun":
                day = r.series["apparent_elevation"] > 0
                ser = r.series[day]
                sky = sky_conditions(plant, pd.DatetimeIndex(ser.index))
                sh, _ = field_shade(plant, sky, sky["solar_azimuth"],
                                    sky["apparent_elevation"])
                shade_rows = [[round(float(v), 5) for v in row] for row in sh.fraction]
                times = [t.isoformat() for t in ser.index]
                fixed = s["fixed_energy_wh"]
        strategies["fixed"] = {"plant_energy_wh": fixed}
        out = {"plant_id": plant.plant_id, "date": date.isoformat(), "step_s": step_s,
               "sky": "clearsky-ineichen", "tracker_ids": list(plant.tracker_ids),
               "times": times, "shaded_fraction": shade_rows, "strategies": strategies}
        self._keep_day(key, out)
        return out


#: Width of the sky map's colour bar strip [px], right of the disk.
COLOUR_BAR_W_PX = 100
#: The colour bar's top and bottom rows [px from the top; from the bottom].
COLOUR_BAR_TOP_PX, COLOUR_BAR_BOTTOM_PX = 48, 90


def _colour_bar(lo: float, hi: float, height_px: int) -> np.ndarray:
    """The sky map's colour bar: POA from ``lo`` (bottom) to ``hi`` (top) [W m⁻²] in the
    disk's turbo scale, five ticks labelled, the quantity and unit above, and the grey of the
    orientations that shade a collector below (it had only a "lo-hi W/m2" corner label)."""
    import cv2

    strip = np.full((height_px, COLOUR_BAR_W_PX, 3), 255, np.uint8)
    top, bottom, x0, width = COLOUR_BAR_TOP_PX, height_px - COLOUR_BAR_BOTTOM_PX, 8, 18
    ramp = np.linspace(255, 0, bottom - top).round().astype(np.uint8)
    strip[top:bottom, x0:x0 + width] = cv2.applyColorMap(
        np.repeat(ramp[:, None], width, axis=1), cv2.COLORMAP_TURBO)
    cv2.rectangle(strip, (x0 - 1, top - 1), (x0 + width, bottom), (0, 0, 0), 1)
    font, black = cv2.FONT_HERSHEY_SIMPLEX, (0, 0, 0)
    cv2.putText(strip, "POA", (x0 - 2, top - 26), font, 0.42, black, 1, cv2.LINE_AA)
    cv2.putText(strip, "[W/m2]", (x0 - 2, top - 10), font, 0.42, black, 1, cv2.LINE_AA)
    for k in range(5):
        y = int(round(bottom - 1 - k / 4 * (bottom - top - 1)))
        cv2.line(strip, (x0 + width, y), (x0 + width + 4, y), black, 1)
        cv2.putText(strip, f"{lo + k / 4 * (hi - lo):.0f}", (x0 + width + 7, y + 4), font, 0.38,
                    black, 1, cv2.LINE_AA)
    cv2.rectangle(strip, (x0, bottom + 22), (x0 + width - 1, bottom + 36), (150, 150, 150), -1)
    cv2.putText(strip, "shades", (x0 + width + 7, bottom + 34), font, 0.38, black, 1,
                cv2.LINE_AA)
    cv2.putText(strip, "a collector", (x0 - 2, bottom + 52), font, 0.38, black, 1, cv2.LINE_AA)
    return strip


def sky_map_png(m: dict[str, Any], size_px: int = 420) -> bytes:
    """Render a sky map (from :meth:`PlantService.sky_map`) as a Lambert-disk PNG with OpenCV.

    Colour: POA (turbo colour map; a colour bar with its range and unit right of the disk,
    :func:`_colour_bar`), grey: orientations that shade a collector, yellow disc: the sun,
    white cross: the chosen orientation. North up, east right (looking down on the sky map).
    The image is ``size_px`` high and ``size_px`` + :data:`COLOUR_BAR_W_PX` wide.
    """
    import cv2

    az = np.asarray(m["azimuth_deg"], dtype=float)
    el = np.asarray(m["elevation_deg"], dtype=float)
    poa = np.array([[np.nan if v is None else v for v in row] for row in m["poa_global_w_m2"]],
                   dtype=float)
    shaded = np.asarray(m["shading"], dtype=bool)
    half = size_px // 2
    yy, xx = np.mgrid[0:size_px, 0:size_px]
    x = (xx - half + 0.5) / (half - 10)
    y = -(yy - half + 0.5) / (half - 10)
    r = np.hypot(x, y)
    inside = r <= 1.0
    zeta = 2 * np.degrees(np.arcsin(np.clip(r / np.sqrt(2.0), 0, 1)))
    e_px = 90.0 - zeta
    a_px = np.degrees(np.arctan2(x, y)) % 360.0
    res_a = az[1] - az[0] if len(az) > 1 else 360.0
    res_e = el[1] - el[0] if len(el) > 1 else 90.0
    ia = np.round(a_px / res_a).astype(int) % len(az)
    ie = np.clip(np.round(e_px / res_e).astype(int), 0, len(el) - 1)
    val = poa[ie, ia]
    lo = float(np.nanmin(poa)) if np.isfinite(poa).any() else 0.0
    hi = float(np.nanmax(poa)) if np.isfinite(poa).any() else 1.0
    norm = np.clip((np.nan_to_num(val, nan=lo) - lo) / max(hi - lo, 1e-9), 0, 1)
    img = cv2.applyColorMap((norm * 255).astype(np.uint8), cv2.COLORMAP_TURBO)
    img[shaded[ie, ia] & inside] = (150, 150, 150)
    img[~inside] = (255, 255, 255)

    def px(a: float, e: float) -> tuple[int, int]:
        lx, ly = lambert_xy(np.array(a), np.array(e))
        return int(half + float(lx) * (half - 10)), int(half - float(ly) * (half - 10))

    for e_ring in (30.0, 60.0):
        cv2.circle(img, (half, half), abs(px(0.0, e_ring)[1] - half), (60, 60, 60), 1)
    cv2.circle(img, (half, half), half - 10, (0, 0, 0), 1)
    for label, a in (("N", 0.0), ("E", 90.0), ("S", 180.0), ("W", 270.0)):
        p = px(a, -3.0)
        cv2.putText(img, label, (p[0] - 5, p[1] + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                    (0, 0, 0), 1, cv2.LINE_AA)
    sun = m["sun"]
    if sun["elevation_deg"] > 0:
        cv2.circle(img, px(sun["azimuth_deg"], sun["elevation_deg"]), 7, (0, 215, 255), -1)
        cv2.circle(img, px(sun["azimuth_deg"], sun["elevation_deg"]), 7, (0, 0, 0), 1)
    ch = m["chosen"]
    cv2.drawMarker(img, px(ch["azimuth_deg"], ch["elevation_deg"]), (255, 255, 255),
                   cv2.MARKER_CROSS, 16, 2)
    img = np.concatenate([img, _colour_bar(lo, hi, size_px)], axis=1)
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return bytes(buf.tobytes())
