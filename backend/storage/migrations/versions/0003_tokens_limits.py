"""Revocable, expiring write tokens; anonymous simulation runs and detections marked.

- ``logger_tokens.expires_at`` / ``revoked_at``: a token past either is refused
  (``backend/auth.py``; ``heliotwin token revoke``, ``DELETE /api/v1/tokens/{id}``).
- ``simulation_runs.anonymous`` and ``vision_detections.anonymous``: asked without a
  token, so kept only within the retention limits of ``backend/limits.py``.

Revision ID: 0003_tokens_limits
Revises: 0002_vision
Create Date: 2026-12-01
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003_tokens_limits"
down_revision = "0002_vision"
branch_labels = None
depends_on = None

_TZ = sa.DateTime(timezone=True)


def upgrade() -> None:
    op.add_column("logger_tokens", sa.Column("expires_at", _TZ, nullable=True))
    op.add_column("logger_tokens", sa.Column("revoked_at", _TZ, nullable=True))
    for table in ("simulation_runs", "vision_detections"):
        op.add_column(table, sa.Column("anonymous", sa.Boolean, nullable=False,
                                       server_default=sa.false()))
        op.create_index(f"ix_{table}_anonymous_created", table, ["anonymous", "created_at"])


def downgrade() -> None:
    for table in ("simulation_runs", "vision_detections"):
        op.drop_index(f"ix_{table}_anonymous_created", table)
        with op.batch_alter_table(table) as batch:
            batch.drop_column("anonymous")
    with op.batch_alter_table("logger_tokens") as batch:
        batch.drop_column("revoked_at")
        batch.drop_column("expires_at")
