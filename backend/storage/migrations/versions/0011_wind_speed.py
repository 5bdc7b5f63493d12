"""A measured wind speed (issue 27): one optional reading column and its rollup sums.

``measurements`` gains the nullable ``wind_speed_m_s`` (an anemometer's mean,
``backend/measurements/fields.py``; the diagnosis's cell temperature takes it instead
of the site's default wind); ``measurement_rollups`` its sum and count, 0 for the
hours stored before (no reading of theirs carried a wind). The rollup columns are
added with a server default of 0 that PostgreSQL then drops (the writer always sets
them); SQLite cannot drop a default in place and keeps it, harmlessly.

Revision ID: 0011_wind_speed
Revises: 0010_anonymous_calibrations
Create Date: 2026-12-04
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0011_wind_speed"
down_revision = "0010_anonymous_calibrations"
branch_labels = None
depends_on = None

FIELD = "wind_speed_m_s"
ROLLUP = ((f"sum_{FIELD}", sa.Float), (f"n_{FIELD}", sa.Integer))


def upgrade() -> None:
    op.add_column("measurements", sa.Column(FIELD, sa.Float, nullable=True))
    for name, kind in ROLLUP:
        op.add_column("measurement_rollups",
                      sa.Column(name, kind, nullable=False, server_default="0"))
        if op.get_bind().dialect.name != "sqlite":
            op.alter_column("measurement_rollups", name, existing_type=kind,
                            server_default=None)


def downgrade() -> None:
    """Back to 0010: the wind speeds and their rollup sums are dropped."""
    with op.batch_alter_table("measurement_rollups", recreate="never") as batch:
        for name, _ in ROLLUP:
            batch.drop_column(name)
    with op.batch_alter_table("measurements", recreate="never") as batch:
        batch.drop_column(FIELD)
