"""The 3D twin's static geometry: ground, tracker (posed by the D–H frames), fixed array, sun.

Node names are paths whose children inherit the parent's transform (viser):
``/tracker/azimuth/elevation/panels/module_i`` moves with the joints,
``/fixed/panels/module_i`` stands still, ``/sun`` is re-posed each time, the
``/shadows/*`` meshes get new vertices. Every function
takes a viser ``SceneApi``: ``client.scene`` for one viewer's own nodes. The
per-viewer logic (time, GUI, readout) is :mod:`backend.twin.scene_view`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import viser
import viser.transforms as vtf
from numpy.typing import NDArray

from backend.twin.scene_shadow import fan_mesh
from sim.array_shade import MODULE_GAP_M, TRACKER_MOUNT_HEIGHT_M
from sim.kinematics import TrackerGeometry

# Kyocera KD205GX-LP outline from pvlib's CEC module table
# ('Kyocera_Solar_KD205GX_LP': Length 1.5 m, Width 0.99 m); frame depth 46 mm
# from the Kyocera datasheet (visual only).
MODULE_LENGTH_M = 1.50
MODULE_WIDTH_M = 0.99
MODULE_DEPTH_M = 0.046
#: Modules are mounted landscape, 2 x 2: long side along the elevation axis (gap:
#: sim.array_shade.MODULE_GAP_M).
ARRAY_WIDTH_M = 2 * MODULE_LENGTH_M + MODULE_GAP_M
ARRAY_HEIGHT_M = 2 * MODULE_WIDTH_M + MODULE_GAP_M

#: Default height of the D–H base frame {0} above the ground [m]: the site config's
#: ``arrays.tracker.mount_height_m`` when it places the arrays, else this
#: (sim.array_shade.TRACKER_MOUNT_HEIGHT_M: elevation axis at 1.30 + d1 ≈ 1.66 m >
#: ARRAY_HEIGHT_M / 2, so the 2 x 2 array clears the ground with the panel vertical).
PEDESTAL_HEIGHT_M = TRACKER_MOUNT_HEIGHT_M
#: Where the fixed array is assumed to stand when the site config places no arrays (ENU,
#: m; the ground point below its centre): east of the tracker, clear of its swing.
FIXED_ARRAY_ORIGIN_M = (4.5, 0.0, 0.0)
#: Seed 000, section 2.2: camera 640 x 480 px, 67° field of view (taken as the
#: horizontal field), at the top centre of the array, looking along the normal.
CAMERA_WIDTH_PX = 640
CAMERA_HEIGHT_PX = 480
CAMERA_FOV_DEG = 67.0
#: Distance at which the sun marker and the day's path are drawn [m].
SUN_DISTANCE_M = 5.5
SUN_PATH_STEP_MIN = 5
_PANEL_BLUE = (28, 52, 110)
_STEEL = (150, 150, 155)
_SUN_YELLOW = (255, 200, 40)
_GHOST_WHITE = (235, 240, 250)
_SHADOW = (40, 44, 52)
#: Dimensions of the bodies whose ground shadows are drawn (x, y, z in their frames) [m].
COLLECTOR_BOX_M = (ARRAY_WIDTH_M, ARRAY_HEIGHT_M, MODULE_DEPTH_M)
PEDESTAL_SIDE_M = 0.22
PEDESTAL_BOX_M = (PEDESTAL_SIDE_M, PEDESTAL_SIDE_M, PEDESTAL_HEIGHT_M)
#: Ground-shadow meshes: name → what casts it.
SHADOW_NODES = ("/shadows/tracker_panels", "/shadows/tracker_pedestal", "/shadows/fixed_panels")


def wxyz(rotation: NDArray[np.floating]) -> NDArray[np.float64]:
    """A rotation matrix as viser's (w, x, y, z) quaternion."""
    return np.asarray(vtf.SO3.from_matrix(rotation).wxyz, dtype=float)


def _modules(scene: viser.SceneApi, parent: str, color: tuple[int, int, int],
             opacity: float | None) -> dict[str, Any]:
    """The 2 × 2 modules of an array under ``parent`` (landscape, long side along x)."""
    out = {}
    for i, (x, y) in enumerate([(sx * (MODULE_LENGTH_M + MODULE_GAP_M) / 2.0,
                                 sy * (MODULE_WIDTH_M + MODULE_GAP_M) / 2.0)
                                for sy in (1, -1) for sx in (-1, 1)]):
        name = f"{parent}/module_{i}"
        out[name] = scene.add_box(
            name, color=color, dimensions=(MODULE_LENGTH_M, MODULE_WIDTH_M, MODULE_DEPTH_M),
            position=(x, y, 0.0), opacity=opacity, cast_shadow=opacity is None)
    return out


