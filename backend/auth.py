"""Per-site write tokens: create, check (cached), list, revoke; each with a scope.

A token is 32 random bytes (``secrets.token_urlsafe``), shown once when made;
the database keeps only its SHA-256 and a short prefix to recognise it by, its
scope, an optional expiry and, once revoked, the time it was revoked (the row
stays, so ``token list`` shows it).

Scopes (:data:`SCOPES`): ``ingest`` — a field device: writes its site's readings
and nothing else (the default, and what every token made before scopes became);
``site`` — the site's operator: also edits the site's config, its calibrations
and the 3D twin's shared replay, and acknowledges the site's alerts. Above both is
the admin token, a setting (``HELIOTWIN_ADMIN_TOKEN``), never stored here.
:class:`TokenCache` answers the hot path from memory for at most ``ttl_s`` after it
last asked the database about a token, so a
token revoked by another process (``heliotwin token revoke``) is refused within
that time; a revocation through this process's cache (the admin HTTP endpoint)
is refused at once.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import secrets
import threading
import time
from dataclasses import dataclass
from typing import Any

from sqlalchemy import Connection, Engine, insert, select, update

from backend.errors import Refusal
from backend.storage.tables import LoggerToken, SiteRow, utcnow
from backend.text import one_line_problem


class UnknownSite(Refusal, LookupError):
    """No site with that id is in the database."""


class UnknownToken(Refusal, LookupError):
    """No stored token matches that token or id."""


#: Token scopes, least first: what each may do is in the module docstring.
SCOPES: tuple[str, ...] = ("ingest", "site")
DEFAULT_SCOPE = "ingest"


def check_scope(scope: str) -> str:
    """``scope`` when it is one of :data:`SCOPES`; ValueError naming them otherwise."""
    if scope not in SCOPES:
        raise ValueError(f"scope: {scope[:20]!r} is not one of {', '.join(SCOPES)}")
    return scope


def scope_allows(held: str, needed: str) -> bool:
    """Whether a token of scope ``held`` may do what needs ``needed`` (``site`` ⊇ ``ingest``)."""
    return SCOPES.index(held) >= SCOPES.index(needed)


@dataclass(frozen=True)
class Grant:
    """What a valid token may do: write to ``site_id`` within ``scope``; and which token it
    is (its stored ``token_id`` and ``label``), to record who did what."""

    site_id: str
    scope: str
    token_id: int = 0
    label: str = ""

    @property
    def name(self) -> str:
        """Who the token is, as an action it did records it: its label, else ``token #<id>``
        (the id ``heliotwin token list`` shows; never the token nor its prefix)."""
        return self.label or f"token #{self.token_id}"


class TokenRefused(LookupError):
    """A token that is not valid now; ``reason`` is ``unknown``, ``revoked`` or ``expired``."""

    def __init__(self, reason: str) -> None:
        super().__init__(f"{reason} write token")
        self.reason = reason


def hash_token(token: str) -> str:
    """SHA-256 hex digest of a token (what the database stores)."""
    return hashlib.sha256(token.encode()).hexdigest()


def _aware(t: dt.datetime | None) -> dt.datetime | None:
    """SQLite gives naive datetimes back: they were stored as UTC."""
    if t is None or t.tzinfo is not None:
        return t
    return t.replace(tzinfo=dt.UTC)


@dataclass(frozen=True)
class TokenInfo:
    """What ``token list`` and ``GET /api/v1/tokens`` show of a token (never the token)."""

    id: int
    site_id: str
    token_prefix: str
    label: str
    scope: str
    created_at: dt.datetime
    expires_at: dt.datetime | None
    revoked_at: dt.datetime | None

    def status(self, now: dt.datetime | None = None) -> str:
        """``active``, ``expired`` or ``revoked``."""
        if self.revoked_at is not None:
            return "revoked"
        if self.expires_at is not None and self.expires_at <= (now or utcnow()):
            return "expired"
        return "active"

    def to_dict(self) -> dict[str, Any]:
        def iso(t: dt.datetime | None) -> str | None:
            return None if t is None else t.isoformat().replace("+00:00", "Z")

        return {"id": self.id, "site_id": self.site_id, "token_prefix": self.token_prefix,
                "label": self.label, "scope": self.scope, "created_at": iso(self.created_at),
                "expires_at": iso(self.expires_at), "revoked_at": iso(self.revoked_at),
                "status": self.status()}


_COLUMNS = select(*LoggerToken.__table__.columns)


def _info(row: Any) -> TokenInfo:
    created = _aware(row.created_at)
    assert created is not None
    return TokenInfo(row.id, row.site_id, row.token_prefix, row.label, row.scope, created,
                     _aware(row.expires_at), _aware(row.revoked_at))


def create_token(conn: Connection, site_id: str, label: str = "",
                 expires_at: dt.datetime | None = None, scope: str = DEFAULT_SCOPE) -> str:
    """Make, store and return a new token of ``scope`` for ``site_id`` (refused from
    ``expires_at``)."""
    check_scope(scope)
    if (problem := one_line_problem(label)) is not None:
        raise ValueError(f"label: {problem}")
    if conn.execute(select(SiteRow.site_id).where(SiteRow.site_id == site_id)).first() is None:
        known = ", ".join(conn.execute(select(SiteRow.site_id)).scalars()) or "none"
        raise UnknownSite(f"unknown site {site_id!r}; known sites: {known}")
    if expires_at is not None and expires_at.tzinfo is None:
        raise ValueError("expires_at must be timezone-aware")
    token = "ht_" + secrets.token_urlsafe(32)
    conn.execute(insert(LoggerToken).values(
        site_id=site_id, token_sha256=hash_token(token), token_prefix=token[:10],
        label=label, scope=scope, created_at=utcnow(), expires_at=expires_at,
    ))
    return token


def list_tokens(conn: Connection, site_id: str | None = None) -> list[TokenInfo]:
    """Every stored token (of one site when given: :class:`UnknownSite` for a site the
    database does not hold, as :func:`create_token`; it answered an empty list), oldest
    first."""
    q = _COLUMNS.order_by(LoggerToken.id)
    if site_id is not None:
        if conn.execute(select(SiteRow.site_id).where(SiteRow.site_id == site_id)).first() \
                is None:
            known = ", ".join(conn.execute(select(SiteRow.site_id)).scalars()) or "none"
            raise UnknownSite(f"unknown site {site_id!r}; known sites: {known}")
        q = q.where(LoggerToken.site_id == site_id)
    return [_info(row) for row in conn.execute(q)]


def find_token(conn: Connection, token_or_id: str | int) -> tuple[TokenInfo, str]:
    """The stored token an id (digits) or the token itself names, and its hash."""
    text = str(token_or_id).strip()
    if text.isdigit():
        what = f"id {text}"
        q = _COLUMNS.where(LoggerToken.id == int(text)) if int(text) < 2**31 else None
    else:
        what = f"token {text[:10]}…"
        q = _COLUMNS.where(LoggerToken.token_sha256 == hash_token(text))
    row = None if q is None else conn.execute(q).first()
    if row is None and not text.isdigit():
        # the prefix `heliotwin token list` shows is not the token: name the id to use
        # (an operator's finding: "no write token with token ht_BEu5pV8…" for a token
        # that list showed as ht_BEu5pV8)
        ids = [str(i) for i in conn.execute(select(LoggerToken.id).where(
            LoggerToken.token_prefix == text).order_by(LoggerToken.id)).scalars()]
        if ids:
            raise UnknownToken(
                f"{text} is the token_prefix `heliotwin token list` shows, not the token: "
                f"name it by its id ({' or '.join(ids)}), e.g. `heliotwin token revoke "
                f"{ids[0]}`")
    if row is None:
        raise UnknownToken(f"no write token with {what} (see `heliotwin token list`)")
    return _info(row), str(row.token_sha256)


def revoke_token(conn: Connection, token_or_id: str | int) -> tuple[TokenInfo, str]:
    """Revoke a token (by id or by the token); the row stays. Returns it and its hash.

    Revoking a revoked token changes nothing (the first revocation time stays).
    """
    info, digest = find_token(conn, token_or_id)
    if info.revoked_at is None:
        conn.execute(update(LoggerToken).where(LoggerToken.id == info.id)
                     .values(revoked_at=utcnow()))
        info, digest = find_token(conn, info.id)
    return info, digest


@dataclass(frozen=True)
class _Entry:
    grant: Grant
    expires_s: float | None  # Unix seconds, or None
    checked_s: float  # time.monotonic() of the database read


class TokenCache:
    """Maps token hashes to their grant: from memory for ``ttl_s``, then from the database."""

    def __init__(self, engine: Engine, ttl_s: float = 0.5) -> None:
        self._engine = engine
        self._ttl_s = ttl_s
        self._entries: dict[str, _Entry] = {}
        self._lock = threading.Lock()

    def _fresh(self, digest: str) -> Grant | None:
        e = self._entries.get(digest)
        if e is None or time.monotonic() - e.checked_s > self._ttl_s:
            return None
        if e.expires_s is not None and time.time() >= e.expires_s:
            return None
        return e.grant

    def cached(self, token: str) -> Grant | None:
        """The grant of a valid token checked less than ``ttl_s`` ago, without the database."""
        return self._fresh(hash_token(token))

    def grant(self, token: str) -> Grant:
        """What a token may do; :class:`TokenRefused` (unknown, revoked, expired) otherwise."""
        digest = hash_token(token)
        fresh = self._fresh(digest)
        if fresh is not None:
            return fresh
        with self._engine.connect() as conn:
            row = conn.execute(
                select(LoggerToken.id, LoggerToken.site_id, LoggerToken.scope,
                       LoggerToken.label, LoggerToken.expires_at, LoggerToken.revoked_at)
                .where(LoggerToken.token_sha256 == digest)
            ).first()
        expires = _aware(row.expires_at) if row is not None else None
        reason = ("unknown" if row is None else "revoked" if row.revoked_at is not None
                  else "expired" if expires is not None and expires <= utcnow() else "")
        if reason:
            self.forget(digest)
            raise TokenRefused(reason)
        assert row is not None
        grant = Grant(str(row.site_id), str(row.scope), int(row.id), str(row.label or ""))
        with self._lock:
            self._entries[digest] = _Entry(
                grant, None if expires is None else expires.timestamp(), time.monotonic())
        return grant

    def site_of(self, token: str) -> str | None:
        """The site a token writes to; None for an unknown, expired or revoked token."""
        try:
            return self.grant(token).site_id
        except TokenRefused:
            return None

    def forget(self, digest: str) -> None:
        """Drop a token (by its hash) from memory: the next check asks the database."""
        with self._lock:
            self._entries.pop(digest, None)
