"""Tests of backend/twin/scene.py: the viser scene, over a real server on a free port.

The tracker's pose is checked against the sun direction from pvlib's own
solar-position code (independent of sim.sun and sim.kinematics) and against
the D–H forward kinematics of sim/.
"""

import socket
import time
from collections.abc import Iterator

import httpx
import numpy as np
import pandas as pd
import pvlib
import pytest
import viser.transforms as vtf

from backend.twin.scene import PEDESTAL_HEIGHT_M, TwinScene
from sim.kinematics import forward_kinematics, inverse_kinematics
from sim.sites import load_site

SITE = load_site("tehuantepec")
TZ = "America/Mexico_City"
NAMED = [
    "/ground",
    "/tracker",
    "/tracker/pedestal",
    "/tracker/azimuth",
    "/tracker/azimuth/elevation",
    "/tracker/azimuth/elevation/panels",
    "/tracker/azimuth/elevation/panels/module_0",
    "/tracker/azimuth/elevation/panels/module_3",
    "/tracker/azimuth/elevation/panels/camera",
    "/fixed",
    "/fixed/panels/module_0",
    "/sun",
    "/sun/disc",
    "/sun_path",
]


@pytest.fixture(scope="module")
def scene() -> Iterator[TwinScene]:
    s = TwinScene(SITE, "127.0.0.1", 0)
    s.start()
    try:
        yield s
    finally:
        s.stop()


def _world(scene: TwinScene, path: str) -> np.ndarray:
    """4x4 world transform of a node, composed from its ancestors' handles."""
    parts = path.strip("/").split("/")
    t = np.eye(4)
    for i in range(1, len(parts) + 1):
        h = scene.nodes["/" + "/".join(parts[:i])]
        local = np.eye(4)
        local[:3, :3] = vtf.SO3(np.asarray(h.wxyz)).as_matrix()
        local[:3, 3] = h.position
        t = t @ local
    return t


def _pvlib_sun(ts: pd.Timestamp) -> tuple[float, float, np.ndarray]:
    sp = pvlib.solarposition.get_solarposition(
        pd.DatetimeIndex([ts]), SITE.latitude, SITE.longitude, SITE.altitude
    )
    az = float(sp["azimuth"].iloc[0])
    el = float(sp["apparent_elevation"].iloc[0])
    a, e = np.radians(az), np.radians(el)
    return az, el, np.array([np.sin(a) * np.cos(e), np.cos(a) * np.cos(e), np.sin(e)])


def test_starts_on_free_port_and_serves_the_client(scene: TwinScene) -> None:
    assert scene.running and scene.port > 0
    r = httpx.get(f"http://127.0.0.1:{scene.port}/", timeout=10.0)
    assert r.status_code == 200 and "<html" in r.text.lower()


def test_named_nodes_exist_in_viser(scene: TwinScene) -> None:
    assert scene.server is not None
    registered = scene.server.scene._handle_from_node_name  # viser's name -> handle map
    for name in NAMED:
        assert name in scene.nodes, name
        assert name in registered, name


@pytest.mark.parametrize("local", ["2024-03-15 08:30", "2024-03-15 12:04", "2024-06-21 12:30",
                                   "2024-12-21 16:45"])
