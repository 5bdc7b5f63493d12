"""One viewer of the 3D twin: its own site, time, play state, replay, scene nodes and panel.

Every browser tab that opens the viser page is a viser client; :class:`TwinView`
builds the whole scene for it with its per-client handles (``client.scene``,
``client.gui``), so one viewer's scrub, play or replay never reaches another.
The server (:class:`backend.twin.scene.TwinScene`) routes clients to views and
runs the one ticker.

The tracker is posed by the same Denavit–Hartenberg kinematics as the
simulation (:mod:`sim.kinematics`, seed 000 Table 2 / eq. 23 with seed 002's
d1 and a2) and the sun comes from :func:`sim.sun.solar_position` (NREL SPA via
pvlib). World coordinates are East-North-Up in metres, z up, origin on the
ground at the foot of the tracker's pedestal. Shadows are cast along the sun
vector (:mod:`backend.twin.scene_shadow`): on the ground from the tracker's
collector and pedestal and the fixed array. The tracker collector's shade on
the fixed array, and its shaded fraction the readout reports as a loss, come
from :func:`sim.array_shade.fixed_shade`, the function the twin's energy uses;
the arrays stand where the site config places them, else the fixed array is
assumed at :data:`backend.twin.scene_build.FIXED_ARRAY_ORIGIN_M` (said in the
readout).
"""

from __future__ import annotations

import datetime as dt
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pandas as pd
import viser
from numpy.typing import NDArray
from pvlib.atmosphere import alt2pres

from backend.twin.scene_build import (
    ARRAY_HEIGHT_M,
    ARRAY_WIDTH_M,
    CAMERA_LOOK_AT_M,
    CAMERA_POSITION_M,
    COLLECTOR_BOX_M,
    FIXED_ARRAY_ORIGIN_M,
    MODULE_DEPTH_M,
    PEDESTAL_HEIGHT_M,
    PEDESTAL_SIDE_M,
    SUN_DISTANCE_M,
    SUN_PATH_STEP_MIN,
    build_ghost,
    build_shadows,
    build_static_scene,
    wxyz,
)
from backend.twin.scene_pose import Replay, ScenePose
from backend.twin.scene_shadow import box_corners, fan_mesh, ground_shadow
from sim.array_shade import Layout, Placement, fixed_shade, layout_of
from sim.kinematics import (
    forward_kinematics,
    joint_transforms,
    morning_azimuth,
    tracking_angles,
)
from sim.sites import Site
from sim.sun import solar_position
from vision.sphere import enu_from_sky

LIVE_REFRESH_S = 5.0
#: The twin's powers at an instant: ``tracker_power_w``, ``fixed_power_w``, … [W] (empty
#: when the site cannot be simulated).
PowerAt = Callable[[Site, pd.Timestamp], dict[str, float]]


def fixed_of(site: Site) -> tuple[float, float] | None:
    """(surface_tilt, surface_azimuth) [°] of the site's ``fixed`` array, None without one."""
    fixed = site.arrays.get("fixed")
    return None if fixed is None else (float(fixed.surface_tilt), float(fixed.surface_azimuth))


def scene_layout(site: Site) -> Layout | None:
    """Where the scene puts the arrays: as the site config places them
    (:func:`sim.array_shade.layout_of`), else the tracker at the origin and the fixed array
    at :data:`FIXED_ARRAY_ORIGIN_M` with the drawn 2 × 2 outline (``Layout.assumed``); None
    without a tracker and a fixed array."""
    w, h = ARRAY_WIDTH_M, ARRAY_HEIGHT_M
    east, north = FIXED_ARRAY_ORIGIN_M[:2]
    return layout_of(site, assumed=(Placement(0.0, 0.0, width_m=w, height_m=h),
                                    Placement(east, north, width_m=w, height_m=h)))