def build_ghost(scene: viser.SceneApi,
                pedestal_height_m: float = PEDESTAL_HEIGHT_M) -> dict[str, Any]:
    """The ideal pose's panels, translucent: ``/ghost/azimuth/elevation/panels`` with the
    tracker's joint frames (posed like them), hidden until the actual pose strays."""
    nodes: dict[str, Any] = {
        "/ghost": scene.add_frame("/ghost", show_axes=False, visible=False,
                                  position=(0.0, 0.0, pedestal_height_m)),
        "/ghost/azimuth": scene.add_frame("/ghost/azimuth", show_axes=False),
        "/ghost/azimuth/elevation": scene.add_frame("/ghost/azimuth/elevation",
                                                    show_axes=False),
        "/ghost/azimuth/elevation/panels": scene.add_frame("/ghost/azimuth/elevation/panels",
                                                           show_axes=False),
    }
    nodes.update(_modules(scene, "/ghost/azimuth/elevation/panels", _GHOST_WHITE, 0.35))
    return nodes


def build_shadows(scene: viser.SceneApi, with_fixed: bool) -> dict[str, Any]:
    """The ground-shadow meshes (empty until posed) and, on the fixed array, the tracker's
    shade (``/shadows/on_fixed``); all in world coordinates (``/shadows`` is the identity)."""
    verts, faces = fan_mesh(np.zeros((0, 2)))
    nodes: dict[str, Any] = {"/shadows": scene.add_frame("/shadows", show_axes=False)}
    for name in SHADOW_NODES:
        if name.startswith("/shadows/fixed") and not with_fixed:
            continue
        nodes[name] = scene.add_mesh_simple(name, verts, faces, color=_SHADOW, opacity=0.55,
                                            side="double", cast_shadow=False,
                                            receive_shadow=False)
    if with_fixed:
        nodes["/shadows/on_fixed"] = scene.add_mesh_simple(
            "/shadows/on_fixed", verts, faces, color=(15, 15, 20), opacity=0.6, side="double",
            cast_shadow=False, receive_shadow=False)
    return nodes


