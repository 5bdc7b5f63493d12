"""The 3D twin: a viser scene of the tracker and the fixed array at a site.

The tracker is posed by the same Denavit–Hartenberg kinematics as the
simulation (:mod:`sim.kinematics`, seed 000 Table 2 / eq. 23 with seed 002's
d1 and a2) and the sun comes from :func:`sim.sun.solar_position` (NREL SPA via
pvlib). World coordinates are East-North-Up in metres, z up, origin on the
ground at the foot of the tracker's pedestal.

Scene tree (children inherit their parent's transform; handles are kept and
only their ``wxyz`` / ``position`` / ``visible`` / ``points`` change)::

    /ground, /compass/{N,E,S,W}
    /tracker                         D–H base frame {0} on top of the pedestal
    /tracker/pedestal
    /tracker/azimuth                 frame {1} (A1, joint 1 = azimuth)
    /tracker/azimuth/elevation       frame {2} (A2, joint 2 = elevation)
    /tracker/azimuth/elevation/panels          panel frame (z = normal)
    /tracker/azimuth/elevation/panels/module_i four KD205GX-LP, 2 x 2
    /tracker/azimuth/elevation/panels/camera   seed 000's camera frustum
    /fixed, /fixed/panels/module_i   4 x KD205GX-LP at 16° facing south
    /sun, /sun/disc, /sun/ray        sun marker and its ray to the tracker
    /sun_path                        the day's sun path (line segments)

GUI: date, time-of-day slider, play/pause with a speed, a live mode that
follows the service's clock (the ``ts`` of :meth:`TwinScene.update_live`, or
the wall clock when no update has come), and readouts of the angles and power.

The FastAPI lifespan owns one :class:`TwinScene`: ``start()`` on startup,
``update_live()`` from the live twin loop, ``stop()`` on shutdown. The only
background thread is the play/live ticker, which ``stop()`` joins.
"""

from __future__ import annotations

import datetime as dt
import errno
import logging
import socket
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pandas as pd
import viser
from numpy.typing import NDArray

from backend.twin.scene_build import (
    PEDESTAL_HEIGHT_M,
    SUN_DISTANCE_M,
    SUN_PATH_STEP_MIN,
    build_ghost,
    build_static_scene,
    wxyz,
)
from backend.twin.scene_pose import Replay, ScenePose
from sim.kinematics import (
    TrackerGeometry,
    forward_kinematics,
    joint_transforms,
    tracking_angles,
)
from sim.pv import ArrayConfig
from sim.sites import Site
from sim.sun import solar_position
from vision.sphere import enu_from_sky

logger = logging.getLogger(__name__)

TICK_S = 0.1
#: How many ports from the requested one :meth:`TwinScene.start` tries.
PORT_TRIES = 20
LIVE_REFRESH_S = 5.0

def _free_port(host: str, port: int) -> int:
    """``port`` if ``host`` can listen on it, else the next free one (0 stays 0: the OS picks).

    Raises ValueError for a port outside 0–65535 and OSError for a host that
    does not resolve or is not an address of this machine, or when none of
    :data:`PORT_TRIES` ports from ``port`` on is free.
    """
    if not 0 <= port <= 65535:
        raise ValueError(f"viser port must be in 0-65535, got {port}")
    try:
        family, _, _, _, addr = socket.getaddrinfo(host or None, port, type=socket.SOCK_STREAM,
                                                   flags=socket.AI_PASSIVE)[0]
    except socket.gaierror as exc:
        raise OSError(f"viser host {host!r} does not resolve: {exc.strerror}") from None
    last: OSError | None = None
    for candidate in range(port, min(port + PORT_TRIES, 65536)) if port else (0,):
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                probe.bind((addr[0], candidate, *addr[2:]))
            except OSError as exc:
                if exc.errno != errno.EADDRINUSE:
                    raise OSError(f"viser cannot listen on {host!r}: {exc.strerror}") from None
                last = exc
                continue
        return candidate
    raise OSError(f"viser: no free port in {port}-{port + PORT_TRIES - 1} on {host!r} "
                  f"({last.strerror if last else 'busy'})")


def _fixed_orientation(site: Site) -> tuple[float, float]:
    """(surface_tilt, surface_azimuth) [°] of the site's ``fixed`` array (its config is
    the one place they are set), or an ``ArrayConfig``'s defaults when it has none."""
    fixed = site.arrays.get("fixed") or ArrayConfig("fixed")
    return float(fixed.surface_tilt), float(fixed.surface_azimuth)


