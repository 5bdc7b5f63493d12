"""Tests of the viser 3D twin (backend/twin/scene*.py) over a real viser server on a free port.

Viewers are real websocket clients speaking viser's protocol (the path of the URL
says what to show, as the dashboard's iframe does). The tracker's pose is checked
against pvlib's own solar position (independent of sim.sun and sim.kinematics);
shadows against a second method each: the area of a box's shadow from its lit
faces (Σ A_f |n_f·s| / s_z over the three face pairs) instead of projecting and
hulling its corners, and the tracker's shade on the fixed array by casting rays
from a grid of points on the fixed array towards the sun instead of projecting and
clipping the tracker's outline.
"""

from __future__ import annotations

import dataclasses
import socket
import threading
import time
from collections.abc import Iterator

import httpx
import msgspec
import numpy as np
import pandas as pd
import pvlib
import pytest
import shapely
import viser
import viser.transforms as vtf
from viser import _messages
from websockets.sync.client import ClientConnection, connect

from backend.twin.scene import (
    ARRAY_HEIGHT_M,
    ARRAY_WIDTH_M,
    PEDESTAL_HEIGHT_M,
    TwinScene,
    parse_view_path,
)
from backend.twin.scene_build import COLLECTOR_BOX_M, PEDESTAL_BOX_M
from backend.twin.scene_plant import COLLECTOR_DEPTH_M, PIVOT_HEIGHT_M, PlantView
from backend.twin.scene_view import TwinView
from sim.array_shade import Layout, Placement, fixed_shade
from sim.kinematics import TrackerGeometry, forward_kinematics, inverse_kinematics, joint_transforms
from sim.plant import load_plant
from sim.plant.fields import collector_from_outline
from sim.plant.shading import plant_shade
from sim.pv import ArrayConfig
from sim.sites import Site, load_site
from sim.twin import simulate

SITE = load_site("tehuantepec")
CAMERA_SITE = load_site("guadalajara_fisheye")
#: A second site, physically different: another latitude, a fixed array tilted 35° facing
#: south-west (built here, not from data/sites/).
OTHER = dataclasses.replace(
    SITE, site_id="other", name="Test site at 40° N", latitude=40.0, longitude=-3.7,
    timezone="Europe/Madrid",
    arrays={**SITE.arrays, "fixed": ArrayConfig("fixed", surface_tilt=35.0,
                                                 surface_azimuth=225.0)})
#: Tehuantepec with its arrays placed by the config: the tracker's pedestal 10 m east, 5 m
#: north of the site origin on a 2.0 m pedestal, the fixed array 3 m east and 1 m north of
#: it (13, 6), its lower edge 0.3 m up.
PLACED = dataclasses.replace(SITE, site_id="placed", placements={
    "tracker": Placement(10.0, 5.0, mount_height_m=2.0),
    "fixed": Placement(13.0, 6.0, mount_height_m=0.3)})
SITES = {s.site_id: s for s in (SITE, CAMERA_SITE, OTHER, PLACED)}
TZ = "America/Mexico_City"
NAMED = [
    "/ground", "/tracker", "/tracker/pedestal", "/tracker/azimuth",
    "/tracker/azimuth/elevation", "/tracker/azimuth/elevation/panels",
    "/tracker/azimuth/elevation/panels/module_0", "/tracker/azimuth/elevation/panels/module_3",
    "/tracker/azimuth/elevation/panels/camera", "/fixed", "/fixed/panels/module_0", "/sun",
    "/sun/disc", "/sun_path", "/shadows/tracker_panels", "/shadows/tracker_pedestal",
    "/shadows/fixed_panels", "/shadows/on_fixed",
]


class Viewer:
    """A viser client over a real websocket: connects to ``path``, reports a camera (viser
    registers a client on its first camera message) and drains what the server sends."""

    def __init__(self, scene: TwinScene, path: str) -> None:
        self.ws: ClientConnection = connect(f"ws://127.0.0.1:{scene.port}{path}",
                                            subprotocols=[f"viser-v{viser.__version__}"])
        cam = _messages.ViewerCameraMessage(
            wxyz=(1.0, 0.0, 0.0, 0.0), position=(6.0, -8.0, 4.0), fov=1.0, near=0.01, far=500.0,
            image_height=480, image_width=640, look_at=(0.0, 0.0, 1.5),
            up_direction=(0.0, 0.0, 1.0))
        self.ws.send(msgspec.msgpack.encode(cam.as_serializable_dict()))
        self.received = 0
        threading.Thread(target=self._drain, daemon=True).start()

    def _drain(self) -> None:
        try:
            while True:
                self.ws.recv()
                self.received += 1
        except Exception:
            return

    def close(self) -> None:
        self.ws.close()


def _open(scene: TwinScene, path: str) -> tuple[Viewer, TwinView | PlantView]:
    before = set(scene.views)
    v = Viewer(scene, path)
    for _ in range(300):
        new = set(scene.views) - before
        if new:
            return v, scene.views[new.pop()]
        time.sleep(0.05)
    v.close()
    raise AssertionError(f"no view for {path}")


@pytest.fixture(scope="module")
def scene() -> Iterator[TwinScene]:
    s = TwinScene(SITE, "127.0.0.1", 0, sites=SITES.get)
    s.start()
    try:
        yield s
    finally:
        s.stop()


