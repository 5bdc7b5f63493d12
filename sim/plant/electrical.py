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


def _blocks_hit(rects: FloatArray, string: FloatArray, n_u: int, n_v: int) -> FloatArray:
    """Blocks of one string (a regular n_u × n_v grid of cells) that some rectangle overlaps.

    Each rectangle covers an index rectangle of cells; the count of their union
    is the union "area" of those index rectangles (exact on integers).
    rects (G, K, 4) → count (G,).
    """
    u0, u1, v0, v1 = string
    cu, cv = (u1 - u0) / n_u, (v1 - v0) / n_v
    ru0 = np.clip(rects[..., 0], u0, u1)
    ru1 = np.clip(rects[..., 1], u0, u1)
    rv0 = np.clip(rects[..., 2], v0, v1)
    rv1 = np.clip(rects[..., 3], v0, v1)
    live = (ru1 - ru0 > 1e-12) & (rv1 - rv0 > 1e-12)
    iu0 = np.floor((ru0 - u0) / cu + 1e-9)
    iu1 = np.ceil((ru1 - u0) / cu - 1e-9)
    iv0 = np.floor((rv0 - v0) / cv + 1e-9)
    iv1 = np.ceil((rv1 - v0) / cv - 1e-9)
    idx = np.stack([iu0, np.where(live, iu1, iu0), iv0, np.where(live, iv1, iv0)], axis=-1)
    return union_area(idx)


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
    n_u, n_v = collector.block_grid()
    string_area = (strings[:, 1] - strings[:, 0]) * (strings[:, 3] - strings[:, 2])
    factor = np.zeros(len(shade.group_step))
    for s in range(len(strings)):
        f_s = union_area(shade.group_rects, clip=strings[s]) / string_area[s]
        n_sb = np.zeros(len(factor))
        for g0 in range(0, len(factor), 20_000):  # bounded memory: (20000, K, n_u, n_v)
            n_sb[g0:g0 + 20_000] = _blocks_hit(shade.group_rects[g0:g0 + 20_000], strings[s],
                                               n_u, n_v)
        loss = direct_martinez(1.0, 1.0, np.minimum(f_s, 1.0), n_sb, float(n_u * n_v))
        factor += (1.0 - np.asarray(loss, dtype=float)) / len(strings)
    electrical[shade.group_step, shade.group_tracker] = factor
    return area, electrical
