"""Regular fields of dual-axis trackers as parameters, and plants scaled in spacing.

A regular field is the lattice of Cumpston & Pye (2014, "Shading and land use in
regularly-spaced sun-tracking collectors", Solar Energy 108, 199–209,
doi:10.1016/j.solener.2014.06.012, §2 and Fig. 2) in the terms of
``twoaxistracking.layout.generate_field_layout`` (Jensen et al., pvlib's project for
two-axis fields): ground cover ratio GCR, aspect ratio (spacing in the primary direction
over the secondary), relative row offset, counter-clockwise rotation of the field, and a
plane ground of slope azimuth/tilt. Lattice point (i, j) lies at

    x = i · AR,  y = j + offset · i,  then rotated by ``rotation`` (counter-clockwise),
    z = −(x sin β_az + y cos β_az) tan β_tilt,   all scaled by √(A / (GCR · AR)),

A the collector area, so that each collector has A / GCR of ground (projected on the
horizontal). Named layouts (twoaxistracking's ``STANDARD_FIELD_LAYOUT_PARAMETERS``):
``square`` (AR 1, offset 0, 0°), ``diagonal`` (square turned 45°), ``hexagonal_n_s``
(AR √3/2, offset −0.5, 0°) and ``hexagonal_e_w`` (the same turned 90°).

:func:`regular_field` places a finite field of ``rows × columns`` collectors around the
interior one (5 × 5 holds twoaxistracking's ``neighbor_order=2``); :func:`scaled_plant`
stretches an existing plant's spacing to a target GCR.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.plant.layout import (
    Collector,
    Plant,
    check_collector_size,
    check_outline,
    plant_gcr,
    plant_land_m2,
)

FloatArray = NDArray[np.float64]

#: Named regular layouts: (aspect ratio, row offset, rotation [°]) — Cumpston & Pye 2014 §2,
#: the values of ``twoaxistracking.trackerfield.STANDARD_FIELD_LAYOUT_PARAMETERS``.
LAYOUT_TYPES: dict[str, tuple[float, float, float]] = {
    "square": (1.0, 0.0, 0.0),
    "diagonal": (1.0, 0.0, 45.0),
    "hexagonal_n_s": (float(np.sqrt(3) / 2), -0.5, 0.0),
    "hexagonal_e_w": (float(np.sqrt(3) / 2), -0.5, 90.0),
}


@dataclass(frozen=True)
class FieldLayout:
    """A regular field (Cumpston & Pye 2014 §2; twoaxistracking's parameters).

    Parameters
    ----------
    name : str
        A name of :data:`LAYOUT_TYPES`, or any label for a custom lattice.
    gcr : float
        Ground cover ratio: collector area over ground area per collector [-].
    aspect_ratio : float
        Spacing in the primary direction over the secondary [-].
    offset : float
        Row offset as a fraction of the secondary spacing, −0.5 ≤ offset < 0.5 [-].
    rotation_deg : float
        Counter-clockwise rotation of the field, 0 ≤ rotation < 180 [°].
    slope_azimuth_deg, slope_tilt_deg : float
        The ground plane: azimuth of its downhill normal on the horizontal (clockwise
        from north) and its tilt [°].
    """

    name: str
    gcr: float
    aspect_ratio: float = 1.0
    offset: float = 0.0
    rotation_deg: float = 0.0
    slope_azimuth_deg: float = 0.0
    slope_tilt_deg: float = 0.0

    @classmethod
    def named(cls, name: str, gcr: float, slope_azimuth_deg: float = 0.0,
              slope_tilt_deg: float = 0.0) -> FieldLayout:
        """One of :data:`LAYOUT_TYPES`; ``ValueError`` naming the known ones otherwise."""
        if name not in LAYOUT_TYPES:
            raise ValueError(f"layout {name!r} is not one of {', '.join(LAYOUT_TYPES)}")
        ar, off, rot = LAYOUT_TYPES[name]
        return cls(name, gcr, ar, off, rot, slope_azimuth_deg, slope_tilt_deg)

    def land_m2_per_collector(self, collector_area_m2: float) -> float:
        """Ground per collector [m²] (horizontal projection): A / GCR."""
        return collector_area_m2 / self.gcr

    def check(self, collector: Collector) -> None:
        """The limits of Cumpston & Pye 2014 §2 (as twoaxistracking checks them), with the
        collector's swept diameter (twoaxistracking's ``min_tracker_spacing``; a
        rectangle's diagonal) as the least distance between pivots; ``ValueError`` names
        the parameter."""
        area, spacing = collector.area, collector.swept_diameter
        if not -0.5 <= self.offset < 0.5:
            raise ValueError(f"offset must be in [-0.5, 0.5), got {self.offset}")
        if not 0 <= self.rotation_deg < 180:
            raise ValueError(f"rotation_deg must be in [0, 180), got {self.rotation_deg}")
        if not 0 <= self.slope_tilt_deg < 45:
            raise ValueError(f"slope_tilt_deg must be in [0, 45), got {self.slope_tilt_deg}")
        if not self.aspect_ratio > 0:
            raise ValueError(f"aspect_ratio must be positive, got {self.aspect_ratio}")
        gcr_max = area / (spacing ** 2 * np.sqrt(1 - self.offset ** 2))
        if not 0 < self.gcr <= gcr_max:
            raise ValueError(f"gcr {self.gcr} outside (0, {gcr_max:.4f}]: above it the "
                             f"collectors of {area:g} m², sweeping {spacing:.2f} m across, "
                             "would collide")
        if self.aspect_ratio < np.sqrt(1 - self.offset ** 2) - 1e-12:
            raise ValueError(f"aspect_ratio {self.aspect_ratio:.4f} below "
                             f"√(1 − offset²) = {np.sqrt(1 - self.offset ** 2):.4f}")
        if self.aspect_ratio > area / (self.gcr * spacing ** 2) + 1e-12:
            raise ValueError(f"aspect_ratio {self.aspect_ratio:.4f} too high for gcr "
                             f"{self.gcr}: the secondary spacing would be below the "
                             f"collector's swept diameter (at most "
                             f"{area / (self.gcr * spacing ** 2):.4f})")


def lattice_positions(layout: FieldLayout, collector_area_m2: float, rows: int, columns: int
                      ) -> tuple[FloatArray, int]:
    """Pivot positions (east, north, up) [m] of a ``rows × columns`` patch of the lattice.

    Cumpston & Pye 2014 §2 in twoaxistracking's construction (module docstring): lattice
    indices i (primary, ``columns`` of them) and j (secondary, ``rows``) centred on the
    interior collector, which is returned as the second value (its index).
    """
    if rows < 1 or columns < 1:
        raise ValueError(f"the field needs at least 1 × 1 collectors, got {rows} × {columns}")
    i = np.arange(columns) - (columns - 1) // 2
    j = np.arange(rows) - (rows - 1) // 2
    ii, jj = (a.ravel().astype(float) for a in np.meshgrid(i, j))
    y = jj + layout.offset * ii
    x = ii * layout.aspect_ratio
    rot = np.radians(layout.rotation_deg)           # counter-clockwise seen from above
    x, y = x * np.cos(rot) - y * np.sin(rot), x * np.sin(rot) + y * np.cos(rot)
    scale = np.sqrt(collector_area_m2 / (layout.gcr * layout.aspect_ratio))
    x, y = x * scale, y * scale
    b_az, b_tilt = np.radians(layout.slope_azimuth_deg), np.radians(layout.slope_tilt_deg)
    z = -(x * np.sin(b_az) + y * np.cos(b_az)) * np.tan(b_tilt)
    interior = int(np.flatnonzero((ii == 0) & (jj == 0))[0])
    return np.stack([x, y, z], axis=-1), interior


def regular_field(layout: FieldLayout, collector: Collector, latitude: float,
                  longitude: float, altitude: float = 0.0, rows: int = 5, columns: int = 5,
                  timezone: str = "UTC", albedo: float = 0.2) -> tuple[Plant, int]:
    """A finite regular field as a :class:`Plant`, and the index of its interior collector.

    ``ValueError`` (naming the parameter) outside the limits of :meth:`FieldLayout.check`.
    """
    layout.check(collector)
    positions, interior = lattice_positions(layout, collector.area, rows, columns)
    plant = Plant(
        plant_id=f"{layout.name}-gcr{layout.gcr:g}", name=f"{layout.name}, GCR {layout.gcr:g}",
        latitude=latitude, longitude=longitude, altitude=altitude, timezone=timezone,
        tracker_ids=tuple(range(1, len(positions) + 1)), positions=positions,
        collector=collector, albedo=albedo,
        slope_azimuth=layout.slope_azimuth_deg, slope_tilt=layout.slope_tilt_deg,
        source="Cumpston & Pye 2014 regular field (sim.plant.fields)")
    return plant, interior


def scaled_plant(plant: Plant, gcr: float) -> Plant:
    """The plant with its pivots moved from its centroid so that :func:`plant_gcr` is ``gcr``.

    Positions (east, north and up, so a slope is kept) scale by k = √(GCR₀ / GCR); the
    ground grows as k². ``ValueError`` when two collectors would then collide.
    """
    if not gcr > 0:
        raise ValueError(f"gcr must be positive, got {gcr}")
    k = float(np.sqrt(plant_gcr(plant) / gcr))
    centre = plant.positions.mean(axis=0)
    positions = centre + (plant.positions - centre) * k
    gaps = np.linalg.norm(positions[:, None, :2] - positions[None, :, :2], axis=-1)
    np.fill_diagonal(gaps, np.inf)
    if gaps.min() < plant.collector.swept_diameter:
        raise ValueError(f"gcr {gcr} too high for plant {plant.plant_id!r}: trackers would be "
                         f"{gaps.min():.2f} m apart, less than the collector's swept "
                         f"diameter {plant.collector.swept_diameter:.2f} m (twice its farthest "
                         "vertex from the pivot: the rectangle's diagonal)")
    return replace(plant, positions=positions, plant_id=f"{plant.plant_id}-gcr{gcr:g}")


def interior_tracker(plant: Plant) -> int:
    """Index of the tracker nearest the centroid of the pivots (the plant's interior one)."""
    xy = plant.positions[:, :2]
    return int(np.argmin(np.linalg.norm(xy - xy.mean(axis=0), axis=1)))


def collector_from_size(width_m: float, height_m: float, template: Collector) -> Collector:
    """A ``width × height`` collector wired like ``template``: the template's module size
    (and so its power per m², orientation, bypass diodes, temperature coefficient), as many
    modules as fit across and up (at least one), their power scaled by the area kept.
    ``ValueError`` for a side not positive or above
    :data:`sim.plant.layout.MAX_COLLECTOR_SIDE_M` (a size in mm taken as metres)."""
    if not (width_m > 0 and height_m > 0):
        raise ValueError(f"collector size must be positive, got {width_m} x {height_m} m")
    check_collector_size(width_m, height_m, ("width", "height"))
    mw, mh = template.width / template.modules_across, template.height / template.modules_high
    across, high = max(1, round(width_m / mw)), max(1, round(height_m / mh))
    module_power = template.module_power * (width_m * height_m) / (across * high * mw * mh)
    return replace(template, width=width_m, height=height_m, modules_across=across,
                   modules_high=high, module_power=module_power)


def collector_from_outline(outline_m: Any, template: Collector) -> Collector:
    """A polygon collector (``outline_m``: (u, v) vertices [m] about the pivot,
    :func:`sim.plant.layout.check_outline`) wired like ``template``: the template's module
    size laid over the outline's bounding box (as many modules as fit across and up, as
    :func:`collector_from_size`), each module row one string; its rated power is the
    grid's share the polygon covers (:attr:`sim.plant.layout.Collector.power_stc`), so the
    collector keeps the template's power per m²."""
    outline = check_outline(outline_m, "collector outline")
    xy = np.asarray(outline)
    box = collector_from_size(float(np.ptp(xy[:, 0])), float(np.ptp(xy[:, 1])), template)
    collector = replace(box, outline=outline)
    if collector.bounds == (-box.width / 2, box.width / 2, -box.height / 2, box.height / 2) \
            and len(outline) == 4 and abs(collector.area - box.area) < 1e-9 * box.area:
        return box                              # a centred rectangle: the fast path
    return collector


def horizon_elevation(solar_azimuth: NDArray[np.float64] | float, slope_azimuth_deg: float,
                      slope_tilt_deg: float) -> FloatArray:
    """Elevation of a plane ground's horizon in the sun's azimuth [°], at least 0.

    Cumpston & Pye 2014 (sloped fields), as ``twoaxistracking.shading.horizon_elevation_angle``:
    arctan(−cos(β_az − γ_s) tan β_tilt), clipped at 0; the sun below it leaves a field on
    that ground in shade.
    """
    az = np.asarray(solar_azimuth, dtype=float)
    h = np.degrees(np.arctan(-np.cos(np.radians(slope_azimuth_deg - az))
                             * np.tan(np.radians(slope_tilt_deg))))
    return np.maximum(h, 0.0)


__all__ = ["LAYOUT_TYPES", "FieldLayout", "collector_from_outline", "collector_from_size",
           "horizon_elevation",
           "interior_tracker", "lattice_positions", "plant_gcr", "plant_land_m2",
           "regular_field", "scaled_plant"]
