"""Settings (``backend/settings.py``): environment, defaults, and the README documents them all."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from backend.settings import Settings, get_settings

README = Path(__file__).resolve().parents[2] / "README.md"


def _documented() -> dict[str, str]:
    text = README.read_text()
    section = text.split("<!-- settings:start -->")[1].split("<!-- settings:end -->")[0]
    rows = re.findall(r"^\| `(HELIOTWIN_[A-Z0-9_]+)` \| (.+?) \|", section, re.M)
    return dict(rows)


def test_readme_documents_every_setting() -> None:
    documented = _documented()
    fields = {f"HELIOTWIN_{name.upper()}" for name in Settings.model_fields}
    assert not fields - set(documented), f"undocumented: {sorted(fields - set(documented))}"
    assert not set(documented) - fields, f"stale: {sorted(set(documented) - fields)}"


def test_readme_defaults_match_the_code() -> None:
    documented = _documented()
    defaults = Settings.model_construct()
    for name, field in Settings.model_fields.items():
        if field.default_factory is not None or field.default is None:
            continue
        value = getattr(defaults, name)
        shown = documented[f"HELIOTWIN_{name.upper()}"].strip("`").replace("_", "")
        expected = str(value).lower() if isinstance(value, bool) else str(value)
        if isinstance(value, Path):
            expected = "<repo>/" + str(value.relative_to(README.parent))
        assert shown == expected.replace("_", ""), name


def test_environment_overrides(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("HELIOTWIN_PORT", "9123")
    monkeypatch.setenv("HELIOTWIN_DATABASE_URL", "postgresql://me@db:5432/x")
    s = get_settings()
    assert s.port == 9123
    assert s.database_url == "postgresql+psycopg://me@db:5432/x"  # the driver we ship
    monkeypatch.setenv("HELIOTWIN_SQLITE_SYNCHRONOUS", "sometimes")
    with pytest.raises(ValueError, match="sqlite_synchronous"):
        get_settings()


def test_defaults_work_without_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    for key in list(__import__("os").environ):
        if key.startswith("HELIOTWIN_"):
            monkeypatch.delenv(key)
    s = get_settings()
    assert s.database_url.startswith("sqlite:///") and s.database_url.endswith(
        "data/heliotwin.sqlite")
    assert (s.port, s.viser_port, s.max_upload_bytes) == (8000, 8080, 10 * 1024 * 1024)
    assert s.sites_dir.is_dir()
