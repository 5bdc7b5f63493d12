"""What shade costs: area-proportional and bypass-diode (Martinez-Moreno 2010) beam factors.

Shaded area is not lost energy. A crystalline module's cells sit in
bypass-diode substrings ("blocks"); a shaded cell makes its substring's diode
conduct and the substring's beam contribution is lost. Martinez-Moreno, Muñoz &
Lorenzo (2010, doi:10.1016/j.solmat.2010.07.029, eqs. 6 and 8), as
``pvlib.shading.direct_martinez``: for a string of N_TB blocks of which N_SB
hold some shade and a shaded area fraction F, the beam is scaled by
(1 − F)(1 − N_SB / (N_TB + 1)); diffuse and ground-reflected light are kept.

The area-proportional model scales the beam by (1 − F) only. Each row of
modules of a collector is one string (:class:`sim.plant.layout.Collector`);
strings are taken to work at their own maximum-power point.

F per string is the union area of the shade rectangles inside the string's band
(kept by :func:`sim.plant.shading.plant_shade` when it is given the strings'
edges, computed here otherwise). N_SB is counted on the block grid: each shade
rectangle covers a rectangle of block indices, and the blocks of a row of blocks
that hold shade are the set bits of the OR of those rectangles' bit masks (one
bit per block across the collector) — exact integer work, and much cheaper than
a union of the index rectangles. A collector with more than
:data:`_MASK_BITS` blocks across falls back to that union.

A polygon collector (``Collector.outline``) is modelled with what the rectangle's
model says of a module grid, on the polygon: the module grid lies over the outline's
bounding box, each module row is one string, and a string is the part of the polygon
inside its row's band (modules cut to the outline: the polygon is all active area).
A string's blocks are the cells of the block grid that hold some of the polygon
(N_TB counts them, so a string cut short by the outline has fewer blocks), F_s is the
shaded share of the string's polygon area, N_SB the cells whose polygon part holds
shade (their interiors meet, shapely), and the collector's beam factor is the strings'
factors weighted by their areas (each string at its own maximum-power point, its
power in proportion to its area). A real collector of that outline carries whole
rectangular modules; this is the idealisation, stated, not a wiring of any plant.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sim.plant.layout import Collector
from sim.plant.shading import PlantShade, band_union_areas, sum_columns

FloatArray = NDArray[np.float64]

_EPS_AREA_M2 = 1e-9
#: Blocks across a collector that one uint64 bit mask per row of blocks can hold.
_MASK_BITS = 63
#: Set bits of every byte (popcount where numpy has no ``bitwise_count``, numpy < 2).
_BYTE_BITS = np.array([bin(b).count("1") for b in range(256)], dtype=np.int64)


def _block_index_rects(rects: FloatArray, collector: Collector) -> FloatArray:
    """Shade rectangles in block-index units: u in [0, n_u), v in [0, strings × n_v).

    Each rectangle covers an index rectangle of blocks (a block counts when the
    shade overlaps it with positive area); the number of blocks of a string that
    hold shade is the union "area" of those index rectangles inside the string's
    rows (exact on integers). rects (..., 4) → (..., 4).
    """
    n_u, n_v = collector.block_grid()
    n_rows = n_v * collector.modules_high
    u_min, v_min = -collector.width / 2, -collector.height / 2
    cu, cv = collector.width / n_u, collector.height / n_rows
    u0, u1, v0, v1 = (rects[..., c] for c in range(4))
    live = (u1 - u0 > 1e-12) & (v1 - v0 > 1e-12)
    c0 = np.clip(np.floor((u0 - u_min) / cu + 1e-9), 0, n_u)
    r0 = np.clip(np.floor((v0 - v_min) / cv + 1e-9), 0, n_rows)
    c1 = np.where(live, np.clip(np.ceil((u1 - u_min) / cu - 1e-9), 0, n_u), c0)
    r1 = np.where(live, np.clip(np.ceil((v1 - v_min) / cv - 1e-9), 0, n_rows), r0)
    return np.stack([c0, c1, r0, r1], axis=-1)


def _popcount(x: NDArray[np.uint64]) -> NDArray[np.int64]:
    """Number of set bits of each element."""
    if hasattr(np, "bitwise_count"):                  # numpy >= 2.0
        return np.bitwise_count(x).astype(np.int64)
    return _BYTE_BITS[np.ascontiguousarray(x).view(np.uint8)].reshape(*x.shape, 8).sum(axis=-1)


def _shaded_blocks(index_rects: FloatArray, group: NDArray[np.intp], n_groups: int, n_u: int,
                   n_rows: int) -> NDArray[np.int64]:
    """Blocks that hold shade in each row of blocks of each group → ``(n_groups, n_rows)``.

    ``index_rects`` (M, 4) from :func:`_block_index_rects`, ``group`` (M,) the group of
    each, non-decreasing. A rectangle covering block columns [c0, c1) of rows [r0, r1)
    sets bits c0 … c1 − 1 of those rows' masks; a row's shaded blocks are the set bits
    of the OR of its rectangles' masks (``n_u`` ≤ :data:`_MASK_BITS`).
    """
    out = np.zeros((n_groups, n_rows), dtype=np.int64)
    if not len(group):
        return out
    c0, c1, r0, r1 = (index_rects[:, c].astype(np.uint64) for c in range(4))
    one = np.uint64(1)
    bits = (one << np.maximum(c1, c0)) - (one << c0)        # (M,); c1 < c0 would wrap
    first = np.flatnonzero(np.concatenate([[True], group[1:] != group[:-1]]))
    zero = np.uint64(0)
    for row in range(n_rows):                               # a few rows: 1-D passes
        masks = np.where((r0 <= row) & (r1 > row), bits, zero)
        out[group[first], row] = _popcount(np.bitwise_or.reduceat(masks, first))
    return out


def _block_counts(index_rects: FloatArray, group: NDArray[np.intp], n_groups: int, n_u: int,
                  n_v: int, n_strings: int) -> FloatArray:
    """Shaded blocks per group and string ``(n_groups, n_strings)`` from block-index
    rectangles ``(M, 4)`` of groups ``group`` (non-decreasing): the bit masks of
    :func:`_shaded_blocks`, or the union of the index rectangles beyond
    :data:`_MASK_BITS` blocks across."""
    if n_u <= _MASK_BITS:
        rows = _shaded_blocks(index_rects, group, n_groups, n_u, n_v * n_strings)
        return sum_columns(rows.reshape(-1, n_v).astype(float)).reshape(-1, n_strings)
    slot = np.arange(len(group)) - np.searchsorted(group, group)
    padded = np.zeros((n_groups, int(slot.max()) + 1 if len(slot) else 1, 4))
    padded[group, slot] = index_rects
    return band_union_areas(padded, n_v * np.arange(n_strings + 1.0))


def beam_factors(shade: PlantShade, collector: Collector) -> tuple[FloatArray, FloatArray]:
    """Fraction of the plane-of-array beam each collector converts, under the two models.

    Parameters
    ----------
    shade : PlantShade
        From :func:`sim.plant.shading.plant_shade`.
    collector : Collector
        Size and electrical layout (strings, bypass-diode blocks).

    Returns
    -------
    area, electrical : numpy.ndarray, shape (T, N)
        Area model (1 − F) and Martinez-Moreno's string-averaged
        (1 − F_s)(1 − N_SB,s / (N_TB,s + 1)) via ``pvlib.shading.direct_martinez``
        [-]; NaN with the sun down.
    """
    from pvlib.shading import direct_martinez

    area = 1.0 - shade.fraction
    electrical = area.copy()
    if not len(shade.group_step):
        return area, electrical
    if not collector.is_rectangle:
        f_s, n_sb, n_tb, weight = _polygon_strings(shade, collector)
        loss = direct_martinez(1.0, 1.0, np.minimum(f_s, 1.0), n_sb, n_tb)
        electrical[shade.group_step, shade.group_tracker] = (
            (1.0 - np.asarray(loss, dtype=float)) @ weight)
        return area, electrical
    strings = collector.strings()                     # horizontal bands, bottom to top
    n_u, n_v = collector.block_grid()
    string_area = (strings[:, 1] - strings[:, 0]) * (strings[:, 3] - strings[:, 2])
    cuts = collector.string_boundaries()
    if (shade.group_band_area is not None and shade.band_edges is not None
            and np.array_equal(shade.band_edges, cuts)):
        f_s = shade.group_band_area / string_area     # kept by plant_shade, (G, S)
    else:
        edges = np.concatenate([[-np.inf], cuts, [np.inf]])  # the rectangles lie inside
        f_s = band_union_areas(shade.group_rects, edges) / string_area
    used = np.flatnonzero(shade.group_by >= 0)        # the slots that hold a rectangle
    g_used = used // shade.group_by.shape[1]          # by group, then slot
    index_rects = _block_index_rects(np.take(shade.group_rects.reshape(-1, 4), used, axis=0),
                                     collector)
    n_sb = _block_counts(index_rects, g_used, len(shade.group_step), n_u, n_v, len(strings))
    loss = direct_martinez(1.0, 1.0, np.minimum(f_s, 1.0), n_sb, float(n_u * n_v))
    n = electrical.shape[1]
    electrical.reshape(-1)[shade.group_step * n + shade.group_tracker] = sum_columns(
        1.0 - np.asarray(loss, dtype=float)) / len(strings)        # the strings' mean
    return area, electrical


def _polygon_strings(shade: PlantShade, collector: Collector
                     ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """A polygon collector's strings (module docstring): per group and string the shaded
    fraction F_s and shaded blocks N_SB ``(G, S)``, and per string its blocks N_TB and its
    share of the collector's area ``(S,)`` (strings without polygon area get weight 0)."""
    import shapely

    if shade.group_shade is None:
        raise ValueError("a polygon collector's shade must come from plant_shade(..., "
                         "outline=collector.outline_m())")
    own = shapely.Polygon(collector.outline_m())
    strings = collector.strings()
    n_s = len(strings)
    string_area = shapely.area(shapely.intersection(own, shapely.box(
        strings[:, 0], strings[:, 2], strings[:, 1], strings[:, 3])))
    # the block grid over the bounding box: string s holds rows s·n_v … (s + 1)·n_v − 1
    n_u, n_v = collector.block_grid()
    n_rows = n_v * n_s
    u_lo, u_hi, v_lo, v_hi = collector.bounds
    cu, cv = (u_hi - u_lo) / n_u, (v_hi - v_lo) / n_rows
    col, row = np.meshgrid(np.arange(n_u), np.arange(n_rows))
    cells = shapely.box(u_lo + col.ravel() * cu, v_lo + row.ravel() * cv,
                        u_lo + (col.ravel() + 1) * cu, v_lo + (row.ravel() + 1) * cv)
    live = shapely.area(shapely.intersection(own, cells)) > _EPS_AREA_M2
    n_tb = live.reshape(n_s, n_v * n_u).sum(axis=1).astype(float)
    # the shade clipped to each row of cells (GEOS clip_by_rect): its area per string gives
    # F_s; a cell holds shade where the shade's interior meets it, and each connected piece
    # of a row's shade spans the open interval of its u bounds, so it holds the row's cells
    # that interval overlaps — index rectangles for the bit-mask count
    pieces, rows_of, groups_of = [], [], []
    shaded = np.zeros((len(shade.group_step), n_s))
    for r in range(n_rows):
        clipped = shapely.clip_by_rect(shade.group_shade, u_lo - 1.0, v_lo + r * cv,
                                       u_hi + 1.0, v_lo + (r + 1) * cv)
        parts, g = shapely.get_parts(clipped, return_index=True)
        part_area = shapely.area(parts)
        keep = part_area > _EPS_AREA_M2
        np.add.at(shaded[:, r // n_v], g[keep], part_area[keep])
        pieces.append(shapely.bounds(parts[keep]))
        groups_of.append(g[keep])
        rows_of.append(np.full(int(keep.sum()), r))
    with np.errstate(divide="ignore", invalid="ignore"):
        f_s = np.where(string_area > 0, shaded / string_area, 0.0)
    box = np.concatenate(pieces)
    group = np.concatenate(groups_of)
    rr = np.concatenate(rows_of).astype(float)
    index_rects = np.stack([np.floor((box[:, 0] - u_lo) / cu + 1e-9),
                            np.ceil((box[:, 2] - u_lo) / cu - 1e-9), rr, rr + 1], axis=-1)
    index_rects[:, :2] = np.clip(index_rects[:, :2], 0, n_u)
    order = np.argsort(group, kind="stable")
    n_sb = _block_counts(index_rects[order], group[order], len(shade.group_step), n_u, n_v,
                         n_s)
    return f_s, n_sb, n_tb, string_area / string_area.sum()