@pytest.fixture()
def view(scene: TwinScene) -> Iterator[TwinView]:
    client, v = _open(scene, "/site/tehuantepec/viewer/t1")
    assert isinstance(v, TwinView)
    try:
        yield v
    finally:
        client.close()


def _world(v: TwinView, path: str) -> np.ndarray:
    """4x4 world transform of a node, composed from its ancestors' handles."""
    parts = path.strip("/").split("/")
    t = np.eye(4)
    for i in range(1, len(parts) + 1):
        h = v.nodes["/" + "/".join(parts[:i])]
        local = np.eye(4)
        local[:3, :3] = vtf.SO3(np.asarray(h.wxyz)).as_matrix()
        local[:3, 3] = h.position
        t = t @ local
    return t


def _pvlib_sun(site: Site, ts: pd.Timestamp) -> tuple[float, float, np.ndarray]:
    sp = pvlib.solarposition.get_solarposition(pd.DatetimeIndex([ts]), site.latitude,
                                               site.longitude, site.altitude)
    az, el = float(sp["azimuth"].iloc[0]), float(sp["apparent_elevation"].iloc[0])
    a, e = np.radians(az), np.radians(el)
    return az, el, np.array([np.sin(a) * np.cos(e), np.cos(a) * np.cos(e), np.sin(e)])


def test_view_paths_parse() -> None:
    assert parse_view_path("/site/tehuantepec/viewer/k1") == {"site": "tehuantepec",
                                                             "viewer": "k1"}
    assert parse_view_path("/plant/pe%C3%B1a/time/2024-12-21T08:24:00Z/dangling") == {
        "plant": "peña", "time": "2024-12-21T08:24:00Z"}
    assert parse_view_path("/") == {}


def test_starts_on_free_port_and_serves_the_client(scene: TwinScene) -> None:
    assert scene.running and scene.port > 0
    r = httpx.get(f"http://127.0.0.1:{scene.port}/", timeout=10.0)
    assert r.status_code == 200 and "<html" in r.text.lower()


def test_named_nodes_exist_for_the_viewer_only(scene: TwinScene, view: TwinView) -> None:
    registered = view.client.scene._handle_from_node_name  # viser's per-client name map
    for name in NAMED:
        assert name in view.nodes, name
        assert name in registered, name
    assert "/tracker" not in scene.server.scene._handle_from_node_name  # nothing global


@pytest.mark.parametrize("local", ["2024-03-15 08:30", "2024-03-15 12:04", "2024-06-21 12:30",
                                   "2024-12-21 16:45"])
def test_tracker_orientation_equals_fk_and_faces_the_sun(view: TwinView, local: str) -> None:
    ts = pd.Timestamp(local, tz=TZ)
    pose = view.show_time(ts)
    panels = _world(view, "/tracker/azimuth/elevation/panels")
    normal = panels[:3, 2]
    az, el, sun = _pvlib_sun(SITE, ts)
    az_j, el_j = inverse_kinematics(az, el, SITE.tracker)
    np.testing.assert_allclose(normal, forward_kinematics(az_j, el_j, SITE.tracker), atol=1e-4)
    assert np.degrees(np.arccos(np.clip(normal @ sun, -1, 1))) < 0.01  # ideal tracking
    assert pose.tracker_aoi_deg < 0.01
    # panel centre: base on the pedestal + d1 up + a2 along the normal (seed 002, eq. 2)
    expected_centre = [0, 0, PEDESTAL_HEIGHT_M + SITE.tracker.d1_m] + SITE.tracker.a2_m * sun
    np.testing.assert_allclose(panels[:3, 3], expected_centre, atol=1e-4)
    sun_pos = view.nodes["/sun"].position - np.array([0, 0, PEDESTAL_HEIGHT_M + 0.355])
    np.testing.assert_allclose(sun_pos / np.linalg.norm(sun_pos), sun, atol=1e-4)
    assert view.nodes["/sun"].visible


def test_fixed_array_faces_south_at_16_deg(view: TwinView) -> None:
    normal = _world(view, "/fixed/panels")[:3, 2]
    t = np.radians(16.0)  # seed 000, section 3.3
    np.testing.assert_allclose(normal, [0.0, -np.sin(t), np.cos(t)], atol=1e-6)
    ts = pd.Timestamp("2024-03-15 15:00", tz=TZ)
    pose = view.show_time(ts)
    az, el, _ = _pvlib_sun(SITE, ts)
    aoi = float(pvlib.irradiance.aoi(16.0, 180.0, 90.0 - el, az))
    assert pose.fixed_aoi_deg == pytest.approx(aoi, abs=0.01)


def test_night_stows_flat_hides_the_sun_and_casts_no_shadow(view: TwinView) -> None:
    pose = view.show_time(pd.Timestamp("2024-03-15 23:00", tz=TZ))
    assert pose.stowed and pose.solar_elevation_deg < 0
    assert not view.nodes["/sun"].visible
    normal = _world(view, "/tracker/azimuth/elevation/panels")[:3, 2]
    np.testing.assert_allclose(normal, [0, 0, 1], atol=1e-9)
    assert all(len(p) == 0 for p in view.shadows.values())
    assert pose.fixed_shaded_fraction == 0.0


