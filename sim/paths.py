"""Where heliotwin's files are: data shipped inside the packages, and the folder it writes to.

Built-in data (``sim/data/sites/``, ``sim/data/plants/``, the dashboard's files) are read
through :mod:`importlib.resources`, so an installed wheel finds them wherever it is
(``pyproject.toml`` declares them as package data). What a user writes — the SQLite file,
their own sites — goes to the checkout's ``data/`` when the code runs from a checkout
(``make run``), and otherwise to the user's data folder (XDG base directory
specification: ``$XDG_DATA_HOME/heliotwin``, default ``~/.local/share/heliotwin``).
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path


def package_dir(package: str, *parts: str) -> Path:
    """The folder ``parts`` shipped inside ``package``, as a resolved file-system path.

    Raises RuntimeError when the package is not on the file system (a zip import),
    where configs could not be globbed.
    """
    root = resources.files(package)
    if not isinstance(root, Path):
        raise RuntimeError(f"package {package!r} is not installed as files ({root!r})")
    return root.joinpath(*parts).resolve()


def checkout_root() -> Path | None:
    """The repository the code runs from, or None when it runs from an installed wheel.

    A checkout is recognised by the ``pyproject.toml`` beside the packages, which an
    install into ``site-packages`` does not have.
    """
    root = Path(__file__).resolve().parents[1]
    return root if (root / "pyproject.toml").is_file() else None


def user_data_dir() -> Path:
    """The folder heliotwin writes to by default: ``<checkout>/data`` or the user's data folder."""
    root = checkout_root()
    if root is not None:
        return root / "data"
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "heliotwin"


def default_sites_dir() -> Path:
    """The built-in sites: ``sim/data/sites/`` (package data)."""
    return package_dir("sim", "data", "sites")


def default_plants_dir() -> Path:
    """The built-in plants: ``sim/data/plants/`` (package data)."""
    return package_dir("sim", "data", "plants")


def default_user_sites_dir() -> Path:
    """``user-sites/`` in :func:`user_data_dir` (a checkout's ``data/user-sites/``): user sites
    when no folder is given, and the default of the service's ``HELIOTWIN_SITES_DIR``."""
    return user_data_dir() / "user-sites"
