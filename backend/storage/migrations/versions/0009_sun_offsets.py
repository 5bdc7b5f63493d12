"""The sun's offset in the tracker camera (issue 25): two optional reading columns.

``measurements`` gains the nullable ``sun_offset_x_mrad`` and ``sun_offset_y_mrad``
(``backend/measurements/fields.py``, the pointing model's observations);
``measurement_rollups`` a sum and a count for each, 0 for the hours stored before
(no reading of theirs carried an offset). Both dialects add the columns in place:
the rollup columns are added with a server default of 0, which PostgreSQL then
drops (the writer always sets them; SQLite cannot drop a default in place and
keeps it, harmlessly).

Revision ID: 0009_sun_offsets
Revises: 0008_token_scopes
Create Date: 2026-12-03
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0009_sun_offsets"
down_revision = "0008_token_scopes"
branch_labels = None
depends_on = None

OFFSETS = ("sun_offset_x_mrad", "sun_offset_y_mrad")


def _rollup_columns() -> list[tuple[str, type[sa.types.TypeEngine]]]:
    return [(f"sum_{c}", sa.Float) for c in OFFSETS] + [(f"n_{c}", sa.Integer) for c in OFFSETS]


def upgrade() -> None:
    for c in OFFSETS:
        op.add_column("measurements", sa.Column(c, sa.Float, nullable=True))
    for name, kind in _rollup_columns():
        op.add_column("measurement_rollups",
                      sa.Column(name, kind, nullable=False, server_default="0"))
    if op.get_bind().dialect.name != "sqlite":
        for name, kind in _rollup_columns():
            op.alter_column("measurement_rollups", name, existing_type=kind, server_default=None)


def downgrade() -> None:
    """Back to 0008: the offsets and their rollup sums are dropped."""
    with op.batch_alter_table("measurement_rollups", recreate="never") as batch:
        for name, _ in _rollup_columns():
            batch.drop_column(name)
    with op.batch_alter_table("measurements", recreate="never") as batch:
        for c in OFFSETS:
            batch.drop_column(c)
