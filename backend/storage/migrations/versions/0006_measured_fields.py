"""Power-only readings and optional sensor fields (issues 13 and 14).

``measurements``: ``voltage_v`` and ``current_a`` become nullable (a power-only
logger sends ``power_w`` alone) and six nullable sensor columns are added
(``backend/measurements/fields.py``). ``measurement_rollups``: the extremes become
nullable, ``n_vi`` counts the readings with voltage and current, and a sum and a
count per sensor field are added. Existing rollups get ``n_vi = n``, zero sensor
sums and counts, and NULL extremes where they held the ±inf of a bucket with no
reading.

SQLite cannot change a column's nullability in place, so there both tables are
rebuilt (``WITHOUT ROWID``, as 0001 made them) and their rows copied; PostgreSQL
alters them.

Revision ID: 0006_measured_fields
Revises: 0005_diagnosis
Create Date: 2026-12-02
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0006_measured_fields"
down_revision = "0005_diagnosis"
branch_labels = None
depends_on = None

SENSORS = ("poa_irradiance_w_m2", "ghi_w_m2", "temp_module_c", "temp_air_c", "azimuth_deg",
           "elevation_deg")
ELECTRICAL = ("voltage_v", "current_a", "power_w")
EXTREMES = tuple(f"{agg}_{q}" for agg in ("min", "max") for q in ELECTRICAL)


def _series_key() -> list[sa.Column]:
    return [
        sa.Column("array_id", sa.Integer, sa.ForeignKey("arrays.id", ondelete="CASCADE"),
                  primary_key=True),
        sa.Column("source", sa.SmallInteger, primary_key=True),
    ]


def _measurements(name: str) -> None:
    op.create_table(
        name, *_series_key(),
        sa.Column("ts_s", sa.BigInteger, primary_key=True),
        sa.Column("voltage_v", sa.Float, nullable=True),
        sa.Column("current_a", sa.Float, nullable=True),
        sa.Column("power_w", sa.Float, nullable=False),
        *[sa.Column(c, sa.Float, nullable=True) for c in SENSORS],
        sa.CheckConstraint("source IN (0, 1)", name="ck_measurements_source"),
        sqlite_with_rowid=False,
    )


def _rollups(name: str) -> None:
    op.create_table(
        name, *_series_key(),
        sa.Column("bucket_s", sa.BigInteger, primary_key=True),
        sa.Column("n", sa.Integer, nullable=False),
        sa.Column("energy_wh", sa.Float, nullable=False),
        *[sa.Column(f"sum_{q}", sa.Float, nullable=False) for q in ELECTRICAL],
        *[sa.Column(c, sa.Float, nullable=True) for c in EXTREMES],
        sa.Column("first_ts_s", sa.BigInteger, nullable=False),
        sa.Column("last_ts_s", sa.BigInteger, nullable=False),
        sa.Column("n_vi", sa.Integer, nullable=False),
        *[sa.Column(f"sum_{c}", sa.Float, nullable=False) for c in SENSORS],
        *[sa.Column(f"n_{c}", sa.Integer, nullable=False) for c in SENSORS],
        sqlite_with_rowid=False,
    )


def _extreme(c: str) -> str:
    return f"CASE WHEN n = 0 THEN NULL ELSE {c} END"


def upgrade() -> None:
    if op.get_bind().dialect.name == "sqlite":
        _measurements("measurements_0006")
        op.execute("INSERT INTO measurements_0006 (array_id, source, ts_s, voltage_v, current_a, "
                   "power_w) SELECT array_id, source, ts_s, voltage_v, current_a, power_w "
                   "FROM measurements")
        op.drop_table("measurements")
        op.rename_table("measurements_0006", "measurements")
        _rollups("measurement_rollups_0006")
        kept = ("array_id", "source", "bucket_s", "n", "energy_wh",
                *(f"sum_{q}" for q in ELECTRICAL), "first_ts_s", "last_ts_s")
        op.execute(
            f"INSERT INTO measurement_rollups_0006 ({', '.join(kept)}, {', '.join(EXTREMES)}, "
            f"n_vi, {', '.join(f'sum_{c}' for c in SENSORS)}, "
            f"{', '.join(f'n_{c}' for c in SENSORS)}) "
            f"SELECT {', '.join(kept)}, {', '.join(_extreme(c) for c in EXTREMES)}, n, "
            f"{', '.join(['0.0'] * len(SENSORS))}, {', '.join(['0'] * len(SENSORS))} "
            "FROM measurement_rollups")
        op.drop_table("measurement_rollups")
        op.rename_table("measurement_rollups_0006", "measurement_rollups")
        return
    for c in ("voltage_v", "current_a"):
        op.alter_column("measurements", c, existing_type=sa.Float, nullable=True)
    for c in SENSORS:
        op.add_column("measurements", sa.Column(c, sa.Float, nullable=True))
    for c in EXTREMES:
        op.alter_column("measurement_rollups", c, existing_type=sa.Float, nullable=True)
        op.execute(f"UPDATE measurement_rollups SET {c} = NULL WHERE n = 0")
    added: list[tuple[str, type[sa.types.TypeEngine], str]] = [("n_vi", sa.Integer, "n")]
    added += [(f"sum_{c}", sa.Float, "0") for c in SENSORS]
    added += [(f"n_{c}", sa.Integer, "0") for c in SENSORS]
    for name, kind, _ in added:
        op.add_column("measurement_rollups", sa.Column(name, kind, nullable=True))
    op.execute(f"UPDATE measurement_rollups SET {', '.join(f'{n} = {v}' for n, _, v in added)}")
    for name, kind, _ in added:
        op.alter_column("measurement_rollups", name, existing_type=kind, nullable=False)


def downgrade() -> None:
    """Back to 0005: the sensor columns are dropped; power-only readings, which 0005
    cannot hold, are deleted with the rollups of their hours (their energy is lost).
    Voltage, current and the extremes stay nullable, which 0005's code never minds."""
    op.execute("DELETE FROM measurements WHERE voltage_v IS NULL OR current_a IS NULL")
    op.execute("DELETE FROM measurement_rollups WHERE n_vi < n")
    with op.batch_alter_table("measurement_rollups", recreate="never") as batch:
        for c in ("n_vi", *(f"sum_{c}" for c in SENSORS), *(f"n_{c}" for c in SENSORS)):
            batch.drop_column(c)
    with op.batch_alter_table("measurements", recreate="never") as batch:
        for c in SENSORS:
            batch.drop_column(c)
