"""``/api/v1/tokens``: the write tokens (admin)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field


class TokenRead(BaseModel):
    """A write token as stored: never the token itself, only its prefix."""

    id: int
    site_id: str
    token_prefix: str
    label: str
    scope: Literal["ingest", "site"] = Field(
        description="ingest: writes readings only; site: also edits the site, its "
                    "calibrations and the shared 3D replay, and acknowledges its alerts")
    created_at: str = Field(description="UTC, ISO 8601")
    expires_at: str | None
    revoked_at: str | None
    status: Literal["active", "expired", "revoked"]


class TokenCreatedRead(TokenRead):
    """A new token: the only answer that holds it (``token``)."""

    token: str


class TokensRead(BaseModel):
    """Every write token (of one site with ``site_id``)."""

    tokens: list[TokenRead]
