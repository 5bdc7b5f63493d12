"""ORM classes of the core tables (SQLAlchemy 2 declarative).

Times at rest are UTC: measurement keys are integer Unix seconds (``ts_s``),
which are unambiguous, compact, and identical on SQLite and PostgreSQL.
``measurements`` and ``measurement_rollups`` are ``WITHOUT ROWID`` on SQLite, so
the primary key is the table's clustered order and range scans per series are
sequential. The schema itself is created by Alembic (``backend/storage/migrations``);
``tests/backend/test_migrations.py`` checks that these classes and the
migrations agree.
"""

from __future__ import annotations

import datetime as dt

from sqlalchemy import (
    BigInteger,
    Boolean,
    CheckConstraint,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    SmallInteger,
    String,
    Text,
    UniqueConstraint,
    false,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

#: ``measurements.source`` codes (the API speaks the names).
SOURCE_CODES: dict[str, int] = {"measured": 0, "twin": 1}
SOURCE_NAMES: dict[int, str] = {v: k for k, v in SOURCE_CODES.items()}

#: Longest note an alert's acknowledgement keeps (``alerts.acknowledged_note``).
ACK_NOTE_MAX_CHARS = 280


def utcnow() -> dt.datetime:
    """The current time, tz-aware UTC."""
    return dt.datetime.now(dt.UTC)


class Base(DeclarativeBase):
    """Declarative base of every table (core and ``backend/vision/store.py``)."""


class SiteRow(Base):
    """A site: place, time zone and its config as loaded from ``sim/data/sites/``."""

    __tablename__ = "sites"

    site_id: Mapped[str] = mapped_column(String(64), primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    latitude_deg: Mapped[float] = mapped_column(Float)
    longitude_deg: Mapped[float] = mapped_column(Float)
    altitude_m: Mapped[float] = mapped_column(Float)
    timezone: Mapped[str] = mapped_column(String(64))
    #: Offset of rollup buckets from the Unix hour grid [s], so that local hours
    #: (and so local days and months) start on bucket boundaries.
    bucket_phase_s: Mapped[int] = mapped_column(Integer, default=0)
    config_json: Mapped[str] = mapped_column(Text)
    updated_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class ArrayRow(Base):
    """A PV array of a site (``tracker`` or ``fixed``) and its logger calibration.

    The calibration converts a logger's raw ADC counts (seed 000, eqs. 16–19):
    ``v_adc = counts · adc_vref_v / (2**adc_bits − 1)``; current from the ACS712
    ``I = (v_adc − current_zero_v) / sensitivity`` (eq. 17); panel voltage from the
    resistive divider ``V_in = v_adc · divider_ratio`` with
    ``divider_ratio = (R1 + R2 + R3) / Rx`` (eq. 19 inverted).
    """

    __tablename__ = "arrays"
    __table_args__ = (UniqueConstraint("site_id", "name", name="uq_arrays_site_name"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    site_id: Mapped[str] = mapped_column(ForeignKey("sites.site_id", ondelete="CASCADE"))
    name: Mapped[str] = mapped_column(String(64))
    kind: Mapped[str] = mapped_column(String(16))
    config_json: Mapped[str] = mapped_column(Text)
    adc_bits: Mapped[int] = mapped_column(Integer, default=10)
    adc_vref_v: Mapped[float] = mapped_column(Float, default=5.0)
    current_zero_v: Mapped[float] = mapped_column(Float, default=2.5)
    current_sensitivity_mv_per_a: Mapped[float] = mapped_column(Float, default=100.0)
    divider_ratio: Mapped[float] = mapped_column(Float, default=10.0)


class LoggerToken(Base):
    """A field logger's write token for one site, stored as its SHA-256 hash."""

    __tablename__ = "logger_tokens"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    site_id: Mapped[str] = mapped_column(ForeignKey("sites.site_id", ondelete="CASCADE"))
    token_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    token_prefix: Mapped[str] = mapped_column(String(12))
    label: Mapped[str] = mapped_column(String(200), default="")
    #: ``ingest`` (write readings) or ``site`` (also edit the site): ``backend/auth.py``.
    scope: Mapped[str] = mapped_column(String(16), default="ingest", server_default="ingest")
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    #: Refused from this instant on (None: never expires).
    expires_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True),
                                                           nullable=True)
    #: When it was revoked (None: not revoked); the row stays, for ``token list``.
    revoked_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True),
                                                           nullable=True)


