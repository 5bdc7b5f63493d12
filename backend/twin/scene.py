"""The 3D twin: one viser server, a scene of its own for every viewer.

Each browser tab that opens the viser page is a viser client with its own
site, time, play state, replay, nodes and panel (:class:`~backend.twin.scene_view.TwinView`,
or :class:`~backend.twin.scene_plant.PlantView` for a plant of trackers), built
with viser's per-client handles in ``on_client_connect``: one viewer's scrub is
never another's. What a viewer shows comes from the path of its websocket URL,
which the dashboard sets in the iframe's ``?websocket=`` parameter (viser's
client connects to that URL)::

    /site/<site_id>[/viewer/<key>][/time/<ISO UTC, e.g. 2024-03-15T13:30:00Z>]
    /plant/<plant_id>[/strategy/<sun|backtrack|sky_scan>][/time/<ISO UTC>]

The bare page (``/``) shows the default site. ``time`` opens scrubbed at that
instant instead of live. ``viewer`` is the dashboard tab's key: a replayed run
(``PUT /api/v1/twin3d/replay``) is kept per key and shown by that tab's viewers
(also after a reload), or shared by every viewer of the run's site when it is
put without a key.

Scene tree of a site view (children inherit their parent's transform; handles
are kept and only their ``wxyz`` / ``position`` / ``visible`` / ``points`` /
``vertices`` change)::

    /ground, /compass/{N,E,S,W}
    /tracker                         D–H base frame {0} on top of the pedestal
    /tracker/pedestal
    /tracker/azimuth                 frame {1} (A1, joint 1 = azimuth)
    /tracker/azimuth/elevation       frame {2} (A2, joint 2 = elevation)
    /tracker/azimuth/elevation/panels          panel frame (z = normal)
    /tracker/azimuth/elevation/panels/module_i four KD205GX-LP, 2 x 2
    /tracker/azimuth/elevation/panels/camera   seed 000's camera frustum
    /fixed, /fixed/panels/module_i   4 x KD205GX-LP at the site's tilt and azimuth
    /sun, /sun/disc, /sun/ray        sun marker and its ray to the tracker
    /sun_path                        the day's sun path (line segments)
    /shadows/{tracker_panels,tracker_pedestal,fixed_panels}   ground shadows
    /shadows/on_fixed                the tracker collector's shade on the fixed array

The FastAPI lifespan owns one :class:`TwinScene`: ``start()`` on startup,
``update_live()`` from the live twin loop, ``stop()`` on shutdown. The only
background thread is the play/live ticker, which ``stop()`` joins.
"""

from __future__ import annotations

import errno
import logging
import socket
import threading
import urllib.parse
from collections.abc import Callable
from typing import Any

import numpy as np
import pandas as pd
import viser

from backend.twin.scene_build import (
    ARRAY_HEIGHT_M,
    ARRAY_WIDTH_M,
    FIXED_ARRAY_ORIGIN_M,
    PEDESTAL_HEIGHT_M,
)
from backend.twin.scene_plant import PlantView
from backend.twin.scene_pose import Replay, ScenePose
from backend.twin.scene_view import TwinView
from sim.plant import Plant, UnknownPlantError, load_plant
from sim.sites import Site
from sim.sky import clearsky_ineichen
from sim.sun import solar_position
from sim.twin import simulate

logger = logging.getLogger(__name__)

__all__ = ["ARRAY_HEIGHT_M", "ARRAY_WIDTH_M", "FIXED_ARRAY_ORIGIN_M", "PEDESTAL_HEIGHT_M",
           "TwinScene", "parse_view_path"]

TICK_S = 0.1
#: How many ports from the requested one :meth:`TwinScene.start` tries.
PORT_TRIES = 20
#: Twin powers kept per (site, minute) for the readouts.
POWER_CACHE_SIZE = 2048
View = TwinView | PlantView


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



def parse_view_path(path: str) -> dict[str, str]:
    """What a viewer asked for, from its websocket URL's path (module docstring):
    ``/site/tehuantepec/viewer/k1`` → ``{"site": "tehuantepec", "viewer": "k1"}``.
    Segments are percent-decoded key/value pairs; a dangling key is ignored."""
    parts = [urllib.parse.unquote(p) for p in path.partition("?")[0].split("/") if p]
    return {parts[i]: parts[i + 1] for i in range(0, len(parts) - 1, 2)}


