"""Config files by id: ``<directory>/<id>.json`` for sites (``sim/data/sites``) and plants
(``sim/data/plants``) — one rule for what an id may be, what an unknown one says, and how a
file that is not JSON is reported."""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

CONFIG_ID = re.compile(r"^[a-z0-9][a-z0-9_-]{0,63}$")
"""Ids are lower-case file stems: no path can be smuggled in through one."""


def read_config(kind: str, config_id: str, directory: Path | Sequence[Path],
                unknown: type[ValueError]) -> tuple[Path, dict[str, Any]]:
    """The parsed JSON of ``<directory>/<config_id>.json`` and its path.

    ``directory`` may be a list of folders: the first that holds the file wins.
    Raises ``unknown`` (listing the known ids) when there is no such file, and
    ValueError naming the file when it is not valid JSON.
    """
    folders = [directory] if isinstance(directory, Path) else list(directory)
    # the id is checked before any path is made of it: a 300-character id was a 500 (the
    # file system's "name too long"), a NUL one "its file is invalid"
    found = [d / f"{config_id}.json" for d in folders
             if CONFIG_ID.match(config_id) and (d / f"{config_id}.json").is_file()]
    if not found:
        ids = sorted({p.stem for d in folders if d.is_dir() for p in d.glob("*.json")})
        raise unknown(f"unknown {kind} {config_id!r}; known {kind}s: {', '.join(ids) or 'none'}")
    path = found[0]
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: must hold a JSON object")
    return path, data