def test_sun_path_covers_daylight_only(view: TwinView) -> None:
    view.show_time(pd.Timestamp("2024-03-15 12:00", tz=TZ))
    pts = np.asarray(view.nodes["/sun_path"].points)
    assert pts.shape[1:] == (2, 3) and len(pts) > 100  # ~12 h at 5 min
    assert np.all(pts[..., 2] > PEDESTAL_HEIGHT_M + 0.355 - 1e-3)


def _box_shadow_area(rot: np.ndarray, dims: tuple[float, float, float], sun: np.ndarray) -> float:
    """Second method: a convex box's shadow area from its lit faces, Σ A_f |n_f·s| / s_z."""
    a, b, c = dims
    return float((b * c * abs(rot[:, 0] @ sun) + a * c * abs(rot[:, 1] @ sun)
                  + a * b * abs(rot[:, 2] @ sun)) / sun[2])


@pytest.mark.parametrize("local", ["2024-03-15 07:30", "2024-03-15 12:00", "2024-03-15 17:30",
                                   "2024-12-21 09:10"])
def test_ground_shadows_are_cast_from_the_sun(view: TwinView, local: str) -> None:
    ts = pd.Timestamp(local, tz=TZ)
    view.show_time(ts)
    az, el, sun = _pvlib_sun(SITE, ts)
    panels = _world(view, "/tracker/azimuth/elevation/panels")
    fixed = _world(view, "/fixed")
    pedestal = _world(view, "/tracker/pedestal")
    for name, t, dims in (("/shadows/tracker_panels", panels, COLLECTOR_BOX_M),
                          ("/shadows/fixed_panels", fixed, COLLECTOR_BOX_M),
                          ("/shadows/tracker_pedestal", pedestal, PEDESTAL_BOX_M)):
        poly = shapely.Polygon(view.shadows[name])
        assert poly.area == pytest.approx(_box_shadow_area(t[:3, :3], dims, sun), rel=1e-3), name
        # a box is centrally symmetric: its shadow's centroid is the shadow of its centre
        c = t[:3, 3]
        expected = c[:2] - c[2] / np.tan(np.radians(el)) * np.array(
            [np.sin(np.radians(az)), np.cos(np.radians(az))])
        np.testing.assert_allclose([poly.centroid.x, poly.centroid.y], expected, atol=2e-3)
    # what the viewer's mesh holds is that polygon (a fan at the ground)
    verts = np.asarray(view.nodes["/shadows/tracker_panels"].vertices)
    np.testing.assert_allclose(verts[:len(view.shadows["/shadows/tracker_panels"]), :2],
                               view.shadows["/shadows/tracker_panels"], atol=1e-4)
    assert np.all(np.abs(verts[:, 2]) < 0.01)


def test_shadows_move_between_morning_and_evening(view: TwinView) -> None:
    view.show_time(pd.Timestamp("2024-03-15 07:30", tz=TZ))
    morning = shapely.Polygon(view.shadows["/shadows/tracker_panels"])
    view.show_time(pd.Timestamp("2024-03-15 17:30", tz=TZ))
    evening = shapely.Polygon(view.shadows["/shadows/tracker_panels"])
    assert morning.centroid.x < -4.0 and evening.centroid.x > 4.0  # west, then east
    assert morning.intersection(evening).area == 0.0


def _ray_cast_fraction(v: TwinView, n: int = 240) -> float:
    """Second method: points on a grid over the fixed array, each a ray towards the sun;
    the fraction that hits the tracker's collector rectangle."""
    assert v.pose is not None
    sun = np.array([np.sin(np.radians(v.pose.solar_azimuth_deg)),
                    np.cos(np.radians(v.pose.solar_azimuth_deg)), 0.0])
    sun = sun * np.cos(np.radians(v.pose.solar_elevation_deg))
    sun[2] = np.sin(np.radians(v.pose.solar_elevation_deg))
    fixed = _world(v, "/fixed")  # the drawn fixed array
    centre, rot = fixed[:3, 3], fixed[:3, :3]
    g = (np.arange(n) + 0.5) / n - 0.5
    uu, vv = np.meshgrid(g * ARRAY_WIDTH_M, g * ARRAY_HEIGHT_M)
    pts = centre + uu.reshape(-1, 1) * rot[:, 0] + vv.reshape(-1, 1) * rot[:, 1]
    panels = _world(v, "/tracker/azimuth/elevation/panels")
    o, r = panels[:3, 3], panels[:3, :3]
    lam = ((o - pts) @ r[:, 2]) / (sun @ r[:, 2])
    hit = pts + lam[:, None] * sun - o
    inside = (lam > 0) & (np.abs(hit @ r[:, 0]) <= ARRAY_WIDTH_M / 2) & (
        np.abs(hit @ r[:, 1]) <= ARRAY_HEIGHT_M / 2)
    return float(inside.mean())


@pytest.mark.parametrize("local", ["2024-03-15 12:00", "2024-03-15 16:30", "2024-03-15 17:00",
                                   "2024-03-15 17:30"])
def test_tracker_shade_on_the_fixed_array_matches_ray_casting(view: TwinView,
                                                               local: str) -> None:
    pose = view.show_time(pd.Timestamp(local, tz=TZ))
    expected = _ray_cast_fraction(view)
    assert pose.fixed_shaded_fraction == pytest.approx(expected, abs=0.01)
    text = view.gui["readout"].content
    if expected > 0.01:
        assert f"{100 * pose.fixed_shaded_fraction:.1f} % of its area" in text
        assert "W lost" in text
    else:
        assert "shadow on the fixed array: none" in text
    # tehuantepec places no arrays: the scene assumes 4.5 m east and says so
    np.testing.assert_allclose(_world(view, "/fixed")[:2, 3], [4.5, 0.0], atol=1e-9)
    assert "Position assumed: the fixed array 4.5 m east" in text


