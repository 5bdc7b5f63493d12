"""What the 3D twin shows at one instant (:class:`ScenePose`) and a simulation run it
replays (:class:`Replay`); the scene itself is :mod:`backend.twin.scene`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from sim.disturbances import Disturbances, base_rotation

#: A replayed run's ideal pose is drawn (the ghost) when the actual normal is further than
#: this from the sun [mrad] — 0.3°, well above the ideal controller's own residual.
GHOST_THRESHOLD_MRAD = 5.0


@dataclass(frozen=True)
class ScenePose:
    """What the scene shows at one instant (angles in degrees, ENU vectors)."""

    ts: pd.Timestamp
    solar_azimuth_deg: float
    solar_elevation_deg: float
    azimuth_joint_deg: float
    elevation_joint_deg: float
    stowed: bool
    tracker_normal_enu: NDArray[np.float64]
    tracker_aoi_deg: float
    fixed_aoi_deg: float
    ideal_azimuth_joint_deg: float = float("nan")
    ideal_elevation_joint_deg: float = float("nan")
    #: Angle between the panel normal and the sun [mrad] in a replayed run (None when live).
    pointing_error_mrad: float | None = None
    replay_run_id: str | None = None
    #: Share of the fixed array's area in the tracker collector's shadow [-] (None: no
    #: fixed array at the site).
    fixed_shaded_fraction: float | None = None

    @property
    def ghost_visible(self) -> bool:
        """Whether the ideal pose is drawn beside the actual one (they differ visibly)."""
        return (self.pointing_error_mrad is not None and not self.stowed
                and self.pointing_error_mrad > GHOST_THRESHOLD_MRAD)


@dataclass(frozen=True)
class Replay:
    """A simulation run shown in the scene: the tracker takes the run's actual joint angles
    (``sim.twin.simulate``'s series) on its disturbed base, the ghost the ideal pose."""

    run_id: str
    ts_s: NDArray[np.int64]
    azimuth_joint_deg: NDArray[np.float64]
    elevation_joint_deg: NDArray[np.float64]
    pointing_error_mrad: NDArray[np.float64]
    base_rotation: NDArray[np.float64]
    step_s: float
    site_id: str = ""
    #: The run's powers per step [W] (empty when its series has none).
    tracker_power_w: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    fixed_power_w: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def from_series(cls, run_id: str, series: pd.DataFrame, disturbances: Disturbances,
                    step_s: float, site_id: str = "") -> Replay:
        missing = [c for c in ("azimuth_joint_deg", "elevation_joint_deg",
                               "pointing_error_mrad") if c not in series.columns]
        if missing:
            raise ValueError(f"run {run_id}: its series lacks {', '.join(missing)}")
        if series.empty:
            raise ValueError(f"run {run_id}: its series is empty")

        def power(col: str) -> NDArray[np.float64]:
            return series[col].to_numpy(float) if col in series.columns else np.zeros(0)

        return cls(run_id, series.index.as_unit("s").asi8.astype(np.int64),
                   series["azimuth_joint_deg"].to_numpy(float),
                   series["elevation_joint_deg"].to_numpy(float),
                   series["pointing_error_mrad"].to_numpy(float),
                   np.asarray(base_rotation(disturbances)), float(step_s), site_id,
                   power("tracker_power_w"), power("fixed_power_w"))

    @property
    def start(self) -> pd.Timestamp:
        return pd.Timestamp(int(self.ts_s[0]), unit="s", tz="UTC")

    @property
    def end(self) -> pd.Timestamp:
        return pd.Timestamp(int(self.ts_s[-1] + self.step_s), unit="s", tz="UTC")

    def row_at(self, ts: pd.Timestamp) -> int | None:
        """The step holding ``ts`` (each sample stands for its step), or None outside."""
        t = ts.value // 1_000_000_000
        i = int(np.searchsorted(self.ts_s, t, side="right")) - 1
        return i if 0 <= i < len(self.ts_s) and t < self.ts_s[i] + self.step_s else None
