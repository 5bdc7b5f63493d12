"""Anonymous calibrations marked (issue 23 item 4): ``vision_calibrations.anonymous``.

A calibration fitted without a token is kept only within the retention limit of
detections (``Settings.vision.anonymous_keep_rows``, ``backend/limits.py``
``prune_anonymous``); the ones stored before are taken as made with a token.

Revision ID: 0010_anonymous_calibrations
Revises: 0009_sun_offsets
Create Date: 2026-12-03
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0010_anonymous_calibrations"
down_revision = "0009_sun_offsets"
branch_labels = None
depends_on = None

_TABLE = "vision_calibrations"


def upgrade() -> None:
    op.add_column(_TABLE, sa.Column("anonymous", sa.Boolean, nullable=False,
                                    server_default=sa.false()))
    op.create_index(f"ix_{_TABLE}_anonymous_created", _TABLE, ["anonymous", "created_at"])


def downgrade() -> None:
    """Back to 0009: the mark is dropped (the calibrations stay)."""
    op.drop_index(f"ix_{_TABLE}_anonymous_created", _TABLE)
    with op.batch_alter_table(_TABLE) as batch:
        batch.drop_column("anonymous")