def test_arrays_placed_by_the_config_are_drawn_there_and_shade_as_the_twin_says(
        scene: TwinScene) -> None:
    client, v = _open(scene, "/site/placed/viewer/p1")
    try:
        assert isinstance(v, TwinView)
        # drawn relative to the tracker's pedestal foot: 3 m east, 1 m north; lower edge 0.3 m
        fixed = _world(v, "/fixed")
        t = np.radians(16.0)
        np.testing.assert_allclose(fixed[:3, 3], [3.0, 1.0, 0.3 + ARRAY_HEIGHT_M / 2 * np.sin(t)],
                                   atol=1e-9)
        np.testing.assert_allclose(_world(v, "/tracker")[:3, 3], [0.0, 0.0, 2.0], atol=1e-9)
        start = pd.Timestamp("2024-03-15 15:00", tz=TZ)
        twin = simulate(PLACED, start, start + pd.Timedelta(hours=3), step_s=900).series
        fractions = twin["fixed_shaded_fraction"]
        assert fractions.max() > 0.3  # the evening shade reaches this nearer array
        for ts, f in fractions.items():
            pose = v.show_time(ts)
            assert pose.fixed_shaded_fraction == pytest.approx(f, abs=1e-7)  # one function
            assert pose.fixed_shaded_fraction == pytest.approx(_ray_cast_fraction(v), abs=0.01)
        text = v.gui["readout"].content
        assert "Arrays placed by the site config" in text and "assumed" not in text
    finally:
        client.close()


def test_readout_follows_the_scrubbed_time_not_the_live_power(scene: TwinScene,
                                                              view: TwinView) -> None:
    view.gui["live"].value = True
    scene.update_live(pd.Timestamp("2024-04-25 12:00", tz=TZ), 612.5, 540.0)
    assert view.live and "612 W" in view.gui["readout"].content  # the live loop's numbers
    view.gui["date"].value = "2024-03-15"
    view.gui["hours"].value = 7.5  # scrubbing leaves live mode
    assert not view.live and view.pose is not None
    assert view.pose.ts == pd.Timestamp("2024-03-15 07:30", tz=TZ)
    minute = view.pose.ts
    row = simulate(SITE, minute, minute + pd.Timedelta(minutes=1), step_s=60).series.iloc[0]
    text = view.gui["readout"].content
    assert "Power at 07:30" in text and "612 W" not in text
    assert f"tracker {row['tracker_power_w']:.0f} W" in text
    assert f"fixed {row['fixed_power_w']:.0f} W" in text
    with pytest.raises(ValueError, match="timezone"):
        scene.update_live(pd.Timestamp("2024-04-25 11:00"), 1.0, 1.0)


def test_two_viewers_scrub_and_play_independently(scene: TwinScene) -> None:
    ca, a = _open(scene, "/site/tehuantepec/viewer/a")
    cb, b = _open(scene, "/site/tehuantepec/viewer/b")
    try:
        assert isinstance(a, TwinView) and isinstance(b, TwinView) and a.client is not b.client
        assert a.live and b.live
        b_before = b.pose
        a.gui["date"].value = "2024-03-15"
        a.gui["hours"].value = 17.5
        assert not a.live and a.pose is not None
        assert a.pose.ts == pd.Timestamp("2024-03-15 17:30", tz=TZ)
        assert b.live and b.pose.ts == b_before.ts and b.gui["live"].value is True
        a.gui["speed"].value = 60
        a.gui["play"].value = True  # a click: a plays, b does not
        time.sleep(0.6)
        a.gui["play"].value = True  # pause
        advanced = a.pose.ts - pd.Timestamp("2024-03-15 17:30", tz=TZ)
        assert pd.Timedelta(minutes=1) < advanced < pd.Timedelta(hours=2)
        assert b.live and not b.playing and b.pose.ts != a.pose.ts
        b.gui["hours"].value = 9.0
        assert a.pose.ts.tz_convert(TZ).hour >= 17  # b's scrub left a where it was
    finally:
        ca.close()
        cb.close()


def test_each_viewer_shows_the_site_of_its_url(scene: TwinScene) -> None:
    co, other = _open(scene, "/site/other/time/2024-06-21T10:00:00Z")
    cc, camera = _open(scene, "/site/guadalajara_fisheye")
    cu, unknown = _open(scene, "/site/atlantis")
    try:
        assert isinstance(other, TwinView) and other.site is OTHER and not other.live
        ts = pd.Timestamp("2024-06-21T10:00:00Z")
        assert other.pose is not None and other.pose.ts == ts
        az, el, _ = _pvlib_sun(OTHER, ts)  # the sun of Madrid's latitude, not Tehuantepec's
        assert other.pose.solar_azimuth_deg == pytest.approx(az, abs=0.01)
        assert other.pose.solar_elevation_deg == pytest.approx(el, abs=0.01)
        n = _world(other, "/fixed/panels")[:3, 2]
        t, a = np.radians(35.0), np.radians(225.0)
        np.testing.assert_allclose(n, [np.sin(t) * np.sin(a), np.sin(t) * np.cos(a), np.cos(t)],
                                   atol=1e-6)
        assert other.pose.fixed_aoi_deg == pytest.approx(
            float(pvlib.irradiance.aoi(35.0, 225.0, 90.0 - el, az)), abs=0.01)
        # a camera-only site: tracker, no fixed array, no power to show
        assert isinstance(camera, TwinView) and camera.site is CAMERA_SITE
        assert "/fixed" not in camera.nodes and "/shadows/fixed_panels" not in camera.nodes
        assert camera.pose is not None and camera.pose.fixed_shaded_fraction is None
        assert "tracker —, fixed —" in camera.gui["readout"].content
        assert isinstance(unknown, TwinView) and unknown.site is SITE
    finally:
        for c in (co, cc, cu):
            c.close()


