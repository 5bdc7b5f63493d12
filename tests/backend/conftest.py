"""Shared fixtures: the service in this process over httpx, on SQLite and PostgreSQL.

Fixtures for other test modules (e.g. ``test_vision_api.py``):

- ``live_server`` (session scope, parametrized ``sqlite`` / ``postgresql``): the app of
  ``backend.app.create_app(settings)`` running in this process with its lifespan
  (:class:`InProcessServer`), as ``heliotwin serve --no-demo`` would run it, on a
  throw-away database (a temp SQLite file; a unique PostgreSQL schema). Yields a
  :class:`LiveServer` with ``base_url`` (a name only the fixture's clients answer),
  ``write_token`` (a write token of the site ``tehuantepec``), ``database_url``, ``env``
  (for a CLI subprocess on the same database), ``token(site_id)`` to make more tokens and
  ``client()``. The live twin loop and viser are off (``HELIOTWIN_LIVE_TWIN=false``,
  ``HELIOTWIN_VISER=false``). Tests sharing it must use their own date ranges (the
  database is shared).
- ``client`` : an ``httpx.Client`` on ``live_server`` (no token).
- ``database`` (function scope, parametrized): a fresh empty database, for tests that
  start their own services (:class:`InProcessServer`, or :class:`ServerProcess` where the
  process is the subject: SIGKILL, signals, the CLI, a real socket).

PostgreSQL (``postgresql+psycopg://postgres@127.0.0.1:5432/test``, or
``HELIOTWIN_TEST_PG_URL``) is skipped when it does not answer, and fails the run
when ``HELIOTWIN_REQUIRE_SERVICES=1``.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from live_service import (
    BACKENDS,
    Database,
    InProcessServer,
    LiveServer,
    ServerProcess,
    new_database,
)

__all__ = ["Database", "InProcessServer", "LiveServer", "ServerProcess"]


@pytest.fixture(scope="session", params=BACKENDS)
def live_server(request: pytest.FixtureRequest,
                tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """The service in this process on SQLite and on PostgreSQL (see the module docstring)."""
    tmp = tmp_path_factory.mktemp(f"server-{request.param}")
    db = new_database(request.param, tmp)
    server = InProcessServer(db.url).start()
    try:
        yield LiveServer(server.base_url, server.token(), db.url, request.param, server)
    finally:
        server.stop()
        db.drop()


@pytest.fixture
def client(live_server: LiveServer) -> Iterator[httpx.Client]:
    """An HTTP client on the live server (no token)."""
    with live_server.client() as c:
        yield c


@pytest.fixture(params=BACKENDS)
def database(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Database]:
    """A fresh empty database per test, on SQLite and on PostgreSQL."""
    db = new_database(request.param, tmp_path)
    try:
        yield db
    finally:
        db.drop()
