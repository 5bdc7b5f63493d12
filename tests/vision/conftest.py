"""Shared fixtures for the vision tests: the real all-sky images beside the repository."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

REAL_SKY = Path(__file__).resolve().parents[2].parent / "shared" / "real-sky"


@pytest.fixture(scope="session")
def real_sky() -> list[dict[str, str]]:
    """Rows of ../shared/real-sky/metadata.csv with a ``path``; skips when absent."""
    meta = REAL_SKY / "metadata.csv"
    if not meta.is_file():
        pytest.skip(f"real-sky images not present at {REAL_SKY}")
    with meta.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        r["path"] = str(REAL_SKY / r["filename"])
    return rows
