"""Plants of dual-axis trackers: layout, collector and wiring (``sim/data/plants/*.json``).

A plant file names its keys with units (``latitude_deg``, ``width_m`` …). Tracker
positions may be given in the plant's own east-north-up frame (``"frame": "enu"``)
or in seed 004's frame (``"frame": "seed004"``: x towards west, y towards south,
z towards the zenith — Fernández-Ahumada et al., Sensors 2021, 21, 726, §2.1
item 2 and Table 1), converted once by :func:`enu_from_seed004`.

A user adds a plant by dropping ``<plant_id>.json`` into the plants directory;
a malformed file raises ``ValueError`` naming the file and the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.configs import read_config
from sim.paths import default_plants_dir
from sim.site_config import (
    ALTITUDE_MAX_M,
    ALTITUDE_MIN_M,
    check_iana_zone,
    equator_azimuth_deg,
    fixed_tilt_from_latitude_deg,
)
from sim.stow import STOW_RELEASE_MAX_MIN, STOW_RELEASE_MIN, STOW_WIND_MAX_M_S, WindStow

FloatArray = NDArray[np.float64]

FRAMES = ("enu", "seed004")
MODULE_ORIENTATIONS = ("portrait", "landscape")


class UnknownPlantError(ValueError):
    """No plant file with that id."""


def enu_from_seed004(xyz_seed004: ArrayLike) -> FloatArray:
    """Convert seed 004's local frame to east-north-up.

    Seed 004 (Fernández-Ahumada et al. 2021, §2.1 item 2, Table 1 and eqs. 1, 4–6)
    uses a right-handed frame with Ox towards the west, Oy towards the south and
    Oz towards the zenith. East = −x, north = −y, up = z (a rotation by 180° about
    the vertical, so it stays right-handed). The same map applies to positions [m]
    and to direction vectors (seed eq. 1 sun vector, eq. 4 collector normal).

    Parameters
    ----------
    xyz_seed004 : array_like, shape (..., 3)
        (x west, y south, z zenith).

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        (east, north, up).
    """
    v = np.asarray(xyz_seed004, dtype=float)
    if v.shape[-1:] != (3,):
        raise ValueError(f"xyz_seed004 must have a last axis of length 3, got shape {v.shape}")
    return np.stack([-v[..., 0], -v[..., 1], v[..., 2]], axis=-1)


def polygon_area(xy: ArrayLike) -> float:
    """Signed area [m²] of a polygon's vertices ``(V, 2)`` (shoelace; positive
    counter-clockwise)."""
    p = np.asarray(xy, dtype=float)
    x, y = p[:, 0], p[:, 1]
    return float(0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def check_outline(vertices: ArrayLike, where: str = "outline"
                  ) -> tuple[tuple[float, float], ...]:
    """A collector outline as :class:`Collector` keeps it: at least 3 finite (u, v) vertices
    [m] of a simple polygon (no self-crossing) with positive area, counter-clockwise, the
    closing vertex dropped when it repeats the first. ``ValueError`` starting with ``where``
    says what is wrong."""
    import shapely

    try:
        p = np.asarray(vertices, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: expected a list of [u, v] pairs in metres") from None
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"{where}: expected a list of [u, v] pairs in metres, got shape "
                         f"{p.shape}")
    if len(p) > 1 and np.array_equal(p[0], p[-1]):
        p = p[:-1]
    if not np.all(np.isfinite(p)):
        bad = int(np.flatnonzero(~np.isfinite(p).all(axis=1))[0])
        raise ValueError(f"{where}: vertex {bad} is not a pair of finite numbers")
    if len(p) < 3:
        raise ValueError(f"{where}: need at least 3 vertices, got {len(p)}")
    if len(p) > 256:
        raise ValueError(f"{where}: at most 256 vertices, got {len(p)}")
    area = polygon_area(p)
    polygon = shapely.Polygon(p)
    # a crossing is told before the area: a symmetric bow tie's signed areas cancel, and it
    # was refused as having none (its parts have: shapely's make_valid keeps them)
    if not polygon.is_valid and (abs(area) > 1e-6 or shapely.make_valid(polygon).area > 1e-6):
        raise ValueError(f"{where}: the polygon crosses itself (give its vertices in order "
                         "around it)")
    if not abs(area) > 1e-6:
        raise ValueError(f"{where}: the polygon has no area")
    if area < 0:
        p = p[::-1]
    return tuple((float(u), float(v)) for u, v in p)


#: Largest side of a tracker's collector [m] (its bounding box): the largest dual-axis
#: trackers built carry about 300 m² (some 25 m across); a side beyond this is a size in mm
#: or cm taken as metres (8000x4000 gave 12 GWh a collector a year, 1.6 km² of land each).
MAX_COLLECTOR_SIDE_M = 50.0


def check_collector_size(width_m: float, height_m: float,
                         keys: tuple[str, str] = ("width_m", "height_m")) -> None:
    """``ValueError`` naming the side (``keys``: how the caller calls width and height) when
    the collector's width or height [m] is more than :data:`MAX_COLLECTOR_SIDE_M`. The one
    bound of a plant file's collector and a sweep's (rectangle or polygon's bounding box)."""
    for key, side in zip(keys, (width_m, height_m), strict=True):
        if side > MAX_COLLECTOR_SIDE_M:
            raise ValueError(f"{key} {side:g} m is more than {MAX_COLLECTOR_SIDE_M:g} m, larger "
                             "than any tracker's collector: give metres (not mm or cm)")


@dataclass(frozen=True)
class Collector:
    """A tracker's collector and its electrical layout.

    The collector is a ``width × height`` rectangle centred on the tracker's pivot;
    its width lies horizontal (seed 004 eq. 5, vector u), its height along the
    in-plane vector v (eq. 6). It carries ``modules_across × modules_high``
    modules; each module has ``bypass_diodes`` substrings (Martinez-Moreno's
    "blocks"); each row of modules is one series string.

    Any other shape is an ``outline``: a simple polygon in the collector plane, (u, v)
    [m] about the pivot (u along the width, v up the height: twoaxistracking's
    ``collector_geometry`` frame, x right and y up when facing the collector). Its
    ``width × height`` is then the outline's bounding box, over which the module grid
    lies; a module row is still one string, the polygon's band of that row
    (:mod:`sim.plant.electrical` states what that assumes).

    Parameters
    ----------
    width, height : float
        Collector size [m] (seed 004: a = 12, b = 5).
    modules_across, modules_high : int
        Module grid on the collector.
    module_orientation : {"portrait", "landscape"}
        Portrait: a module's bypass substrings are vertical strips; landscape:
        horizontal strips.
    bypass_diodes : int
        Bypass-diode substrings per module.
    module_power : float
        Module DC power at STC [W].
    gamma_pdc : float
        Power temperature coefficient [1/°C].
    module_name : str
    outline : tuple of (u, v), optional
        Polygon vertices [m] about the pivot (:func:`check_outline`); None: the
        ``width × height`` rectangle centred on the pivot.
    """

    width: float
    height: float
    modules_across: int
    modules_high: int
    module_orientation: str
    bypass_diodes: int
    module_power: float
    gamma_pdc: float
    module_name: str = ""
    outline: tuple[tuple[float, float], ...] | None = None

    @property
    def is_rectangle(self) -> bool:
        """The ``width × height`` rectangle centred on the pivot (the shade engine's fast
        path), not an outline."""
        return self.outline is None

    def outline_m(self) -> FloatArray:
        """Vertices ``(V, 2)`` (u, v) [m] about the pivot, counter-clockwise (the rectangle's
        four corners when there is no outline)."""
        if self.outline is not None:
            return np.asarray(self.outline, dtype=float)
        a, b = self.width / 2, self.height / 2
        return np.array([[-a, -b], [a, -b], [a, b], [-a, b]])

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """Bounding box (u0, u1, v0, v1) [m] in collector coordinates."""
        if self.outline is None:
            return -self.width / 2, self.width / 2, -self.height / 2, self.height / 2
        xy = self.outline_m()
        return (float(xy[:, 0].min()), float(xy[:, 0].max()), float(xy[:, 1].min()),
                float(xy[:, 1].max()))

    @property
    def area(self) -> float:
        """Collector area [m²] (the outline's, by the shoelace formula)."""
        if self.outline is None:
            return self.width * self.height
        return polygon_area(self.outline_m())

    @property
    def diagonal(self) -> float:
        """Diagonal of the collector's bounding box [m]: no two translates of the collector
        overlap farther apart than this (the shade engine's bound)."""
        return float(np.hypot(self.width, self.height))

    @property
    def swept_diameter(self) -> float:
        """Diameter of the circle the collector sweeps about its pivot [m]: twice its
        farthest vertex (twoaxistracking's ``min_tracker_spacing``; the rectangle's
        diagonal). Pivots closer than this can collide."""
        if self.outline is None:
            return self.diagonal
        return float(2 * np.max(np.hypot(*self.outline_m().T)))

    @property
    def power_stc(self) -> float:
        """Collector DC power at STC [W]: the module grid's, and for an outline the grid's
        share the polygon covers (its modules cut to the outline, all of it active: the
        power per m² of the grid kept)."""
        grid_w = self.module_power * self.modules_across * self.modules_high
        if self.outline is None:
            return grid_w
        return grid_w * self.area / (self.width * self.height)

    def strings(self) -> FloatArray:
        """String rectangles ``(S, 4)`` = (u0, u1, v0, v1) [m] in collector coordinates (for
        an outline, the bands of its bounding box that hold each string)."""
        u_lo, u_hi, v_lo, _ = self.bounds
        h = self.height / self.modules_high
        v0 = v_lo + h * np.arange(self.modules_high)
        return np.stack([np.full_like(v0, u_lo), np.full_like(v0, u_hi), v0, v0 + h], axis=-1)

    def string_boundaries(self) -> FloatArray:
        """v of the boundaries between strings [m], bottom to top, shape ``(S − 1,)``: the
        band edges that :func:`sim.plant.shading.plant_shade` keeps string areas for."""
        return self.strings()[1:, 2]

    def block_grid(self) -> tuple[int, int]:
        """Blocks of one string as a regular grid: (across the width, up the string's height)."""
        if self.module_orientation == "portrait":
            return self.modules_across * self.bypass_diodes, 1
        return self.modules_across, self.bypass_diodes

    def blocks(self) -> tuple[FloatArray, NDArray[np.int64]]:
        """Bypass-diode blocks: rectangles ``(B, 4)`` (u0, u1, v0, v1) [m], their string index
        (over the bounding box of an outline, blocks outside it included)."""
        mw, mh = self.width / self.modules_across, self.height / self.modules_high
        n = self.bypass_diodes
        u_lo, _, v_lo, _ = self.bounds
        rects, owner = [], []
        for r in range(self.modules_high):
            for c in range(self.modules_across):
                u0, v0 = u_lo + c * mw, v_lo + r * mh
                for k in range(n):
                    if self.module_orientation == "portrait":
                        rects.append((u0 + k * mw / n, u0 + (k + 1) * mw / n, v0, v0 + mh))
                    else:
                        rects.append((u0, u0 + mw, v0 + k * mh / n, v0 + (k + 1) * mh / n))
                    owner.append(r)
        return np.asarray(rects, dtype=float), np.asarray(owner, dtype=np.int64)


@dataclass(frozen=True)
class Plant:
    """A plant of identical dual-axis trackers on (nearly) flat ground.

    Parameters
    ----------
    plant_id, name : str
    latitude, longitude : float
        [°], north and east positive.
    altitude : float
        [m].
    timezone : str
        IANA zone.
    tracker_ids : tuple of int
    positions : numpy.ndarray, shape (N, 3)
        Pivot positions (east, north, up) [m].
    collector : Collector
    albedo : float
        Ground reflectance [-].
    temp_air, wind_speed : float
        Clear-sky weather [°C], [m s⁻¹].
    fixed_tilt, fixed_azimuth : float
        Orientation of the fixed comparison plant [°] (a plant file without them: the tilt
        from the latitude and facing the equator, :func:`plant_from_dict`).
    slope_azimuth, slope_tilt : float
        The plane ground the plant stands on, when it extends beyond the plant (a regular
        field of :mod:`sim.plant.fields`): azimuth of its downhill normal and tilt [°]. With
        the sun below the ground's horizon every collector is in shade
        (:func:`sim.plant.fields.horizon_elevation`). 0: flat, no horizon.
    wind_stow : WindStow, optional
        Every tracker's wind stow (the plant file's ``tracker.stow_wind_speed_m_s`` and
        ``stow_release_min``, a site's keys, :class:`sim.stow.WindStow`); None: it never stows.
    """

    plant_id: str
    name: str
    latitude: float
    longitude: float
    altitude: float
    timezone: str
    tracker_ids: tuple[int, ...]
    positions: FloatArray
    collector: Collector
    albedo: float = 0.2
    temp_air: float = 20.0
    wind_speed: float = 1.0
    fixed_tilt: float = 30.0
    fixed_azimuth: float = 180.0
    slope_azimuth: float = 0.0
    slope_tilt: float = 0.0
    source: str = ""
    notes: str = ""
    wind_stow: WindStow | None = None

    @property
    def n_trackers(self) -> int:
        """Number of trackers."""
        return len(self.tracker_ids)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description, units in the keys, positions in ENU."""
        c = self.collector
        return {
            "plant_id": self.plant_id,
            "name": self.name,
            "latitude_deg": self.latitude,
            "longitude_deg": self.longitude,
            "altitude_m": self.altitude,
            "timezone": self.timezone,
            "albedo": self.albedo,
            "temp_air_c": self.temp_air,
            "wind_speed_m_s": self.wind_speed,
            "fixed": {"surface_tilt_deg": self.fixed_tilt,
                      "surface_azimuth_deg": self.fixed_azimuth},
            "collector": {
                "width_m": c.width, "height_m": c.height, "area_m2": c.area,
                "modules_across": c.modules_across, "modules_high": c.modules_high,
                "module_orientation": c.module_orientation, "bypass_diodes": c.bypass_diodes,
                "module_power_w": c.module_power, "gamma_pdc_per_c": c.gamma_pdc,
                "module_name": c.module_name, "power_stc_w": c.power_stc,
                **({"outline_m": [list(p) for p in c.outline]} if c.outline else {}),
            },
            "trackers": [
                {"tracker_id": tid, "east_m": float(p[0]), "north_m": float(p[1]),
                 "up_m": float(p[2])}
                for tid, p in zip(self.tracker_ids, self.positions, strict=True)
            ],
            **({} if self.wind_stow is None else {"tracker": {
                "stow_wind_speed_m_s": self.wind_stow.wind_speed_m_s,
                "stow_release_min": self.wind_stow.release_min}}),
            "gcr": plant_gcr(self) if self.n_trackers >= 3 else None,
            "land_m2": plant_land_m2(self) if self.n_trackers >= 3 else None,
            "source": self.source,
            "notes": self.notes,
        }


def plant_land_m2(plant: Plant) -> float:
    """Ground of an irregular plant [m²]: its pivots' convex hull grown by half the median
    nearest-neighbour distance r (Steiner's formula: hull area + perimeter·r + π r²).

    For an n × n square lattice of spacing L this is n²L² − (1 − π/4)L², the lattice's
    own ground less the rounded corners; it scales as the square of the spacing. A single
    row is a segment of length L: 2L·r + π r² (its hull had raised a ``QhullError``).
    """
    from scipy.spatial import ConvexHull, QhullError

    xy = plant.positions[:, :2]
    if len(xy) < 3:
        raise ValueError("a plant needs at least 3 trackers to have a ground area")
    gaps = np.linalg.norm(xy[:, None] - xy[None], axis=-1)
    length = float(gaps.max())
    np.fill_diagonal(gaps, np.inf)
    r = float(np.median(gaps.min(axis=1))) / 2
    try:
        hull = ConvexHull(xy)                          # 2-D: volume = area, area = perimeter
        area, perimeter = float(hull.volume), float(hull.area)
    except QhullError:                                 # one row: a segment
        area, perimeter = 0.0, 2 * length
    return area + perimeter * r + np.pi * r * r


def plant_gcr(plant: Plant) -> float:
    """Ground cover ratio of a plant: N · collector area / :func:`plant_land_m2` [-]."""
    return plant.n_trackers * plant.collector.area / plant_land_m2(plant)


#: Lowest ground cover ratio of a plant file (:func:`plant_gcr`). Built plants of dual-axis
#: trackers lie at about 0.1–0.6 (Peñarroya I: 0.14); 0.02 leaves a sparse test layout
#: room and refuses positions typed in cm (GCR ÷ 10⁴: 0.14 → 0.00001) or dm (÷ 100). The
#: other side is the swept-diameter rule: trackers that close would collide.
MIN_PLANT_GCR = 0.02


def _num(d: dict[str, Any], key: str, where: str, default: float | None = None,
         lo: float | None = None, hi: float | None = None, positive: bool = False) -> float:
    if key not in d:
        if default is None:
            raise ValueError(f"{where}: missing field {key!r}")
        return default
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v):
        raise ValueError(f"{where}: field {key!r} must be a finite number, got {v!r}")
    v = float(v)
    if positive and not v > 0:
        raise ValueError(f"{where}: field {key!r} must be positive, got {v}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise ValueError(f"{where}: field {key!r} = {v} outside [{lo}, {hi}]")
    return v


def _int(d: dict[str, Any], key: str, where: str, default: int | None = None) -> int:
    if key not in d:
        if default is None:
            raise ValueError(f"{where}: missing field {key!r}")
        return default
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise ValueError(f"{where}: field {key!r} must be a positive integer, got {v!r}")
    return v


def _collector(d: Any, where: str) -> Collector:
    if not isinstance(d, dict):
        raise ValueError(f"{where}: field 'collector' must be an object")
    w = f"{where}: collector"
    orient = d.get("module_orientation", "portrait")
    if orient not in MODULE_ORIENTATIONS:
        raise ValueError(f"{w}: field 'module_orientation' must be one of "
                         f"{', '.join(MODULE_ORIENTATIONS)}, got {orient!r}")
    outline = None
    if "outline_m" in d:
        outline = check_outline(d["outline_m"], f"{w}: field 'outline_m'")
        xy = np.asarray(outline)
        width, height = (float(np.ptp(xy[:, 0])), float(np.ptp(xy[:, 1])))
        for key, box in (("width_m", width), ("height_m", height)):  # Plant.to_dict writes
            if key in d and not math.isclose(_num(d, key, w), box, rel_tol=1e-9):  # them
                raise ValueError(f"{w}: give 'width_m' and 'height_m' (a rectangle) or "
                                 f"'outline_m' (a polygon): with an outline '{key}' is its "
                                 f"bounding box's, {box:g} m")
    else:
        width = _num(d, "width_m", w, positive=True)
        height = _num(d, "height_m", w, positive=True)
    try:
        check_collector_size(width, height, ("'width_m'", "'height_m'") if outline is None
                             else ("'outline_m' width", "'outline_m' height"))
    except ValueError as exc:
        raise ValueError(f"{w}: field {exc}") from None
    return Collector(
        width=width,
        height=height,
        outline=outline,
        modules_across=_int(d, "modules_across", w),
        modules_high=_int(d, "modules_high", w),
        module_orientation=orient,
        bypass_diodes=_int(d, "bypass_diodes", w),
        module_power=_num(d, "module_power_w", w, positive=True),
        gamma_pdc=_num(d, "gamma_pdc_per_c", w, default=-0.004, lo=-0.02, hi=0.0),
        module_name=str(d.get("module_name", "")),
    )


def _wind_stow(d: Any, where: str) -> WindStow | None:
    """The plant file's ``tracker`` object: ``stow_wind_speed_m_s`` and ``stow_release_min``,
    the bounds of a site's (:class:`sim.site_config.TrackerGeometry`); None without a speed."""
    if not isinstance(d, dict):
        raise ValueError(f"{where} must be an object")
    unknown = sorted(set(d) - {"stow_wind_speed_m_s", "stow_release_min"})
    if unknown:
        raise ValueError(f"{where}: unknown field {unknown[0]!r} (a plant's tracker takes "
                         "stow_wind_speed_m_s and stow_release_min)")
    if "stow_wind_speed_m_s" not in d:
        if "stow_release_min" in d:
            raise ValueError(f"{where}: field 'stow_release_min' is only used with "
                             "'stow_wind_speed_m_s'")
        return None
    speed = _num(d, "stow_wind_speed_m_s", where, positive=True, hi=STOW_WIND_MAX_M_S)
    return WindStow(speed, _num(d, "stow_release_min", where, default=STOW_RELEASE_MIN, lo=0,
                                hi=STOW_RELEASE_MAX_MIN))


def plant_from_dict(d: dict[str, Any], where: str = "plant") -> Plant:
    """A :class:`Plant` from the layout of ``sim/data/plants/*.json``; ValueError names a field."""
    if not isinstance(d, dict):
        raise ValueError(f"{where}: a plant file must hold a JSON object")
    if "plant_id" not in d:
        raise ValueError(f"{where}: missing field 'plant_id'")
    plant_id = str(d["plant_id"])
    lat = _num(d, "latitude_deg", where, lo=-90, hi=90)
    lon = _num(d, "longitude_deg", where, lo=-180, hi=180)
    tz = d.get("timezone")
    if not isinstance(tz, str):
        raise ValueError(f"{where}: missing field 'timezone' (an IANA zone name)")
    try:
        check_iana_zone(tz)
    except ValueError as exc:
        raise ValueError(f"{where}: field 'timezone' {exc}") from None
    frame = d.get("frame", "enu")
    if frame not in FRAMES:
        raise ValueError(f"{where}: field 'frame' must be one of {', '.join(FRAMES)}, "
                         f"got {frame!r}")
    collector = _collector(d.get("collector"), where)
    rows = d.get("trackers")
    if not isinstance(rows, list) or len(rows) < 1:
        raise ValueError(f"{where}: field 'trackers' must be a non-empty list")
    keys = ("x_m", "y_m", "z_m") if frame == "seed004" else ("east_m", "north_m", "up_m")
    ids: list[int] = []
    xyz = []
    for k, row in enumerate(rows):
        w = f"{where}: trackers[{k}]"
        if not isinstance(row, dict):
            raise ValueError(f"{w} must be an object")
        ids.append(_int(row, "tracker_id", w))
        xyz.append([_num(row, keys[0], w), _num(row, keys[1], w),
                    _num(row, keys[2], w, default=0.0)])
    if len(set(ids)) != len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        raise ValueError(f"{where}: field 'trackers' has duplicate tracker_id {dup}")
    positions = np.asarray(xyz, dtype=float)
    if frame == "seed004":
        positions = enu_from_seed004(positions)
    if len(ids) > 1:
        gaps = np.linalg.norm(positions[:, None, :2] - positions[None, :, :2], axis=-1)
        np.fill_diagonal(gaps, np.inf)
        i, j = np.unravel_index(np.argmin(gaps), gaps.shape)
        if gaps[i, j] < collector.swept_diameter:
            raise ValueError(
                f"{where}: field 'trackers': trackers {ids[i]} and {ids[j]} are "
                f"{gaps[i, j]:.2f} m apart, less than the collector's swept diameter "
                f"{collector.swept_diameter:.2f} m (their collectors would collide)")
    fixed = d.get("fixed", {})
    if not isinstance(fixed, dict):
        raise ValueError(f"{where}: field 'fixed' must be an object")
    plant = Plant(
        plant_id=plant_id,
        name=str(d.get("name", plant_id)),
        latitude=lat,
        longitude=lon,
        altitude=_num(d, "altitude_m", where, default=0.0, lo=ALTITUDE_MIN_M,
                      hi=ALTITUDE_MAX_M),
        timezone=tz,
        tracker_ids=tuple(ids),
        positions=positions,
        collector=collector,
        albedo=_num(d, "albedo", where, default=0.2, lo=0, hi=1),
        temp_air=_num(d, "temp_air_c", where, default=20.0, lo=-60, hi=60),
        wind_speed=_num(d, "wind_speed_m_s", where, default=1.0, lo=0, hi=60),
        fixed_tilt=_num(fixed, "surface_tilt_deg", f"{where}: fixed",
                        default=fixed_tilt_from_latitude_deg(lat), lo=0, hi=90),
        # facing the equator, as a site's fixed array (a southern plant's had faced the pole)
        fixed_azimuth=_num(fixed, "surface_azimuth_deg", f"{where}: fixed",
                           default=equator_azimuth_deg(lat), lo=0, hi=360),
        source=str(d.get("source", "")),
        notes=str(d.get("notes", "")),
        wind_stow=_wind_stow(d.get("tracker", {}), f"{where}: tracker"),
    )
    if len(ids) >= 3 and (gcr := plant_gcr(plant)) < MIN_PLANT_GCR:
        raise ValueError(
            f"{where}: field 'trackers': ground cover ratio {gcr:.2g} (collector area over the "
            f"ground the trackers cover) is below {MIN_PLANT_GCR:g}, a real plant's lies at "
            f"about 0.1-0.6: trackers {ids[i]} and {ids[j]}, the nearest, are "
            f"{gaps[i, j]:.4g} m apart for a {collector.width:g} m x {collector.height:g} m "
            "collector; give positions in metres (not cm or mm)")
    return plant


def load_plant(plant_id: str, plants_dir: str | Path | None = None) -> Plant:
    """Read ``<plants_dir>/<plant_id>.json`` (default: :func:`default_plants_dir`).

    Raises
    ------
    UnknownPlantError
        No such plant (the message lists the known ids).
    ValueError
        The file is malformed (the message names the file and the field).
    """
    directory = Path(plants_dir) if plants_dir is not None else default_plants_dir()
    path, data = read_config("plant", plant_id, directory, UnknownPlantError)
    plant = plant_from_dict(data, where=str(path))
    if plant.plant_id != plant_id:
        raise ValueError(f"{path}: field 'plant_id' {plant.plant_id!r} does not match the "
                         "file name")
    return plant


def list_plants(plants_dir: str | Path | None = None
                ) -> tuple[list[Plant], list[tuple[str, str]]]:
    """The plants of ``plants_dir`` (default: :func:`default_plants_dir`) that load, sorted by
    id, and the files that do not: (file name, its problem) — one bad file leaves the others
    listed (it made ``plant list`` fail for all). ``ValueError`` for a missing folder."""
    directory = Path(plants_dir) if plants_dir is not None else default_plants_dir()
    if not directory.is_dir():  # a mistyped folder listed nothing, as an empty one
        raise ValueError(f"plants folder {str(directory)!r} does not exist")
    plants, skipped = [], []
    for path in sorted(directory.glob("*.json")):
        try:
            plants.append(load_plant(path.stem, directory))
        except ValueError as exc:
            skipped.append((path.name, plant_file_problem(exc, path)))
    return plants, skipped


def plant_file_problem(exc: ValueError, path: str | Path) -> str:
    """What is wrong with a plant file, from :func:`load_plant`'s error without the file's
    path in front (the caller names the file)."""
    text = str(exc)
    return text.removeprefix(f"{path}: ")