def test_replays_are_kept_per_viewer_key(scene: TwinScene) -> None:
    # A day of open-loop SPA with a 2° pedestal yaw: the twin's actual joints on a base
    # turned by 2° point off the sun; the viewer "r1" shows that and the ghost, "r2" not.
    from backend.twin.scene_pose import GHOST_THRESHOLD_MRAD, Replay
    from sim.disturbances import Disturbances

    d = Disturbances(pedestal_yaw_deg=2.0)
    start = pd.Timestamp("2024-03-15", tz=TZ)
    run = simulate(SITE, start, start + pd.Timedelta(days=1), step_s=300,
                   controller="open_loop_spa", disturbances=d)
    c1, v1 = _open(scene, "/site/tehuantepec/viewer/r1")
    c2, v2 = _open(scene, "/site/tehuantepec/viewer/r2")
    try:
        assert isinstance(v1, TwinView) and isinstance(v2, TwinView)
        replay = Replay.from_series("run-a", run.series, d, 300.0, "tehuantepec")
        poses = scene.load_replay(replay, "r1")
        assert len(poses) == 1 and poses[0].replay_run_id == "run-a"
        assert v2.replay is None and v2.live
        noon = pd.Timestamp("2024-03-15 12:30", tz=TZ)
        pose = v1.show_time(noon)
        assert pose.pointing_error_mrad > GHOST_THRESHOLD_MRAD and pose.ghost_visible
        assert v1.nodes["/ghost"].visible and not v2.nodes["/ghost"].visible
        shown = _world(v1, "/tracker/azimuth/elevation/panels")[:3, 2]
        ghost = _world(v1, "/ghost/azimuth/elevation/panels")[:3, 2]
        _, _, sun = _pvlib_sun(SITE, noon)
        assert np.degrees(np.arccos(np.clip(ghost @ sun, -1, 1))) < 0.05
        row = run.series.loc[noon.tz_convert("UTC")]
        a = np.radians(row["azimuth_joint_deg"] + 2.0)
        e = np.radians(row["elevation_joint_deg"])
        yawed = np.array([np.sin(a) * np.cos(e), np.cos(a) * np.cos(e), np.sin(e)])
        assert np.degrees(np.arccos(np.clip(shown @ yawed, -1, 1))) < 0.01
        # the readout gives the run's own power at that step
        assert f"tracker {row['tracker_power_w']:.0f} W" in v1.gui["readout"].content
        assert "run run-a" in v1.gui["readout"].content
        # a reload of the same tab (same key) shows the run again
        c1.close()
        c1, v1b = _open(scene, "/site/tehuantepec/viewer/r1")
        assert isinstance(v1b, TwinView) and v1b.replay is replay
        assert scene.clear_replay("r1") == 1 and v1b.replay is None and v1b.live
        # without a key the replay is shared by the site's viewers
        assert len(scene.load_replay(replay)) >= 2 and v2.replay is replay
        assert scene.clear_replay() >= 2 and v2.replay is None
    finally:
        scene.replays.clear()
        c1.close()
        c2.close()


# seed 004, Peñarroya: 21 Dec in the morning neighbours shade each other under sun
# tracking; backtracking is shade-free by definition; at the June solstice noon nobody is
# shaded.
MORNING = "2024-12-21T08:30:00Z"


@pytest.mark.parametrize("strategy,time_utc,any_shaded", [
    ("sun", MORNING, True), ("backtrack", MORNING, False), ("sun", "2024-06-21T12:00:00Z", False)])
