"""Per-site write tokens for field loggers.

A token is 32 random bytes (``secrets.token_urlsafe``), shown once when made;
the database keeps only its SHA-256 and a short prefix to recognise it by.
:class:`TokenCache` answers the hot path from memory and asks the database only
for a token it has not seen (one made by ``heliotwin token create`` while the
service runs, say).
"""

from __future__ import annotations

import hashlib
import secrets
import threading

from sqlalchemy import Connection, Engine, insert, select

from backend.storage.tables import LoggerToken, SiteRow, utcnow


class UnknownSite(LookupError):
    """No site with that id is in the database."""


def hash_token(token: str) -> str:
    """SHA-256 hex digest of a token (what the database stores)."""
    return hashlib.sha256(token.encode()).hexdigest()


def create_token(conn: Connection, site_id: str, label: str = "") -> str:
    """Make, store and return a new write token for ``site_id``."""
    if conn.execute(select(SiteRow.site_id).where(SiteRow.site_id == site_id)).first() is None:
        known = ", ".join(conn.execute(select(SiteRow.site_id)).scalars()) or "none"
        raise UnknownSite(f"unknown site {site_id!r}; known sites: {known}")
    token = "ht_" + secrets.token_urlsafe(32)
    conn.execute(insert(LoggerToken).values(
        site_id=site_id, token_sha256=hash_token(token), token_prefix=token[:10],
        label=label, created_at=utcnow(),
    ))
    return token


class TokenCache:
    """Maps token hashes to their site, from memory, falling back to the database."""

    def __init__(self, engine: Engine) -> None:
        self._engine = engine
        self._site_of: dict[str, str] = {}
        self._lock = threading.Lock()

    def cached(self, token: str) -> str | None:
        """The site of a token already seen, without touching the database."""
        return self._site_of.get(hash_token(token))

    def site_of(self, token: str) -> str | None:
        """The site a token writes to, or None for an unknown token."""
        digest = hash_token(token)
        site = self._site_of.get(digest)
        if site is not None:
            return site
        with self._engine.connect() as conn:
            site = conn.execute(
                select(LoggerToken.site_id).where(LoggerToken.token_sha256 == digest)
            ).scalar_one_or_none()
        if site is not None:
            with self._lock:
                self._site_of[digest] = site
        return site
