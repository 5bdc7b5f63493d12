"""Alembic environment: every table of ``backend.storage.tables`` on one ``Base.metadata``.

``backend.storage.engine.run_migrations`` passes an open connection in
``config.attributes["connection"]``; run from the ``alembic`` command line the URL
comes from ``sqlalchemy.url`` or ``HELIOTWIN_DATABASE_URL``.
"""

from __future__ import annotations

from alembic import context
from sqlalchemy import create_engine

import backend.storage.tables
from backend.settings import get_settings

target_metadata = backend.storage.tables.Base.metadata


def _run(connection) -> None:  # type: ignore[no-untyped-def]
    context.configure(
        connection=connection,
        target_metadata=target_metadata,
        render_as_batch=connection.dialect.name == "sqlite",
    )
    with context.begin_transaction():
        context.run_migrations()


connection = context.config.attributes.get("connection")
if connection is not None:
    _run(connection)
else:
    url = context.config.get_main_option("sqlalchemy.url") or get_settings().database.url
    engine = create_engine(url)
    with engine.begin() as conn:
        _run(conn)
    engine.dispose()