class Measurement(Base):
    """One reading of one array: measured by a logger or expected by the twin."""

    __tablename__ = "measurements"
    __table_args__ = (
        CheckConstraint("source IN (0, 1)", name="ck_measurements_source"),
        {"sqlite_with_rowid": False},
    )

    array_id: Mapped[int] = mapped_column(
        ForeignKey("arrays.id", ondelete="CASCADE"), primary_key=True
    )
    source: Mapped[int] = mapped_column(SmallInteger, primary_key=True)
    ts_s: Mapped[int] = mapped_column(BigInteger, primary_key=True)
    #: NULL on a power-only reading (``backend/measurements/fields.py``)
    voltage_v: Mapped[float | None] = mapped_column(Float, nullable=True)
    current_a: Mapped[float | None] = mapped_column(Float, nullable=True)
    power_w: Mapped[float] = mapped_column(Float)
    # optional sensor fields (SENSOR_FIELDS), NULL when not sent
    poa_irradiance_w_m2: Mapped[float | None] = mapped_column(Float, nullable=True)
    ghi_w_m2: Mapped[float | None] = mapped_column(Float, nullable=True)
    temp_module_c: Mapped[float | None] = mapped_column(Float, nullable=True)
    temp_air_c: Mapped[float | None] = mapped_column(Float, nullable=True)
    azimuth_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    elevation_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    sun_offset_x_mrad: Mapped[float | None] = mapped_column(Float, nullable=True)
    sun_offset_y_mrad: Mapped[float | None] = mapped_column(Float, nullable=True)
    wind_speed_m_s: Mapped[float | None] = mapped_column(Float, nullable=True)


class MeasurementRollup(Base):
    """Per-hour aggregate of one series, maintained by the writer at write time.

    ``energy_wh`` is the trapezoid integral of power over the part of the hour
    covered by consecutive readings no further apart than
    ``Settings.ingest.energy_max_gap_s``, split exactly at the bucket edges.
    """

    __tablename__ = "measurement_rollups"
    __table_args__ = ({"sqlite_with_rowid": False},)

    array_id: Mapped[int] = mapped_column(
        ForeignKey("arrays.id", ondelete="CASCADE"), primary_key=True
    )
    source: Mapped[int] = mapped_column(SmallInteger, primary_key=True)
    bucket_s: Mapped[int] = mapped_column(BigInteger, primary_key=True)
    n: Mapped[int] = mapped_column(Integer)
    energy_wh: Mapped[float] = mapped_column(Float)
    sum_voltage_v: Mapped[float] = mapped_column(Float)
    sum_current_a: Mapped[float] = mapped_column(Float)
    sum_power_w: Mapped[float] = mapped_column(Float)
    # extremes are NULL when no reading of the hour has the value (power-only readings)
    min_voltage_v: Mapped[float | None] = mapped_column(Float, nullable=True)
    max_voltage_v: Mapped[float | None] = mapped_column(Float, nullable=True)
    min_current_a: Mapped[float | None] = mapped_column(Float, nullable=True)
    max_current_a: Mapped[float | None] = mapped_column(Float, nullable=True)
    min_power_w: Mapped[float | None] = mapped_column(Float, nullable=True)
    max_power_w: Mapped[float | None] = mapped_column(Float, nullable=True)
    first_ts_s: Mapped[int] = mapped_column(BigInteger)
    last_ts_s: Mapped[int] = mapped_column(BigInteger)
    #: readings with voltage and current (``n`` minus the power-only ones)
    n_vi: Mapped[int] = mapped_column(Integer)
    sum_poa_irradiance_w_m2: Mapped[float] = mapped_column(Float)
    sum_ghi_w_m2: Mapped[float] = mapped_column(Float)
    sum_temp_module_c: Mapped[float] = mapped_column(Float)
    sum_temp_air_c: Mapped[float] = mapped_column(Float)
    sum_azimuth_deg: Mapped[float] = mapped_column(Float)
    sum_elevation_deg: Mapped[float] = mapped_column(Float)
    n_poa_irradiance_w_m2: Mapped[int] = mapped_column(Integer)
    n_ghi_w_m2: Mapped[int] = mapped_column(Integer)
    n_temp_module_c: Mapped[int] = mapped_column(Integer)
    n_temp_air_c: Mapped[int] = mapped_column(Integer)
    n_azimuth_deg: Mapped[int] = mapped_column(Integer)
    n_elevation_deg: Mapped[int] = mapped_column(Integer)
    sum_sun_offset_x_mrad: Mapped[float] = mapped_column(Float)
    sum_sun_offset_y_mrad: Mapped[float] = mapped_column(Float)
    n_sun_offset_x_mrad: Mapped[int] = mapped_column(Integer)
    n_sun_offset_y_mrad: Mapped[int] = mapped_column(Integer)
    sum_wind_speed_m_s: Mapped[float] = mapped_column(Float)
    n_wind_speed_m_s: Mapped[int] = mapped_column(Integer)