def test_plant_view_poses_every_collector_and_marks_the_shaded(
        scene: TwinScene, strategy: str, time_utc: str, any_shaded: bool) -> None:
    plant = load_plant("penarroya")
    c, v = _open(scene, f"/plant/penarroya/strategy/{strategy}/time/{time_utc}")
    try:
        assert isinstance(v, PlantView) and v.strategy == strategy
        ts = pd.Timestamp(time_utc)
        az, el, sun = _pvlib_sun(plant, ts)  # type: ignore[arg-type]
        normals = []
        for k, tid in enumerate(plant.tracker_ids):
            frame = v.nodes[f"/plant/tracker_{tid}"]
            rot = vtf.SO3(np.asarray(frame.wxyz)).as_matrix()
            normals.append(rot[:, 2])
            np.testing.assert_allclose(frame.position,
                                       v.pivots[k], atol=1e-9)
            color = tuple(v.nodes[f"/plant/tracker_{tid}/collector"].color)
            assert (color == (214, 80, 40)) == (v.fraction[k] > 0)
        normals = np.array(normals)
        assert np.ptp(normals, axis=0).max() < 1e-9  # one common orientation
        if strategy == "sun":
            assert np.degrees(np.arccos(np.clip(normals[0] @ sun, -1, 1))) < 0.02
        assert bool(v.shaded_ids()) == any_shaded
        assert ("Shaded: 0 of 29" in v.gui["readout"].content) != any_shaded
        # the view's sun is pvlib's; the shadows below are cast from the view's own sun (at
        # 7° elevation a 0.01° difference moves a shadow's area by 0.1 %)
        assert v.sun[0] == pytest.approx(az, abs=0.01) and v.sun[1] == pytest.approx(el, abs=0.01)
        a_r, e_r = np.radians(v.sun[0]), np.radians(v.sun[1])
        sun = np.array([np.sin(a_r) * np.cos(e_r), np.cos(a_r) * np.cos(e_r), np.sin(e_r)])
        az, el = v.sun
        # each collector's ground shadow: its rectangle cast along the sun (area A |n·s|/s_z)
        area = plant.collector.area * abs(normals[0] @ sun) / sun[2]
        for quad in v.ground_shadows:
            assert shapely.Polygon(quad[:, :2]).area == pytest.approx(area, rel=1e-6)
        centroid = v.ground_shadows[0][:, :2].mean(axis=0)
        expected = v.pivots[0][:2] - PIVOT_HEIGHT_M / np.tan(np.radians(el)) * np.array(
            [np.sin(np.radians(az)), np.cos(np.radians(az))])
        np.testing.assert_allclose(centroid, expected, atol=1e-3)
    finally:
        c.close()


def test_plant_view_draws_the_shade_the_twin_casts_from_the_scene_boxes(
        scene: TwinScene) -> None:
    """Seed 004's 12 m × 5 m collectors, a low morning sun off every axis: each collector box
    is posed in the twin's panel frame (D–H chain: width along x, height up the slope), and
    the shade drawn on a collector is what the twin (sim.array_shade) casts from the posed
    neighbour boxes — not a mirror image (a width/height or sign mix-up moves it)."""
    plant = load_plant("penarroya")
    c, v = _open(scene, f"/plant/penarroya/strategy/sun/time/{MORNING}")
    try:
        assert isinstance(v, PlantView) and v.shade is not None and v.shaded_ids()
        w, h = plant.collector.width, plant.collector.height
        assert (w, h) == (12.0, 5.0)
        frames = []
        twin_rot = joint_transforms(*v.orientation, TrackerGeometry())[2][:3, :3]
        for tid in plant.tracker_ids:
            node = v.nodes[f"/plant/tracker_{tid}"]
            f = np.eye(4)
            f[:3, :3] = vtf.SO3(np.asarray(node.wxyz)).as_matrix()
            f[:3, 3] = node.position
            np.testing.assert_allclose(f[:3, :3], twin_rot, atol=1e-6)  # wxyz in float32
            assert tuple(v.nodes[f"/plant/tracker_{tid}/collector"].dimensions) == pytest.approx(
                (w, h, COLLECTOR_DEPTH_M))
            frames.append(f)
        a_r, e_r = np.radians(v.sun[0]), np.radians(v.sun[1])
        sun = np.array([np.sin(a_r) * np.cos(e_r), np.cos(a_r) * np.cos(e_r), np.sin(e_r)])
        expected, offsets = [], []
        for k in np.nonzero(v.fraction > 0)[0]:
            layout = Layout(tracker_mount_height_m=0.0, tracker_size_m=(w, h),
                            fixed_centre_enu=frames[k][:3, 3], fixed_axes=frames[k][:3, :3],
                            fixed_size_m=(w, h))
            for b in v.shade.shaded_by(0, int(k)):
                cast = fixed_shade(layout, frames[b][None], sun[None])
                poly = cast.polygon_enu[0, :cast.vertices[0]]
                # up the slope from the receiver's centre [m]
                offsets.append(float((poly.mean(axis=0) - frames[k][:3, 3]) @ frames[k][:3, 1]))
                expected.append(poly + (COLLECTOR_DEPTH_M / 2 + 0.03) * frames[k][:3, 2])
        drawn = np.asarray(v.nodes["/plant/shade_on_collectors"].vertices, dtype=float)
        drawn = drawn.reshape(-1, 4, 3)
        drawn = drawn[np.abs(drawn).sum(axis=(1, 2)) > 0]
        assert len(expected) == len(drawn) > 0
        # the shade sits off the collectors' centre lines (else a mirror image would pass):
        # the low sun shades their lower parts
        assert all(o < -0.5 for o in offsets), offsets
        for quad in drawn:
            centre = quad.mean(axis=0)
            match = min(expected, key=lambda p: float(np.linalg.norm(p.mean(axis=0) - centre)))
            got, want = shapely.Polygon(quad[:, :2]), shapely.Polygon(match[:, :2])
            assert got.symmetric_difference(want).area < 1e-4 * want.area  # float32 vertices
            np.testing.assert_allclose(centre, match.mean(axis=0), atol=1e-4)
    finally:
        c.close()


#: An L-shaped collector [m] about the pivot: 12 m × 5 m less its upper right 6 m × 2.5 m.
L_SHAPE = [(-6.0, -2.5), (6.0, -2.5), (6.0, 0.0), (0.0, 0.0), (0.0, 2.5), (-6.0, 2.5)]


