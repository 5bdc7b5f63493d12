"""The per-day diagnosis cache (``diagnosis_days``, issue 13): one JSON payload per site
and local day, deleted by the writer when readings of that day arrive.

Revision ID: 0005_diagnosis
Revises: 0004_calibration_names
Create Date: 2026-12-02
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005_diagnosis"
down_revision = "0004_calibration_names"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "diagnosis_days",
        sa.Column("site_id", sa.String(64), sa.ForeignKey("sites.site_id", ondelete="CASCADE"),
                  primary_key=True),
        sa.Column("day_start_s", sa.BigInteger, primary_key=True),
        sa.Column("day_end_s", sa.BigInteger, nullable=False),
        sa.Column("payload_json", sa.Text, nullable=False),
    )


def downgrade() -> None:
    op.drop_table("diagnosis_days")
