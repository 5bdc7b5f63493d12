"""The 3D replay never shows a pointing error where the twin defines none (issue 22.3):
at night, in stow or with the sun below the stated elevation the readout says "—"."""

from __future__ import annotations

import numpy as np
import pandas as pd
from test_twin3d import SITE, TZ, _open, scene  # noqa: F401  (the module's viser fixture)

from backend.twin.scene import TwinScene
from backend.twin.scene_pose import Replay
from backend.twin.scene_view import TwinView
from sim.disturbances import Disturbances
from sim.twin import simulate


def test_replay_at_midnight_shows_no_pointing_error(scene: TwinScene) -> None:  # noqa: F811
    d = Disturbances(pedestal_yaw_deg=2.0)
    start = pd.Timestamp("2024-03-15", tz=TZ)
    run = simulate(SITE, start, start + pd.Timedelta(days=1), step_s=300,
                   controller="open_loop_spa", disturbances=d)
    # a run stored before the rule: a number at every step, night included
    old = run.series.copy()
    old["pointing_error_mrad"] = old["pointing_error_mrad"].fillna(1955.5)
    client, view = _open(scene, "/site/tehuantepec/viewer/pe1")
    try:
        assert isinstance(view, TwinView)
        for series in (run.series, old):
            scene.load_replay(Replay.from_series("run-pe", series, d, 300.0, "tehuantepec"),
                              "pe1")
            pose = view.show_time(start)  # midnight, where a replay opens
            text = view.gui["readout"].content
            assert pose.pointing_error_mrad is None and "pointing error —" in text
            assert "1955.5" not in text and "nan" not in text and "**—**" not in text
            noon = view.show_time(pd.Timestamp("2024-03-15 12:30", tz=TZ))
            assert noon.pointing_error_mrad is not None and np.isfinite(noon.pointing_error_mrad)
            assert f"pointing error {noon.pointing_error_mrad:.1f} mrad" in (
                view.gui["readout"].content)
    finally:
        scene.replays.clear()
        client.close()
