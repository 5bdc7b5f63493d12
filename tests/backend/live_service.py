"""Helpers of the backend tests: throw-away databases, the service in this process, and
``heliotwin serve`` subprocesses.

- :class:`InProcessServer`: ``backend.app.create_app(settings)`` in the test process, its
  lifespan running on an event loop of its own thread, requests through httpx's
  ``ASGITransport`` (no socket), tokens made by ``backend.auth`` through the service's
  writer. For the HTTP contract: starting it costs the migrations and the sites, not an
  interpreter, and a token costs one insert instead of a CLI process.
- :class:`ServerProcess`: a ``heliotwin serve`` subprocess on free ports, for the tests
  whose subject is the process (SIGKILL, signals, the CLI, real sockets, the browser).

Both read the same settings: the ``HELIOTWIN_*`` variables of :func:`service_env`
(viser and the live twin loop off, the test's own variables on top); nothing else of the
test run's environment reaches them.

Imported by ``conftest.py`` (fixtures) and by tests that start their own servers.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar
from unittest import mock

import httpx
import pytest

if TYPE_CHECKING:
    from sqlalchemy import Connection

    from backend.context import ServiceContext
    from backend.settings import Settings

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


@contextlib.contextmanager
def service_context(backend: str, tmp_dir: Path, **settings: object
                    ) -> Iterator[ServiceContext]:
    """The service's parts without HTTP (``backend.context.open_context``: the writer, the
    built-in sites) on a new database of their own (:func:`new_database`), with
    ``settings`` on top; closed and dropped after."""
    from backend.context import open_context
    from backend.settings import get_settings

    db = new_database(backend, tmp_dir)
    ctx = open_context(get_settings(database_url=db.url, sites_dir=get_settings().sites.user_dir,
                                    **settings))
    try:
        yield ctx
    finally:
        ctx.close()
        db.drop()


def service_env(database_url: str, extra_env: Mapping[str, str] | None = None) -> dict[str, str]:
    """The ``HELIOTWIN_*`` settings of a test service: its database, viser and the live
    twin loop off (tests that want them turn them on in ``extra_env``)."""
    return {"HELIOTWIN_DATABASE_URL": database_url, "HELIOTWIN_VISER": "false",
            "HELIOTWIN_LIVE_TWIN": "false", **(extra_env or {})}


def process_env(database_url: str, extra_env: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment of a subprocess on that database (``heliotwin serve``, a CLI
    command): this run's environment without its ``HELIOTWIN_*`` variables, plus
    :func:`service_env`."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("HELIOTWIN_")}
    return {**env, "PYTHONUNBUFFERED": "1", **service_env(database_url, extra_env)}


def settings_from_env(env: Mapping[str, str]) -> Settings:
    """``backend.settings.get_settings()`` as a process started with ``env`` would read it
    (no other ``HELIOTWIN_*`` variable of this run), so a test names its settings as a
    user would: by their environment variables."""
    from backend.settings import get_settings

    with mock.patch.dict(os.environ):
        for name in [k for k in os.environ if k.startswith("HELIOTWIN_")]:
            del os.environ[name]
        os.environ.update(env)
        return get_settings()


@contextlib.contextmanager
def upgraded_from(database_url: str, revision: str,
                  rows: Callable[[Connection], None]) -> Iterator[Connection]:
    """A database migrated to ``revision`` with ``rows(conn)`` written as that revision's
    schema has them, then upgraded to the heads: the connection after the upgrade (its
    transaction), for a test of what a migration keeps."""
    from alembic import command

    from backend.settings import get_settings
    from backend.storage.engine import alembic_config, make_engine

    engine = make_engine(get_settings(database_url=database_url))
    cfg = alembic_config(engine)
    try:
        with engine.begin() as conn:
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, revision)
            rows(conn)
        with engine.begin() as conn:
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "heads")
            yield conn
    finally:
        engine.dispose()


#: a site ``s`` as the ``sites`` table stores one from revision 0005 on
OLD_SITE_SQL = ("INSERT INTO sites (site_id, name, latitude_deg, longitude_deg, altitude_m, "
                "timezone, bucket_phase_s, config_json, updated_at) "
                "VALUES ('s', 's', 0, 0, 0, 'UTC', 0, '{}', '2026-01-01')")


def make_token(database_url: str, site_id: str = "tehuantepec", label: str = "tests") -> str:
    """A new write token of ``site_id`` stored in that database by ``backend.auth``, as
    ``heliotwin token create`` would (migrated first, the built-in sites loaded)."""
    from backend.auth import create_token
    from backend.sites import Registry, sync_sites
    from backend.storage.engine import make_engine, run_migrations

    settings = settings_from_env(service_env(database_url))
    engine = make_engine(settings)
    try:
        run_migrations(engine)
        registry = Registry.load_files(settings.sites.user_dir)
        # BEGIN IMMEDIATE, as the CLI's (backend/cli/db.py): a deferred transaction that
        # reads, then writes beside a running server's writer is refused at once ("database
        # is locked", whatever the busy timeout: a fresh clone's e2e run)
        with engine.connect().execution_options(sqlite_immediate=True) as conn, conn.begin():
            sync_sites(conn, [info.site for info in registry.sites.values()])
            return create_token(conn, site_id, label)
    finally:
        engine.dispose()


class _Lifespan:
    """The ASGI lifespan protocol of one app, driven as a server drives it."""

    def __init__(self, app: Any) -> None:
        self.app = app
        self._task: asyncio.Task[None] | None = None

    async def startup(self) -> None:
        self._receive: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self._send: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        scope = {"type": "lifespan", "asgi": {"version": "3.0", "spec_version": "2.0"},
                 "state": {}}
        self._task = asyncio.create_task(self.app(scope, self._receive.get, self._send.put))
        await self._receive.put({"type": "lifespan.startup"})
        await self._expect("lifespan.startup.complete")

    async def shutdown(self) -> None:
        await self._receive.put({"type": "lifespan.shutdown"})
        await self._expect("lifespan.shutdown.complete")
        assert self._task is not None
        await self._task

    async def _expect(self, want: str) -> None:
        assert self._task is not None
        message = asyncio.ensure_future(self._send.get())
        await asyncio.wait({message, self._task}, return_when=asyncio.FIRST_COMPLETED)
        if not message.done():  # the app returned or raised instead of answering
            message.cancel()
            self._task.result()
            raise RuntimeError(f"the lifespan ended without {want}")
        got = message.result()
        if got["type"] != want:
            raise RuntimeError(f"{got['type']}: {got.get('message', '')}")


class _ASGIBridge(httpx.BaseTransport):
    """A synchronous httpx transport onto ``httpx.ASGITransport`` run on the service's
    event loop: a test's plain ``httpx.Client`` calls the app in this process. The request
    body is read first (a generator body stays chunked: no Content-Length is added); the
    response comes back whole, still encoded (the client decodes gzip as over a socket).
    An exception in the app is a 500, as a server answers it; the client's read timeout
    bounds the wait."""

    def __init__(self, app: Any, loop: asyncio.AbstractEventLoop,
                 client_host: str = "127.0.0.1") -> None:
        self._asgi = httpx.ASGITransport(app=app, raise_app_exceptions=False,
                                         client=(client_host, 123))
        self._loop = loop

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        body = request.read()
        forwarded = httpx.Request(request.method, request.url, headers=request.headers,
                                  stream=httpx.ByteStream(body))

        async def send() -> tuple[int, httpx.Headers, bytes]:
            response = await self._asgi.handle_async_request(forwarded)
            raw = b"".join([part async for part in response.stream])  # type: ignore[union-attr]
            return response.status_code, response.headers, raw

        future = asyncio.run_coroutine_threadsafe(send(), self._loop)
        timeout_s = request.extensions.get("timeout", {}).get("read")
        try:
            status, headers, raw = future.result(timeout_s)
        except concurrent.futures.TimeoutError as exc:
            future.cancel()
            raise httpx.ReadTimeout(f"no answer in {timeout_s} s", request=request) from exc
        return httpx.Response(status, headers=headers, stream=httpx.ByteStream(raw),
                              request=request)


@dataclass
class InProcessServer:
    """``backend.app.create_app(settings)`` in this process (see the module docstring).

    The settings are those of ``heliotwin serve --no-demo`` started with
    :func:`service_env` (``extra_env`` on top). :meth:`client` gives an ``httpx.Client``
    on it with ``base_url`` :attr:`base_url`; no socket is opened, so the host is a name
    nothing answers at (a request that misses the client fails instead of reaching a
    stranger's server).
    """

    database_url: str
    extra_env: dict[str, str] = field(default_factory=dict)
    base_url: ClassVar[str] = "http://testserver"
    app: Any = field(default=None, init=False)
    _loop: asyncio.AbstractEventLoop | None = field(default=None, init=False, repr=False)
    _thread: threading.Thread | None = field(default=None, init=False, repr=False)
    _lifespan: _Lifespan | None = field(default=None, init=False, repr=False)

    @property
    def env(self) -> dict[str, str]:
        """The environment of a CLI subprocess on the same database."""
        return process_env(self.database_url, self.extra_env)

    @property
    def settings(self) -> Settings:
        return self.app.state.settings

    @property
    def ctx(self) -> ServiceContext:
        """The running service's ``backend.context.ServiceContext``."""
        return self.app.state.ctx

    def start(self, timeout_s: float = 120.0) -> InProcessServer:
        """Build the app and run its lifespan's startup (migrations, sites, the writer…)."""
        from backend.app import create_app

        env = {"HELIOTWIN_DEMO_LOGGER": "false",
               **service_env(self.database_url, self.extra_env)}
        self.app = create_app(settings_from_env(env))
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, daemon=True,
                                        name="in-process-service")
        self._thread.start()
        self._lifespan = _Lifespan(self.app)
        try:
            self._run(self._lifespan.startup(), timeout_s)
        except BaseException:
            self._close_loop()
            raise
        return self

    def stop(self, timeout_s: float = 120.0) -> None:
        """Run the lifespan's shutdown (everything acknowledged committed) and end the loop."""
        if self._lifespan is None:
            return
        lifespan, self._lifespan = self._lifespan, None
        try:
            self._run(lifespan.shutdown(), timeout_s)
        finally:
            self._close_loop()

    def client(self, timeout_s: float = 60.0, client_host: str = "127.0.0.1",
               **kwargs: Any) -> httpx.Client:
        """An ``httpx.Client`` on the app (close it, or use it in a ``with``), calling from
        ``client_host`` (the address anonymous work is counted by)."""
        assert self._loop is not None, "start() first"
        return httpx.Client(transport=_ASGIBridge(self.app, self._loop, client_host),
                            base_url=self.base_url, timeout=timeout_s, **kwargs)

    def token(self, site_id: str = "tehuantepec", label: str = "tests",
              scope: str = "ingest") -> str:
        """A new token of ``site_id`` and ``scope``, stored through the service's writer."""
        from backend.auth import create_token

        future = self.ctx.writer.call(
            lambda conn: create_token(conn, site_id, label, scope=scope))
        return str(future.result(60))

    def __enter__(self) -> InProcessServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self, coro: Any, timeout_s: float) -> Any:
        assert self._loop is not None
        return asyncio.run_coroutine_threadsafe(coro, self._loop).result(timeout_s)

    def _close_loop(self) -> None:
        loop, thread = self._loop, self._thread
        if loop is None or thread is None:
            return
        loop.call_soon_threadsafe(loop.stop)
        thread.join(30)
        loop.close()
        self._loop = self._thread = None


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
    args: tuple[str, ...] = ()  # more flags of ``heliotwin serve``

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def env(self) -> dict[str, str]:
        return process_env(self.database_url, self.extra_env)

    def start(self, timeout_s: float = 120.0, attempts: int = 3) -> ServerProcess:
        """Start and wait for ``/healthz``; again on new ports (``attempts`` in all) when a
        port found free was taken before the server bound it (another test's process got
        it from the kernel first: the Dask sweep tests hung on such a race)."""
        attempt = 1
        while True:
            try:
                return self._start_once(timeout_s)
            except RuntimeError as exc:
                if attempt >= attempts or "address already in use" not in str(exc).lower():
                    raise
                attempt += 1

    def _start_once(self, timeout_s: float) -> ServerProcess:
        """One start; its failure names this attempt's log lines only (an earlier attempt's
        "address already in use" must not make a later failure look like one)."""
        self.port = free_port()
        since = self.log_path.stat().st_size if self.log_path.exists() else 0
        log = self.log_path.open("ab")
        self.proc = subprocess.Popen(
            [*HELIOTWIN, "serve", "--host", "127.0.0.1", "--port", str(self.port),
             "--viser-port", str(self.viser_port or free_port()),
             *([] if self.demo else ["--no-demo"]), *self.args],
            cwd=ROOT, env=self.env, stdout=log, stderr=subprocess.STDOUT,
        )
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server exited at start:\n{self.log_tail(since=since)}")
            try:
                if httpx.get(self.base_url + "/healthz", timeout=1.0).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            time.sleep(0.1)
        self.kill()
        raise RuntimeError(f"server did not answer /healthz in {timeout_s} s:\n"
                           f"{self.log_tail(since=since)}")

    def log_tail(self, lines: int = 30, since: int = 0) -> str:
        """The log's last ``lines`` lines, of its bytes from ``since`` on."""
        with self.log_path.open("rb") as fh:
            fh.seek(since)
            text = fh.read().decode(errors="replace")
        return "\n".join(text.splitlines()[-lines:])

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
        """A new write token, stored in the server's database by ``backend.auth``."""
        return make_token(self.database_url, site_id)