def test_plant_view_of_a_polygon_collector_draws_and_shades_the_polygon() -> None:
    """Peñarroya's pivots with an L-shaped collector, the low morning sun, sun tracking (all
    it can take): each collector is drawn as the L (45 m², not the 60 m² box), its shaded
    fraction is what shapely gives when every neighbour's L, posed as drawn, is cast along
    the sun onto it (an independent projection; the bounding boxes would give other
    fractions), the shade drawn on the collectors covers that area, and each ground shadow
    is the L's area × |n·s| / s_z."""
    base = load_plant("penarroya")
    plant = dataclasses.replace(base, collector=collector_from_outline(L_SHAPE, base.collector))
    scene = TwinScene(SITE, "127.0.0.1", 0, sites=SITES.get, plants=lambda _id: plant)
    scene.start()
    try:
        # asked for backtracking, which a polygon cannot take: the view shows sun tracking
        c, v = _open(scene, f"/plant/penarroya/strategy/backtrack/time/{MORNING}")
        try:
            assert isinstance(v, PlantView) and v.shade is not None and v.strategy == "sun"
            assert tuple(v.gui["strategy"].options) == ("sun",)
            own = shapely.Polygon(L_SHAPE)
            node = v.nodes[f"/plant/tracker_{plant.tracker_ids[0]}"]
            rot = vtf.SO3(np.asarray(node.wxyz)).as_matrix()
            u, w, n = rot[:, 0], rot[:, 1], rot[:, 2]
            mesh = np.asarray(v.nodes[f"/plant/tracker_{plant.tracker_ids[0]}/collector"]
                              .vertices, dtype=float).reshape(-1, 3, 3)
            assert np.abs(mesh[..., 2]).max() == 0.0  # flat in the frame's (u, v) plane
            assert sum(shapely.Polygon(t[:, :2]).area for t in mesh) == pytest.approx(45.0)
            a_r, e_r = np.radians(v.sun[0]), np.radians(v.sun[1])
            sun = np.array([np.sin(a_r) * np.cos(e_r), np.cos(a_r) * np.cos(e_r), np.sin(e_r)])
            expected = np.zeros(plant.n_trackers)
            for k, pk in enumerate(v.pivots):
                cast = []
                for b, pb in enumerate(v.pivots):
                    t = -float((pb - pk) @ n) / float(sun @ n)  # along the sun onto k's plane
                    if b == k or t >= 0:                       # b must lie towards the sun
                        continue
                    uv = [(float((pb + x * u + y * w + t * sun - pk) @ u),
                           float((pb + x * u + y * w + t * sun - pk) @ w)) for x, y in L_SHAPE]
                    cast.append(shapely.Polygon(uv))
                expected[k] = shapely.union_all(cast).intersection(own).area / own.area
            assert expected.max() > 0.05
            np.testing.assert_allclose(v.fraction, expected, atol=1e-9)
            box = plant_shade(plant.positions, *v.sun, *v.orientation, 12.0, 5.0).fraction[0]
            assert np.abs(np.nan_to_num(box) - expected).max() > 0.05  # not the bounding box
            drawn = np.asarray(v.nodes["/plant/shade_on_collectors"].vertices,
                               dtype=float).reshape(-1, 3, 3)
            drawn = drawn[np.abs(drawn).sum(axis=(1, 2)) > 0]
            area = sum(shapely.Polygon((t - t.mean(axis=0)) @ np.column_stack([u, w])).area
                       for t in drawn)
            assert area == pytest.approx(45.0 * expected.sum(), rel=1e-4)  # float32 vertices
            for quad in v.ground_shadows:
                assert shapely.Polygon(quad[:, :2]).area == pytest.approx(
                    45.0 * abs(n @ sun) / sun[2], rel=1e-6)
        finally:
            c.close()
    finally:
        scene.stop()


def test_plant_view_strategy_control_reposes(scene: TwinScene) -> None:
    c, v = _open(scene, f"/plant/penarroya/time/{MORNING}")
    try:
        assert isinstance(v, PlantView) and v.strategy == "sun" and v.shaded_ids()
        sun_el = v.orientation[1]
        v.gui["strategy"].value = "backtrack"
        assert v.strategy == "backtrack" and not v.shaded_ids()
        assert v.orientation[1] != pytest.approx(sun_el, abs=0.5)  # tilted away
    finally:
        c.close()


def test_an_unknown_plant_is_said_to_the_viewer_not_logged_as_a_fault(
        scene: TwinScene, caplog: pytest.LogCaptureFixture) -> None:
    """A viewer's address naming no plant gets "No such plant" in its panel; the service
    logged an ERROR with a traceback and showed "could not build this view"."""
    with caplog.at_level("INFO", logger="backend.twin.scene"):
        v = Viewer(scene, "/plant/atlantis")
        try:
            deadline = time.monotonic() + 15
            while "atlantis" not in caplog.text:
                assert time.monotonic() < deadline, "the viewer was never answered"
                time.sleep(0.05)
        finally:
            v.close()
    assert not [r for r in caplog.records if r.levelname in ("ERROR", "WARNING")], caplog.text
    assert "could not be built" not in caplog.text


