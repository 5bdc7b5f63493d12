"""Plain DBAPI queries through a SQLAlchemy connection, for the read hot paths.

Statements are written with ``?`` placeholders (SQLite's qmark style) and turned
into ``%s`` for psycopg; results come back as tuples, which NumPy takes directly
(SQLAlchemy ``Row`` objects cost ~10× more for tens of thousands of rows).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sqlalchemy import Connection


def fetch(conn: Connection, sql: str, params: Sequence[Any]) -> list[tuple[Any, ...]]:
    """Run ``sql`` (``?`` placeholders) on the connection's driver and fetch every row."""
    dbapi = conn.connection.driver_connection
    if conn.dialect.name == "postgresql":
        sql = sql.replace("?", "%s")
    cur = dbapi.cursor()  # type: ignore[union-attr]
    try:
        cur.execute(sql, tuple(params))
        return list(cur.fetchall())
    finally:
        cur.close()
