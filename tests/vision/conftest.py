"""Shared fixtures for the vision tests: the real all-sky frames shipped in tests/data/real-sky."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

REAL_SKY = Path(__file__).resolve().parents[1] / "data" / "real-sky"


def read_real_sky() -> list[dict[str, str]]:
    """Rows of ``metadata.csv`` joined with ``split.csv``, each with its ``path``."""
    with (REAL_SKY / "metadata.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    with (REAL_SKY / "split.csv").open(newline="") as fh:
        split = {r["filename"]: r for r in csv.DictReader(fh)}
    for r in rows:
        r["path"] = str(REAL_SKY / r["filename"])
        r["split"] = split[r["filename"]]["split"]
        r["sun_visible"] = split[r["filename"]]["sun_visible"]
        r["camera"] = split[r["filename"]]["camera"]
    return rows


@pytest.fixture(scope="session")
def real_sky() -> list[dict[str, str]]:
    """The real frames of five cameras (never skipped: they are part of the repository)."""
    return read_real_sky()