def test_tracker_orientation_equals_fk_and_faces_the_sun(scene: TwinScene, local: str) -> None:
    ts = pd.Timestamp(local, tz=TZ)
    pose = scene.show_time(ts)
    panels = _world(scene, "/tracker/azimuth/elevation/panels")
    normal = panels[:3, 2]
    az, el, sun = _pvlib_sun(ts)
    az_j, el_j = inverse_kinematics(az, el, SITE.tracker)
    np.testing.assert_allclose(normal, forward_kinematics(az_j, el_j, SITE.tracker), atol=1e-4)
    assert np.degrees(np.arccos(np.clip(normal @ sun, -1, 1))) < 0.01  # ideal tracking
    assert pose.tracker_aoi_deg < 0.01
    # panel centre: base on the pedestal + d1 up + a2 along the normal (seed 002, eq. 2)
    expected_centre = [0, 0, PEDESTAL_HEIGHT_M + SITE.tracker.d1_m] + SITE.tracker.a2_m * sun
    np.testing.assert_allclose(panels[:3, 3], expected_centre, atol=1e-4)
    # the sun marker sits on the ray through the elevation axis
    sun_pos = scene.nodes["/sun"].position - np.array([0, 0, PEDESTAL_HEIGHT_M + 0.355])
    np.testing.assert_allclose(sun_pos / np.linalg.norm(sun_pos), sun, atol=1e-4)
    assert scene.nodes["/sun"].visible


def test_fixed_array_faces_south_at_16_deg(scene: TwinScene) -> None:
    normal = _world(scene, "/fixed/panels")[:3, 2]
    t = np.radians(16.0)  # seed 000, section 3.3
    np.testing.assert_allclose(normal, [0.0, -np.sin(t), np.cos(t)], atol=1e-6)
    # AOI of the fixed array matches pvlib's for the same sun
    ts = pd.Timestamp("2024-03-15 15:00", tz=TZ)
    pose = scene.show_time(ts)
    az, el, _ = _pvlib_sun(ts)
    aoi = float(pvlib.irradiance.aoi(16.0, 180.0, 90.0 - el, az))
    assert pose.fixed_aoi_deg == pytest.approx(aoi, abs=0.01)


def test_night_stows_flat_and_hides_the_sun(scene: TwinScene) -> None:
    pose = scene.show_time(pd.Timestamp("2024-03-15 23:00", tz=TZ))
    assert pose.stowed and pose.solar_elevation_deg < 0
    assert not scene.nodes["/sun"].visible
    normal = _world(scene, "/tracker/azimuth/elevation/panels")[:3, 2]
    np.testing.assert_allclose(normal, [0, 0, 1], atol=1e-9)


def test_sun_path_covers_daylight_only(scene: TwinScene) -> None:
    scene.show_time(pd.Timestamp("2024-03-15 12:00", tz=TZ))
    pts = np.asarray(scene.nodes["/sun_path"].points)
    assert pts.shape[1:] == (2, 3) and len(pts) > 100  # ~12 h at 5 min
    assert np.all(pts[..., 2] > PEDESTAL_HEIGHT_M + 0.355 - 1e-3)


def test_update_live_moves_scene_in_live_mode_and_validates(scene: TwinScene) -> None:
    scene.gui["live"].value = True
    ts = pd.Timestamp("2024-04-25 11:00", tz=TZ)
    scene.update_live(ts, 612.5, 540.0)
    assert scene.pose is not None and scene.pose.ts == ts
    text = scene.gui["readout"].content
    assert "612 W" in text or "613 W" in text
    assert "540 W" in text
    scene.update_live(ts, None, float("nan"))
    assert "—" in scene.gui["readout"].content
    with pytest.raises(ValueError, match="timezone"):
        scene.update_live(pd.Timestamp("2024-04-25 11:00"), 1.0, 1.0)


def test_gui_scrub_date_and_play(scene: TwinScene) -> None:
    scene.show_time(pd.Timestamp("2024-03-15 09:00", tz=TZ))
    scene.gui["hours"].value = 14.5  # scrubbing leaves live mode
    assert scene.gui["live"].value is False
    assert scene.pose is not None
    assert scene.pose.ts == pd.Timestamp("2024-03-15 14:30", tz=TZ)
    scene.gui["date"].value = "2024-06-21"
    assert scene.pose.ts == pd.Timestamp("2024-06-21 14:30", tz=TZ)
    scene.gui["date"].value = "21/06/2024"
    assert "not YYYY-MM-DD" in scene.gui["readout"].content
    scene.gui["speed"].value = 60
    scene.gui["play"].value = True  # a click
    time.sleep(0.6)
    scene.gui["play"].value = True  # pause
    advanced = scene.pose.ts - pd.Timestamp("2024-06-21 14:30", tz=TZ)
    assert pd.Timedelta(minutes=1) < advanced < pd.Timedelta(hours=2)


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
    with pytest.raises(RuntimeError, match="start"):
        twin.show_time(pd.Timestamp("2024-03-15 12:00", tz=TZ))