@dataclass
class LiveServer:
    """What ``live_server`` yields: the service in this process (:class:`InProcessServer`)
    and what the tests need to know about it."""

    base_url: str
    write_token: str
    database_url: str
    backend: str
    process: InProcessServer

    @property
    def env(self) -> dict[str, str]:
        """The environment of a CLI subprocess on the same database."""
        return self.process.env

    def token(self, site_id: str = "tehuantepec", scope: str = "ingest") -> str:
        return self.process.token(site_id, scope=scope)

    def client(self, timeout_s: float = 60.0, **kwargs: Any) -> httpx.Client:
        return self.process.client(timeout_s, **kwargs)


def run_in_own_thread(coro: Any) -> Any:
    """``asyncio.run(coro)`` on a thread of its own: on an xdist worker that ran a browser
    test first, sync Playwright (session-scoped) keeps an event loop running on the main
    thread, where ``asyncio.run`` refuses to start."""
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        return pool.submit(asyncio.run, coro).result()


def tehuantepec_elsewhere(client: httpx.Client, site_id: str, **place: object) -> dict:
    """What the Sites page sends for "New site from the selected one" with Tehuantepec
    selected: its config with a new id and ``place``, without the keys the place decides
    (frontend/js/sites.js)."""
    config = client.get("/api/v1/sites/tehuantepec/config").json()
    for key in ("temp_air_c", "wind_speed_m_s", "assumed"):
        config.pop(key, None)
    for arr in config["arrays"].values():
        if arr["mount"] == "fixed":
            arr.pop("surface_tilt_deg"), arr.pop("surface_azimuth_deg")
    return {**config, **place, "site_id": site_id, "name": site_id, "source": "", "notes": ""}


def sites_service(tmp_dir: Path, admin_token: str) -> InProcessServer:
    """A started service of its own on a SQLite file in ``tmp_dir``, with a user-sites
    folder there (``user-sites``, not yet made) and ``admin_token`` as its admin token."""
    env = {"HELIOTWIN_SITES_DIR": str(tmp_dir / "user-sites"),
           "HELIOTWIN_ADMIN_TOKEN": admin_token}
    return InProcessServer(f"sqlite:///{tmp_dir / 'sites.sqlite'}", extra_env=env).start()