def _port_is_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def test_start_stop_twice_frees_the_port() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    twin = TwinScene(SITE, "127.0.0.1", port)
    for _ in range(2):
        t0 = time.monotonic()
        twin.start()
        assert time.monotonic() - t0 < 10.0  # returns, does not serve forever
        assert twin.port == port and not _port_is_free(port)
        twin.start()  # no-op on a running scene
        twin.stop()
        assert not twin.running and _port_is_free(port)
    twin.stop()  # idempotent


def test_busy_port_moves_to_the_next_free_one() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        twin = TwinScene(SITE, "127.0.0.1", port)
        try:
            twin.start()
            bound = twin.port
            assert twin.running and port < bound < port + 20
            assert httpx.get(f"http://127.0.0.1:{bound}/", timeout=10.0).status_code == 200
        finally:
            twin.stop()
        assert _port_is_free(bound)


@pytest.mark.parametrize("host,port,error", [("256.1.1.1", 0, OSError),  # not an address
                                             ("192.0.2.1", 0, OSError),  # TEST-NET-1, not ours
                                             ("127.0.0.1", 70000, ValueError)])
def test_unusable_host_or_port_fails_fast(host: str, port: int, error: type) -> None:
    """viser alone would retry such a host on port after port, forever."""
    twin = TwinScene(SITE, host, port)
    t0 = time.monotonic()
    with pytest.raises(error):
        twin.start()
    assert time.monotonic() - t0 < 5.0 and not twin.running
    twin.stop()


def test_failure_while_setting_up_stops_viser(monkeypatch: pytest.MonkeyPatch) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    twin = TwinScene(SITE, "127.0.0.1", port)

    def broken() -> None:
        raise RuntimeError("setup failed")

    monkeypatch.setattr(twin, "_setup_server", broken)
    with pytest.raises(RuntimeError, match="setup failed"):
        twin.start()
    assert not twin.running and _port_is_free(port)
    monkeypatch.undo()
    twin.start()  # and it can start again
    try:
        assert twin.running and twin.port == port
    finally:
        twin.stop()


class _PortOnly:
    """What :class:`Viewer` needs of a scene: its port."""

    def __init__(self, port: int) -> None:
        self.port = port


def test_service_keys_replays_by_viewer_over_http(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The service with viser on (its app and lifespan in this process, viser on a real
    port): viewers follow the site of their URL through the service's registry, and
    PUT/DELETE /api/v1/twin3d/replay reach one viewer key."""
    from tests.backend.live_service import InProcessServer, new_database

    db = new_database("sqlite", tmp_path)
    server = InProcessServer(db.url, extra_env={"HELIOTWIN_VISER": "true",
                                                "HELIOTWIN_VISER_PORT": "0"}).start()
    viewers: list[Viewer] = []
    try:
        with server.client() as http:
            port = http.get("/api/v1/meta").json()["viser_port"]
            for path in ("/site/tehuantepec/viewer/k1", "/site/tehuantepec/viewer/k2",
                         "/site/guadalajara_fisheye/viewer/k3"):
                viewers.append(Viewer(_PortOnly(port), path))  # type: ignore[arg-type]
            for _ in range(200):
                rows = http.get("/api/v1/twin3d").json()["viewers"]
                if len(rows) == 3:
                    break
                time.sleep(0.05)
            by_key = {r["viewer"]: r for r in rows}
            assert by_key["k1"]["site_id"] == "tehuantepec" and by_key["k1"]["mode"] == "live"
            assert by_key["k3"]["site_id"] == "guadalajara_fisheye"
            run = http.post("/api/v1/simulations", json={
                "site_id": "tehuantepec", "start": "2024-03-15", "end": "2024-03-16",
                "step_s": 300, "controller": "open_loop_spa", "pedestal_yaw_deg": 2.0})
            assert run.status_code == 200, run.text
            run_id = run.json()["run_id"]
            r = http.put("/api/v1/twin3d/replay", json={"run_id": run_id, "viewer": "k1"})
            assert r.status_code == 200, r.text
            # the replay opens at the run's start, midnight: no pointing error there (issue 22.3)
            assert r.json()["viewers"] == 1 and r.json()["pointing_error_mrad"] is None
            by_key = {r["viewer"]: r for r in http.get("/api/v1/twin3d").json()["viewers"]}
            assert by_key["k1"]["replay_run_id"] == run_id and by_key["k1"]["mode"] == "scrubbing"
            assert by_key["k2"]["replay_run_id"] is None and by_key["k2"]["mode"] == "live"
            bad = http.put("/api/v1/twin3d/replay", json={"run_id": run_id, "viewer": "k3"})
            assert bad.status_code == 422 and bad.json()["detail"].startswith("viewer:")
            bad = http.put("/api/v1/twin3d/replay", json={"run_id": run_id, "viewer": "a b"})
            assert bad.status_code == 422 and "viewer" in str(bad.json()["detail"])
            gone = http.put("/api/v1/twin3d/replay", json={"run_id": "nope", "viewer": "k1"})
            assert gone.status_code == 404 and "run_id" in gone.json()["detail"]
            assert http.delete("/api/v1/twin3d/replay", params={"viewer": "k1"}).json() == {
                "replay": None}
            by_key = {r["viewer"]: r for r in http.get("/api/v1/twin3d").json()["viewers"]}
            assert by_key["k1"]["replay_run_id"] is None and by_key["k1"]["mode"] == "live"
    finally:
        for v in viewers:
            v.close()
        server.stop()
