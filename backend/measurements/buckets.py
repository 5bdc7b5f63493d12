"""The rollup time grid: one hour wide, phased so local hours are whole buckets.

Bucket ``k`` is ``[k·ROLLUP_WIDTH_S + phase_s, (k+1)·ROLLUP_WIDTH_S + phase_s)``,
where ``phase_s`` is the site's standard-time UTC offset modulo one hour (India's
+05:30 gives 1800 s). Local hours, days and months are then unions of buckets,
so energy per day or month adds stored hourly buckets only.
"""

from __future__ import annotations

import datetime as dt
from typing import Any
from zoneinfo import ZoneInfo

import numpy as np

#: Width of one rollup bucket [s].
ROLLUP_WIDTH_S = 3600


def bucket_phase_s(timezone: str) -> int:
    """Offset [s] of the zone's local hours from the UTC hour grid (standard time)."""
    offset = dt.datetime(2024, 1, 15, tzinfo=ZoneInfo(timezone)).utcoffset()
    return int(offset.total_seconds()) % ROLLUP_WIDTH_S if offset else 0


def bucket_index(ts_s: np.ndarray, phase_s: int, width_s: int = ROLLUP_WIDTH_S) -> np.ndarray:
    """Index ``k`` of the bucket holding each time [s]."""
    return (np.asarray(ts_s, np.int64) - phase_s) // width_s


def bucket_start_s(k: int, phase_s: int, width_s: int = ROLLUP_WIDTH_S) -> int:
    """Start [s] of bucket ``k``."""
    return k * width_s + phase_s


def grid_ceil(t_s: Any, phase_s: int, width_s: int = ROLLUP_WIDTH_S) -> Any:
    """First bucket edge at or after ``t_s`` (an int, or each of an integer array)."""
    return -((phase_s - t_s) // width_s) * width_s + phase_s


def grid_floor(t_s: Any, phase_s: int, width_s: int = ROLLUP_WIDTH_S) -> Any:
    """Last bucket edge at or before ``t_s`` (an int, or each of an integer array)."""
    return ((t_s - phase_s) // width_s) * width_s + phase_s
