"""A hidden low sun's glare refused for another reason still reports a confidence; where the
disc is behind the obstacle that confidence is none (issue 24: no sun with confidence ≥ 0.3
where none is visible). The frame: the independent low-sun renderer's development cut frame
7005 (``benchmarks/lowsun_set.py render … --n 24 --seed 7000 --cut``; equidistant lens, 1536
px, the sun 4.5° high, its disc 2.4° under the skyline)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

from vision.detect import detect_sun

_LOWSUN = Path(__file__).resolve().parents[2] / "benchmarks" / "lowsun_set.py"


def _lowsun_set():
    spec = importlib.util.spec_from_file_location("lowsun_set", _LOWSUN)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_a_refused_glare_whose_disc_is_behind_the_skyline_has_no_confidence() -> None:
    """Refused as "not radially symmetric" at 0.46 before (a confidence ≥ 0.3 for a sun
    nobody can see); the centre of the refused glare is found as for a found one, the disc
    there is darker than the sky (``vision.detect._disc_behind_obstacle``): 0.0, and the
    reason says so."""
    ls = _lowsun_set()
    spec = ls.specs(6, 7000, True)[5]
    img, truth = ls.render(spec)
    assert truth["hidden"] and not truth["visible"]
    d = detect_sun(img)
    assert not d.sun_found and d.confidence < 0.3, (d.confidence, d.reason)
    assert "behind the obstacle" in str(d.reason)
    assert d.centroid_px is None and d.radius_px == 0.0
