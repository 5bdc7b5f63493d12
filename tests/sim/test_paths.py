"""``sim/paths.py``: built-in data inside the packages, user files in the checkout or elsewhere."""

from __future__ import annotations

from pathlib import Path

import pytest

from sim import paths

ROOT = Path(__file__).resolve().parents[2]


def test_built_in_configs_are_package_data_of_sim() -> None:
    assert paths.default_sites_dir() == ROOT / "sim" / "data" / "sites"
    assert (paths.default_sites_dir() / "tehuantepec.json").is_file()
    assert (paths.default_plants_dir() / "penarroya.json").is_file()


def test_a_checkout_writes_to_its_data_folder() -> None:
    assert paths.checkout_root() == ROOT
    assert paths.user_data_dir() == ROOT / "data"
    assert paths.default_user_sites_dir() == ROOT / "data" / "user-sites"


def test_an_install_writes_to_the_xdg_data_folder(monkeypatch: pytest.MonkeyPatch,
                                                  tmp_path: Path) -> None:
    monkeypatch.setattr(paths, "checkout_root", lambda: None)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert paths.user_data_dir() == tmp_path / "xdg" / "heliotwin"
    monkeypatch.delenv("XDG_DATA_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert paths.default_user_sites_dir() == tmp_path / "home" / ".local" / "share" / \
        "heliotwin" / "user-sites"
