"""A twin run's series at the export boundary: column names with units, UTC and local time.

Inside ``sim/`` the series keeps pvlib's glossary names (``solar_azimuth``,
``tracker_poa_global``, …, units in docstrings); every file a user gets — the
full-series CSV of ``heliotwin simulate --csv`` and of
``GET /api/v1/simulations/{run_id}/series?format=csv`` — names each quantity's
unit instead (DESIGN.md, conventions). :func:`export_names` is the one mapping;
:func:`series_csv` writes ``time_utc``, ``time_local`` (the site's zone, with
its offset) and every column.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

#: pvlib-glossary columns of :data:`sim.twin.SERIES_COLUMNS` and their exported names.
EXPORT_NAMES = {
    "solar_azimuth": "solar_azimuth_deg",
    "apparent_elevation": "solar_apparent_elevation_deg",
    "tracker_aoi": "tracker_aoi_deg",
    "fixed_aoi": "fixed_aoi_deg",
    "tracker_poa_global": "tracker_poa_global_w_m2",
    "fixed_poa_global": "fixed_poa_global_w_m2",
    "tracker_temp_cell": "tracker_temp_cell_c",
    "fixed_temp_cell": "fixed_temp_cell_c",
    "fixed_shaded_fraction": "fixed_shaded_frac",  # sim/array_shade.py, placed sites only
}
#: Name endings that already state a unit (DESIGN.md: a quantity carries its unit in its name).
UNIT_SUFFIXES = ("_deg", "_mrad", "_rad", "_w", "_wh", "_w_m2", "_c", "_a", "_v", "_m", "_s",
                 "_pct", "_m_s", "_nm", "_frac")


def export_names(columns: list[str]) -> list[str]:
    """Exported names of series ``columns``; a column whose name states no unit is an error
    (whoever adds a series column names its unit, or adds it to :data:`EXPORT_NAMES`)."""
    out = []
    for c in columns:
        name = EXPORT_NAMES.get(c, c)
        if not name.endswith(UNIT_SUFFIXES):
            raise ValueError(f"series column {c!r} names no unit; add it to EXPORT_NAMES")
        out.append(name)
    return out


def _iso(index: pd.DatetimeIndex, timezone: str) -> np.ndarray:
    """ISO 8601 strings of ``index`` in ``timezone`` with the offset, vectorised (a year of
    minutes through ``strftime`` takes seconds)."""
    utc = index.tz_convert("UTC")
    local = utc.tz_convert(timezone)
    wall = local.tz_localize(None).to_numpy().astype("datetime64[ns]")
    offset_s = (wall - utc.tz_localize(None).to_numpy().astype("datetime64[ns]")).astype(
        "timedelta64[s]").astype(np.int64)
    whole = bool((wall.astype(np.int64) % 1_000_000_000 == 0).all())
    text = np.datetime_as_string(wall, unit="s" if whole else "ms")
    values, inverse = np.unique(offset_s, return_inverse=True)
    labels = np.array([f"{'+' if v >= 0 else '-'}{abs(v) // 3600:02d}:{abs(v) % 3600 // 60:02d}"
                       for v in values.tolist()])
    return np.char.add(text.astype(str), labels[inverse.ravel()] if len(values) else labels)


def export_frame(series: pd.DataFrame, timezone: str, decimals: int = 4) -> pd.DataFrame:
    """``series`` (UTC index, pvlib names) as exported: ``time_utc``, ``time_local`` in
    ``timezone`` and every column under :func:`export_names`, rounded to ``decimals``."""
    index = pd.DatetimeIndex(series.index)
    if index.tz is None:
        raise ValueError("series index must be timezone-aware")
    out = series.round(decimals)
    out.columns = export_names(list(series.columns))
    out.insert(0, "time_local", _iso(index, timezone))
    out.insert(0, "time_utc", _iso(index, "UTC"))
    return out.reset_index(drop=True)


def series_csv(series: pd.DataFrame, timezone: str, path: str | None = None) -> str | None:
    """The series as CSV text (or written to ``path``): see :func:`export_frame`."""
    return export_frame(series, timezone).to_csv(path, index=False, lineterminator="\n")
