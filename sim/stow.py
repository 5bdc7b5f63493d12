"""Wind stow: the tracker lies flat while the wind is too strong, as real dual-axis trackers do.

A dual-axis tracker's controller reads an anemometer and, when the wind passes a threshold,
drives the panel to its stow pose: horizontal, facing the zenith, so that the wind meets
only its edge; it returns to tracking once the wind has calmed (Solaflect, "What happens to
the Tracker when it is windy?", solaflect.com FAQ: "the Tracker will 'stow' in a horizontal
orientation … the panels are facing straight upward … once the wind has calmed, the Tracker
automatically returns"). Controllers hold a stow for a while before returning, so that a
lull between gusts does not set the tracker moving (PlantPredict's wind stow, "stow dwell
time": the minimum time the wind must stay at or below the threshold before tracking
resumes, docs.plantpredict.com/models/tracking/wind_stow; the OVRO 40 m telescope's
``hold_time``). This module holds that rule; :func:`sim.twin.simulate` poses the tracker
flat in the stowed steps (the night stow's pose, :func:`sim.kinematics.tracking_angles`:
elevation joint at ``elevation_max_deg``) and reports the minutes and the energy lost;
:func:`sim.plant.simulate.simulate_plant` lays every tracker of a plant flat alike.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Hold [min] after the last over-threshold wind before the tracker tracks again when a site
#: does not say: an assumption (manufacturers set it per site; PlantPredict leaves it to
#: the user). Half an hour outlasts the gusts of one squall.
STOW_RELEASE_MIN = 30.0
#: The bounds a site's or a plant's file may give [m s⁻¹], [min]: a threshold above 0 and at
#: most 100 m s⁻¹ (no anemometer reading beyond stands), a hold of at most a day
STOW_WIND_MAX_M_S = 100.0
STOW_RELEASE_MAX_MIN = 1440.0


@dataclass(frozen=True)
class WindStow:
    """A tracker's wind stow (site config ``tracker.stow_wind_speed_m_s``/``stow_release_min``).

    Parameters
    ----------
    wind_speed_m_s : float
        The tracker stows when the weather's wind speed exceeds this [m s⁻¹] (the weather's
        ``wind_speed`` as the file gives it: a mean, or a gust where that is what it holds).
    release_min : float
        It returns to tracking once the wind has stayed at or below the threshold this
        long [min].
    """

    wind_speed_m_s: float
    release_min: float = STOW_RELEASE_MIN

    def __post_init__(self) -> None:
        if not self.wind_speed_m_s > 0:
            raise ValueError(f"stow_wind_speed_m_s must be > 0, got {self.wind_speed_m_s}")
        if not self.release_min >= 0:
            raise ValueError(f"stow_release_min must be >= 0, got {self.release_min}")

    def stowed(self, times_s: np.ndarray, wind_speed: np.ndarray) -> np.ndarray:
        """Whether the tracker is stowed at each sample (bool array).

        Stowed at a sample whose ``wind_speed`` [m s⁻¹] exceeds the threshold, and at every
        sample less than ``release_min`` after the last such one (``times_s`` [s],
        ascending): the hysteresis of a controller that holds its stow until the wind has
        stayed calm that long. Before the first sample the tracker is taken as tracking.
        """
        t = np.asarray(times_s, dtype=float)
        over = np.asarray(wind_speed, dtype=float) > self.wind_speed_m_s
        last_over_s = np.maximum.accumulate(np.where(over, t, -np.inf))
        return over | (t - last_over_s < self.release_min * 60.0)


def daylight_minutes(stowed: np.ndarray, daylight: np.ndarray, step_s: float,
                     duration_s: float) -> int:
    """Daylight minutes stowed over a run's steps (the twin's and the plant's ``stow_min``):
    each step stowed with the sun up (``stowed``, ``daylight``: bool per step, the run's
    steps only, not its closing instant) counts ``step_s`` [s], the last one only up to the
    run's end (``duration_s`` [s]: a step that does not divide the range)."""
    n = len(stowed)
    step_cut_s = np.full(n, float(step_s))
    if n:
        step_cut_s[-1] = float(duration_s) - (n - 1) * float(step_s)
    return int(round(float(step_cut_s[np.asarray(stowed) & np.asarray(daylight)].sum()) / 60.0))
