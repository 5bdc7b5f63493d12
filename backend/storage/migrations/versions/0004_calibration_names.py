"""Fisheye calibrations get a name (``vision_calibrations.name``), so a person can tell
them apart in the dashboard and delete the one that is wrong.

Revision ID: 0004_calibration_names
Revises: 0003_tokens_limits
Create Date: 2026-12-02
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004_calibration_names"
down_revision = "0003_tokens_limits"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("vision_calibrations") as batch:
        batch.add_column(sa.Column("name", sa.String(100), nullable=False, server_default=""))


def downgrade() -> None:
    with op.batch_alter_table("vision_calibrations") as batch:
        batch.drop_column("name")
