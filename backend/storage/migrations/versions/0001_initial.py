"""Core tables: sites, arrays (with logger calibration), logger tokens, measurements,
hourly rollups, twin coverage, simulation runs and their series.

Revision ID: 0001_initial
Revises:
Create Date: 2026-11-22
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0001_initial"
down_revision = None
branch_labels = None
depends_on = None

_TZ = sa.DateTime(timezone=True)


def upgrade() -> None:
    op.create_table(
        "sites",
        sa.Column("site_id", sa.String(64), primary_key=True),
        sa.Column("name", sa.String(200), nullable=False),
        sa.Column("latitude_deg", sa.Float, nullable=False),
        sa.Column("longitude_deg", sa.Float, nullable=False),
        sa.Column("altitude_m", sa.Float, nullable=False),
        sa.Column("timezone", sa.String(64), nullable=False),
        sa.Column("bucket_phase_s", sa.Integer, nullable=False),
        sa.Column("config_json", sa.Text, nullable=False),
        sa.Column("updated_at", _TZ, nullable=False),
    )
    op.create_table(
        "arrays",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column(
            "site_id", sa.String(64),
            sa.ForeignKey("sites.site_id", ondelete="CASCADE"), nullable=False,
        ),
        sa.Column("name", sa.String(64), nullable=False),
        sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("config_json", sa.Text, nullable=False),
        sa.Column("adc_bits", sa.Integer, nullable=False),
        sa.Column("adc_vref_v", sa.Float, nullable=False),
        sa.Column("current_zero_v", sa.Float, nullable=False),
        sa.Column("current_sensitivity_mv_per_a", sa.Float, nullable=False),
        sa.Column("divider_ratio", sa.Float, nullable=False),
        sa.UniqueConstraint("site_id", "name", name="uq_arrays_site_name"),
    )
    op.create_table(
        "logger_tokens",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column(
            "site_id", sa.String(64),
            sa.ForeignKey("sites.site_id", ondelete="CASCADE"), nullable=False,
        ),
        sa.Column("token_sha256", sa.String(64), nullable=False, unique=True),
        sa.Column("token_prefix", sa.String(12), nullable=False),
        sa.Column("label", sa.String(200), nullable=False),
        sa.Column("created_at", _TZ, nullable=False),
    )
    def series_key() -> list[sa.Column]:
        return [
            sa.Column(
                "array_id", sa.Integer,
                sa.ForeignKey("arrays.id", ondelete="CASCADE"), primary_key=True,
            ),
            sa.Column("source", sa.SmallInteger, primary_key=True),
        ]

    op.create_table(
        "measurements",
        *series_key(),
        sa.Column("ts_s", sa.BigInteger, primary_key=True),
        sa.Column("voltage_v", sa.Float, nullable=False),
        sa.Column("current_a", sa.Float, nullable=False),
        sa.Column("power_w", sa.Float, nullable=False),
        sa.CheckConstraint("source IN (0, 1)", name="ck_measurements_source"),
        sqlite_with_rowid=False,
    )
    op.create_table(
        "measurement_rollups",
        *series_key(),
        sa.Column("bucket_s", sa.BigInteger, primary_key=True),
        sa.Column("n", sa.Integer, nullable=False),
        sa.Column("energy_wh", sa.Float, nullable=False),
        *[
            sa.Column(f"{agg}_{q}", sa.Float, nullable=False)
            for agg in ("sum", "min", "max")
            for q in ("voltage_v", "current_a", "power_w")
        ],
        sa.Column("first_ts_s", sa.BigInteger, nullable=False),
        sa.Column("last_ts_s", sa.BigInteger, nullable=False),
        sqlite_with_rowid=False,
    )
    op.create_table(
        "twin_coverage",
        sa.Column(
            "site_id", sa.String(64),
            sa.ForeignKey("sites.site_id", ondelete="CASCADE"), primary_key=True,
        ),
        sa.Column("day_start_s", sa.BigInteger, primary_key=True),
        sa.Column("covered_until_s", sa.BigInteger, nullable=False),
    )
    op.create_table(
        "simulation_runs",
        sa.Column("run_id", sa.String(32), primary_key=True),
        sa.Column(
            "site_id", sa.String(64),
            sa.ForeignKey("sites.site_id", ondelete="CASCADE"), nullable=False,
        ),
        sa.Column("params_json", sa.Text, nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("progress", sa.Float, nullable=False),
        sa.Column("summary_json", sa.Text, nullable=True),
        sa.Column("error", sa.Text, nullable=True),
        sa.Column("created_at", _TZ, nullable=False),
        sa.Column("finished_at", _TZ, nullable=True),
    )
    op.create_table(
        "simulation_series",
        sa.Column(
            "run_id", sa.String(32),
            sa.ForeignKey("simulation_runs.run_id", ondelete="CASCADE"), primary_key=True,
        ),
        sa.Column("npz", sa.LargeBinary, nullable=False),
    )


def downgrade() -> None:
    for table in (
        "simulation_series", "simulation_runs", "twin_coverage", "measurement_rollups",
        "measurements", "logger_tokens", "arrays", "sites",
    ):
        op.drop_table(table)
