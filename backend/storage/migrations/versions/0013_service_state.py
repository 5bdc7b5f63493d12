"""``service_state``: what the stored data was computed under.

Its first key, ``rollup_energy_max_gap_s``, is the energy gap the hourly rollups' energy
bridged. Raising ``HELIOTWIN_ENERGY_MAX_GAP_S`` for an hourly logger left the hours stored
before at 0 Wh, shown as full coverage (a tester's finding): the writer now recomputes the
rollups' energy when the gap differs from the one recorded here (or none is, as after
this migration), and drops the cached diagnosis days.

Revision ID: 0013_service_state
Revises: 0012_calibration_ids
Create Date: 2026-12-05
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0013_service_state"
down_revision = "0012_calibration_ids"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "service_state",
        sa.Column("key", sa.String(64), primary_key=True),
        sa.Column("value", sa.Text, nullable=False),
    )


def downgrade() -> None:
    """Back to 0012: the rollups' gap is not recorded."""
    op.drop_table("service_state")
