"""Token scopes (issue 23, item 7): ``logger_tokens.scope``, ``ingest`` or ``site``.

Every token stored before is a field logger's, so it becomes ``ingest`` (write
readings only) by the column's server default; ``site`` tokens (edit the site,
its calibrations and the shared 3D replay) are made from now on with
``heliotwin token create --scope site``. ``backend/auth.py`` checks the value.

Revision ID: 0008_token_scopes
Revises: 0007_alerts
Create Date: 2026-12-03
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0008_token_scopes"
down_revision = "0007_alerts"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.add_column("logger_tokens", sa.Column("scope", sa.String(16), nullable=False,
                                             server_default="ingest"))


def downgrade() -> None:
    with op.batch_alter_table("logger_tokens") as batch:
        batch.drop_column("scope")