def tracker_world(azimuth_joint_deg: float, elevation_joint_deg: float, site: Site,
                  base: NDArray[np.float64], pedestal_height_m: float = PEDESTAL_HEIGHT_M
                  ) -> tuple[NDArray[np.float64], ...]:
    """World transforms (4 × 4) of the tracker's D–H frames {1}, {2} and its panel frame,
    with the base frame {0} on top of the pedestal turned by ``base`` (3 × 3)."""
    t_base = np.eye(4)
    t_base[:3, :3] = base
    t_base[:3, 3] = (0.0, 0.0, pedestal_height_m)
    return tuple(t_base @ t for t in joint_transforms(azimuth_joint_deg, elevation_joint_deg,
                                                      site.tracker))


def shadows_at(layout: Layout | None, panels_world: NDArray[np.float64],
               base: NDArray[np.float64], sun_enu: NDArray[np.float64],
               pedestal_height_m: float = PEDESTAL_HEIGHT_M
               ) -> tuple[dict[str, NDArray[np.float64]], float | None, NDArray[np.float64]]:
    """Ground shadows by node name, the fixed array's shaded fraction (None without a fixed
    array) and the shade polygon on it (ENU), for the tracker's panel frame ``panels_world``."""
    h = pedestal_height_m
    pedestal = np.eye(4)
    pedestal[:3, :3] = base
    pedestal[:3, 3] = base @ (0.0, 0.0, -h / 2.0) + (0, 0, h)
    out = {
        "/shadows/tracker_panels": ground_shadow(box_corners(panels_world, COLLECTOR_BOX_M),
                                                 sun_enu),
        "/shadows/tracker_pedestal": ground_shadow(
            box_corners(pedestal, (PEDESTAL_SIDE_M, PEDESTAL_SIDE_M, h)), sun_enu),
    }
    if layout is None:
        return out, None, np.zeros((0, 3))
    t_fixed = np.eye(4)
    t_fixed[:3, :3], t_fixed[:3, 3] = layout.fixed_axes, layout.fixed_centre_enu
    out["/shadows/fixed_panels"] = ground_shadow(
        box_corners(t_fixed, (*layout.fixed_size_m, MODULE_DEPTH_M)), sun_enu)
    shade = fixed_shade(layout, panels_world[None], sun_enu[None])
    polygon = shade.polygon_enu[0, :shade.vertices[0]]
    lift = MODULE_DEPTH_M / 2.0 + 0.01  # drawn just above the modules' front faces
    return out, float(shade.fraction[0]), polygon + lift * layout.fixed_axes[:, 2]


