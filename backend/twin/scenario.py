"""A twin scenario: what ``heliotwin simulate`` and ``POST /api/v1/simulations`` both run.

One table (:data:`backend.twin.parameters.MACHINE_PARAMETERS`) declares the
machine's parameters beyond site, range and step — the controller's
disturbances and the receiver — with their units, defaults and bounds; the CLI
builds its flags from it and the HTTP schema its fields, so the two never
drift apart. :func:`run_scenario` is the one call into ``sim.twin.simulate``.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import pandas as pd

from backend.twin.parameters import DISTURBANCE_NAMES, MACHINE_PARAMETERS, RUN_PARAMETERS
from sim.control import ControlSettings
from sim.disturbances import Disturbances
from sim.sites import Site
from sim.twin import CONTROLLERS, RECEIVERS, TwinResult, simulate


@dataclass(frozen=True)
class Scenario:
    """A validated twin scenario."""

    site_id: str
    start: pd.Timestamp
    end: pd.Timestamp
    step_s: float = 60.0
    controller: str = "ideal"
    receiver: str = "flat"
    machine: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.controller not in CONTROLLERS:
            raise ValueError(f"controller: {self.controller!r} is not one of "
                             f"{', '.join(CONTROLLERS)}")
        if self.receiver not in RECEIVERS:
            raise ValueError(f"receiver: {self.receiver!r} is not one of {', '.join(RECEIVERS)}")
        known = {p.name: p for p in MACHINE_PARAMETERS}
        for name, value in self.machine.items():
            p = known.get(name)
            if p is None:
                raise ValueError(f"{name}: not a machine parameter")
            if (p.minimum is not None and value < p.minimum) or (
                    p.maximum is not None and value > p.maximum):
                raise ValueError(f"{name}: {value} is outside [{p.minimum}, {p.maximum}]")

    def disturbances(self) -> Disturbances:
        return disturbances_of(self.machine)

    def to_dict(self) -> dict[str, Any]:
        return {"site_id": self.site_id, "start": self.start.isoformat(),
                "end": self.end.isoformat(), "step_s": self.step_s,
                "controller": self.controller, "receiver": self.receiver, **self.machine}

    def to_json(self) -> str:
        return json.dumps(self.to_dict())


def run_scenario(site: Site, scenario: Scenario, weather: pd.DataFrame | None = None,
                 progress: Callable[[float], None] | None = None) -> TwinResult:
    """``sim.twin.simulate`` for ``scenario`` (the one call the CLI and the API share)."""
    defaults = {p.name: p.default for p in MACHINE_PARAMETERS}
    run = {k: scenario.machine.get(k, defaults[k]) for k in RUN_PARAMETERS}
    return simulate(
        site, scenario.start, scenario.end, step_s=scenario.step_s,
        controller=scenario.controller, weather=weather, progress=progress,
        disturbances=scenario.disturbances(), receiver=scenario.receiver,
        acceptance_angle_deg=run["acceptance_angle_deg"],
        spot_distance_m=run["spot_distance_m"],
        settings=ControlSettings(chronological_interval_min=run["chronological_interval_min"]),
    )


def disturbances_of(params: dict[str, Any]) -> Disturbances:
    """The disturbances of a stored run's parameters (:meth:`Scenario.to_dict`)."""
    values: dict[str, Any] = {k: float(params[k]) for k in DISTURBANCE_NAMES if k in params}
    return Disturbances(**values)
