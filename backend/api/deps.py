"""FastAPI dependencies: settings, sessions, the service context, write tokens.

``SessionDep`` and ``SettingsDep`` follow the full-stack-fastapi-template style
(``Annotated`` aliases). Write tokens come as ``Authorization: Bearer <token>``:

- :data:`SiteTokenDep` (routes with a ``{site_id}`` path parameter): 401 without a
  token or with an unknown one, 403 with a token of another site; gives the site id.
- :data:`VisionTokenDep`: when ``Settings.vision.require_token`` is set, a valid
  token of any site is needed (401 otherwise); gives that token's site id, or
  None when no token is needed and none was sent.
"""

from __future__ import annotations

import hmac
from collections.abc import Iterator
from typing import Annotated

import anyio
from fastapi import Depends, HTTPException, Query, Request
from sqlalchemy.orm import Session

from backend.context import ServiceContext
from backend.settings import Settings
from backend.sites import SiteInfo

_BEARER = {"WWW-Authenticate": "Bearer"}


async def get_context(request: Request) -> ServiceContext:
    """The running service's context (``app.state.ctx``)."""
    return request.app.state.ctx  # type: ignore[no-any-return]


async def get_settings_dep(request: Request) -> Settings:
    """The settings the app was created with."""
    return request.app.state.settings  # type: ignore[no-any-return]


def get_session(request: Request) -> Iterator[Session]:
    """A database session for one request (reads; writes go through the writer)."""
    session = request.app.state.ctx.sessions()
    try:
        yield session
    finally:
        session.close()


ContextDep = Annotated[ServiceContext, Depends(get_context)]
SettingsDep = Annotated[Settings, Depends(get_settings_dep)]
SessionDep = Annotated[Session, Depends(get_session)]


def site_or_404(ctx: ServiceContext, site_id: str) -> SiteInfo:
    """The site, or 404 naming the known ones."""
    info = ctx.registry.get(site_id)
    if info is None:
        known = ", ".join(ctx.registry.sites) or "none"
        raise HTTPException(404, f"unknown site {site_id!r}; known sites: {known}")
    return info


def bearer_token(request: Request) -> str | None:
    """The token of an ``Authorization: Bearer`` header, or None."""
    return parse_bearer(request.headers.get("authorization"))


def parse_bearer(header: str | None) -> str | None:
    """The token of an ``Authorization`` header value, or None when there is none."""
    if not header:
        return None
    scheme, _, token = header.partition(" ")
    if scheme.lower() != "bearer" or not token.strip():
        raise HTTPException(401, "Authorization must be 'Bearer <token>'", headers=_BEARER)
    return token.strip()


def is_admin_token(settings: Settings, token: str | None) -> bool:
    """Whether ``token`` is ``Settings.server.admin_token`` (constant-time; never when unset)."""
    expected = settings.server.admin_token
    return bool(token and expected and hmac.compare_digest(
        token.encode(), expected.get_secret_value().encode()))


async def token_site(request: Request, token: str) -> str | None:
    """The site of a token (memory first, the database on a miss)."""
    return await _token_site(request.app.state.ctx, token)


async def _token_site(ctx: ServiceContext, token: str) -> str | None:
    cache = ctx.tokens
    site = cache.cached(token)
    if site is not None:
        return site
    return await anyio.to_thread.run_sync(cache.site_of, token)


async def require_site_token(request: Request, site_id: str) -> str:
    """Dependency: a write token of ``site_id`` (401 none/unknown, 403 another site's)."""
    return await check_site_token(request.app.state.ctx, site_id,
                                  request.headers.get("authorization"))


async def check_site_token(ctx: ServiceContext, site_id: str, authorization: str | None) -> str:
    """The check behind :func:`require_site_token`, for callers without a ``Request``."""
    token = parse_bearer(authorization)
    if token is None:
        raise HTTPException(401, "write token required: send 'Authorization: Bearer <token>' "
                                 "(make one with `heliotwin token create --site ID`)",
                            headers=_BEARER)
    owner = await _token_site(ctx, token)
    if owner is None:
        raise HTTPException(401, "unknown write token", headers=_BEARER)
    if owner != site_id:
        raise HTTPException(403, f"this token writes to site {owner!r}, not {site_id!r}")
    return owner


async def vision_token(request: Request) -> str | None:
    """Dependency: a token only when ``vision_require_token`` is set; gives its site or None."""
    settings: Settings = request.app.state.settings
    token = bearer_token(request)
    if token is None:
        if settings.vision.require_token:
            raise HTTPException(401, "this service requires a site write token for vision "
                                     "requests: send 'Authorization: Bearer <token>'",
                                headers=_BEARER)
        return None
    owner = await token_site(request, token)
    if owner is None:
        raise HTTPException(401, "unknown write token", headers=_BEARER)
    return owner


SiteTokenDep = Annotated[str, Depends(require_site_token)]
VisionTokenDep = Annotated[str | None, Depends(vision_token)]


RangeStart = Annotated[str, Query(min_length=1, max_length=64,
                                  description="date (site midnight) or ISO date-time, inclusive")]
"""The ``start`` of a site's range query (``backend.timestamps.parse_range`` reads it)."""
RangeEnd = Annotated[str, Query(min_length=1, max_length=64,
                                description="date or ISO date-time, exclusive")]
"""The ``end`` of a site's range query."""