def test_busy_port_moves_to_the_next_free_one() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        twin = TwinScene(SITE, "127.0.0.1", port)
        try:
            t0 = time.monotonic()
            twin.start()
            assert time.monotonic() - t0 < 10.0
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


def test_failure_while_building_stops_viser(monkeypatch: pytest.MonkeyPatch) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    twin = TwinScene(SITE, "127.0.0.1", port)

    def broken() -> None:
        raise RuntimeError("GUI failed")

    monkeypatch.setattr(twin, "_build_gui", broken)
    with pytest.raises(RuntimeError, match="GUI failed"):
        twin.start()
    assert not twin.running and _port_is_free(port)
    monkeypatch.undo()
    twin.start()  # and it can start again
    try:
        assert twin.running and twin.port == port
    finally:
        twin.stop()


def test_a_replayed_run_poses_the_actual_tracker_with_a_ghost_of_the_ideal(
        scene: TwinScene) -> None:
    # A day of open-loop SPA with a 2° pedestal yaw: the twin's actual joints on a base
    # turned by 2° point off the sun; the scene must show that (the panel normal seen in
    # the scene = the sun direction of pvlib, turned 2° about the vertical) and the ghost.
    from backend.twin.scene_pose import GHOST_THRESHOLD_MRAD, Replay
    from sim.disturbances import Disturbances
    from sim.twin import simulate

    d = Disturbances(pedestal_yaw_deg=2.0)
    start = pd.Timestamp("2024-03-15", tz=TZ)
    run = simulate(SITE, start, start + pd.Timedelta(days=1), step_s=300,
                   controller="open_loop_spa", disturbances=d)
    try:
        pose = scene.load_replay(Replay.from_series("run-a", run.series, d, 300.0))
        assert pose is not None and pose.replay_run_id == "run-a"
        noon = pd.Timestamp("2024-03-15 12:30", tz=TZ)
        pose = scene.show_time(noon)
        assert pose.pointing_error_mrad > GHOST_THRESHOLD_MRAD and pose.ghost_visible
        assert scene.nodes["/ghost"].visible
        shown = _world(scene, "/tracker/azimuth/elevation/panels")[:3, 2]
        ghost = _world(scene, "/ghost/azimuth/elevation/panels")[:3, 2]
        _, _, sun = _pvlib_sun(noon)
        # the ghost (ideal pose, level base) is on the sun; the shown panel is the run's
        # actual joints on a base turned 2° clockwise: azimuth joint + 2°
        assert np.degrees(np.arccos(np.clip(ghost @ sun, -1, 1))) < 0.05
        row = run.series.loc[noon.tz_convert("UTC")]
        a = np.radians(row["azimuth_joint_deg"] + 2.0)
        e = np.radians(row["elevation_joint_deg"])
        yawed = np.array([np.sin(a) * np.cos(e), np.cos(a) * np.cos(e), np.sin(e)])
        assert np.degrees(np.arccos(np.clip(shown @ yawed, -1, 1))) < 0.01
        err = np.degrees(np.arccos(np.clip(shown @ sun, -1, 1)))
        assert err * 17.453 == pytest.approx(pose.pointing_error_mrad, rel=0.05)
    finally:
        scene.clear_replay()
    pose = scene.show_time(pd.Timestamp("2024-03-15 12:30", tz=TZ))
    assert pose.replay_run_id is None and not scene.nodes["/ghost"].visible