def build_static_scene(scene: viser.SceneApi, geom: TrackerGeometry,
                       fixed: tuple[NDArray[np.float64], NDArray[np.float64]] | None,
                       pedestal_height_m: float = PEDESTAL_HEIGHT_M) -> dict[str, Any]:
    """Add every node that is not re-created later; returns the handles by path.

    ``fixed`` is the fixed array's centre (ENU, m) and axes (columns: width, height up the
    slope, normal; :func:`sim.array_shade.fixed_pose`), or None for a site without one (a
    camera-only site shows the tracker alone). The tracker's pedestal foot is the origin.
    """
    nodes: dict[str, Any] = {}

    def add(name: str, handle: Any) -> Any:
        nodes[name] = handle
        return handle

    def add_modules(parent: str) -> None:
        nodes.update(_modules(scene, parent, _PANEL_BLUE, None))

    scene.set_up_direction("+z")
    # the only shadows are the ones cast from the sun (build_shadows): viser's default
    # lights keep shading the faces but throw no fixed shadow of their own
    scene.configure_default_lights(enabled=True, cast_shadow=False)
    add("/ground", scene.add_grid(
        "/ground", width=24.0, height=24.0, plane="xy", cell_size=1.0, section_size=5.0,
        plane_color=(200, 214, 180), plane_opacity=0.6, position=(0.0, 0.0, -0.002)))
    for label, (lx, ly) in {"N": (0.0, 10.0), "E": (10.0, 0.0), "S": (0.0, -10.0),
                            "W": (-10.0, 0.0)}.items():
        add(f"/compass/{label}", scene.add_label(
            f"/compass/{label}", label, position=(lx, ly, 0.05), anchor="center-center",
            font_screen_scale=1.6))

    # Tracker: base frame {0} on top of the pedestal.
    h = pedestal_height_m
    add("/tracker", scene.add_frame("/tracker", show_axes=False, position=(0.0, 0.0, h)))
    add("/tracker/pedestal", scene.add_box(
        "/tracker/pedestal", color=_STEEL, dimensions=(PEDESTAL_SIDE_M, PEDESTAL_SIDE_M, h),
        position=(0.0, 0.0, -h / 2.0)))
    add("/tracker/footing", scene.add_box(
        "/tracker/footing", color=(120, 120, 120), dimensions=(0.7, 0.7, 0.12),
        position=(0.0, 0.0, -h + 0.06)))
    # Frame {1}: z1 is the (horizontal) elevation axis, y1 is up (alpha1 = 90°).
    add("/tracker/azimuth", scene.add_frame("/tracker/azimuth", show_axes=False))
    add("/tracker/azimuth/turret", scene.add_box(
        "/tracker/azimuth/turret", color=(110, 110, 118),
        dimensions=(0.18, geom.d1_m, 0.26), position=(0.0, -geom.d1_m / 2.0, 0.0)))
    add("/tracker/azimuth/axle", scene.add_box(
        "/tracker/azimuth/axle", color=(90, 90, 95),
        dimensions=(0.07, 0.07, ARRAY_WIDTH_M * 0.8)))
    # Frame {2}: x2 is the panel normal; the link a2 runs along it.
    add("/tracker/azimuth/elevation", scene.add_frame(
        "/tracker/azimuth/elevation", show_axes=False))
    add("/tracker/azimuth/elevation/arm", scene.add_box(
        "/tracker/azimuth/elevation/arm", color=_STEEL,
        dimensions=(geom.a2_m, 0.08, 0.08), position=(-geom.a2_m / 2.0, 0.0, 0.0)))
    add("/tracker/azimuth/elevation/panels", scene.add_frame(
        "/tracker/azimuth/elevation/panels", show_axes=False))
    add_modules("/tracker/azimuth/elevation/panels")
    for i, y in enumerate((-0.5, 0.5)):  # purlins behind the modules
        name = f"/tracker/azimuth/elevation/panels/rail_{i}"
        add(name, scene.add_box(name, color=_STEEL,
                                      dimensions=(ARRAY_WIDTH_M * 0.95, 0.05, 0.04),
                                      position=(0.0, y, -MODULE_DEPTH_M / 2 - 0.02)))
    vfov = 2.0 * np.arctan(np.tan(np.radians(CAMERA_FOV_DEG) / 2.0)
                           * CAMERA_HEIGHT_PX / CAMERA_WIDTH_PX)
    # OpenCV camera (+z forward, +y down): looking along the normal, image
    # "down" = down the panel's slope.
    add("/tracker/azimuth/elevation/panels/camera", scene.add_camera_frustum(
        "/tracker/azimuth/elevation/panels/camera", fov=float(vfov),
        aspect=CAMERA_WIDTH_PX / CAMERA_HEIGHT_PX, scale=0.35, color=(200, 40, 40),
        thickness=0.012, wxyz=(0.0, 0.0, 0.0, 1.0),
        position=(0.0, ARRAY_HEIGHT_M / 2.0 + 0.06, 0.03)))

    if fixed is not None:
        _add_fixed(scene, *fixed, add, add_modules)

    # Sun: /sun's local z points at the sun, so the ray is a constant segment.
    add("/sun", scene.add_frame("/sun", show_axes=False))
    add("/sun/disc", scene.add_icosphere("/sun/disc", radius=0.28,
                                               color=_SUN_YELLOW, cast_shadow=False))
    add("/sun/ray", scene.add_line_segments(
        "/sun/ray", points=np.array([[[0.0, 0.0, 0.0], [0.0, 0.0, -SUN_DISTANCE_M]]]),
        colors=_SUN_YELLOW, thickness=0.02))
    add("/sun_path", scene.add_line_segments(
        "/sun_path", points=np.zeros((1, 2, 3)), colors=(230, 150, 20), thickness=0.03))
    return nodes


def _add_fixed(scene: viser.SceneApi, centre: NDArray[np.float64], rot: NDArray[np.float64],
               add: Any, add_modules: Any) -> None:
    """Fixed array: same panel-frame convention as the tracker."""
    add("/fixed", scene.add_frame("/fixed", show_axes=False,
                                  position=tuple(centre), wxyz=wxyz(rot)))
    add("/fixed/panels", scene.add_frame("/fixed/panels", show_axes=False))
    add_modules("/fixed/panels")
    for i, (x, y) in enumerate([(sx * ARRAY_WIDTH_M * 0.42, sy * ARRAY_HEIGHT_M * 0.42)
                                for sx in (-1, 1) for sy in (-1, 1)]):
        foot = centre + rot @ np.array([x, y, 0.0])
        name = f"/fixed_legs/leg_{i}"
        add(name, scene.add_box(name, color=_STEEL, dimensions=(0.05, 0.05, float(foot[2])),
                                position=(float(foot[0]), float(foot[1]),
                                          float(foot[2]) / 2.0)))


#: From the south-east, a little above the panels: tracker in front, fixed array to its
#: right, the sun's arc behind (ENU, m).
CAMERA_POSITION_M = (6.8, -8.4, 4.2)
CAMERA_LOOK_AT_M = (2.3, 1.2, 2.9)
