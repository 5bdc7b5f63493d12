"""The machine parameters of a twin scenario, declared once (no heavy imports: the CLI
builds its flags from this table at start-up, the HTTP schema its fields)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Parameter:
    """One machine parameter: its name (units in it), default, bounds and help."""

    name: str
    default: float
    help: str
    minimum: float | None = None
    maximum: float | None = None


#: The disturbances (``sim.disturbances.Disturbances``, same names) and the receiver's
#: acceptance angle; defaults are a perfect machine.
MACHINE_PARAMETERS: tuple[Parameter, ...] = (
    Parameter("pedestal_yaw_deg", 0.0, "azimuth misalignment of the pedestal [deg]",
              -180.0, 180.0),
    Parameter("elevation_zero_deg", 0.0, "elevation encoder's zero: real joint = encoder + "
              "this [deg]", -30.0, 30.0),
    Parameter("pedestal_tilt_deg", 0.0, "tilt of the pedestal axis from vertical [deg]",
              0.0, 45.0),
    Parameter("pedestal_tilt_azimuth_deg", 0.0, "azimuth the pedestal leans to [deg]",
              -360.0, 360.0),
    Parameter("encoder_drift_mrad_per_h", 0.0, "joint-reading drift, both axes [mrad/h]",
              -1000.0, 1000.0),
    Parameter("clock_offset_s", 0.0, "controller clock minus true time [s]",
              -86400.0, 86400.0),
    Parameter("backlash_deg", 0.0, "gear backlash per axis [deg]", 0.0, 10.0),
    # an 80 m² collector with an 8 m chord takes 3-7.5 kN m at 8 m/s and 19-47 kN m at 20 m/s
    # (½ρv²·A·1.2·(0.1-0.25 chord), docs/control.md); 1,000 N m had refused them
    Parameter("gust_torque_nm", 0.0, "wind-gust torque amplitude per axis [N m]", 0.0, 1e6),
    Parameter("camera_offset_right_deg", 0.0, "camera boresight right of the normal [deg]",
              -30.0, 30.0),
    Parameter("camera_offset_up_deg", 0.0, "camera boresight above the normal [deg]",
              -30.0, 30.0),
    Parameter("acceptance_angle_deg", 0.5, "CPV receiver's acceptance half-angle [deg]",
              0.01, 10.0),
    Parameter("spot_distance_m", 1.5, "lens-to-receiver distance for the spot shift [m]",
              0.01, 100.0),
    Parameter("chronological_interval_min", 30.0, "chronological controller's period [min]",
              1.0, 240.0),
)
#: Parameters that are not disturbances: they go to simulate() or to ControlSettings.
RUN_PARAMETERS = ("acceptance_angle_deg", "spot_distance_m", "chronological_interval_min")
DISTURBANCE_NAMES = tuple(p.name for p in MACHINE_PARAMETERS if p.name not in RUN_PARAMETERS)
