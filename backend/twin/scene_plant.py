"""One viewer's 3D view of a plant of dual-axis trackers (seed 004), e.g. Peñarroya I.

Every collector is posed at the common orientation the chosen strategy gives at
the chosen instant (:func:`sim.plant.strategies.orientations`: ``sun``,
``backtrack``, ``sky_scan``, clear sky from :func:`sim.plant.simulate.sky_conditions`),
the shaded ones are coloured by their shaded fraction with the shade drawn on
them (:func:`sim.plant.simulate.field_shade`, the twin's own shade: seed 004 §2.1, each
neighbour's collector projected along the sun vector onto the collector's plane), and
every collector casts its shadow on the ground (its outline projected along the sun
vector onto z = 0, :mod:`backend.twin.scene_shadow`). A rectangular collector is a box
and its shade rectangles; a polygon collector (``outline_m``) is drawn as its polygon,
and its shade as the exact clipped polygons the twin computed.

The plant file gives pivot positions on flat ground (z = 0) with the collector
centred on the pivot; the view lifts every pivot by :data:`PIVOT_HEIGHT_M` so a
5 m collector clears the ground when vertical — the same lift for all, so the
shading between collectors is unchanged. The scene is centred on the plant's
centroid (ENU, m).
"""

from __future__ import annotations

import datetime as dt
import threading
from typing import Any

import numpy as np
import pandas as pd
import viser
from numpy.typing import NDArray

from backend.twin.scene_build import wxyz
from backend.twin.scene_shadow import SHADOW_LIFT_M
from sim.plant import Plant
from sim.plant.shading import PlantShade, collector_axes
from sim.plant.simulate import field_shade, sky_conditions
from sim.plant.strategies import orientations, strategies_for
from vision.sphere import enu_from_sky

#: Pivot height above the ground in the view [m] (an assumption: the plant file has none).
PIVOT_HEIGHT_M = 3.0
COLLECTOR_DEPTH_M = 0.12
#: Shade rectangles drawn per shaded collector (more neighbours than this are rare).
MAX_SHADE_RECTS = 4
#: Triangles of shade drawn per shaded polygon collector (its clipped shade, triangulated).
MAX_SHADE_TRIANGLES = 32
_BLUE = (28, 52, 110)
_SHADED = (214, 80, 40)
_STEEL = (150, 150, 155)


def _quads(corners: NDArray[np.float64]) -> tuple[NDArray[np.float32], NDArray[np.uint32]]:
    """Quads (Q, 4, 3) as one mesh: 4 vertices and 2 triangles each."""
    q = len(corners)
    base = 4 * np.arange(q)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=0)
    return corners.reshape(-1, 3).astype(np.float32), faces.astype(np.uint32)


def _triangle_mesh(triangles: NDArray[np.float64]
                   ) -> tuple[NDArray[np.float32], NDArray[np.uint32]]:
    """Triangles (M, 3, 3) as one mesh: 3 vertices and 1 face each."""
    faces = np.arange(3 * len(triangles)).reshape(-1, 3)
    return triangles.reshape(-1, 3).astype(np.float32), faces.astype(np.uint32)


def _triangulate(geometry: Any) -> NDArray[np.float64]:
    """A shapely (multi)polygon in the collector plane as triangles (M, 3, 2) [m]
    (constrained Delaunay: its edges kept, non-convex shapes and holes too)."""
    import shapely

    if geometry is None or geometry.is_empty:
        return np.zeros((0, 3, 2))
    parts = shapely.get_parts(shapely.constrained_delaunay_triangles(geometry))
    return np.asarray([np.asarray(t.exterior.coords)[:3] for t in parts], dtype=float
                      ).reshape(-1, 3, 2)


