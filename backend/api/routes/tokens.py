"""``/api/v1/tokens``: the write tokens, for an administrator (``HELIOTWIN_ADMIN_TOKEN``).

The same operations as ``heliotwin token create|list|revoke`` (``backend/auth.py``),
authenticated by ``Authorization: Bearer <admin token>`` where the admin token is
the setting ``HELIOTWIN_ADMIN_TOKEN`` (unset: these endpoints answer 403). A
site's token (scope ``ingest`` or ``site``) is not an admin token. A revocation
here is refused by this service at once (its cache forgets the token); writes go
through the writer.
"""

from __future__ import annotations

import asyncio
import datetime as dt
from typing import Annotated, Any, Literal

import anyio
import orjson
from fastapi import APIRouter, Depends, HTTPException, Path, Query, Request
from fastapi.responses import Response
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, StringConstraints
from sqlalchemy import Connection

from backend.api.deps import (
    ContextDep,
    is_admin_token,
    parse_bearer,
    site_or_404,
    token_grant,
)
from backend.api.schemas.tokens import TokenCreatedRead, TokenRead, TokensRead
from backend.auth import (
    TokenRefused,
    UnknownToken,
    create_token,
    find_token,
    list_tokens,
    revoke_token,
)
from backend.text import one_line
from backend.timestamps import TimestampError, parse_instant

router = APIRouter(prefix="/api/v1/tokens", tags=["tokens"])

_ADMIN_DOC: dict[str, Any] = {"security": [{"bearerAuth": []}]}
_RESPONSES: dict[int | str, dict[str, Any]] = {
    401: {"description": "no admin token, or a wrong one"},
    403: {"description": "admin endpoints are disabled (HELIOTWIN_ADMIN_TOKEN unset), or a "
                         "valid site token (not allowed here)"},
}


async def require_admin(request: Request) -> None:
    """Dependency: ``Authorization: Bearer`` equal to ``Settings.server.admin_token``."""
    expected = request.app.state.settings.server.admin_token
    if not expected:
        raise HTTPException(403, "admin endpoints are disabled: set HELIOTWIN_ADMIN_TOKEN "
                                 "(or use `heliotwin token` on the server)")
    token = parse_bearer(request.headers.get("authorization"))
    if is_admin_token(request.app.state.settings, token):
        return
    if token is not None:  # a valid site token is authenticated, only not allowed here
        try:
            grant = await token_grant(request.app.state.ctx, token)
        except TokenRefused:
            pass
        else:
            article = "an" if grant.scope[:1] in tuple("aeiou") else "a"  # an ingest-, a site-
            raise HTTPException(403, f"{article} {grant.scope}-scope token of site "
                                     f"{grant.site_id!r} "
                                     "cannot manage tokens: send the admin token "
                                     "(HELIOTWIN_ADMIN_TOKEN)")
    raise HTTPException(401, "admin token required: send 'Authorization: Bearer "
                             "<HELIOTWIN_ADMIN_TOKEN>'",
                        headers={"WWW-Authenticate": "Bearer"})


AdminDep = Annotated[None, Depends(require_admin)]
_TOKEN_ID = Annotated[int, Path(ge=1, le=2**31 - 1, description="the id `list` shows")]


class TokenCreate(BaseModel):
    """A new write token for a site; strict, as every request model (``true`` is not a
    number of days: it made a token expiring in one)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)

    site_id: str = Field(..., min_length=1, max_length=64, examples=["tehuantepec"])
    label: Annotated[str, StringConstraints(max_length=200), AfterValidator(one_line)] = Field(
        "", description="a note to recognise the token by, one line (no "
                                        "control characters: backend.text.one_line); "
                                        "shown as who acknowledged an alert")
    scope: Literal["ingest", "site"] = Field(
        "ingest", description="ingest: a field device, writes readings only; site: also "
                              "edits the site, its calibrations and the shared 3D replay, "
                              "and acknowledges its alerts")
    expires_in_days: float | None = Field(None, gt=0, le=36_600,
                                          description="refused after this many days [d]")
    expires_at: str | None = Field(None, description="refused from this instant (ISO 8601 "
                                                     "with offset); not with expires_in_days")


def _json(data: Any, status: int = 200) -> Response:
    return Response(orjson.dumps(data), status_code=status, media_type="application/json")


@router.get("", response_model=TokensRead, openapi_extra=_ADMIN_DOC,
            responses={**_RESPONSES, 404: {"description": "unknown site"}})
async def get_tokens(ctx: ContextDep, _admin: AdminDep,
                     site_id: Annotated[str | None, Query(max_length=64)] = None) -> Response:
    """Every write token (of one site with ``site_id``): id, prefix, times, status."""
    if site_id is not None:
        site_or_404(ctx, site_id, "site_id")

    def read() -> list[dict[str, Any]]:
        with ctx.engine.connect() as conn:
            return [t.to_dict() for t in list_tokens(conn, site_id)]

    return _json({"tokens": await anyio.to_thread.run_sync(read)})


@router.post("", status_code=201, response_model=TokenCreatedRead, openapi_extra=_ADMIN_DOC,
             responses={**_RESPONSES, 404: {"description": "unknown site"}, 422: {}})
async def post_token(body: TokenCreate, ctx: ContextDep, _admin: AdminDep) -> Response:
    """Make a write token; the answer holds it once (``token``), with its ``id``."""
    site_or_404(ctx, body.site_id, "site_id")
    if body.expires_in_days is not None and body.expires_at is not None:
        raise HTTPException(422, "expires_at: give expires_at or expires_in_days, not both")
    now = dt.datetime.now(dt.UTC)
    expires = None
    if body.expires_in_days is not None:
        expires = now + dt.timedelta(days=body.expires_in_days)
    elif body.expires_at is not None:
        try:
            expires = parse_instant(body.expires_at, "expires_at")
        except TimestampError as exc:
            raise HTTPException(422, str(exc)) from None
        if expires <= now:
            raise HTTPException(422, f"expires_at: {body.expires_at} is in the past")

    def make(conn: Connection) -> dict[str, Any]:
        token = create_token(conn, body.site_id, body.label, expires, body.scope)
        return {**find_token(conn, token)[0].to_dict(), "token": token}

    return _json(await asyncio.wrap_future(ctx.writer.call(make)), 201)


@router.delete("/{token_id}", response_model=TokenRead, openapi_extra=_ADMIN_DOC,
               responses={**_RESPONSES, 404: {"description": "no such token"}})
async def delete_token(token_id: _TOKEN_ID, ctx: ContextDep, _admin: AdminDep) -> Response:
    """Revoke a token (refused from now on); the answer is its row with ``revoked_at``."""
    try:
        info, digest = await asyncio.wrap_future(
            ctx.writer.call(lambda conn: revoke_token(conn, token_id)))
    except UnknownToken as exc:
        raise HTTPException(404, f"token_id: {exc}") from None
    ctx.tokens.forget(digest)
    return _json(info.to_dict())
