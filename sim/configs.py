"""Config files by id: ``<directory>/<id>.json`` for sites (``data/sites``) and plants
(``data/plants``) — one rule for what an id may be, what an unknown one says, and how a
file that is not JSON is reported."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

CONFIG_ID = re.compile(r"^[a-z0-9][a-z0-9_-]{0,63}$")
"""Ids are lower-case file stems: no path can be smuggled in through one."""


def read_config(kind: str, config_id: str, directory: Path,
                unknown: type[ValueError]) -> tuple[Path, dict[str, Any]]:
    """The parsed JSON of ``<directory>/<config_id>.json`` and its path.

    Raises ``unknown`` (listing the known ids) when there is no such file, and
    ValueError naming the file when it is not valid JSON.
    """
    path = directory / f"{config_id}.json"
    if not CONFIG_ID.match(config_id) or not path.is_file():
        known = ", ".join(p.stem for p in sorted(directory.glob("*.json"))) or "none"
        raise unknown(f"unknown {kind} {config_id!r}; known {kind}s: {known}")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: must hold a JSON object")
    return path, data
