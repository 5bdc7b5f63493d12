"""Plants of dual-axis trackers (seed 004): layout, inter-shading, electrical loss, strategies.

- :mod:`sim.plant.layout` — :class:`Plant`, :func:`load_plant`, :func:`list_plants`,
  :func:`enu_from_seed004` (seed 004's x-west/y-south/z-zenith frame → ENU);
- :mod:`sim.plant.shading` — seed 004's inter-shading Boolean and shaded fractions;
- :mod:`sim.plant.electrical` — Martinez-Moreno (2010) bypass-diode loss via pvlib;
- :mod:`sim.plant.strategies` — ``sun``, ``backtrack``, ``sky_scan`` orientations;
- :mod:`sim.plant.simulate` — a plant over a time range.
"""

from sim.plant.layout import (
    Collector,
    Plant,
    UnknownPlantError,
    default_plants_dir,
    enu_from_seed004,
    list_plants,
    load_plant,
)

__all__ = [
    "Collector",
    "Plant",
    "UnknownPlantError",
    "default_plants_dir",
    "enu_from_seed004",
    "list_plants",
    "load_plant",
]
