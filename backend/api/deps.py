"""FastAPI dependencies: settings, sessions, the service context, write tokens.

``SessionDep`` and ``SettingsDep`` follow the full-stack-fastapi-template style
(``Annotated`` aliases). Write tokens come as ``Authorization: Bearer <token>``:

- :func:`check_site_token` (the ingest route, which checks its token before reading its
  body): 401 without a token or with an unknown, revoked or expired one (the message
  says which), 403 with a token of another site or with the admin token (a logger
  sends a site's token); gives the site id. Any scope may write readings.
- :data:`SiteAdminDep`: the admin token or a ``site``-scope token of ``{site_id}``
  (403 naming the scope for an ``ingest`` token); :data:`CallerDep` who called (or
  None), for a route whose site is in its body, to :func:`authorize` there.
- :func:`read_token` (every route's): when ``Settings.server.read_require_token`` is
  set, the reads of the service's data (every GET but :data:`PUBLIC_READS`) need a valid
  token of any site and scope, or the admin token (401 naming the setting otherwise).
- :data:`VisionTokenDep`: when ``Settings.vision.require_token`` is set, a valid
  token of any site is needed (401 otherwise); gives that token's site id, or
  None when no token is needed and none was sent.

:func:`anonymous_read` (a read route's ``**anonymous_read_route(responses)``) is the one
rule of the reads of a site's data without a token: 429 with ``Retry-After`` when the
caller's address has spent ``HELIOTWIN_ANONYMOUS_READ_CPU_S_PER_MIN``, then charged the
CPU time the read took.
"""

from __future__ import annotations

import datetime as dt
import hmac
from collections.abc import AsyncIterator, Iterator
from typing import Annotated, Any, Literal

import anyio
from fastapi import Depends, HTTPException, Query, Request
from sqlalchemy.orm import Session

from backend.auth import Grant, TokenRefused, scope_allows
from backend.context import ServiceContext
from backend.limits import Busy, start_meter
from backend.settings import Settings
from backend.sites import SiteInfo
from backend.timestamps import parse_range

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


def site_or_404(ctx: ServiceContext, site_id: str, field: str | None = None) -> SiteInfo:
    """The site, or 404 naming the known ones (and ``field``, the body's or the query's
    field that named it: a path's site needs no name); 503 while its arrays have no
    database rows (:meth:`backend.sites.SiteInfo.ready`)."""
    info = ctx.registry.get(site_id)
    if info is None:
        known = ", ".join(ctx.registry.sites) or "none"
        named = f"{field}: " if field else ""
        raise HTTPException(404, f"{named}unknown site {site_id[:64]!r}; known sites: {known}")
    if not info.ready():
        missing = sorted(set(info.site.arrays) - set(info.arrays))
        raise HTTPException(503, f"site {site_id!r}: arrays {missing} have no rows in the "
                                 "database yet (its file was read while the service runs); "
                                 "retry, or restart the service",
                            headers={"Retry-After": "5"})
    return info


def site_range(ctx: ServiceContext, site_id: str, start: str, end: str
               ) -> tuple[SiteInfo, dt.datetime, dt.datetime]:
    """The site of a read (404, :func:`site_or_404`) and its ``[start, end)`` in the site's
    zone (``backend.timestamps.parse_range``: 422 naming the field that is wrong)."""
    info = site_or_404(ctx, site_id)
    try:
        t0, t1 = parse_range(start, end, info.zone)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    return info, t0, t1


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
    """The site of a valid token (memory first, the database on a miss), or None."""
    try:
        return (await token_grant(request.app.state.ctx, token)).site_id
    except TokenRefused:
        return None


async def token_grant(ctx: ServiceContext, token: str) -> Grant:
    """What a token may do (memory first); :class:`TokenRefused` for an invalid one."""
    cache = ctx.tokens
    grant = cache.cached(token)
    if grant is not None:
        return grant
    return await anyio.to_thread.run_sync(cache.grant, token)


async def _valid_grant(ctx: ServiceContext, token: str) -> Grant:
    try:
        return await token_grant(ctx, token)
    except TokenRefused as exc:  # "unknown", "revoked" or "expired write token"
        raise HTTPException(401, str(exc), headers=_BEARER) from None


Caller = Grant | Literal["admin"] | None
"""Who sent a request: the admin token, a valid site token's grant, or nobody (None)."""


