"""Settings (``backend/settings.py``): environment, defaults, and the README documents them all."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from pydantic import SecretStr

from backend.settings import Settings, env_fields, get_settings

README = Path(__file__).resolve().parents[2] / "README.md"


def _documented() -> dict[str, str]:
    text = README.read_text()
    section = text.split("<!-- settings:start -->")[1].split("<!-- settings:end -->")[0]
    rows = re.findall(r"^\| `(HELIOTWIN_[A-Z0-9_]+)` \| (.+?) \|", section, re.M)
    return dict(rows)


def test_readme_documents_every_setting() -> None:
    documented = _documented()
    fields = set(env_fields())
    assert not fields - set(documented), f"undocumented: {sorted(fields - set(documented))}"
    assert not set(documented) - fields, f"stale: {sorted(set(documented) - fields)}"


def test_readme_defaults_match_the_code() -> None:
    documented = _documented()
    for env, (_, _, field) in env_fields().items():
        if field.default_factory is not None or field.default is None:
            continue
        value = field.default
        shown = documented[env].strip("`").replace("_", "")
        expected = str(value).lower() if isinstance(value, bool) else str(value)
        assert shown == expected.replace("_", ""), env


def test_environment_overrides(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every group reads its variables under their public names, flat or not."""
    monkeypatch.setenv("HELIOTWIN_PORT", "9123")
    monkeypatch.setenv("HELIOTWIN_DATABASE_URL", "postgresql://me@db:5432/x")
    monkeypatch.setenv("HELIOTWIN_ALERTS", "false")
    monkeypatch.setenv("HELIOTWIN_ALERT_INTERVAL_S", "5")
    monkeypatch.setenv("HELIOTWIN_LIVE_TWIN", "false")
    monkeypatch.setenv("HELIOTWIN_MQTT_URL", "")
    s = get_settings()
    assert s.server.port == 9123
    assert s.database.url == "postgresql+psycopg://me@db:5432/x"  # the driver we ship
    assert (s.alerts.enabled, s.alerts.interval_s, s.twin.live) == (False, 5.0, False)
    assert s.mqtt.url is None  # an empty variable leaves an optional setting unset
    assert get_settings(port=9124, alert_interval_s=7).server.port == 9124  # flat overrides
    monkeypatch.setenv("HELIOTWIN_SQLITE_SYNCHRONOUS", "sometimes")
    with pytest.raises(ValueError, match="(?i)sqlite_synchronous"):
        get_settings()


def test_secrets_are_never_shown(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("HELIOTWIN_ADMIN_TOKEN", "adm-s3cret")
    monkeypatch.setenv("HELIOTWIN_ALERT_WEBHOOK_SECRET", "hook-s3cret")
    monkeypatch.setenv("HELIOTWIN_MQTT_URL", "mqtt://me:mqtt-s3cret@broker")
    monkeypatch.setenv("HELIOTWIN_DEMO_TOKEN", "demo-s3cret")
    s = get_settings()
    assert isinstance(s.server.admin_token, SecretStr)
    assert s.server.admin_token.get_secret_value() == "adm-s3cret"
    assert "s3cret" not in repr(s) and "s3cret" not in str(s.model_dump())
    monkeypatch.setenv("HELIOTWIN_ALERT_WEBHOOK_URL", "ftp://user:hook-s3cret@host/x")
    with pytest.raises(ValueError) as err:
        get_settings()
    assert "s3cret" not in str(err.value)


def test_defaults_work_without_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    for key in list(__import__("os").environ):
        if key.startswith("HELIOTWIN_"):
            monkeypatch.delenv(key)
    s = get_settings()
    assert s.database.url.startswith("sqlite:///") and s.database.url.endswith(
        "data/heliotwin.sqlite")
    assert (s.server.port, s.server.viser_port, s.server.max_upload_bytes) == (
        8000, 8080, 10 * 1024 * 1024)
    assert s.sites.user_dir.is_dir()
    assert isinstance(Settings(), Settings)