class TwinCoverage(Base):
    """How far the twin series of one site is stored for one local day."""

    __tablename__ = "twin_coverage"

    site_id: Mapped[str] = mapped_column(
        ForeignKey("sites.site_id", ondelete="CASCADE"), primary_key=True
    )
    day_start_s: Mapped[int] = mapped_column(BigInteger, primary_key=True)
    covered_until_s: Mapped[int] = mapped_column(BigInteger)


class DiagnosisDay(Base):
    """The diagnosis of one local day of a site, cached (``backend/diagnosis/service.py``);
    deleted by the writer when readings of that day arrive."""

    __tablename__ = "diagnosis_days"

    site_id: Mapped[str] = mapped_column(
        ForeignKey("sites.site_id", ondelete="CASCADE"), primary_key=True
    )
    day_start_s: Mapped[int] = mapped_column(BigInteger, primary_key=True)
    day_end_s: Mapped[int] = mapped_column(BigInteger)
    payload_json: Mapped[str] = mapped_column(Text)


class ServiceState(Base):
    """What the stored data was computed under, by name: ``rollup_energy_max_gap_s``, the
    energy gap the hourly rollups' ``energy_wh`` bridged (``backend.measurements.writer.
    Writer.match_rollups_to_gap``)."""

    __tablename__ = "service_state"

    key: Mapped[str] = mapped_column(String(64), primary_key=True)
    value: Mapped[str] = mapped_column(Text)


class SimulationRun(Base):
    """A twin scenario run from the API (synchronous or in the background)."""

    __tablename__ = "simulation_runs"
    __table_args__ = (Index("ix_simulation_runs_anonymous_created", "anonymous", "created_at"),)

    run_id: Mapped[str] = mapped_column(String(32), primary_key=True)
    site_id: Mapped[str] = mapped_column(ForeignKey("sites.site_id", ondelete="CASCADE"))
    params_json: Mapped[str] = mapped_column(Text)
    status: Mapped[str] = mapped_column(String(16))
    progress: Mapped[float] = mapped_column(Float, default=0.0)
    summary_json: Mapped[str | None] = mapped_column(Text, nullable=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    finished_at: Mapped[dt.datetime | None] = mapped_column(
        DateTime(timezone=True), nullable=True
    )
    #: Asked without a token: kept within ``Settings.simulations.anonymous_keep_runs``.
    anonymous: Mapped[bool] = mapped_column(Boolean, default=False, server_default=false())


class SimulationSeries(Base):
    """The time series of a finished run: columns as a compressed ``.npz`` blob."""

    __tablename__ = "simulation_series"

    run_id: Mapped[str] = mapped_column(
        ForeignKey("simulation_runs.run_id", ondelete="CASCADE"), primary_key=True
    )
    npz: Mapped[bytes] = mapped_column(LargeBinary)


class VisionCalibration(Base):
    """A fisheye camera fitted from timestamped frames (``vision.calibrate``)."""

    __tablename__ = "vision_calibrations"
    # AUTOINCREMENT: a deleted calibration's id is never given to the next (migration 0012)
    __table_args__ = (Index("ix_vision_calibrations_anonymous_created", "anonymous",
                            "created_at"), {"sqlite_autoincrement": True})

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True))
    #: A person's name for it ("roof camera, June"); "" for calibrations made before names.
    name: Mapped[str] = mapped_column(String(100), default="", server_default="")
    site_id: Mapped[str | None] = mapped_column(String(64), nullable=True)
    latitude_deg: Mapped[float] = mapped_column(Float)
    longitude_deg: Mapped[float] = mapped_column(Float)
    elevation_m: Mapped[float] = mapped_column(Float)
    projection: Mapped[str] = mapped_column(String(16))
    cx_px: Mapped[float] = mapped_column(Float)
    cy_px: Mapped[float] = mapped_column(Float)
    px_per_deg: Mapped[float] = mapped_column(Float)
    north_offset_deg: Mapped[float] = mapped_column(Float)
    east: Mapped[str] = mapped_column(String(8))
    radial_coeffs_json: Mapped[str] = mapped_column(Text)
    tilt_north_deg: Mapped[float] = mapped_column(Float)
    tilt_east_deg: Mapped[float] = mapped_column(Float)
    image_width_px: Mapped[int] = mapped_column(Integer)
    image_height_px: Mapped[int] = mapped_column(Integer)
    n_frames: Mapped[int] = mapped_column(Integer)
    rms_px: Mapped[float] = mapped_column(Float)
    max_px: Mapped[float] = mapped_column(Float)
    rms_deg: Mapped[float] = mapped_column(Float)
    max_deg: Mapped[float] = mapped_column(Float)
    frames_json: Mapped[str] = mapped_column(Text)
    #: Fitted without a token: kept within ``Settings.vision.anonymous_keep_rows``.
    anonymous: Mapped[bool] = mapped_column(Boolean, default=False, server_default=false())


