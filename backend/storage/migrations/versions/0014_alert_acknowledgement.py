"""Alert acknowledgement: an operator says "seen, someone is on it" (docs/service.md, "Alerts").

``alerts`` gains three nullable columns, null until the alert is acknowledged (and for
every alert stored before): ``acknowledged_at_s`` (UTC Unix seconds, as the table's other
times), ``acknowledged_by`` (the token's label, ``token #<id>`` for a token without one,
or ``admin``) and ``acknowledged_note`` (at most 280 characters). An alert is acknowledged
once, while active (``POST /api/v1/alerts/{alert_id}/acknowledge``).

Revision ID: 0014_alert_acknowledgement
Revises: 0013_service_state
Create Date: 2026-12-05
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0014_alert_acknowledgement"
down_revision = "0013_service_state"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.add_column("alerts", sa.Column("acknowledged_at_s", sa.BigInteger, nullable=True))
    op.add_column("alerts", sa.Column("acknowledged_by", sa.String(200), nullable=True))
    op.add_column("alerts", sa.Column("acknowledged_note", sa.String(280), nullable=True))


def downgrade() -> None:
    """Back to 0013: who acknowledged which alert is forgotten."""
    with op.batch_alter_table("alerts") as batch:
        batch.drop_column("acknowledged_note")
        batch.drop_column("acknowledged_by")
        batch.drop_column("acknowledged_at_s")