def caller_name(caller: Caller) -> str:
    """How an action is recorded as done by ``caller``: ``admin``, or the token's
    :attr:`backend.auth.Grant.name`."""
    if caller is None:
        raise ValueError("an anonymous caller has no name: authorize() first")
    return "admin" if caller == "admin" else caller.name


async def caller_of(ctx: ServiceContext, authorization: str | None,
                    admin_ok: bool = True) -> Caller:
    """The caller an ``Authorization`` header names (401 for an invalid token)."""
    token = parse_bearer(authorization)
    if token is None:
        return None
    if is_admin_token(ctx.settings, token):
        if admin_ok:
            return "admin"
        raise HTTPException(403, "the admin token does not write a site's data: a logger sends a "
                                 "site's 'ingest' token (`heliotwin token create --site ID`)")
    return await _valid_grant(ctx, token)


def authorize(caller: Caller, site_id: str, scope: str = "ingest", what: str = "this") -> str:
    """``"admin"``, or the site of a token of ``site_id`` whose scope allows ``scope``:
    401 without a token, 403 for another site's or too narrow a scope (naming it);
    ``what`` names the action in that 403."""
    if caller == "admin":
        return "admin"
    if caller is None:
        raise HTTPException(401, "write token required: send 'Authorization: Bearer <token>' "
                                 f"(make one with `heliotwin token create --site ID"
                                 f"{'' if scope == 'ingest' else ' --scope ' + scope}`)",
                            headers=_BEARER)
    if caller.site_id != site_id:
        raise HTTPException(403, f"this token writes to site {caller.site_id!r}, not "
                                 f"{site_id!r}")
    if not scope_allows(caller.scope, scope):
        raise HTTPException(403, f"this token has scope {caller.scope!r}, which does not "
                                 f"allow {what}: that needs a {scope!r} token of the site "
                                 f"(`heliotwin token create --scope {scope}`) or the admin "
                                 "token")
    return caller.site_id


async def check_site_token(ctx: ServiceContext, site_id: str, authorization: str | None,
                           scope: str = "ingest", what: str = "this") -> str:
    """A token (not the admin's) of ``site_id`` whose scope allows ``scope``; its site id."""
    return authorize(await caller_of(ctx, authorization, admin_ok=False), site_id, scope, what)


async def check_site_admin(ctx: ServiceContext, site_id: str, authorization: str | None,
                           what: str) -> str:
    """``"admin"`` for the admin token, else a ``site``-scope token of ``site_id`` (its id);
    ``what`` names the action in a 403 (an ``ingest`` token's)."""
    return authorize(await caller_of(ctx, authorization), site_id, "site", what)


async def require_site_admin(request: Request, site_id: str) -> str:
    """Dependency: the admin token or a ``site``-scope token of ``site_id``."""
    return await check_site_admin(request.app.state.ctx, site_id,
                                  request.headers.get("authorization"),
                                  f"changing site {site_id!r}")


async def optional_caller(request: Request) -> Caller:
    """Dependency: the caller, or None without a token (the route decides; 401 for an
    invalid token)."""
    return await caller_of(request.app.state.ctx, request.headers.get("authorization"))


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
    if is_admin_token(settings, token):
        raise HTTPException(403, "the admin token is not a site's token: vision requests write "
                                 "a site's history, so they need a token of the site "
                                 "(`heliotwin token create --site ID`)")
    return (await _valid_grant(request.app.state.ctx, token)).site_id


async def authenticated_first(ctx: ServiceContext, authorization: str | None) -> None:
    """The cheap check that comes before an expensive body (``StrictBodies``): 401 unless
    ``authorization`` holds the admin token or a valid token of any scope and site (the
    route checks the site and scope after)."""
    if await caller_of(ctx, authorization) is None:
        raise HTTPException(401, "this request needs a token: send 'Authorization: Bearer "
                                 "<token>'", headers=_BEARER)


#: The reads (GET) that stay open when ``HELIOTWIN_READ_REQUIRE_TOKEN`` is set, by route
#: path: they hold none of the sites' data. The liveness probe; what the dashboard needs to
#: know before it has a token (the meta says that reads need one); the dashboard's page and
#: its Plotly; the API docs (``/openapi.json`` is a plain route, not checked at all); the
#: JSON schema of a site's config (the Sites form); the time a sky image's file *name*
#: carries (the Sky page's analysis is ruled by ``HELIOTWIN_VISION_REQUIRE_TOKEN``).
#: ``tests/backend/test_read_token.py`` checks every other GET against the setting.
PUBLIC_READS: frozenset[str] = frozenset({
    "/healthz", "/api/v1/meta", "/", "/vendor/plotly.min.js", "/docs",
    "/api/v1/sites/schema.json", "/api/v1/vision/frame-times"})

