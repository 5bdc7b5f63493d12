"""A vision calibration's id is never given again (SQLite ``AUTOINCREMENT``).

Without it SQLite hands out the highest id again after that row is deleted: a tab that
still listed the deleted calibration's id silently ran detection with the next one fitted
(another camera; a tester's finding). The table is rebuilt with ``AUTOINCREMENT`` (its
rows, ids and indexes kept); PostgreSQL's sequence never reuses an id and is left alone.

Revision ID: 0012_calibration_ids
Revises: 0011_wind_speed
Create Date: 2026-12-05
"""

from __future__ import annotations

from alembic import op

revision = "0012_calibration_ids"
down_revision = "0011_wind_speed"
branch_labels = None
depends_on = None

_TABLE = "vision_calibrations"


def upgrade() -> None:
    if op.get_bind().dialect.name == "sqlite":
        with op.batch_alter_table(_TABLE, recreate="always",
                                  table_kwargs={"sqlite_autoincrement": True}):
            pass


def downgrade() -> None:
    """Back to 0011: ids may be reused again."""
    if op.get_bind().dialect.name == "sqlite":
        with op.batch_alter_table(_TABLE, recreate="always",
                                  table_kwargs={"sqlite_autoincrement": False}):
            pass
