"""Vision tables: stored sun detections and fisheye calibrations (``backend/vision/store.py``).

Revision ID: 0002_vision
Revises: 0001_initial
Create Date: 2026-11-22
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002_vision"
down_revision = "0001_initial"
branch_labels = None
depends_on = None

_TZ = sa.DateTime(timezone=True)


def upgrade() -> None:
    op.create_table(
        "vision_calibrations",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("created_at", _TZ, nullable=False),
        sa.Column("site_id", sa.String(64), nullable=True),
        sa.Column("latitude_deg", sa.Float, nullable=False),
        sa.Column("longitude_deg", sa.Float, nullable=False),
        sa.Column("elevation_m", sa.Float, nullable=False),
        sa.Column("projection", sa.String(16), nullable=False),
        sa.Column("cx_px", sa.Float, nullable=False),
        sa.Column("cy_px", sa.Float, nullable=False),
        sa.Column("px_per_deg", sa.Float, nullable=False),
        sa.Column("north_offset_deg", sa.Float, nullable=False),
        sa.Column("east", sa.String(8), nullable=False),
        sa.Column("radial_coeffs_json", sa.Text, nullable=False),
        sa.Column("tilt_north_deg", sa.Float, nullable=False),
        sa.Column("tilt_east_deg", sa.Float, nullable=False),
        sa.Column("image_width_px", sa.Integer, nullable=False),
        sa.Column("image_height_px", sa.Integer, nullable=False),
        sa.Column("n_frames", sa.Integer, nullable=False),
        sa.Column("rms_px", sa.Float, nullable=False),
        sa.Column("max_px", sa.Float, nullable=False),
        sa.Column("rms_deg", sa.Float, nullable=False),
        sa.Column("max_deg", sa.Float, nullable=False),
        sa.Column("frames_json", sa.Text, nullable=False),
    )
    op.create_table(
        "vision_detections",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("created_at", _TZ, nullable=False),
        sa.Column("ts_ms", sa.BigInteger, nullable=True),
        sa.Column("site_id", sa.String(64), nullable=True),
        sa.Column("latitude_deg", sa.Float, nullable=True),
        sa.Column("longitude_deg", sa.Float, nullable=True),
        sa.Column("camera", sa.String(16), nullable=False),
        sa.Column(
            "calibration_id", sa.Integer,
            sa.ForeignKey("vision_calibrations.id", ondelete="SET NULL"), nullable=True,
        ),
        sa.Column("method", sa.String(32), nullable=False),
        sa.Column("image_width_px", sa.Integer, nullable=False),
        sa.Column("image_height_px", sa.Integer, nullable=False),
        sa.Column("sun_found", sa.Boolean, nullable=False),
        sa.Column("confidence", sa.Float, nullable=False),
        sa.Column("centroid_x_px", sa.Float, nullable=True),
        sa.Column("centroid_y_px", sa.Float, nullable=True),
        sa.Column("azimuth_deg", sa.Float, nullable=True),
        sa.Column("elevation_deg", sa.Float, nullable=True),
        sa.Column("pointing_error_horizontal_deg", sa.Float, nullable=True),
        sa.Column("pointing_error_vertical_deg", sa.Float, nullable=True),
        sa.Column("pointing_error_mrad", sa.Float, nullable=True),
        sa.Column("ephemeris_azimuth_deg", sa.Float, nullable=True),
        sa.Column("ephemeris_elevation_deg", sa.Float, nullable=True),
        sa.Column("error_deg", sa.Float, nullable=True),
    )
    op.create_index("ix_vision_detections_site_ts", "vision_detections", ["site_id", "ts_ms"])


def downgrade() -> None:
    op.drop_index("ix_vision_detections_site_ts", table_name="vision_detections")
    op.drop_table("vision_detections")
    op.drop_table("vision_calibrations")