class VisionDetection(Base):
    """One frame's detection, with the ephemeris when time and place were given."""

    __tablename__ = "vision_detections"
    __table_args__ = (Index("ix_vision_detections_site_ts", "site_id", "ts_ms"),
                      Index("ix_vision_detections_anonymous_created", "anonymous", "created_at"))

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True))
    ts_ms: Mapped[int | None] = mapped_column(BigInteger, nullable=True)
    site_id: Mapped[str | None] = mapped_column(String(64), nullable=True)
    latitude_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    longitude_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    camera: Mapped[str] = mapped_column(String(16))
    calibration_id: Mapped[int | None] = mapped_column(
        Integer, ForeignKey("vision_calibrations.id", ondelete="SET NULL"), nullable=True)
    method: Mapped[str] = mapped_column(String(32))
    image_width_px: Mapped[int] = mapped_column(Integer)
    image_height_px: Mapped[int] = mapped_column(Integer)
    sun_found: Mapped[bool] = mapped_column(Boolean)
    confidence: Mapped[float] = mapped_column(Float)
    centroid_x_px: Mapped[float | None] = mapped_column(Float, nullable=True)
    centroid_y_px: Mapped[float | None] = mapped_column(Float, nullable=True)
    azimuth_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    elevation_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    pointing_error_horizontal_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    pointing_error_vertical_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    pointing_error_mrad: Mapped[float | None] = mapped_column(Float, nullable=True)
    ephemeris_azimuth_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    ephemeris_elevation_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    error_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    #: Uploaded without a token: kept within ``Settings.vision.anonymous_keep_rows``.
    anonymous: Mapped[bool] = mapped_column(Boolean, default=False, server_default=false())


class AlertRow(Base):
    """An alert (``backend/alerts/``): one condition of a site's array — a silent logger, a
    diagnosis fault, a low performance ratio — raised once when it starts and cleared once
    when it ends (migration ``0007_alerts``), acknowledged at most once by an operator while
    active (``0014_alert_acknowledgement``). Times are UTC Unix seconds."""

    __tablename__ = "alerts"
    __table_args__ = (
        CheckConstraint("state IN ('active', 'cleared')", name="ck_alerts_state"),
        Index("ix_alerts_site_state", "site_id", "state"),
        Index("ix_alerts_raised_at", "raised_at_s"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    site_id: Mapped[str] = mapped_column(ForeignKey("sites.site_id", ondelete="CASCADE"))
    array_name: Mapped[str] = mapped_column(String(64))
    #: ``logger_silent``, ``fault`` or ``low_performance_ratio``
    kind: Mapped[str] = mapped_column(String(32))
    #: the diagnosis fault's kind (``stuck``, ``module_loss``, …) for ``kind = 'fault'``
    fault_kind: Mapped[str | None] = mapped_column(String(32), nullable=True)
    state: Mapped[str] = mapped_column(String(16))
    #: when the condition began (the last reading, the fault's first day, …)
    since_s: Mapped[int] = mapped_column(BigInteger)
    raised_at_s: Mapped[int] = mapped_column(BigInteger)
    cleared_at_s: Mapped[int | None] = mapped_column(BigInteger, nullable=True)
    detail: Mapped[str] = mapped_column(Text)
    cleared_detail: Mapped[str | None] = mapped_column(Text, nullable=True)
    #: the numbers behind the alert, units in the names (JSON object)
    data_json: Mapped[str] = mapped_column(Text)
    #: delivery of the latest event (raised or cleared) to the webhook: ``off`` (no URL),
    #: ``queued``, ``delivered``, ``failed`` (retries spent or refused), ``dropped`` (queue full)
    webhook_status: Mapped[str] = mapped_column(String(16))
    webhook_attempts: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    #: when an operator acknowledged it (``POST …/acknowledge``, migration
    #: ``0014_alert_acknowledgement``); null until then, set once
    acknowledged_at_s: Mapped[int | None] = mapped_column(BigInteger, nullable=True)
    #: who: the token's label, ``token #<id>`` for a token without one, or ``admin``
    acknowledged_by: Mapped[str | None] = mapped_column(String(200), nullable=True)
    #: the operator's note, at most :data:`ACK_NOTE_MAX_CHARS` characters
    acknowledged_note: Mapped[str | None] = mapped_column(String(ACK_NOTE_MAX_CHARS),
                                                          nullable=True)
