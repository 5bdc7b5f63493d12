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
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sim.plant.layout import Collector
from sim.plant.shading import PlantShade, union_area

FloatArray = NDArray[np.float64]


def _overlaps(rects: FloatArray, boxes: FloatArray) -> NDArray[np.bool_]:
    """(G, K, 4) rectangles against (B, 4) boxes → (G, B): some rectangle overlaps the box."""
    r = rects[:, :, None, :]
    b = boxes[None, None, :, :]
    hit = (np.minimum(r[..., 1], b[..., 1]) > np.maximum(r[..., 0], b[..., 0]) + 1e-12) & \
        (np.minimum(r[..., 3], b[..., 3]) > np.maximum(r[..., 2], b[..., 2]) + 1e-12)
    return np.asarray(hit.any(axis=1))


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
    strings = collector.strings()
    blocks, owner = collector.blocks()
    total_blocks = np.bincount(owner, minlength=len(strings)).astype(float)
    string_area = (strings[:, 1] - strings[:, 0]) * (strings[:, 3] - strings[:, 2])
    factor = np.zeros(len(shade.group_step))
    for s in range(len(strings)):
        f_s = union_area(shade.group_rects, clip=strings[s]) / string_area[s]
        in_s = blocks[owner == s]
        n_sb = np.zeros(len(factor))
        for g0 in range(0, len(factor), 4096):  # bounded memory: (4096, K, B)
            hit = _overlaps(shade.group_rects[g0:g0 + 4096], in_s)
            n_sb[g0:g0 + 4096] = hit.sum(axis=1)
        loss = direct_martinez(1.0, 1.0, np.minimum(f_s, 1.0), n_sb, total_blocks[s])
        factor += (1.0 - np.asarray(loss, dtype=float)) / len(strings)
    electrical[shade.group_step, shade.group_tracker] = factor
    return area, electrical
