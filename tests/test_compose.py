"""``docker-compose.yml``: valid for Compose, every profile, every setting listed.

Validated by ``docker compose config`` (or the older ``docker-compose config``);
skipped when neither is installed (they need no Docker daemon for this).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from backend.settings import env_fields

ROOT = Path(__file__).resolve().parents[1]
COMPOSE = ROOT / "docker-compose.yml"


def _compose() -> list[str]:
    docker = shutil.which("docker")
    if docker and subprocess.run([docker, "compose", "version"], capture_output=True
                                 ).returncode == 0:
        return [docker, "compose"]
    legacy = shutil.which("docker-compose")
    if legacy:
        return [legacy]
    pytest.skip("neither `docker compose` nor `docker-compose` is installed")


def _config(*profiles: str) -> dict:
    args = [a for p in profiles for a in ("--profile", p)]
    out = subprocess.run([*_compose(), "-f", str(COMPOSE), *args, "config"], cwd=ROOT,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return yaml.safe_load(out.stdout)


def test_compose_config_is_valid_for_every_profile() -> None:
    both = _config("postgres", "mqtt")["services"]
    assert set(both) == {"heliotwin", "heliotwin-pg", "postgres", "heliotwin-mqtt",
                         "mosquitto"}
    # `docker compose up` starts the service alone; the others come with their profile
    # (docker-compose 1.x lists every service in `config`, so read the profiles)
    profiles = {name: set(svc.get("profiles", [])) for name, svc in both.items()}
    assert profiles == {"heliotwin": set(), "heliotwin-pg": {"postgres"},
                        "postgres": {"postgres"}, "heliotwin-mqtt": {"mqtt"},
                        "mosquitto": {"mqtt"}}
    for name, svc in both.items():
        assert "healthcheck" in svc, f"{name} has no healthcheck"
    assert both["heliotwin-pg"]["environment"]["HELIOTWIN_DATABASE_URL"].startswith(
        "postgresql+psycopg://")
    assert both["heliotwin-mqtt"]["environment"]["HELIOTWIN_MQTT_URL"] == \
        "mqtt://mosquitto:1883"
    assert both["heliotwin-pg"]["depends_on"]["postgres"]["condition"] == "service_healthy"
    for name in ("heliotwin", "postgres", "mosquitto"):
        assert both[name].get("volumes"), f"{name} keeps no data on a volume"


def test_every_setting_is_listed() -> None:
    listed = set(yaml.safe_load(COMPOSE.read_text())["x-settings"])
    fields = set(env_fields())
    assert fields == listed, (sorted(fields - listed), sorted(listed - fields))


def test_each_service_frames_the_viser_port_it_publishes() -> None:
    """The dashboard frames viser at ``HELIOTWIN_VISER_PUBLIC_PORT`` on the page's host: in
    every service it is the host port published for the container's viser port (8080
    inside each; framed there, the PostgreSQL service's 3D tab showed the SQLite one's)."""
    services = yaml.safe_load(COMPOSE.read_text())["services"]
    checked = 0
    for name, svc in services.items():
        env = svc.get("environment") or {}
        inside = env.get("HELIOTWIN_VISER_PORT")
        if inside is None:
            continue
        # ADDRESS:HOST_PORT:CONTAINER_PORT, each of the first two possibly ${VAR:-default}
        published = [re.fullmatch(r"(\$\{[^}]*\}|[^:]*):(\$\{[^}]*\}|[^:]*):(\d+)", p)
                     for p in svc["ports"]]
        outside = next(m.group(2) for m in published if m and m.group(3) == inside)
        assert env["HELIOTWIN_VISER_PUBLIC_PORT"] == outside, name
        checked += 1
    assert checked == 4
