"""The CLI's writes to the service's database (``HELIOTWIN_DATABASE_URL``): one write
transaction that takes SQLite's write lock first, so a command works while a running
service and its loggers write (``token``, ``site create``, ``site from-weather``)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


def locked(exc: BaseException) -> bool:
    """SQLite's "database is locked"/"busy": another writer held the lock past the timeout."""
    from sqlalchemy.exc import OperationalError

    return isinstance(exc, OperationalError) and any(
        w in str(exc.orig) for w in ("locked", "busy"))


def with_db(work: Callable[[Any], Any], site_id: str | None = None,
            configured: bool = True) -> Any:
    """Migrate if needed, run ``work(conn)`` in one write transaction, retried while locked.

    On SQLite the transaction is ``BEGIN IMMEDIATE``: it takes the write lock first (and
    waits for it, ``busy_timeout``), where a deferred one that reads and then writes fails
    at once with "database is locked" when a logger committed in between. A ``site_id``
    must have a site config (built-in or in ``HELIOTWIN_SITES_DIR``), or with ``configured``
    False at least a row in the database (:class:`backend.auth.UnknownSite` otherwise,
    naming the configured sites): a site the database still held after its file went had
    been given a token whose every reading the service refused as "unknown site" (its 404),
    and a built-in site the database did not hold yet had been "unknown" to ``token list``.
    ``sites`` is not rewritten: only a ``site_id`` missing from the database is added from
    its file (a token needs its site's row). Still locked after the timeout: retried 4
    times with backoff (:mod:`backend.retry`), then the error.
    """
    from sqlalchemy import select
    from tenacity import Retrying, retry_if_exception, stop_after_attempt

    from backend.auth import UnknownSite
    from backend.cli import fail
    from backend.retry import backoff
    from backend.settings import get_settings
    from backend.sites import Registry, sync_sites
    from backend.storage.engine import make_engine, run_migrations
    from backend.storage.tables import SiteRow

    settings = get_settings()
    engine = make_engine(settings)

    def attempt() -> Any:
        with engine.connect().execution_options(sqlite_immediate=True) as conn, conn.begin():
            if site_id is not None:
                stored = conn.execute(
                    select(SiteRow.site_id).where(SiteRow.site_id == site_id)).first()
                info = registry.sites.get(site_id)
                if info is None and (configured or stored is None):
                    raise UnknownSite(
                        f"unknown site {site_id!r}: no site config gives it (built-in, or a "
                        f"file in HELIOTWIN_SITES_DIR, {settings.sites.user_dir}); known "
                        f"sites: {', '.join(registry.sites) or 'none'}")
                if stored is None and info is not None:
                    sync_sites(conn, [info.site])
            return work(conn)

    try:
        run_migrations(engine)
        try:
            registry = Registry.load_files(settings.sites.user_dir)
        except ValueError as exc:  # a broken file in the folder (a draft, a copy): say which
            fail(f"HELIOTWIN_SITES_DIR: {exc}: fix or move that file (the service does not "
                 "start with it either)")
        return Retrying(stop=stop_after_attempt(5), wait=backoff(0.5, 4.0),
                        retry=retry_if_exception(locked), reraise=True)(attempt)
    finally:
        engine.dispose()
