"""Helpers of the backend tests: throw-away databases and ``heliotwin serve`` subprocesses.

Imported by ``conftest.py`` (fixtures) and by tests that start their own servers.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import pytest

ROOT = Path(__file__).resolve().parents[2]
HELIOTWIN = [sys.executable, "-m", "backend"]
PG_URL = os.environ.get("HELIOTWIN_TEST_PG_URL",
                        "postgresql+psycopg://postgres@127.0.0.1:5432/test")
REQUIRE_SERVICES = os.environ.get("HELIOTWIN_REQUIRE_SERVICES") == "1"
BACKENDS = ["sqlite", "postgresql"]


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _pg_available() -> str | None:
    """None when PostgreSQL answers, else why not."""
    try:
        import psycopg

        with psycopg.connect(PG_URL.replace("+psycopg", ""), connect_timeout=3):
            return None
    except Exception as exc:  # noqa: BLE001 - any failure means "not available"
        return f"PostgreSQL at {PG_URL} not available: {exc}"


def need_postgres() -> None:
    """Skip (or fail under HELIOTWIN_REQUIRE_SERVICES=1) when PostgreSQL is absent."""
    why = _pg_available()
    if why is None:
        return
    if REQUIRE_SERVICES:
        pytest.fail(why + " (HELIOTWIN_REQUIRE_SERVICES=1)")
    pytest.skip(why)


@dataclass
class Database:
    """A throw-away database: its URL and how to drop it."""

    url: str
    schema: str | None = None

    def drop(self) -> None:
        if self.schema is None:
            return
        import psycopg

        with psycopg.connect(PG_URL.replace("+psycopg", ""), autocommit=True) as conn:
            conn.execute(f'DROP SCHEMA IF EXISTS "{self.schema}" CASCADE')


def new_database(backend: str, tmp_dir: Path) -> Database:
    """A fresh SQLite file, or a fresh PostgreSQL schema on the search path."""
    if backend == "sqlite":
        return Database(f"sqlite:///{tmp_dir / f'heliotwin-{uuid.uuid4().hex[:8]}.sqlite'}")
    need_postgres()
    import psycopg

    schema = f"ht_test_{uuid.uuid4().hex[:10]}"
    with psycopg.connect(PG_URL.replace("+psycopg", ""), autocommit=True) as conn:
        conn.execute(f'CREATE SCHEMA "{schema}"')
    sep = "&" if "?" in PG_URL else "?"
    return Database(f"{PG_URL}{sep}options=-csearch_path%3D{schema}", schema)


@dataclass
class ServerProcess:
    """A ``heliotwin serve`` subprocess on free ports."""

    database_url: str
    log_path: Path
    extra_env: dict[str, str] = field(default_factory=dict)
    demo: bool = False
    viser_port: int = 0  # 0: a free one
    port: int = 0
    proc: subprocess.Popen[bytes] | None = None

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def env(self) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if not k.startswith("HELIOTWIN_")}
        env.update({
            "HELIOTWIN_DATABASE_URL": self.database_url,
            "HELIOTWIN_VISER": "false",
            "HELIOTWIN_LIVE_TWIN": "false",
            "PYTHONUNBUFFERED": "1",
        })
        env.update(self.extra_env)
        return env

    def start(self, timeout_s: float = 60.0) -> ServerProcess:
        """Start and wait for ``/healthz``."""
        self.port = free_port()
        log = self.log_path.open("ab")
        self.proc = subprocess.Popen(
            [*HELIOTWIN, "serve", "--host", "127.0.0.1", "--port", str(self.port),
             "--viser-port", str(self.viser_port or free_port()),
             *([] if self.demo else ["--no-demo"])],
            cwd=ROOT, env=self.env, stdout=log, stderr=subprocess.STDOUT,
        )
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server exited at start:\n{self.log_tail()}")
            try:
                if httpx.get(self.base_url + "/healthz", timeout=1.0).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            time.sleep(0.1)
        self.kill()
        raise RuntimeError(f"server did not answer /healthz in {timeout_s} s:\n{self.log_tail()}")

    def log_tail(self, lines: int = 30) -> str:
        return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])

    def stop(self, timeout_s: float = 20.0) -> int | None:
        """SIGTERM (graceful), then wait; SIGKILL if it hangs."""
        if self.proc is None or self.proc.poll() is not None:
            return None if self.proc is None else self.proc.returncode
        self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.kill()
            return None

    def kill(self) -> None:
        """SIGKILL: no shutdown code runs."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(10)

    def token(self, site_id: str = "tehuantepec") -> str:
        """A new write token from ``heliotwin token create`` (its last word)."""
        out = subprocess.run([*HELIOTWIN, "token", "create", "--site", site_id], cwd=ROOT,
                             env=self.env, capture_output=True, text=True, timeout=60,
                             check=True)
        return out.stdout.strip().split()[-1]


@dataclass
class LiveServer:
    """What ``live_server`` yields."""

    base_url: str
    write_token: str
    database_url: str
    backend: str
    process: ServerProcess

    @property
    def env(self) -> dict[str, str]:
        return self.process.env

    def token(self, site_id: str = "tehuantepec") -> str:
        return self.process.token(site_id)