class PlantView:
    """A plant of trackers as one viser client sees it: its own strategy and instant.

    Parameters
    ----------
    client : viser.ClientHandle
    plant : sim.plant.Plant
    lock : threading.RLock
        The scene's lock.
    """

    def __init__(self, client: viser.ClientHandle, plant: Plant, lock: threading.RLock) -> None:
        self.client = client
        self.plant = plant
        self._lock = lock
        self._tz = plant.timezone
        self.centre = plant.positions.mean(axis=0) * (1.0, 1.0, 0.0)
        self.pivots = plant.positions - self.centre + (0.0, 0.0, PIVOT_HEIGHT_M)
        self.nodes: dict[str, Any] = {}
        self.gui: dict[str, Any] = {}
        self.strategy = "sun"
        self.ts: pd.Timestamp | None = None
        self.sun = (float("nan"), float("nan"))
        self.orientation = (float("nan"), float("nan"))
        self.fraction = np.zeros(plant.n_trackers)
        self.shade: PlantShade | None = None
        self.ground_shadows = np.zeros((0, 4, 3))
        #: a polygon collector's triangles (F, 3, 2) (u, v) [m]; None for the rectangle
        self.triangles_uv: NDArray[np.float64] | None = None
        if not plant.collector.is_rectangle:
            import shapely

            self.triangles_uv = _triangulate(shapely.Polygon(plant.collector.outline_m()))
        self._syncing = False

    def build(self, start: pd.Timestamp, strategy: str = "sun") -> None:
        """Add the plant's nodes and panel and show ``start`` under ``strategy``."""
        if strategy not in strategies_for(self.plant.collector):
            strategy = "sun"  # an unknown name, or one a polygon collector cannot take
        scene, p = self.client.scene, self.plant
        c = p.collector
        span = float(np.ptp(self.pivots[:, :2], axis=0).max()) + 2 * c.width
        with self._lock:
            scene.set_up_direction("+z")
            scene.configure_default_lights(enabled=True, cast_shadow=False)  # only sun shadows
            self.nodes["/ground"] = scene.add_grid(
                "/ground", width=span, height=span, plane="xy", cell_size=5.0,
                section_size=25.0, plane_color=(200, 214, 180), plane_opacity=0.6,
                position=(0.0, 0.0, -0.002))
            for label, (lx, ly) in {"N": (0, 1), "E": (1, 0), "S": (0, -1),
                                    "W": (-1, 0)}.items():
                self.nodes[f"/compass/{label}"] = scene.add_label(
                    f"/compass/{label}", label, position=(lx * span / 2.2, ly * span / 2.2, 0.1),
                    anchor="center-center", font_screen_scale=1.6)
            for k, tid in enumerate(p.tracker_ids):
                x, y, z = self.pivots[k]
                name = f"/plant/tracker_{tid}"
                self.nodes[f"/plant/posts/post_{tid}"] = scene.add_box(
                    f"/plant/posts/post_{tid}", color=_STEEL, dimensions=(0.3, 0.3, z),
                    position=(x, y, z / 2))
                self.nodes[name] = scene.add_frame(name, show_axes=False, position=(x, y, z))
                if self.triangles_uv is None:
                    self.nodes[f"{name}/collector"] = scene.add_box(
                        f"{name}/collector", color=_BLUE,
                        dimensions=(c.width, c.height, COLLECTOR_DEPTH_M))
                else:  # the polygon in the frame's (u, v) plane, both faces lit
                    flat = np.concatenate([self.triangles_uv,
                                           np.zeros((*self.triangles_uv.shape[:2], 1))], axis=2)
                    self.nodes[f"{name}/collector"] = scene.add_mesh_simple(
                        f"{name}/collector", *_triangle_mesh(flat), color=_BLUE, side="double")
                self.nodes[f"/plant/labels/label_{tid}"] = scene.add_label(
                    f"/plant/labels/label_{tid}", str(tid), position=(x, y, z + c.height / 2 + 1),
                    anchor="bottom-center", font_screen_scale=0.9)
            n = p.n_trackers
            if self.triangles_uv is None:
                verts, faces = _quads(np.zeros((n, 4, 3)))
            else:
                verts, faces = _triangle_mesh(np.zeros((n * len(self.triangles_uv), 3, 3)))
            self.nodes["/plant/shadows"] = scene.add_mesh_simple(
                "/plant/shadows", verts, faces, color=(40, 44, 52), opacity=0.5, side="double",
                cast_shadow=False, receive_shadow=False)
            if self.triangles_uv is None:
                verts, faces = _quads(np.zeros((n * MAX_SHADE_RECTS, 4, 3)))
            else:
                verts, faces = _triangle_mesh(np.zeros((n * MAX_SHADE_TRIANGLES, 3, 3)))
            self.nodes["/plant/shade_on_collectors"] = scene.add_mesh_simple(
                "/plant/shade_on_collectors", verts, faces, color=(15, 15, 20), opacity=0.65,
                side="double", cast_shadow=False, receive_shadow=False)
            self.client.camera.position = (span * 0.45, -span * 0.75, span * 0.45)
            self.client.camera.look_at = (0.0, 0.0, 0.0)
            self._build_gui(strategy)
            self.show(start, strategy)

    def _build_gui(self, strategy: str) -> None:
        gui, g, p = self.client.gui, self.gui, self.plant
        c = p.collector
        shape = (f"{c.width:g} m × {c.height:g} m" if c.is_rectangle else
                 f"polygons of {len(c.outline_m())} vertices, {c.area:.3g} m² "
                 f"(in {c.width:g} m × {c.height:g} m)")
        gui.add_markdown(f"**{p.name}** — plant view  \n{p.n_trackers} trackers, collectors "
                         f"{shape} · {self._tz}")
        g["strategy"] = gui.add_dropdown("Strategy", strategies_for(p.collector),
                                         initial_value=strategy)
        g["date"] = gui.add_text("Date (local)", initial_value="",
                                 hint="YYYY-MM-DD, in the plant's time zone")
        g["hours"] = gui.add_slider("Local time [h]", min=0.0, max=24.0, step=0.05,
                                    initial_value=12.0,
                                    marks=((0.0, "0"), (6.0, "6"), (12.0, "12"), (18.0, "18"),
                                           (24.0, "24")))
        g["readout"] = gui.add_markdown("")

        def changed(_: Any) -> None:
            if self._syncing:
                return
            try:
                day = dt.date.fromisoformat(str(g["date"].value).strip())
            except ValueError:
                g["readout"].content = f"**Date {g['date'].value!r} is not YYYY-MM-DD**"
                return
            ts = pd.Timestamp(day).tz_localize(self._tz) + pd.Timedelta(
                hours=float(g["hours"].value))
            self.show(ts, str(g["strategy"].value))

        for key in ("strategy", "date", "hours"):
            g[key].on_update(changed)

    def show(self, ts: pd.Timestamp, strategy: str) -> None:
        """Pose every collector for ``strategy`` at ``ts`` (tz-aware), mark the shaded ones,
        cast the shadows."""
        stamp = pd.Timestamp(ts)
        if stamp.tzinfo is None:
            raise ValueError("ts must be timezone-aware")
        allowed = strategies_for(self.plant.collector)
        if strategy not in allowed:
            raise ValueError(f"strategy must be one of {', '.join(allowed)}")
        p, c = self.plant, self.plant.collector
        sky = sky_conditions(p, pd.DatetimeIndex([stamp.tz_convert("UTC")]))
        saz, sel = orientations(strategy, p, sky)
        sun_az, sun_el = float(sky["solar_azimuth"][0]), float(sky["apparent_elevation"][0])
        shade, _ = field_shade(p, sky, saz, sel)
        n_vec, u, v = (a[0] for a in collector_axes(saz, sel))
        # the collector box's frame is the plant's: x along its width (u), y up its slope (v),
        # z the normal (sim.kinematics.panel_axes, right-handed)
        rot = np.column_stack([u, v, n_vec])
        frac = np.nan_to_num(shade.fraction[0])
        sun = enu_from_sky(sun_az, sun_el)
        lift = (COLLECTOR_DEPTH_M / 2 + 0.03) if self.triangles_uv is None else 0.03

        def on_collector(k: Any, uv: NDArray[np.float64]) -> NDArray[np.float64]:
            """Points (…, 2) (u, v) [m] of collector(s) ``k`` in the scene (ENU, m)."""
            return np.asarray(self.pivots[k])[..., None, :] + uv[..., :1] * u + uv[..., 1:] * v

        def on_ground(points: NDArray[np.float64]) -> NDArray[np.float64]:
            """Points cast along the sun onto z = 0, drawn just above the grid."""
            if sun[2] <= np.sin(np.radians(0.5)):
                return np.zeros_like(points)
            cast = points - points[..., 2:3] / sun[2] * sun
            cast[..., 2] = SHADOW_LIFT_M
            return cast

        idx = np.arange(p.n_trackers)
        ground = on_ground(on_collector(idx, c.outline_m()[None]))  # (N, V, 3)
        if self.triangles_uv is None:
            shadow_mesh = _quads(ground)[0]
            rects = np.zeros((p.n_trackers * MAX_SHADE_RECTS, 4, 3))
            slot = 0
            for g_i in range(len(shade.group_step)):
                k = int(shade.group_tracker[g_i])
                for r, by in zip(shade.group_rects[g_i], shade.group_by[g_i], strict=True):
                    if by < 0 or slot >= len(rects) or r[1] <= r[0] or r[3] <= r[2]:
                        continue
                    uv = np.array([[r[0], r[2]], [r[1], r[2]], [r[1], r[3]], [r[0], r[3]]])
                    rects[slot] = on_collector(k, uv) + lift * n_vec
                    slot += 1
            shade_mesh = _quads(rects)[0]
        else:
            tris = on_collector(idx[:, None], self.triangles_uv[None])  # (N, F, 3, 3)
            shadow_mesh = _triangle_mesh(on_ground(tris).reshape(-1, 3, 3))[0]
            drawn = np.zeros((p.n_trackers * MAX_SHADE_TRIANGLES, 3, 3))
            slot = 0
            for g_i, geometry in enumerate(shade.group_shade if shade.group_shade is not None
                                           else ()):
                k = int(shade.group_tracker[g_i])
                part = _triangulate(geometry)[:len(drawn) - slot]
                drawn[slot:slot + len(part)] = on_collector(k, part) + lift * n_vec
                slot += len(part)
            shade_mesh = _triangle_mesh(drawn)[0]
        with self._lock:
            self.strategy, self.ts, self.shade = strategy, stamp.tz_convert("UTC"), shade
            self.sun, self.orientation = (sun_az, sun_el), (float(saz[0]), float(sel[0]))
            self.fraction, self.ground_shadows = frac, ground
            with self.client.atomic():
                for k, tid in enumerate(p.tracker_ids):
                    self.nodes[f"/plant/tracker_{tid}"].wxyz = wxyz(rot)
                    color = _SHADED if frac[k] > 0 else _BLUE
                    self.nodes[f"/plant/tracker_{tid}/collector"].color = color
                self.nodes["/plant/shadows"].vertices = shadow_mesh
                self.nodes["/plant/shade_on_collectors"].vertices = shade_mesh
            self._sync_gui()
            self._refresh_readout()

    def shaded_ids(self) -> list[int]:
        """Ids of the trackers shaded at the shown instant."""
        return [tid for tid, f in zip(self.plant.tracker_ids, self.fraction, strict=True)
                if f > 0]

    def _sync_gui(self) -> None:
        if self.ts is None or "hours" not in self.gui:
            return
        local = self.ts.tz_convert(self._tz)
        self._syncing = True
        try:
            self.gui["strategy"].value = self.strategy
            self.gui["date"].value = local.date().isoformat()
            self.gui["hours"].value = round(local.hour + local.minute / 60.0, 2)
        finally:
            self._syncing = False

    def _refresh_readout(self) -> None:
        if self.ts is None or "readout" not in self.gui:
            return
        local = self.ts.tz_convert(self._tz)
        p = self.plant
        lines = [f"**{local:%Y-%m-%d %H:%M} {local.tzname()}** · strategy `{self.strategy}`", "",
                 f"Sun: azimuth {self.sun[0]:.1f}°, elevation {self.sun[1]:.1f}°  ",
                 f"Collectors: azimuth {self.orientation[0]:.1f}°, "
                 f"elevation {self.orientation[1]:.1f}°", ""]
        if self.sun[1] <= 0:
            lines.append("Sun below the horizon: collectors stowed flat.")
        else:
            shaded = self.shaded_ids()
            lines.append(f"Shaded: {len(shaded)} of {p.n_trackers} collectors, mean shaded "
                         f"fraction {100 * float(self.fraction.mean()):.2f} %")
            if shaded and self.shade is not None:
                lines += ["", "| tracker | shaded | by |", "|---|---|---|"]
                for k, tid in enumerate(p.tracker_ids):
                    if self.fraction[k] > 0:
                        by = ", ".join(str(p.tracker_ids[b]) for b in self.shade.shaded_by(0, k))
                        lines.append(f"| {tid} | {100 * self.fraction[k]:.1f} % | {by} |")
        self.gui["readout"].content = "\n".join(lines)
