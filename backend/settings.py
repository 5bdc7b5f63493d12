"""Service settings: one typed object from ``HELIOTWIN_*`` environment variables.

Every field has a working default (SQLite under ``sim.paths.user_data_dir()``,
port 8000 for the API and dashboard, 8080 for viser). ``get_settings()`` builds
the object; nothing is read from the environment at import time. The README's
settings table (between ``<!-- settings:start -->`` and ``<!-- settings:end -->``)
documents every field, and ``tests/backend/test_settings.py`` checks that it does.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from sim.energy import DEFAULT_MAX_GAP_S
from sim.paths import default_plants_dir, default_user_sites_dir, user_data_dir


def _default_database_url() -> str:
    """SQLite in :func:`sim.paths.user_data_dir`: a checkout's ``data/``, else the user's
    data folder (an installed wheel has no repository to write into)."""
    return f"sqlite:///{user_data_dir() / 'heliotwin.sqlite'}"


class Settings(BaseSettings):
    """All settings of the service and the ``heliotwin`` commands that use the database."""

    model_config = SettingsConfigDict(env_prefix="HELIOTWIN_", extra="ignore")

    database_url: str = Field(
        default_factory=_default_database_url,
        description="SQLAlchemy URL; `postgresql+psycopg://user@host:5432/db` for PostgreSQL.",
    )
    host: str = Field("127.0.0.1", description="Interface the API and dashboard listen on.")
    port: int = Field(8000, ge=0, le=65535, description="Port of the API and dashboard.")
    viser_port: int = Field(8080, ge=0, le=65535, description="Port of the viser 3D twin.")
    viser: bool = Field(True, description="Start the viser 3D twin with the service.")
    sites_dir: Path = Field(
        default_factory=default_user_sites_dir,
        description="Folder of your own site configs, added to the built-in sites (a file "
                    "with a built-in id replaces it); the dashboard and `heliotwin site create` "
                    "write here.")
    plants_dir: Path = Field(default_factory=default_plants_dir,
                             description="Folder of plant layouts (seed 004), one JSON each.")
    default_site: str = Field(
        "tehuantepec", description="Site of the 3D scene, the demo logger and the dashboard."
    )
    max_upload_bytes: int = Field(
        10 * 1024 * 1024, gt=0, description="Largest request body accepted (ingest, images)."
    )
    max_batch_rows: int = Field(
        100_000, gt=0, description="Most readings in one measurements POST (more → 413)."
    )
    max_json_points: int = Field(
        200_000, gt=0, description="Most raw points one JSON measurements answer holds."
    )
    future_tolerance_s: int = Field(
        900, ge=0, description="How far past the server clock a reading may be stamped."
    )
    max_voltage_v: float = Field(1500.0, gt=0, description="Highest plausible array voltage.")
    max_current_a: float = Field(100.0, gt=0, description="Highest plausible array current.")
    min_current_a: float = Field(
        -1.0, le=0, description="Lowest plausible current (sensor offset at night)."
    )
    power_tolerance_w: float = Field(
        5.0, ge=0, description="Allowed gap between power_w and voltage_v·current_a, beyond 5 %."
    )
    energy_max_gap_s: int = Field(
        DEFAULT_MAX_GAP_S, gt=0, le=3600,
        description="Longest gap between readings that energy bridges (sim/energy.py: every "
                    "logger cadence up to 15 min is bridged at the default)."
    )
    writer_max_group_rows: int = Field(
        200_000, gt=0, description="Most rows the writer commits in one group commit."
    )
    sqlite_synchronous: str = Field(
        "NORMAL", pattern="^(NORMAL|FULL|EXTRA)$",
        description="SQLite `synchronous`: NORMAL survives a killed process, FULL also "
                    "a power cut (one fsync per group commit).",
    )
    live_twin: bool = Field(True, description="Write the twin's I/V/P every minute (source twin).")
    live_twin_interval_s: float = Field(
        60.0, gt=0, description="Period of the live twin loop (tests shorten it)."
    )
    twin_on_demand_max_days: int = Field(
        800, ge=0, description="Most days of twin series one query (energy, source=twin) computes."
    )
    twin_history_days: int = Field(
        400,
        ge=0,
        description="Days before now that reads fill with the twin on demand; older days only "
        "where measured data exist.",
    )
    demo_logger: bool = Field(True, description="`heliotwin serve` runs the demo field logger.")
    demo_token: str | None = Field(
        None, description="Write token of the demo logger; created at start when unset."
    )
    demo_backfill_days: int = Field(
        7, ge=0, le=366, description="Days of history the demo logger back-fills at start."
    )
    max_simulation_steps: int = Field(
        1_100_000, gt=0, description="Most time steps one simulation request may ask for."
    )
    vision_max_pixels: int = Field(
        40_000_000, gt=0, description="Largest image (pixels) the vision endpoints decode."
    )
    vision_require_token: bool = Field(
        False, description="Vision endpoints need a site write token."
    )
    access_log: bool = Field(False, description="Log every HTTP request (uvicorn access log).")
    admin_token: str | None = Field(
        None, description="Bearer token of the admin endpoints (`/api/v1/tokens`); unset: "
                          "they answer 403."
    )
    token_cache_ttl_s: float = Field(
        0.5, gt=0, le=1.0, description="How long a checked write token is trusted from "
                                       "memory (a revocation by the CLI takes effect within it)."
    )
    simulation_workers: int = Field(
        1, ge=1, le=8, description="Worker processes running simulations at once."
    )
    simulation_queue: int = Field(
        2, ge=0, le=100, description="Simulations waiting for a worker; more → 503 with "
                                     "Retry-After."
    )
    simulation_anonymous_keep_runs: int = Field(
        10, ge=0, description="Runs asked without a token that stay stored (older ones are "
                              "deleted with their series); runs with a token stay."
    )
    anonymous_simulation_steps_per_min: int = Field(
        2_200_000, gt=0, description="Simulated time steps one client address may ask per "
                                     "minute without a token (token bucket; more → 429)."
    )
    anonymous_vision_pixels_per_min: int = Field(
        400_000_000, gt=0, description="Image pixels one client address may upload per minute "
                                       "without a token (token bucket; more → 429)."
    )
    vision_decode_pixels: int = Field(
        40_000_000, gt=0, description="Pixels decoded at once across all vision requests "
                                      "(≈ 6 bytes each at the peak); others wait."
    )
    vision_queue: int = Field(
        8, ge=0, le=1000, description="Vision requests waiting for the decode budget; more → "
                                      "503 with Retry-After."
    )
    vision_anonymous_keep_rows: int = Field(
        1000, ge=0, description="Detections uploaded without a token that stay stored (older "
                                "ones are deleted); with a token they stay."
    )
    mqtt_url: str | None = Field(
        None, description="`mqtt://[user:password@]host[:port]` of the broker; unset: no MQTT."
    )
    mqtt_client_id: str | None = Field(
        None, description="MQTT client id; set: a persistent session (the broker keeps "
                          "QoS 1 readings while the service is away); unset: a random id."
    )
    mqtt_state_topic: str = Field(
        "heliotwin/{site_id}/{array}/state", description="Topic template of JSON readings."
    )
    mqtt_value_topic: str = Field(
        "heliotwin/{site_id}/{array}/{quantity}",
        description="Topic template of OpenDTU-style single values (quantity: voltage, "
                    "current, power), assembled per minute.",
    )
    mqtt_errors_topic: str = Field(
        "heliotwin/{site_id}/errors", description="Where rejected MQTT messages are reported."
    )
    mqtt_ha_prefix: str = Field(
        "homeassistant", description="Home Assistant discovery prefix (retained configs)."
    )
    mqtt_ha_state_topic: str = Field(
        "heliotwin/{site_id}/{array}/ha/{sensor}",
        description="Topic template of the states published for Home Assistant.",
    )
    mqtt_publish_interval_s: float = Field(
        60.0, gt=0, description="Period of the Home Assistant state publications."
    )
    mqtt_minute_grace_s: float = Field(
        5.0, ge=0, le=55, description="Wait after a minute ends before closing its single "
                                      "values without power_w (power = voltage·current).",
    )
    mqtt_retry_max_s: float = Field(
        30.0, gt=0, description="Longest wait between MQTT reconnection attempts."
    )
    # alerts (backend/alerts/, docs/service.md "Alerts")
    alerts: bool = Field(True, description="Evaluate alerts in the background (silent "
                                           "loggers, diagnosis faults, low PR).")
    alert_interval_s: float = Field(
        60.0, gt=0, le=3600, description="Period of the alert evaluation (tests shorten it)."
    )
    alert_silent_min: float = Field(
        30.0, gt=0, description="A logger with no reading for this many minutes (counted "
                                "from the service's start at the earliest) raises "
                                "`logger_silent`.")
    alert_silent_daylight_only: bool = Field(
        True, description="Count a logger's silence only while the sun is up at the site, "
                          "so a logger that sleeps at night is not reported every night.")
    alert_pr_below: float = Field(
        0.8, ge=0, le=2, description="A tracker day whose performance ratio under the "
                                     "measured sky is below this raises "
                                     "`low_performance_ratio`.")
    alert_fault_confidence_min: float = Field(
        0.5, ge=0, le=1, description="Least confidence of a diagnosis fault that raises a "
                                     "`fault` alert.")
    alert_diagnosis_days: int = Field(
        7, ge=0, le=400, description="Complete local days up to yesterday diagnosed for "
                                     "fault and PR alerts (0: only `logger_silent`).")
    alert_webhook_url: str | None = Field(
        None, description="`http(s)://…` that each raised or cleared alert is POSTed to as "
                          "JSON; unset: alerts are only stored and shown.")
    alert_webhook_secret: str | None = Field(
        None, description="Signs each webhook body: `X-Heliotwin-Signature: sha256=<HMAC-SHA256 "
                          "hex>`; unset: unsigned.")
    alert_webhook_timeout_s: float = Field(
        5.0, gt=0, le=120, description="Timeout of one webhook POST (connect and answer).")
    alert_webhook_retries: int = Field(
        5, ge=0, le=30, description="Retries of a failed webhook POST (5xx, 408, 429, no "
                                    "answer) before it is given up.")
    alert_webhook_backoff_s: float = Field(
        2.0, gt=0, description="Wait before the first retry; doubled at each next one.")
    alert_webhook_backoff_max_s: float = Field(
        300.0, gt=0, description="Longest wait between two webhook attempts (a 429's "
                                 "Retry-After included).")
    alert_webhook_queue: int = Field(
        1000, ge=1, le=100_000, description="Webhook events waiting to be sent; more are "
                                            "dropped (counted, the alert stays stored).")

    @model_validator(mode="after")
    def _check(self) -> Settings:
        if not self.alert_webhook_url:
            self.alert_webhook_url = None
        elif not self.alert_webhook_url.startswith(("http://", "https://")) or \
                not self.alert_webhook_url.split("://", 1)[1].split("/", 1)[0]:
            raise ValueError("alert_webhook_url: not an http:// or https:// URL with a host "
                             "(the value is not echoed: it may hold a secret)")
        if self.database_url.startswith("postgresql://"):
            self.database_url = "postgresql+psycopg://" + self.database_url[len("postgresql://"):]
        return self

    @property
    def is_sqlite(self) -> bool:
        """Whether the database is SQLite."""
        return self.database_url.startswith("sqlite")


def get_settings(**overrides: object) -> Settings:
    """Build the settings from the environment, with keyword overrides on top."""
    return Settings(**overrides)  # type: ignore[arg-type]