READ_TOKEN_REQUIRED = (
    "this service requires a token to read its data (HELIOTWIN_READ_REQUIRE_TOKEN is set): "
    "send 'Authorization: Bearer <token>' with any site's token (ingest or site scope; "
    "`heliotwin token create --site ID`) or the admin token")


async def read_token(request: Request) -> None:
    """Dependency of every route (``create_app``): when ``Settings.server.read_require_token``
    is set, a GET other than :data:`PUBLIC_READS` needs the admin token or a valid token of
    any site and scope — 401 naming the setting without one, 401 as everywhere for an
    unknown, revoked or expired one. A token of one site reads every site's data: the
    setting keeps out who has no token; it does not part the sites of one service. Other
    methods are the routes' own (writes need a token of their site and scope; the
    simulations, sweeps and vision analysis keep their anonymous allowances)."""
    settings: Settings = request.app.state.settings
    if not settings.server.read_require_token or request.method not in ("GET", "HEAD"):
        return
    route = request.scope.get("route")
    if getattr(route, "path", None) in PUBLIC_READS:
        return
    if await caller_of(request.app.state.ctx, request.headers.get("authorization")) is None:
        raise HTTPException(401, READ_TOKEN_REQUIRED, headers=_BEARER)


SiteAdminDep = Annotated[str, Depends(require_site_admin)]
CallerDep = Annotated[Caller, Depends(optional_caller)]
VisionTokenDep = Annotated[str | None, Depends(vision_token)]


def client_address(request: Request) -> str:
    """The caller's address (``request.client.host``; behind a proxy, ``heliotwin serve
    --forwarded-allow-ips`` (or ``FORWARDED_ALLOW_IPS``) makes it the client's), by which
    anonymous work is counted."""
    return request.client.host if request.client else "?"


async def anonymous_read(request: Request, caller: CallerDep) -> AsyncIterator[None]:
    """Dependency of a read of a site's data: without a token, 429 with ``Retry-After``
    when the caller's address has spent its allowance in the last minute
    (``HELIOTWIN_ANONYMOUS_READ_CPU_S_PER_MIN``); the read is then charged the CPU time
    its :func:`backend.limits.metered` work took — the handler's and, as the exit code of
    this dependency runs once the response is sent, its streamed body's. A caller with a
    valid token is not limited (a bad token is a 401)."""
    if caller is not None:
        yield
        return
    limits = request.app.state.ctx.limits
    try:
        charge = limits.admit_read(client_address(request))
    except Busy as exc:
        raise HTTPException(exc.status_code, exc.message, headers=exc.headers) from None
    meter = start_meter()
    try:
        yield
    finally:
        limits.reads.settle(charge, meter.cpu_s)


#: The answers :func:`anonymous_read` adds to a route's OpenAPI ``responses``.
_ANONYMOUS_READ_RESPONSES: dict[int | str, dict[str, Any]] = {
    401: {"description": "a token was sent but is unknown, expired or revoked"},
    429: {"description": "without a token, this address's CPU time of reads in the last "
                         "minute is spent (HELIOTWIN_ANONYMOUS_READ_CPU_S_PER_MIN); see "
                         "Retry-After"}}


def anonymous_read_route(responses: dict[int | str, dict[str, Any]]) -> dict[str, Any]:
    """The arguments of a read route (``@router.get(path, **anonymous_read_route({...}))``):
    :func:`anonymous_read` as a dependency, its 401 and 429 beside the route's ``responses``,
    and a ``security`` of anonymous or a bearer token (not limited)."""
    return {"dependencies": [Depends(anonymous_read)],
            "responses": {**responses, **_ANONYMOUS_READ_RESPONSES},
            "openapi_extra": {"security": [{}, {"bearerAuth": []}]}}

RangeStart = Annotated[str, Query(min_length=1, max_length=64,
                                  description="date (site midnight) or ISO date-time, inclusive")]
"""The ``start`` of a site's range query (``backend.timestamps.parse_range`` reads it)."""
RangeEnd = Annotated[str, Query(min_length=1, max_length=64,
                                description="date or ISO date-time, exclusive")]
"""The ``end`` of a site's range query."""