class TwinView:
    """The 3D twin as one viser client sees it.

    Parameters
    ----------
    client : viser.ClientHandle
        The viewer; every node and control is added through its handles.
    site : sim.sites.Site
        What it shows (tracker geometry, place, fixed array).
    lock : threading.RLock
        The scene's lock (viser calls back from its thread pool, the ticker from its own).
    live_now : callable
        The service's current time (the live clock).
    power_at : callable
        The twin's powers at an instant (:data:`PowerAt`).
    viewer : str
        The viewer key from the page's URL ('' when none): replays are keyed by it.
    note : str
        A line for the panel (e.g. an unknown site that fell back to the default).
    """

    def __init__(self, client: viser.ClientHandle, site: Site, lock: threading.RLock,
                 live_now: Callable[[], pd.Timestamp], power_at: PowerAt, viewer: str = "",
                 note: str = "") -> None:
        self.client = client
        self.site = site
        self.viewer = viewer
        self._lock = lock
        self._live_now = live_now
        self._power_at = power_at
        self._note = note
        self._tz = site.timezone
        self.layout = scene_layout(site)
        self._pedestal_m = (PEDESTAL_HEIGHT_M if self.layout is None
                            else self.layout.tracker_mount_height_m)
        self.nodes: dict[str, Any] = {}
        self.gui: dict[str, Any] = {}
        self.pose: ScenePose | None = None
        self.power: dict[str, float] = {}
        self.shadows: dict[str, NDArray[np.float64]] = {}
        self.replay: Replay | None = None
        self.live = True
        self.playing = False
        self._day: dt.date | None = None
        self._hours = 12.0
        self._syncing = False
        self._azimuth_reference: float | None = None
        self._last_live_refresh = 0.0

    # ---------------------------------------------------------------- building
    def build(self, start: pd.Timestamp | None = None) -> None:
        """Add the viewer's scene and panel, then show ``start`` (scrubbed) or the live time."""
        scene = self.client.scene
        with self._lock:
            lay = self.layout
            fixed = None if lay is None else (lay.fixed_centre_enu, lay.fixed_axes)
            self.nodes.update(build_static_scene(scene, self.site.tracker, fixed,
                                                 self._pedestal_m))
            self.nodes.update(build_ghost(scene, self._pedestal_m))
            self.nodes.update(build_shadows(scene, lay is not None))
            self.client.camera.position = CAMERA_POSITION_M
            self.client.camera.look_at = CAMERA_LOOK_AT_M
            self._build_gui()
            if start is None:
                self._show(self._live_now())
            else:
                self.show_time(start)

    def _build_gui(self) -> None:
        gui, g, s = self.client.gui, self.gui, self.site
        gui.add_markdown(f"**{s.name}** — 3D twin  \n{s.latitude:.4f}°, {s.longitude:.4f}° · "
                         f"{self._tz}" + (f"  \n*{self._note}*" if self._note else ""))
        with gui.add_folder("Time"):
            g["live"] = gui.add_checkbox("Live (service clock)", initial_value=self.live,
                                         hint="Follow the service's clock")
            g["date"] = gui.add_text("Date (local)", initial_value="",
                                     hint="YYYY-MM-DD, in the site's time zone")
            g["hours"] = gui.add_slider(
                "Local time [h]", min=0.0, max=24.0, step=0.01, initial_value=12.0,
                marks=((0.0, "0"), (6.0, "6"), (12.0, "12"), (18.0, "18"), (24.0, "24")))
            g["play"] = gui.add_button("Play", icon=viser.Icon.PLAYER_PLAY)
            g["speed"] = gui.add_slider("Speed [min/s]", min=1, max=120, step=1,
                                        initial_value=10,
                                        hint="Simulated minutes per second of playback")
        with gui.add_folder("Readouts"):
            g["readout"] = gui.add_markdown("")

        @g["live"].on_update
        def _(_: Any) -> None:
            if self._syncing:
                return
            with self._lock:
                self.live = bool(g["live"].value)
                if self.live:
                    self._set_playing(False)
                    self._show(self._live_now())

        @g["hours"].on_update
        def _(_: Any) -> None:
            if self._syncing:
                return
            with self._lock:
                self._leave_live()
                self._show_hours(float(g["hours"].value))

        @g["date"].on_update
        def _(_: Any) -> None:
            if self._syncing:
                return
            try:
                day = dt.date.fromisoformat(str(g["date"].value).strip())
            except ValueError:
                self._refresh_readout(error=f"Date {g['date'].value!r} is not YYYY-MM-DD")
                return
            with self._lock:
                self._leave_live()
                self._set_day(day)
                self._show_hours(self._hours)

        @g["play"].on_click
        def _(_: Any) -> None:
            with self._lock:
                self._leave_live()
                self._set_playing(not self.playing)

    # ------------------------------------------------------------------ state
    def pose_at(self, ts: pd.Timestamp) -> ScenePose:
        """Sun, tracker pose and the fixed array's shade at ``ts`` (no scene change).

        The tracker follows the sun by :func:`sim.kinematics.tracking_angles` (limits
        applied; the previous azimuth as the wrap reference; stowed flat with the sun
        down), or takes a replayed run's joints where the run covers ``ts``.
        """
        stamp = pd.Timestamp(ts)
        if stamp.tzinfo is None:
            raise ValueError("ts must be timezone-aware")
        stamp = stamp.tz_convert("UTC")
        site = self.site
        sp = self._sun(pd.DatetimeIndex([stamp]))
        sun_az = float(sp["azimuth"].iloc[0])
        sun_el = float(sp["apparent_elevation"].iloc[0])
        az_j, el_j = tracking_angles(
            sun_az, sun_el, site.tracker, reference_azimuth=self._azimuth_reference,
            night_azimuth=float(morning_azimuth(pd.DatetimeIndex([stamp]), site.latitude,
                                                site.longitude)[0]))  # the twin's stow rule
        ideal_az, ideal_el = float(az_j), float(el_j)
        az_joint, el_joint, error_mrad, run_id = ideal_az, ideal_el, None, None
        base = np.eye(3)
        row = None if self.replay is None else self.replay.row_at(stamp)
        if row is not None and self.replay is not None:
            r = self.replay
            az_joint = float(r.azimuth_joint_deg[row])
            el_joint = float(r.elevation_joint_deg[row])
            stated, run_id, base = float(r.pointing_error_mrad[row]), r.run_id, r.base_rotation
            # defined only while tracking with the sun up (sim.twin): NaN or a stowed night
            # step (a run stored before that rule) is no pointing error at all
            error_mrad = stated if np.isfinite(stated) and sun_el > 0.0 else None
        normal = base @ forward_kinematics(az_joint, el_joint, site.tracker)
        sun_vec = enu_from_sky(sun_az, sun_el)
        fixed = fixed_of(site)
        fixed_aoi = float("nan")
        if fixed is not None:
            fixed_normal = enu_from_sky(fixed[1], 90.0 - fixed[0])
            fixed_aoi = float(np.degrees(np.arccos(np.clip(fixed_normal @ sun_vec, -1, 1))))
        panels = tracker_world(az_joint, el_joint, site, base, self._pedestal_m)[2]
        shadows, shaded, shade_poly = shadows_at(self.layout, panels, base, sun_vec,
                                                 self._pedestal_m)
        self.shadows = {**shadows, "/shadows/on_fixed": shade_poly}
        return ScenePose(
            ts=stamp, solar_azimuth_deg=sun_az, solar_elevation_deg=sun_el,
            azimuth_joint_deg=az_joint, elevation_joint_deg=el_joint, stowed=sun_el <= 0.0,
            tracker_normal_enu=normal,
            tracker_aoi_deg=float(np.degrees(np.arccos(np.clip(normal @ sun_vec, -1, 1)))),
            fixed_aoi_deg=fixed_aoi, ideal_azimuth_joint_deg=ideal_az,
            ideal_elevation_joint_deg=ideal_el, pointing_error_mrad=error_mrad,
            replay_run_id=run_id, fixed_shaded_fraction=shaded)

    def show_time(self, ts: pd.Timestamp) -> ScenePose:
        """Scrub this viewer to ``ts`` (tz-aware): it leaves live mode, as the panel's time
        controls do, and the scene and panel show ``ts``."""
        with self._lock:
            self._leave_live()
            return self._show(ts)

    def _show(self, ts: pd.Timestamp) -> ScenePose:
        """Pose the scene at ``ts`` and sync the panel to it (the mode stays)."""
        with self._lock:
            pose = self.pose_at(ts)
            self._azimuth_reference = pose.azimuth_joint_deg
            local = pose.ts.tz_convert(self._tz)
            if local.date() != self._day:
                self._set_day(local.date())
            self._hours = local.hour + local.minute / 60.0 + local.second / 3600.0
            self._apply_pose(pose)
            self.pose = pose
            self.power = self._powers(pose)
            self._sync_gui(local)
            self._refresh_readout()
            return pose

    def _powers(self, pose: ScenePose) -> dict[str, float]:
        """The twin's powers at the shown instant: the replayed run's step, else the twin."""
        r = self.replay
        row = None if r is None or pose.replay_run_id is None else r.row_at(pose.ts)
        if r is not None and row is not None and len(r.tracker_power_w):
            return {"tracker_power_w": float(r.tracker_power_w[row]),
                    "fixed_power_w": float(r.fixed_power_w[row])}
        return self._power_at(self.site, pose.ts)

    def load_replay(self, replay: Replay) -> ScenePose:
        """Show a simulation run: leaves live mode and moves to the run's start."""
        with self._lock:
            self.replay = replay
            self._set_playing(False)
            return self.show_time(replay.start)

    def clear_replay(self) -> ScenePose:
        """Back to ideal tracking and the live clock."""
        with self._lock:
            self.replay = None
            self.live = True
            self._set_gui("live", True)
            return self._show(self._live_now())

    def tick(self, dt_s: float) -> None:
        """The ticker's call: play advances the time; live refreshes every LIVE_REFRESH_S."""
        with self._lock:
            if self.playing:
                speed_min_s = float(self.gui["speed"].value)
                self._show_hours((self._hours + speed_min_s * dt_s / 60.0) % 24.0)
            elif self.live and time.monotonic() - self._last_live_refresh > LIVE_REFRESH_S:
                self._last_live_refresh = time.monotonic()
                self._show(self._live_now())

    def on_live(self, ts: pd.Timestamp) -> None:
        """A new live time from the service: a live viewer moves there at once."""
        with self._lock:
            if self.live:
                self._show(ts)

    # ---------------------------------------------------------------- helpers
    def _set_gui(self, key: str, value: Any) -> None:
        if key not in self.gui:
            return
        self._syncing = True
        try:
            self.gui[key].value = value
        finally:
            self._syncing = False

    def _leave_live(self) -> None:
        if self.live:
            self.live = False
            self._set_gui("live", False)

    def _set_playing(self, playing: bool) -> None:
        self.playing = playing
        button = self.gui.get("play")
        if button is not None:
            button.label = "Pause" if playing else "Play"
            button.icon = viser.Icon.PLAYER_PAUSE if playing else viser.Icon.PLAYER_PLAY

    def _show_hours(self, hours: float) -> None:
        if self._day is None:
            return
        start = pd.Timestamp(self._day).tz_localize(self._tz)
        self._show(start + pd.Timedelta(hours=hours))

    def _sync_gui(self, local: pd.Timestamp) -> None:
        self._set_gui("hours", round(self._hours, 2))
        self._set_gui("date", local.date().isoformat())

    def _sun(self, times: pd.DatetimeIndex) -> pd.DataFrame:
        """Sun positions as the twin computes them (the site's pressure and air temperature
        for the refraction, :func:`sim.twin.simulate`)."""
        s = self.site
        return solar_position(times, s.latitude, s.longitude, s.altitude,
                              float(alt2pres(s.altitude)), s.temp_air)

    def _sun_centre(self) -> NDArray[np.float64]:
        """The point the sun marker and path are drawn around: the elevation axis."""
        return np.array([0.0, 0.0, self._pedestal_m + self.site.tracker.d1_m])

    def _set_day(self, day: dt.date) -> None:
        """Recompute the day's sun path (local calendar day of the site)."""
        self._day = day
        start = pd.Timestamp(day).tz_localize(self._tz)
        times = pd.date_range(start, start + pd.Timedelta(days=1),
                              freq=f"{SUN_PATH_STEP_MIN}min", inclusive="left")
        sp = self._sun(times)
        el = sp["apparent_elevation"].to_numpy()
        pts = self._sun_centre() + SUN_DISTANCE_M * enu_from_sky(sp["azimuth"].to_numpy(), el)
        up = (el[:-1] > 0.0) & (el[1:] > 0.0)
        segments = np.stack([pts[:-1][up], pts[1:][up]], axis=1)
        if len(segments) == 0:  # polar night
            segments = np.zeros((1, 2, 3))
        self.nodes["/sun_path"].points = segments.astype(np.float32)
        self._set_gui("date", day.isoformat())

    def _apply_pose(self, pose: ScenePose) -> None:
        t01, t02, t0p = joint_transforms(pose.azimuth_joint_deg, pose.elevation_joint_deg,
                                         self.site.tracker)
        sun_dir = enu_from_sky(pose.solar_azimuth_deg, pose.solar_elevation_deg)
        x = np.cross([0.0, 0.0, 1.0], sun_dir)  # a rotation whose z axis is the sun direction
        x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-9 else np.array([1.0, 0.0, 0.0])
        sun_rot = np.column_stack([x, np.cross(sun_dir, x), sun_dir])
        base = self.replay.base_rotation if pose.replay_run_id and self.replay else np.eye(3)
        g01, g02, g0p = joint_transforms(pose.ideal_azimuth_joint_deg,
                                         pose.ideal_elevation_joint_deg, self.site.tracker)
        n = self.nodes

        def chain(prefix: str, a: NDArray[np.float64], b: NDArray[np.float64],
                  c: NDArray[np.float64]) -> None:
            for name, t in ((f"{prefix}/azimuth", a),
                            (f"{prefix}/azimuth/elevation", np.linalg.solve(a, b)),
                            (f"{prefix}/azimuth/elevation/panels", np.linalg.solve(b, c))):
                n[name].wxyz = wxyz(t[:3, :3])
                n[name].position = t[:3, 3]

        with self.client.atomic():
            n["/tracker"].wxyz = wxyz(base)
            n["/ghost"].visible = pose.ghost_visible
            chain("/ghost", g01, g02, g0p)
            chain("/tracker", t01, t02, t0p)
            n["/sun"].position = self._sun_centre() + SUN_DISTANCE_M * sun_dir
            n["/sun"].wxyz = wxyz(sun_rot)
            n["/sun"].visible = pose.solar_elevation_deg > 0.0
            for name, poly in self.shadows.items():
                if name in n:
                    n[name].vertices = fan_mesh(poly)[0]

    def _refresh_readout(self, error: str | None = None) -> None:
        if "readout" not in self.gui or self.pose is None:
            return
        p, site = self.pose, self.site
        local = p.ts.tz_convert(self._tz)

        def watts(key: str) -> str:
            x = self.power.get(key)
            return "—" if x is None or not np.isfinite(x) else f"{x:.0f} W"

        mode = "live" if self.live else "playing" if self.playing else "scrubbing"
        lines = [
            f"**{local:%Y-%m-%d %H:%M} {local.tzname()}** ({mode})", "",
            "| | azimuth | elevation |", "|---|---|---|",
            f"| sun | {p.solar_azimuth_deg:.1f}° | {p.solar_elevation_deg:.1f}° |",
            f"| tracker joints | {p.azimuth_joint_deg:.1f}° | {p.elevation_joint_deg:.1f}° |",
            "", f"Tracker: {'stowed (sun down)' if p.stowed else 'tracking'}, "
                f"AOI {p.tracker_aoi_deg:.1f}°  ",
        ]
        fixed = fixed_of(site)
        if fixed is not None:
            lines.append(f"Fixed ({fixed[0]:.0f}° tilt, {fixed[1]:.0f}° az): "
                         f"AOI {p.fixed_aoi_deg:.1f}°")
        source = (f"run {p.replay_run_id[:8]}" if p.replay_run_id and "tracker_power_w" in
                  self.power and self.replay is not None and len(self.replay.tracker_power_w)
                  else "twin, clear sky")
        lines += ["", f"Power at {local:%H:%M} ({source}): tracker {watts('tracker_power_w')}, "
                      f"fixed {watts('fixed_power_w')}"]
        if p.fixed_shaded_fraction is not None:
            f = p.fixed_shaded_fraction
            if f > 0:
                beam = self.power.get("fixed_beam_share", float("nan"))
                loss = self.power.get("fixed_power_w", float("nan")) * f * beam
                lines += ["", f"**Tracker shades the fixed array: {100 * f:.1f} % of its area**"
                          + (f", ≈ {loss:.0f} W lost (area-proportional, beam only; more with "
                             "bypass diodes)" if np.isfinite(loss) else "")]
            else:
                lines += ["", "Tracker's shadow on the fixed array: none"]
            if self.layout is not None and self.layout.assumed:
                east, north = FIXED_ARRAY_ORIGIN_M[:2]
                lines.append(f"*Position assumed: the fixed array {east:g} m east, {north:g} m "
                             "north of the tracker (the site config places no arrays); this "
                             "shade is not in the twin's energy.*")
            else:
                lines.append("*Arrays placed by the site config; the twin's fixed power "
                             "includes this shade.*")
        if p.replay_run_id is not None:
            shown = ("—" if p.pointing_error_mrad is None else
                     f"{p.pointing_error_mrad:.1f} mrad")
            lines += ["", f"Run {p.replay_run_id[:8]}: pointing error {shown}"
                      + (" (ideal pose shown translucent)" if p.ghost_visible else "")]
        if error:
            lines.append(f"\n**{error}**")
        self.gui["readout"].content = "\n".join(lines)
