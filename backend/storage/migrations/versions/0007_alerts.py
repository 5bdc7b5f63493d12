"""Alerts (issue 13, item 7): ``alerts``, one row per raised condition of a site's array —
a silent logger, a diagnosis fault, a low performance ratio — with its state
(``active``/``cleared``), times in UTC Unix seconds, the plain-words detail and the
delivery of its latest event to the webhook (``backend/alerts/``).

Revision ID: 0007_alerts
Revises: 0006_measured_fields
Create Date: 2026-12-02
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0007_alerts"
down_revision = "0006_measured_fields"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "alerts",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("site_id", sa.String(64), sa.ForeignKey("sites.site_id", ondelete="CASCADE"),
                  nullable=False),
        sa.Column("array_name", sa.String(64), nullable=False),
        sa.Column("kind", sa.String(32), nullable=False),
        sa.Column("fault_kind", sa.String(32), nullable=True),
        sa.Column("state", sa.String(16), nullable=False),
        sa.Column("since_s", sa.BigInteger, nullable=False),
        sa.Column("raised_at_s", sa.BigInteger, nullable=False),
        sa.Column("cleared_at_s", sa.BigInteger, nullable=True),
        sa.Column("detail", sa.Text, nullable=False),
        sa.Column("cleared_detail", sa.Text, nullable=True),
        sa.Column("data_json", sa.Text, nullable=False),
        sa.Column("webhook_status", sa.String(16), nullable=False),
        sa.Column("webhook_attempts", sa.Integer, nullable=False, server_default="0"),
        sa.CheckConstraint("state IN ('active', 'cleared')", name="ck_alerts_state"),
    )
    op.create_index("ix_alerts_site_state", "alerts", ["site_id", "state"])
    op.create_index("ix_alerts_raised_at", "alerts", ["raised_at_s"])


def downgrade() -> None:
    op.drop_index("ix_alerts_raised_at", table_name="alerts")
    op.drop_index("ix_alerts_site_state", table_name="alerts")
    op.drop_table("alerts")