class TwinScene:
    """The viser 3D twin of one site.

    Parameters
    ----------
    site : sim.sites.Site
        Location (``latitude``, ``longitude``, ``altitude``, ``timezone``), the
        tracker geometry (``tracker``) and the arrays (``arrays['fixed']`` gives
        the fixed array's tilt/azimuth).
    host, port : str, int
        Where viser listens. Port 0 picks a free port (see :attr:`port`); a busy
        port makes :meth:`start` take the next free one (logged).
    clock : callable, optional
        Returns the current UTC time; the wall clock by default.
    """

    def __init__(
        self,
        site: Site,
        host: str = "127.0.0.1",
        port: int = 8080,
        clock: Callable[[], pd.Timestamp] | None = None,
    ) -> None:
        self.site = site
        self.host = host
        self.requested_port = port
        self._clock = clock or (lambda: pd.Timestamp.now(tz="UTC"))
        self._geometry: TrackerGeometry = site.tracker
        self._tz = site.timezone
        self._fixed_tilt_deg, self._fixed_azimuth_deg = _fixed_orientation(site)
        self._lock = threading.RLock()
        self._stop_event = threading.Event()
        self._thread: threading.Thread | None = None
        self.server: viser.ViserServer | None = None
        self.nodes: dict[str, Any] = {}
        self.gui: dict[str, Any] = {}
        self.pose: ScenePose | None = None
        self._day: dt.date | None = None
        self._hours = 12.0
        self._playing = False
        self._live = True
        self._last_live_refresh = 0.0
        self._syncing_gui = False
        self._azimuth_reference: float | None = None
        self.replay: Replay | None = None
        self._live_ts: pd.Timestamp | None = None
        self._live_tracker_power_w: float | None = None
        self._live_fixed_power_w: float | None = None

    # ------------------------------------------------------------------ lifecycle
    @property
    def port(self) -> int:
        """The port viser actually bound (``requested_port`` until started)."""
        return self.server.get_port() if self.server is not None else self.requested_port

    @property
    def running(self) -> bool:
        return self.server is not None

    def start(self) -> None:
        """Start viser, build the scene and the GUI, start the ticker thread.

        Returns at once (viser serves from its own thread). Calling it on a
        running scene does nothing. A host that cannot be listened on, or no
        free port among the next :data:`PORT_TRIES`, is an OSError raised
        before viser starts (viser itself would retry such a host forever); a
        failure while building the scene stops viser again before re-raising.
        """
        with self._lock:
            if self.server is not None:
                logger.warning("TwinScene.start() on a running scene ignored")
                return
            port = _free_port(self.host, self.requested_port)
            if port != self.requested_port:
                logger.warning("viser port %d busy, serving on %d", self.requested_port, port)
            self.server = viser.ViserServer(host=self.host, port=port, verbose=False)
            self.nodes = {}
            self.gui = {}
            self._day = None
            self._azimuth_reference = None
            try:
                self._build_static_scene()
                self._build_gui()
                self.show_time(self._live_now())
            except BaseException:
                server, self.server = self.server, None
                self.nodes, self.gui = {}, {}
                server.stop()
                raise
            self._stop_event.clear()
            self._thread = threading.Thread(target=self._tick_loop, name="twin3d-ticker",
                                            daemon=True)
            self._thread.start()
            logger.info("3D twin for %s at http://%s:%d/", self.site.site_id, self.host,
                        self.port)

    def stop(self) -> None:
        """Stop the ticker thread and viser, freeing the port. Idempotent."""
        self._stop_event.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout=5.0)
        with self._lock:
            server, self.server = self.server, None
            self.nodes = {}
            self.gui = {}
        if server is not None:
            server.stop()

    # ---------------------------------------------------------------- public API
    def update_live(
        self, ts: pd.Timestamp | dt.datetime, tracker_power_w: float | None,
        fixed_power_w: float | None,
    ) -> None:
        """Latest time and powers from the service's live twin loop.

        In live mode the scene moves to ``ts`` at once. ``ts`` must be
        timezone-aware (ValueError otherwise); powers may be None (unknown).
        """
        stamp = pd.Timestamp(ts)
        if stamp.tzinfo is None:
            raise ValueError("ts must be timezone-aware")
        with self._lock:
            self._live_ts = stamp.tz_convert("UTC")
            self._live_tracker_power_w = None if tracker_power_w is None else float(
                tracker_power_w)
            self._live_fixed_power_w = None if fixed_power_w is None else float(fixed_power_w)
            if self.server is None:
                return
            if self._live:
                self.show_time(self._live_ts)
            else:
                self._refresh_readout()

    def pose_at(self, ts: pd.Timestamp) -> ScenePose:
        """Sun and tracker pose at ``ts`` (no scene change).

        The tracker follows the sun by :func:`sim.kinematics.tracking_angles`
        (limits applied; the previous azimuth as the wrap reference); with the
        sun below the horizon the scene shows it stowed flat (elevation joint at
        its upper limit).
        """
        stamp = pd.Timestamp(ts)
        if stamp.tzinfo is None:
            raise ValueError("ts must be timezone-aware")
        site = self.site
        sp = solar_position(pd.DatetimeIndex([stamp]), site.latitude, site.longitude,
                            site.altitude)
        sun_az = float(sp["azimuth"].iloc[0])
        sun_el = float(sp["apparent_elevation"].iloc[0])
        az_j, el_j = tracking_angles(sun_az, sun_el, self._geometry,
                                     reference_azimuth=self._azimuth_reference)
        ideal_az, ideal_el = float(az_j), float(el_j)
        az_joint, el_joint, error_mrad, run_id = ideal_az, ideal_el, None, None
        base = np.eye(3)
        row = None if self.replay is None else self.replay.row_at(stamp.tz_convert("UTC"))
        if row is not None and self.replay is not None:
            r = self.replay
            az_joint = float(r.azimuth_joint_deg[row])
            el_joint = float(r.elevation_joint_deg[row])
            error_mrad, run_id, base = float(r.pointing_error_mrad[row]), r.run_id, r.base_rotation
        stowed = sun_el <= 0.0
        normal = base @ forward_kinematics(az_joint, el_joint, self._geometry)
        sun_vec = enu_from_sky(sun_az, sun_el)
        fixed_normal = forward_kinematics(self._fixed_azimuth_deg,
                                          90.0 - self._fixed_tilt_deg, self._geometry)
        return ScenePose(
            ts=stamp.tz_convert("UTC"),
            solar_azimuth_deg=sun_az,
            solar_elevation_deg=sun_el,
            azimuth_joint_deg=az_joint,
            elevation_joint_deg=el_joint,
            stowed=stowed,
            tracker_normal_enu=normal,
            tracker_aoi_deg=float(np.degrees(np.arccos(np.clip(normal @ sun_vec, -1, 1)))),
            fixed_aoi_deg=float(np.degrees(np.arccos(np.clip(fixed_normal @ sun_vec, -1, 1)))),
            ideal_azimuth_joint_deg=ideal_az,
            ideal_elevation_joint_deg=ideal_el,
            pointing_error_mrad=error_mrad,
            replay_run_id=run_id,
        )

    def load_replay(self, replay: Replay) -> ScenePose | None:
        """Show a simulation run: scrubbing its days poses the tracker as the run did; the
        scene leaves live mode and moves to the run's start."""
        with self._lock:
            self.replay = replay
            if self.server is None:
                return None
            self._leave_live()
            self._set_playing(False)
            return self.show_time(replay.start)

    def clear_replay(self) -> ScenePose | None:
        """Back to ideal tracking and the live clock."""
        with self._lock:
            self.replay = None
            if self.server is None:
                return None
            self._live = True
            self._syncing_gui = True
            try:
                self.gui["live"].value = True
            finally:
                self._syncing_gui = False
            return self.show_time(self._live_now())

    def show_time(self, ts: pd.Timestamp) -> ScenePose:
        """Pose the whole scene at ``ts`` (tz-aware) and sync the GUI to it."""
        with self._lock:
            if self.server is None:
                raise RuntimeError("TwinScene is not running; call start() first")
            pose = self.pose_at(ts)
            self._azimuth_reference = pose.azimuth_joint_deg
            local = pose.ts.tz_convert(self._tz)
            if local.date() != self._day:
                self._set_day(local.date())
            self._hours = local.hour + local.minute / 60.0 + local.second / 3600.0
            self._apply_pose(pose)
            self.pose = pose
            self._sync_gui(local)
            self._refresh_readout()
            return pose

    # ------------------------------------------------------------- scene building
    def _add(self, name: str, handle: Any) -> Any:
        self.nodes[name] = handle
        return handle

    def _build_static_scene(self) -> None:
        assert self.server is not None
        self.nodes.update(build_static_scene(self.server, self._geometry,
                                             self._fixed_tilt_deg, self._fixed_azimuth_deg))
        self.nodes.update(build_ghost(self.server))

    def _sun_centre(self) -> NDArray[np.float64]:
        """The point the sun marker and path are drawn around: the tracker's
        elevation axis."""
        return np.array([0.0, 0.0, PEDESTAL_HEIGHT_M + self._geometry.d1_m])

    def _set_day(self, day: dt.date) -> None:
        """Recompute the day's sun path (local calendar day of the site)."""
        self._day = day
        start = pd.Timestamp(day).tz_localize(self._tz)
        times = pd.date_range(start, start + pd.Timedelta(days=1),
                              freq=f"{SUN_PATH_STEP_MIN}min", inclusive="left")
        sp = solar_position(times, self.site.latitude, self.site.longitude,
                            self.site.altitude)
        el = sp["apparent_elevation"].to_numpy()
        pts = self._sun_centre() + SUN_DISTANCE_M * enu_from_sky(sp["azimuth"].to_numpy(), el)
        up = (el[:-1] > 0.0) & (el[1:] > 0.0)
        segments = np.stack([pts[:-1][up], pts[1:][up]], axis=1)
        if len(segments) == 0:  # polar night
            segments = np.zeros((1, 2, 3))
        self.nodes["/sun_path"].points = segments.astype(np.float32)
        if "date" in self.gui:
            self._syncing_gui = True
            try:
                self.gui["date"].value = day.isoformat()
            finally:
                self._syncing_gui = False

    def _apply_pose(self, pose: ScenePose) -> None:
        assert self.server is not None
        t01, t02, t0p = joint_transforms(pose.azimuth_joint_deg, pose.elevation_joint_deg,
                                         self._geometry)
        t12 = np.linalg.solve(t01, t02)
        t2p = np.linalg.solve(t02, t0p)
        sun_dir = enu_from_sky(pose.solar_azimuth_deg, pose.solar_elevation_deg)
        # rotation whose z axis is the sun direction
        z = sun_dir
        x = np.cross([0.0, 0.0, 1.0], z)
        x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-9 else np.array([1.0, 0.0, 0.0])
        sun_rot = np.column_stack([x, np.cross(z, x), z])
        base = self.replay.base_rotation if pose.replay_run_id and self.replay else np.eye(3)
        g01, g02, g0p = joint_transforms(pose.ideal_azimuth_joint_deg,
                                         pose.ideal_elevation_joint_deg, self._geometry)
        n = self.nodes
        with self.server.atomic():
            n["/tracker"].wxyz = wxyz(base)
            n["/ghost"].visible = pose.ghost_visible
            n["/ghost/azimuth"].wxyz = wxyz(g01[:3, :3])
            n["/ghost/azimuth"].position = g01[:3, 3]
            n["/ghost/azimuth/elevation"].wxyz = wxyz(np.linalg.solve(g01, g02)[:3, :3])
            n["/ghost/azimuth/elevation"].position = np.linalg.solve(g01, g02)[:3, 3]
            n["/ghost/azimuth/elevation/panels"].wxyz = wxyz(np.linalg.solve(g02, g0p)[:3, :3])
            n["/ghost/azimuth/elevation/panels"].position = np.linalg.solve(g02, g0p)[:3, 3]
            n["/tracker/azimuth"].wxyz = wxyz(t01[:3, :3])
            n["/tracker/azimuth"].position = t01[:3, 3]
            n["/tracker/azimuth/elevation"].wxyz = wxyz(t12[:3, :3])
            n["/tracker/azimuth/elevation"].position = t12[:3, 3]
            n["/tracker/azimuth/elevation/panels"].wxyz = wxyz(t2p[:3, :3])
            n["/tracker/azimuth/elevation/panels"].position = t2p[:3, 3]
            n["/sun"].position = self._sun_centre() + SUN_DISTANCE_M * sun_dir
            n["/sun"].wxyz = wxyz(sun_rot)
            n["/sun"].visible = pose.solar_elevation_deg > 0.0

    # ---------------------------------------------------------------------- GUI
    def _build_gui(self) -> None:
        assert self.server is not None
        gui = self.server.gui
        g = self.gui
        gui.add_markdown(f"**{self.site.name}** — 3D twin  \n"
                         f"{self.site.latitude:.4f}°, {self.site.longitude:.4f}° · "
                         f"{self._tz}")
        with gui.add_folder("Time"):
            g["live"] = gui.add_checkbox("Live (service clock)", initial_value=self._live,
                                         hint="Follow the service's clock and live power")
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
            if self._syncing_gui:
                return
            self._live = bool(g["live"].value)
            if self._live:
                self._set_playing(False)
                self.show_time(self._live_now())

        @g["hours"].on_update
        def _(_: Any) -> None:
            if self._syncing_gui:
                return
            self._leave_live()
            self._show_hours(float(g["hours"].value))

        @g["date"].on_update
        def _(_: Any) -> None:
            if self._syncing_gui:
                return
            try:
                day = dt.date.fromisoformat(str(g["date"].value).strip())
            except ValueError:
                self._refresh_readout(error=f"Date {g['date'].value!r} is not YYYY-MM-DD")
                return
            self._leave_live()
            with self._lock:
                if self.server is not None:
                    self._set_day(day)
                self._show_hours(self._hours)

        @g["play"].on_click
        def _(_: Any) -> None:
            self._leave_live()
            self._set_playing(not self._playing)

    def _leave_live(self) -> None:
        if self._live:
            self._live = False
            self._syncing_gui = True
            try:
                self.gui["live"].value = False
            finally:
                self._syncing_gui = False

    def _set_playing(self, playing: bool) -> None:
        self._playing = playing
        button = self.gui.get("play")
        if button is not None:
            button.label = "Pause" if playing else "Play"
            button.icon = viser.Icon.PLAYER_PAUSE if playing else viser.Icon.PLAYER_PLAY

    def _show_hours(self, hours: float) -> None:
        with self._lock:
            if self.server is None or self._day is None:
                return
            start = pd.Timestamp(self._day).tz_localize(self._tz)
            self.show_time(start + pd.Timedelta(hours=hours))

    def _sync_gui(self, local: pd.Timestamp) -> None:
        if "hours" not in self.gui:
            return
        self._syncing_gui = True
        try:
            self.gui["hours"].value = round(self._hours, 2)
            self.gui["date"].value = local.date().isoformat()
        finally:
            self._syncing_gui = False

    def _refresh_readout(self, error: str | None = None) -> None:
        if "readout" not in self.gui or self.pose is None:
            return
        p = self.pose
        local = p.ts.tz_convert(self._tz)

        def watts(x: float | None) -> str:
            return "—" if x is None or not np.isfinite(x) else f"{x:.0f} W"

        live_at = ("no live data yet" if self._live_ts is None else
                   self._live_ts.tz_convert(self._tz).strftime("%Y-%m-%d %H:%M"))
        state = "stowed (sun down)" if p.stowed else "tracking"
        run = []
        if p.replay_run_id is not None:
            run = ["", f"Run {p.replay_run_id[:8]}: pointing error {p.pointing_error_mrad:.1f} mrad"
                   + (" (ideal pose shown translucent)" if p.ghost_visible else "")]
        lines = [
            f"**{local:%Y-%m-%d %H:%M} {local.tzname()}** "
            f"({'live' if self._live else 'playing' if self._playing else 'scrubbing'})",
            "",
            "| | azimuth | elevation |",
            "|---|---|---|",
            f"| sun | {p.solar_azimuth_deg:.1f}° | {p.solar_elevation_deg:.1f}° |",
            f"| tracker joints | {p.azimuth_joint_deg:.1f}° | {p.elevation_joint_deg:.1f}° |",
            "",
            f"Tracker: {state}, AOI {p.tracker_aoi_deg:.1f}°  ",
            f"Fixed ({self._fixed_tilt_deg:.0f}° tilt, {self._fixed_azimuth_deg:.0f}° az): "
            f"AOI {p.fixed_aoi_deg:.1f}°",
            "",
            f"Live power ({live_at}): tracker {watts(self._live_tracker_power_w)}, "
            f"fixed {watts(self._live_fixed_power_w)}",
            *run,
        ]
        if error:
            lines.append(f"\n**{error}**")
        self.gui["readout"].content = "\n".join(lines)

    # ------------------------------------------------------------------- ticker
    def _live_now(self) -> pd.Timestamp:
        return self._live_ts if self._live_ts is not None else pd.Timestamp(self._clock())

    def _tick_loop(self) -> None:
        """Play mode advances the scrubbed time; live mode refreshes from the
        clock every LIVE_REFRESH_S. Runs until ``stop()`` sets the event."""
        while not self._stop_event.wait(TICK_S):
            try:
                if self._playing:
                    speed_min_s = float(self.gui["speed"].value)
                    self._show_hours((self._hours + speed_min_s * TICK_S / 60.0) % 24.0)
                elif self._live and time.monotonic() - self._last_live_refresh > LIVE_REFRESH_S:
                    self._last_live_refresh = time.monotonic()
                    with self._lock:
                        if self.server is not None:
                            self.show_time(self._live_now())
            except Exception:  # keep the ticker alive; the service must not die
                logger.exception("3D twin tick failed")
