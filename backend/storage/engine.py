"""Engine, sessions and migrations (SQLAlchemy 2 + Alembic).

SQLite runs in WAL mode with foreign keys on and a busy timeout, so readers on
the pool never block the one writer (``backend/measurements/writer.py``) and the writer never
blocks them (SQLite docs, "Write-Ahead Logging"). ``synchronous`` comes from
``Settings.database.sqlite_synchronous``: NORMAL by default, with which a commit in WAL
mode survives a crash or SIGKILL of the service (it is in the WAL file before
the answer goes out) but the last commits may be lost in an OS crash or power
cut; FULL also fsyncs the WAL at every group commit (SQLite docs, "PRAGMA
synchronous"). PostgreSQL needs nothing special.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sqlalchemy import Connection, Engine, create_engine, event
from sqlalchemy.engine import make_url
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session, sessionmaker

from backend.errors import SetupError
from backend.settings import Settings

if TYPE_CHECKING:
    from alembic.config import Config

logger = logging.getLogger(__name__)

MIGRATIONS_DIR = Path(__file__).resolve().parent / "migrations"
#: How long a SQLite connection waits for a lock before it answers "database is locked".
SQLITE_BUSY_TIMEOUT_MS = 30_000
_migrate_lock = threading.Lock()


def make_engine(settings: Settings) -> Engine:
    """Create the engine for ``settings.database.url`` (SQLite pragmas set per connection)."""
    url = make_url(settings.database.url)
    if url.get_backend_name() == "sqlite":
        pool: dict[str, int] = {}
        if url.database and url.database != ":memory:":
            Path(url.database).parent.mkdir(parents=True, exist_ok=True)
            pool = {"pool_size": 16, "max_overflow": 16}
        engine = create_engine(
            url, connect_args={"check_same_thread": False,
                               "timeout": SQLITE_BUSY_TIMEOUT_MS / 1000}, **pool
        )
        synchronous = settings.database.sqlite_synchronous

        @event.listens_for(engine, "connect")
        def _sqlite_pragmas(dbapi_conn: Any, _record: Any) -> None:
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA foreign_keys=ON")
            cur.execute(f"PRAGMA synchronous={synchronous}")
            cur.execute(f"PRAGMA busy_timeout={SQLITE_BUSY_TIMEOUT_MS}")
            cur.execute("PRAGMA cache_size=-65536")
            cur.close()

        install_sqlite_transactions(engine)
        return engine
    return create_engine(url, pool_size=16, max_overflow=16, pool_pre_ping=True)


def install_sqlite_transactions(engine: Engine) -> None:
    """Let SQLAlchemy, not ``sqlite3``, emit BEGIN (SQLAlchemy docs, "pysqlite" recipe).

    Connections with the execution option ``sqlite_immediate`` begin with
    ``BEGIN IMMEDIATE`` so the writer takes the write lock up front.
    """

    @event.listens_for(engine, "connect")
    def _autocommit_driver(dbapi_conn: Any, _record: Any) -> None:
        dbapi_conn.isolation_level = None

    @event.listens_for(engine, "begin")
    def _begin(conn: Connection) -> None:
        immediate = conn.get_execution_options().get("sqlite_immediate", False)
        conn.exec_driver_sql("BEGIN IMMEDIATE" if immediate else "BEGIN")


def make_sessionmaker(engine: Engine) -> sessionmaker[Session]:
    """A session factory bound to ``engine`` (objects stay usable after commit)."""
    return sessionmaker(engine, expire_on_commit=False)


@contextmanager
def session_scope(factory: sessionmaker[Session]) -> Iterator[Session]:
    """A session that commits on success and rolls back on error."""
    session = factory()
    try:
        yield session
        session.commit()
    except BaseException:
        session.rollback()
        raise
    finally:
        session.close()


def alembic_config(engine: Engine) -> Config:
    """Alembic config pointing at ``backend/storage/migrations`` (no ``alembic.ini`` needed)."""
    # alembic logs its plugin set-up at INFO on import; nothing for the service log
    logging.getLogger("alembic").setLevel(logging.WARNING)
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    url = engine.url.render_as_string(hide_password=False)
    cfg.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return cfg


class DatabaseUnreachableError(SetupError):
    """The database could not be connected to (PostgreSQL not running, a wrong host, a
    SQLite file that cannot be opened)."""


def connect(engine: Engine) -> Connection:
    """``engine.connect()``; a failure to connect is :class:`DatabaseUnreachableError`, one
    line naming the URL (password hidden), the driver's reason and what to do (``heliotwin
    serve`` with PostgreSQL down had printed SQLAlchemy's traceback)."""
    try:
        return engine.connect()
    except OperationalError as exc:
        why = " ".join(str(exc.orig or exc).split())
        todo = ("start PostgreSQL (the README's \"PostgreSQL and Mosquitto\" says how) or set "
                "HELIOTWIN_DATABASE_URL to one that runs"
                if engine.url.get_backend_name() == "postgresql" else
                "check that its folder exists and is writable, or set HELIOTWIN_DATABASE_URL")
        raise DatabaseUnreachableError(
            f"cannot connect to the database {engine.url.render_as_string(hide_password=True)}"
            f": {why}; {todo}") from None


class SchemaTooNewError(SetupError):
    """The database holds a migration this code does not have: a newer heliotwin wrote it."""


def _refuse_newer(engine: Engine, conn: Connection, script: Any) -> None:
    """Raise :class:`SchemaTooNewError` if ``conn``'s database is at a revision ``script``
    (the code's migrations) does not know."""
    from alembic.migration import MigrationContext

    current = MigrationContext.configure(conn).get_current_heads()
    unknown = sorted(set(current) - {rev.revision for rev in script.walk_revisions()})
    if unknown:
        raise SchemaTooNewError(
            f"the database {engine.url.render_as_string(hide_password=True)} is at schema "
            f"revision {', '.join(unknown)}, which this heliotwin does not know (its latest: "
            f"{', '.join(script.get_heads())}): a newer heliotwin migrated it. Run that "
            "version or a newer one, or restore a backup taken before the upgrade; the "
            "database was left as it is")


def check_schema(engine: Engine) -> None:
    """Refuse, reading only, a database a newer heliotwin migrated (:class:`SchemaTooNewError`).

    ``heliotwin serve`` asks before it starts uvicorn: refused in the app's lifespan, the
    message came under uvicorn's 90-line traceback."""
    cfg = alembic_config(engine)  # first: it quietens alembic's import-time log
    from alembic.script import ScriptDirectory

    script = ScriptDirectory.from_config(cfg)
    with connect(engine) as conn:
        _refuse_newer(engine, conn, script)


def run_migrations(engine: Engine) -> None:
    """Upgrade the database to every head revision (core ``0001_initial`` and later).

    A database at a revision this code does not know (written by a newer heliotwin) is
    refused with :class:`SchemaTooNewError`, untouched: Alembic's own answer was only
    "Can't locate revision identified by '…'" under a long traceback."""
    cfg = alembic_config(engine)
    from alembic import command
    from alembic.script import ScriptDirectory

    script = ScriptDirectory.from_config(cfg)
    with _migrate_lock, connect(engine) as conn, conn.begin():
        _refuse_newer(engine, conn, script)
        cfg.attributes["connection"] = conn
        command.upgrade(cfg, "heads")
    logger.info("database at the latest schema (%s)", engine.url.get_backend_name())