def _client_path(server: viser.ViserServer, client: viser.ClientHandle) -> str:
    """The path of a client's websocket URL. viser (1.1) keeps the websocket connection
    per client id in its server; it has no public accessor, so this reads it there and
    falls back to '/' (the default site) when a viser version keeps it elsewhere."""
    live = getattr(getattr(server, "_websock_server", None), "_live_connections", {})
    conn = live.get(client.client_id)
    request = getattr(conn, "request", None)
    return str(getattr(request, "path", "/") or "/")


def _instant(text: str | None) -> pd.Timestamp | None:
    if not text:
        return None
    try:
        ts = pd.Timestamp(text)
    except ValueError:
        return None
    return None if ts.tzinfo is None else ts.tz_convert("UTC")


def _minute_s(ts: pd.Timestamp) -> int:
    return int(ts.floor("min").value // 10**9)


def twin_minute(site: Site, ts: pd.Timestamp) -> dict[str, float]:
    """The twin's powers [W] in the minute holding ``ts`` (``sim.twin.simulate``, clear sky,
    ideal tracking — what the live loop computes) and the fixed array's beam share of its
    plane-of-array irradiance (clear-sky DNI · cos AOI / POA, :func:`sim.sky.clearsky_ineichen`);
    empty for a site without both arrays."""
    if not {"tracker", "fixed"} <= set(site.arrays):
        return {}
    minute = ts.floor("min")
    row = simulate(site, minute, minute + pd.Timedelta(minutes=1), step_s=60).series.iloc[0]
    sp = solar_position(pd.DatetimeIndex([minute]), site.latitude, site.longitude,
                        site.altitude)
    dni = float(clearsky_ineichen(pd.DatetimeIndex([minute]), sp["apparent_zenith"].to_numpy(),
                                  site.latitude, site.longitude, site.altitude)["dni"][0])
    poa = float(row["fixed_poa_global"])
    beam = dni * max(np.cos(np.radians(float(row["fixed_aoi"]))), 0.0)
    return {"tracker_power_w": float(row["tracker_power_w"]),
            "fixed_power_w": float(row["fixed_power_w"]),
            "fixed_beam_share": float(min(beam / poa, 1.0)) if poa > 0 else 0.0}


class TwinScene:
    """The viser server of the 3D twin and its viewers.

    Parameters
    ----------
    site : sim.sites.Site
        The default site (the bare page and a viewer naming an unknown site).
    host, port : str, int
        Where viser listens. Port 0 picks a free port (see :attr:`port`); a busy
        port makes :meth:`start` take the next free one (logged).
    clock : callable, optional
        Returns the current UTC time; the wall clock by default.
    sites : callable, optional
        ``site_id → Site | None``: the sites a viewer may ask for (the service's
        registry); only the default site without it.
    plants : callable, optional
        ``plant_id → Plant`` (raises ``ValueError`` for an unknown or bad one); the
        built-in ``sim/data/plants/`` by default.
    """

    def __init__(
        self,
        site: Site,
        host: str = "127.0.0.1",
        port: int = 8080,
        clock: Callable[[], pd.Timestamp] | None = None,
        sites: Callable[[str], Site | None] | None = None,
        plants: Callable[[str], Plant] | None = None,
    ) -> None:
        self.site = site
        self.host = host
        self.requested_port = port
        self._clock = clock or (lambda: pd.Timestamp.now(tz="UTC"))
        self._sites = sites or (lambda site_id: site if site_id == self.site.site_id else None)
        self._plants = plants or load_plant
        self._lock = threading.RLock()
        self._stop_event = threading.Event()
        self._thread: threading.Thread | None = None
        self.server: viser.ViserServer | None = None
        self.views: dict[int, View] = {}
        #: Replays by viewer key ('' = shared by every viewer of the run's site).
        self.replays: dict[str, Replay] = {}
        self._live_ts: pd.Timestamp | None = None
        self._power_cache: dict[tuple[str, int], tuple[Site, dict[str, float]]] = {}
        self._live_powers: dict[tuple[str, int], dict[str, float]] = {}

    # ------------------------------------------------------------------ lifecycle
    @property
    def port(self) -> int:
        """The port viser actually bound (``requested_port`` until started)."""
        return self.server.get_port() if self.server is not None else self.requested_port

    @property
    def running(self) -> bool:
        return self.server is not None

    def start(self) -> None:
        """Start viser and the ticker thread; viewers get their scenes as they connect.

        Returns at once (viser serves from its own thread). Calling it on a
        running scene does nothing. A host that cannot be listened on, or no
        free port among the next :data:`PORT_TRIES`, is an OSError raised
        before viser starts (viser itself would retry such a host forever); a
        failure while setting the server up stops viser again before re-raising.
        """
        with self._lock:
            if self.server is not None:
                logger.warning("TwinScene.start() on a running scene ignored")
                return
            port = _free_port(self.host, self.requested_port)
            if port != self.requested_port:
                logger.warning("viser port %d busy, serving on %d", self.requested_port, port)
            self.server = viser.ViserServer(host=self.host, port=port, verbose=False)
            self.views = {}
            try:
                self._setup_server()
            except BaseException:
                server, self.server = self.server, None
                server.stop()
                raise
            self._stop_event.clear()
            self._thread = threading.Thread(target=self._tick_loop, name="twin3d-ticker",
                                            daemon=True)
            self._thread.start()
            logger.info("3D twin (default site %s) at http://%s:%d/", self.site.site_id,
                        self.host, self.port)

    def _setup_server(self) -> None:
        assert self.server is not None
        self.server.scene.set_up_direction("+z")
        self.server.on_client_connect(self._on_connect)
        self.server.on_client_disconnect(self._on_disconnect)

    def stop(self) -> None:
        """Stop the ticker thread and viser, freeing the port. Idempotent."""
        self._stop_event.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout=5.0)
        with self._lock:
            server, self.server = self.server, None
            self.views = {}
        if server is not None:
            server.stop()

    # ------------------------------------------------------------------ viewers
    def _on_connect(self, client: viser.ClientHandle) -> None:
        assert self.server is not None
        want = parse_view_path(_client_path(self.server, client))
        start = _instant(want.get("time"))
        try:
            view: View = (self._plant_view(client, want, start) if "plant" in want
                          else self._site_view(client, want, start))
        except UnknownPlantError as exc:  # the viewer's address, not a fault of the service
            logger.info("3D twin: viewer %d asked for %s", client.client_id, exc)
            client.gui.add_markdown(f"**No such plant**: {exc}.")
            return
        except Exception:
            logger.exception("3D twin: viewer %d (%s) could not be built", client.client_id,
                             want)
            client.gui.add_markdown("**The 3D twin could not build this view** (see the "
                                    "service log).")
            return
        with self._lock:
            if self.server is not None:
                self.views[client.client_id] = view

    def _site_view(self, client: viser.ClientHandle, want: dict[str, str],
                   start: pd.Timestamp | None) -> TwinView:
        site_id = want.get("site", self.site.site_id)
        site = self._sites(site_id)
        note = ""
        if site is None:
            site, note = self.site, f"Unknown site {site_id!r}: showing {self.site.site_id}."
        view = TwinView(client, site, self._lock, self.live_now, self.power_at,
                        viewer=want.get("viewer", ""), note=note)
        view.build(start)
        replay = self.replays.get(view.viewer) or self.replays.get("")
        if replay is not None and replay.site_id in ("", site.site_id):
            view.load_replay(replay)
        return view

    def _plant_view(self, client: viser.ClientHandle, want: dict[str, str],
                    start: pd.Timestamp | None) -> PlantView:
        plant = self._plants(want["plant"])
        view = PlantView(client, plant, self._lock)
        view.build(start or self.live_now(), want.get("strategy", "sun"))
        return view

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        with self._lock:
            self.views.pop(client.client_id, None)

    def site_views(self, viewer: str | None = None) -> list[TwinView]:
        """The connected site viewers (those with key ``viewer`` when given)."""
        with self._lock:
            return [v for v in self.views.values() if isinstance(v, TwinView)
                    and (viewer is None or v.viewer == viewer)]

    # ---------------------------------------------------------------- public API
    def live_now(self) -> pd.Timestamp:
        """The service's clock: the last :meth:`update_live` time, else the wall clock."""
        return self._live_ts if self._live_ts is not None else pd.Timestamp(self._clock())

    def update_live(
        self, ts: pd.Timestamp | Any, tracker_power_w: float | None = None,
        fixed_power_w: float | None = None, site_id: str | None = None,
    ) -> None:
        """Latest time (and the twin's powers for ``site_id``, the default site if None)
        from the service's live twin loop.

        Live viewers move to ``ts`` at once; the powers are the readout's for that
        minute (the loop ran the same one-minute simulation :func:`twin_minute` would).
        ``ts`` must be timezone-aware (ValueError otherwise); powers may be None.
        """
        stamp = pd.Timestamp(ts)
        if stamp.tzinfo is None:
            raise ValueError("ts must be timezone-aware")
        stamp = stamp.tz_convert("UTC")
        sid = site_id or self.site.site_id
        with self._lock:
            self._live_ts = stamp
            if tracker_power_w is not None and fixed_power_w is not None:
                if len(self._live_powers) >= POWER_CACHE_SIZE:
                    self._live_powers.clear()
                self._live_powers[(sid, _minute_s(stamp))] = {
                    "tracker_power_w": float(tracker_power_w),
                    "fixed_power_w": float(fixed_power_w)}
            views = list(self.views.values())
        for view in views:
            if isinstance(view, TwinView):
                view.on_live(stamp)

    def power_at(self, site: Site, ts: pd.Timestamp) -> dict[str, float]:
        """The twin's powers at ``ts`` (:func:`twin_minute`, cached per site and minute); in
        a minute the live loop reported (:meth:`update_live`), its powers."""
        stamp = pd.Timestamp(ts).tz_convert("UTC")
        key = (site.site_id, _minute_s(stamp))
        with self._lock:
            hit = self._power_cache.get(key)
            live = self._live_powers.get(key)
        if hit is not None and hit[0] is site:  # the same site object: not edited since
            values = hit[1]
        else:
            try:
                values = twin_minute(site, stamp)
            except Exception:  # a readout never takes the viewer down
                logger.exception("3D twin: the twin at %s for %s failed", stamp, site.site_id)
                values = {}
            with self._lock:
                if len(self._power_cache) >= POWER_CACHE_SIZE:
                    self._power_cache.clear()
                self._power_cache[key] = (site, values)
        return {**values, **live} if live is not None and values else values

    def load_replay(self, replay: Replay, viewer: str = "") -> list[ScenePose]:
        """Show a run: in the viewers with key ``viewer`` (kept for the key, so a reload shows
        it again), or with ``viewer`` '' in every viewer of the run's site without a replay
        of its own. Returns the poses of the viewers it reached now (possibly none)."""
        with self._lock:
            self.replays[viewer] = replay
            views = [v for v in self.site_views(viewer or None)
                     if replay.site_id in ("", v.site.site_id)
                     and (viewer or v.viewer not in self.replays or not v.viewer)]
        return [v.load_replay(replay) for v in views]

    def clear_replay(self, viewer: str = "") -> int:
        """Forget the replay of key ``viewer`` ('' = the shared one); its viewers go back to
        the live clock. Returns how many viewers that reset."""
        with self._lock:
            replay = self.replays.pop(viewer, None)
            views = [v for v in self.site_views() if replay is not None and v.replay is replay]
        for v in views:
            v.clear_replay()
        return len(views)

    # ------------------------------------------------------------------- ticker
    def _tick_loop(self) -> None:
        """Every TICK_S: each viewer's play or live refresh. Runs until ``stop()``."""
        while not self._stop_event.wait(TICK_S):
            with self._lock:
                views = list(self.views.values())
            for view in views:
                if not isinstance(view, TwinView):
                    continue  # a plant view has no clock of its own
                try:
                    view.tick(TICK_S)
                except Exception:  # keep the ticker alive; the service must not die
                    logger.exception("3D twin tick failed")
