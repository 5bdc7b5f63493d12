"""Service settings: typed groups per concept, from ``HELIOTWIN_*`` environment variables.

Every field has a working default (SQLite under ``sim.paths.user_data_dir()``,
port 8000 for the API and dashboard, 8080 for viser). ``get_settings()`` builds
the object; nothing is read from the environment at import time.

:class:`Settings` holds one group per concept (``settings.database.url``,
``settings.alerts.interval_s``, …). The environment variables' names are a public
contract and stayed as they were when the settings were grouped: a group reads its
variables under its own prefix (``HELIOTWIN_MQTT_`` + ``url``), and a field whose
name in its group is not its variable's suffix names the variable itself
(``alerts.enabled`` ← ``HELIOTWIN_ALERTS``). Keyword overrides
(``get_settings(database_url=…)``, ``Settings(port=0)``) use the variable's name
without ``HELIOTWIN_``, lower-case; :func:`env_fields` lists every variable.
Secrets (the admin and demo tokens, the webhook secret, the MQTT URL with its
password) are ``SecretStr``: never in a repr, a log or an answer, and no
invalid value is echoed in an error. The README's settings table (between
``<!-- settings:start -->`` and ``<!-- settings:end -->``) documents every variable,
and ``tests/backend/test_settings.py`` checks that it does.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import (
    BaseModel,
    Field,
    HttpUrl,
    SecretStr,
    ValidationError,
    ValidationInfo,
    field_validator,
)
from pydantic.fields import FieldInfo
from pydantic_settings import BaseSettings, SettingsConfigDict
from sqlalchemy.engine import make_url
from sqlalchemy.exc import ArgumentError

from sim.energy import DEFAULT_MAX_GAP_S
from sim.paths import default_plants_dir, default_user_sites_dir, user_data_dir

#: The prefix of every environment variable of the service.
PREFIX = "HELIOTWIN_"


def _default_database_url() -> str:
    """SQLite in :func:`sim.paths.user_data_dir`: a checkout's ``data/``, else the user's
    data folder (an installed wheel has no repository to write into)."""
    return f"sqlite:///{user_data_dir() / 'heliotwin.sqlite'}"


def _config(env_prefix: str) -> SettingsConfigDict:
    """A group's config: its variables' prefix; fields set by name or by variable; no
    input echoed in a validation error (a value may hold a secret)."""
    return SettingsConfigDict(env_prefix=env_prefix, extra="ignore", validate_by_name=True,
                              validate_by_alias=True, hide_input_in_errors=True)


def _env(name: str) -> str:
    """The variable of a field whose name in its group is not its variable's suffix."""
    return PREFIX + name.upper()


class _Group(BaseSettings):
    """A group of settings, read from the environment when it is built."""

    @field_validator("*", mode="before")
    @classmethod
    def _blank_is_unset(cls, value: Any, info: ValidationInfo) -> Any:
        """An empty variable leaves an optional setting (one unset by default) unset."""
        field = cls.model_fields[info.field_name or ""]
        unset_by_default = field.default is None and field.default_factory is None
        return None if value == "" and unset_by_default else value


class ServerSettings(_Group):
    """What the service listens on and who may administer it."""

    model_config = _config("HELIOTWIN_")

    host: str = Field("127.0.0.1", description="Interface the API and dashboard listen on.")
    port: int = Field(8000, ge=0, le=65535, description="Port of the API and dashboard.")
    viser: bool = Field(True, description="Start the viser 3D twin with the service.")
    viser_port: int = Field(8080, ge=0, le=65535, description="Port of the viser 3D twin.")
    viser_public_port: int | None = Field(
        None, ge=1, le=65535,
        description="Port browsers reach the 3D twin on, at the dashboard's host name, when "
                    "it is not the one it listens on (a container's published port, a proxy); "
                    "unset: the port it listens on.")
    access_log: bool = Field(False, description="Log every HTTP request (uvicorn access log).")
    max_upload_bytes: int = Field(
        10 * 1024 * 1024, gt=0,
        description="Largest request body accepted (ingest, weather files; a vision "
                    "upload's: `HELIOTWIN_VISION_MAX_IMAGE_BYTES`, "
                    "`HELIOTWIN_VISION_MAX_BATCH_BYTES`)."
    )
    admin_token: SecretStr | None = Field(
        None, description="Bearer token of the admin endpoints (`/api/v1/tokens`); unset: "
                          "they answer 403."
    )
    read_require_token: bool = Field(
        False, description="Reads of the sites' data (every GET of the API but `/healthz`, "
                           "`/api/v1/meta`, the docs and the dashboard's files) need a valid "
                           "token: any site's, any scope, or the admin token; unset: anyone "
                           "who reaches the port reads them (docs/service.md, \"Who may "
                           "read\").")
    token_cache_ttl_s: float = Field(
        0.5, gt=0, le=1.0, description="How long a checked write token is trusted from "
                                       "memory (a revocation by the CLI takes effect within it)."
    )


class SiteSettings(_Group):
    """Where site and plant configs are read, and the default site."""

    model_config = _config("HELIOTWIN_")

    user_dir: Path = Field(
        default_factory=default_user_sites_dir,
        description="Folder of your own site configs, added to the built-in sites (a file "
                    "with a built-in id replaces it); the dashboard and `heliotwin site create` "
                    "write here.", validation_alias=_env("sites_dir"))
    plants_dir: Path = Field(default_factory=default_plants_dir,
                             description="Folder of plant layouts (seed 004), one JSON each.")
    default_site: str = Field(
        "tehuantepec", description="Site of the 3D scene, the demo logger and the dashboard."
    )


class DatabaseSettings(_Group):
    """Storage: the database and how the one writer commits."""

    model_config = _config("HELIOTWIN_DATABASE_")

    url: str = Field(
        default_factory=_default_database_url,
        description="SQLAlchemy URL; `postgresql+psycopg://user@host:5432/db` for PostgreSQL.",
    )
    sqlite_synchronous: str = Field(
        "NORMAL", pattern="^(NORMAL|FULL|EXTRA)$",
        description="SQLite `synchronous`: NORMAL survives a killed process, FULL also "
                    "a power cut (one fsync per group commit).",
        validation_alias=_env("sqlite_synchronous"))
    writer_max_group_rows: int = Field(
        20_000, gt=0, description="Most rows the writer commits in one transaction: a bigger "
                                  "batch is committed in pieces of this size, other writes "
                                  "between them (a live reading waits for one piece, not for "
                                  "a whole back-fill).",
        validation_alias=_env("writer_max_group_rows"))

    @field_validator("url")
    @classmethod
    def _driver(cls, url: str) -> str:
        """``postgresql://`` means the driver we ship (psycopg 3); a URL SQLAlchemy cannot
        read is refused at start, not at the first connection."""
        if url.startswith("postgresql://"):
            url = "postgresql+psycopg://" + url[len("postgresql://"):]
        try:
            make_url(url)
        except ArgumentError:
            raise ValueError("not an SQLAlchemy database URL") from None
        return url

    @property
    def is_sqlite(self) -> bool:
        """Whether the database is SQLite."""
        return self.url.startswith("sqlite")


#: The longest gap energy may be set to bridge [s]: an hourly logger's step.
MAX_ENERGY_GAP_S = 3600


class IngestSettings(_Group):
    """Bounds of logger batches and of reads of a site's data, and the energy rule's gap."""

    model_config = _config("HELIOTWIN_")

    max_batch_rows: int = Field(
        100_000, gt=0, description="Most readings in one measurements POST (more → 413)."
    )
    max_json_points: int = Field(
        200_000, gt=0, description="Most raw points one JSON measurements answer holds."
    )
    anonymous_read_cpu_s_per_min: float = Field(
        30.0, gt=0, description="CPU time [s] one client address may spend without a token "
                                "in any minute on reads of a site's data (measurements, "
                                "energy, reports, diagnosis, pointing, pointing model): each "
                                "read charged the CPU time it took, its streamed body "
                                "included; more → 429.")
    future_tolerance_s: int = Field(
        900, ge=0, description="How far past the server clock a reading may be stamped."
    )
    max_voltage_v: float = Field(1500.0, gt=0, description="Highest plausible array voltage.")
    min_voltage_v: float = Field(
        -1.0, le=0, description="Lowest plausible array voltage (a transducer's zero offset "
                                "at night: NREL SERF West's logger reads down to −0.026 V)."
    )
    max_current_a: float = Field(100.0, gt=0, description="Highest plausible array current.")
    min_current_a: float = Field(
        -1.0, le=0, description="Lowest plausible current (sensor offset at night)."
    )
    power_tolerance_w: float = Field(
        5.0, ge=0, description="Allowed gap between power_w and voltage_v·current_a, beyond 5 %."
    )
    energy_max_gap_s: int = Field(
        DEFAULT_MAX_GAP_S, gt=0, le=MAX_ENERGY_GAP_S,
        description="Longest gap between readings that energy bridges (sim/energy.py: every "
                    "logger cadence up to 15 min is bridged at the default)."
    )


class TwinSettings(_Group):
    """The live twin and the twin computed on demand."""

    model_config = _config("HELIOTWIN_TWIN_")

    live: bool = Field(True, description="Write the twin's I/V/P every minute (source twin).",
        validation_alias=_env("live_twin"))
    live_interval_s: float = Field(
        60.0, gt=0, description="Period of the live twin loop (tests shorten it).",
        validation_alias=_env("live_twin_interval_s"))
    on_demand_max_days: int = Field(
        800, ge=0, description="Most days of twin series one query (energy, source=twin) computes."
    )
    history_days: int = Field(
        400,
        ge=0,
        description="Days before now that reads fill with the twin on demand; older days only "
        "where measured data exist.",
    )


class DemoSettings(_Group):
    """The demo field logger of `heliotwin serve`."""

    model_config = _config("HELIOTWIN_DEMO_")

    enabled: bool = Field(True, description="`heliotwin serve` runs the demo field logger.",
        validation_alias=_env("demo_logger"))
    token: SecretStr | None = Field(
        None, description="Write token of the demo logger; created at start when unset."
    )
    backfill_days: int = Field(
        7, ge=0, le=366, description="Days of history the demo logger back-fills at start."
    )


class SimulationSettings(_Group):
    """Simulations run from the API: size, workers, queue, anonymous allowance."""

    model_config = _config("HELIOTWIN_SIMULATION_")

    max_steps: int = Field(
        1_100_000, gt=0, description="Most time steps one simulation request may ask for.",
        validation_alias=_env("max_simulation_steps"))
    workers: int = Field(
        1, ge=1, le=8, description="Worker processes running simulations at once."
    )
    queue: int = Field(
        2, ge=0, le=100, description="Simulations waiting for a worker; more → 503 with "
                                     "Retry-After."
    )
    anonymous_keep_runs: int = Field(
        10, ge=0, description="Runs asked without a token that stay stored (older ones are "
                              "deleted with their series); runs with a token stay."
    )
    anonymous_steps_per_min: int = Field(
        2_200_000, gt=0, description="Simulated time steps one client address may ask per "
                                     "minute without a token (token bucket; more → 429).",
        validation_alias=_env("anonymous_simulation_steps_per_min"))
    anonymous_run_max_s: float = Field(
        60.0, gt=0, description="Most worker time one run asked without a token may take [s]: "
                                "refused (422) when its estimate is more, stopped when it runs "
                                "longer.")
    anonymous_hour_max_s: float = Field(
        300.0, gt=0, description="Worker time one client address may ask without a token in "
                                 "any hour [s] (estimates, trued up to the time taken; more "
                                 "→ 429).")
    anonymous_series_cells_per_min: int = Field(
        20_000_000, gt=0, description="Series values (rows × columns) one client address may "
                                      "read per minute without a token (token bucket; more "
                                      "→ 429).",
        validation_alias=_env("anonymous_series_cells_per_min"))


class PlantSettings(_Group):
    """Plant-design sweeps run from the API (``POST /api/v1/plants/sweeps``, issue 26)."""

    model_config = _config("HELIOTWIN_PLANTS_")

    dask_scheduler: str | None = Field(
        None, description="`tcp://HOST:PORT` of a running Dask scheduler for the sweeps; "
                          "unset: a LocalCluster of one worker process per core for each sweep.")
    sweep_queue: int = Field(
        2, ge=0, le=100, description="Sweeps waiting while one runs; more → 503 with "
                                     "Retry-After.")
    anonymous_sweep_case_steps: int = Field(
        1_000_000, gt=0, description="Most cases × time steps of one sweep asked without a "
                                     "token (more → 422); the steps also come out of the "
                                     "address's anonymous simulation allowance.")


class VisionSettings(_Group):
    """The vision endpoints: image sizes, decode budget, anonymous allowance."""

    model_config = _config("HELIOTWIN_VISION_")

    max_pixels: int = Field(
        40_000_000, gt=0, description="Largest image (pixels) the vision endpoints decode."
    )
    max_image_bytes: int = Field(
        64 * 1024 * 1024, gt=0,
        description="Largest request body of a single-frame upload (`POST /api/v1/vision/sun`, "
                    "a pointing-model observation): a 6000×4000 camera JPEG at quality 100 is "
                    "≈ 13 MiB, a 16-bit PNG of 3000×2000 px ≈ 27 MiB; larger → 413. The "
                    "frame's pixels are bounded by `HELIOTWIN_VISION_MAX_PIXELS`."
    )
    max_batch_bytes: int = Field(
        64 * 1024 * 1024, gt=0,
        description="Largest request body of a calibration or an evaluation (`POST "
                    "/api/v1/vision/calibrations`, `/evaluate`: up to 64 frames; 12 frames of "
                    "1920² px as JPEG at quality 92 come to ≈ 14 MB); larger → 413. The frames "
                    "are decoded one at a time."
    )
    require_token: bool = Field(
        False, description="Vision endpoints need a site write token."
    )
    anonymous_pixels_per_min: int = Field(
        400_000_000, gt=0, description="Image pixels one client address may upload per minute "
                                       "without a token (token bucket; more → 429).",
        validation_alias=_env("anonymous_vision_pixels_per_min"))
    decode_pixels: int = Field(
        40_000_000, gt=0, description="Pixels decoded at once across all vision requests "
                                      "(≈ 6 bytes each at the peak); others wait."
    )
    queue: int = Field(
        8, ge=0, le=1000, description="Vision requests waiting for the decode budget; more → "
                                      "503 with Retry-After."
    )
    anonymous_keep_rows: int = Field(
        1000, ge=0, description="Detections and calibrations made without a token that stay "
                                "stored, each (older ones are deleted); with a token they stay."
    )


class MqttSettings(_Group):
    """MQTT ingestion and Home Assistant (off without a broker URL)."""

    model_config = _config("HELIOTWIN_MQTT_")

    url: SecretStr | None = Field(
        None, description="`mqtt://[user:password@]host[:port]` of the broker; unset: no MQTT."
    )
    client_id: str | None = Field(
        None, description="MQTT client id; set: a persistent session (the broker keeps "
                          "QoS 1 readings while the service is away); unset: a random id."
    )
    state_topic: str = Field(
        "heliotwin/{site_id}/{array}/state", description="Topic template of JSON readings."
    )
    value_topic: str = Field(
        "heliotwin/{site_id}/{array}/{quantity}",
        description="Topic template of OpenDTU-style single values (quantity: voltage, "
                    "current, power), assembled per minute.",
    )
    errors_topic: str = Field(
        "heliotwin/{site_id}/errors", description="Where rejected MQTT messages are reported."
    )
    ha_prefix: str = Field(
        "homeassistant", description="Home Assistant discovery prefix (retained configs)."
    )
    ha_state_topic: str = Field(
        "heliotwin/{site_id}/{array}/ha/{sensor}",
        description="Topic template of the states published for Home Assistant.",
    )
    publish_interval_s: float = Field(
        60.0, gt=0, description="Period of the Home Assistant state publications."
    )
    minute_grace_s: float = Field(
        5.0, ge=0, le=55, description="Wait after a minute ends before closing its single "
                                      "values without power_w (power = voltage·current).",
    )
    retry_max_s: float = Field(
        30.0, gt=0, description="Longest wait between MQTT reconnection attempts."
    )


class AlertSettings(_Group):
    """The alert evaluator and its webhook (backend/alerts/, docs/service.md "Alerts")."""

    model_config = _config("HELIOTWIN_ALERT_")

    enabled: bool = Field(True, description="Evaluate alerts in the background (silent "
                                           "loggers, diagnosis faults, low PR).",
        validation_alias=_env("alerts"))
    interval_s: float = Field(
        60.0, gt=0, le=3600, description="Period of the alert evaluation (tests shorten it)."
    )
    silent_min: float = Field(
        30.0, gt=0, description="A logger with no reading for this many minutes (counted "
                                "from the service's start at the earliest), or for 2.5 of "
                                "its own cadence when that is longer (a 30-minute logger: "
                                "75 min), raises `logger_silent`.")
    silent_daylight_only: bool = Field(
        True, description="Count a logger's silence only while the sun is up at the site, "
                          "so a logger that sleeps at night is not reported every night.")
    pr_below: float = Field(
        0.8, ge=0, le=2, description="A tracker day whose performance ratio under the "
                                     "measured sky is below this raises "
                                     "`low_performance_ratio`.")
    fault_confidence_min: float = Field(
        0.5, ge=0, le=1, description="Least confidence of a diagnosis fault that raises a "
                                     "`fault` alert.")
    # 21: the slowest soiling the diagnosis names (0.1 %/day, SOILING_MIN_PCT_PER_DAY) loses
    # its 2 % (SOILING_MIN_TOTAL) over 20 days; over 7 days an alert needed 0.33 %/day and
    # a 0.3 %/day soiling the diagnosis found was never alerted (a tester's finding)
    diagnosis_days: int = Field(
        21, ge=0, le=400, description="Complete local days up to yesterday diagnosed for "
                                      "fault and PR alerts (0: only `logger_silent`; 21: the "
                                      "slowest soiling the diagnosis names, 0.1 %/day, "
                                      "reaches its 2 % in 20 days).")
    webhook_url: HttpUrl | None = Field(
        None, description="`http(s)://…` that each alert raised, acknowledged or cleared is "
                          "POSTed to as JSON; unset: alerts are only stored and shown.")
    webhook_secret: SecretStr | None = Field(
        None, description="Signs each webhook body: `X-Heliotwin-Signature: sha256=<HMAC-SHA256 "
                          "hex>`; unset: unsigned.")
    webhook_timeout_s: float = Field(
        5.0, gt=0, le=120, description="Timeout of one webhook POST (connect and answer).")
    webhook_retries: int = Field(
        5, ge=0, le=30, description="Retries of a failed webhook POST (5xx, 408, 429, no "
                                    "answer) before it is given up.")
    webhook_backoff_s: float = Field(
        2.0, gt=0, description="Wait before the first retry; doubled at each next one.")
    webhook_backoff_max_s: float = Field(
        300.0, gt=0, description="Longest wait between two webhook attempts (a 429's "
                                 "Retry-After included).")
    webhook_queue: int = Field(
        1000, ge=1, le=100_000, description="Webhook events waiting to be sent; more are "
                                            "dropped (counted, the alert stays stored).")


class Settings(BaseModel):
    """All settings of the service and the ``heliotwin`` commands that use the database."""

    server: ServerSettings
    sites: SiteSettings
    database: DatabaseSettings
    ingest: IngestSettings
    twin: TwinSettings
    demo: DemoSettings
    simulations: SimulationSettings
    plants: PlantSettings
    vision: VisionSettings
    mqtt: MqttSettings
    alerts: AlertSettings

    def __init__(self, **overrides: Any) -> None:
        """Every group built, and so read from the environment, with the overrides on top:
        flat names (a variable's name without the prefix, lower-case: ``database_url=…``)
        or whole groups (``database=DatabaseSettings(…)`` or a dict). Other names are
        ignored, as unknown variables are."""
        routed: dict[str, dict[str, Any]] = {group: {} for group in _GROUPS}
        whole: dict[str, Any] = {}
        for key, value in overrides.items():
            if key in _GROUPS and isinstance(value, dict | _Group):  # not alerts=False
                whole[key] = value
            elif key in _FLAT:
                group, name = _FLAT[key]
                routed[group][name] = value
        for group, value in whole.items():
            if routed[group]:
                raise ValueError(f"{group}: given both whole and by its fields")
            routed[group] = value if isinstance(value, dict) else value.model_dump()
        super().__init__(**{group: _GROUPS[group](**values) for group, values in routed.items()})


#: Each group's class by its name in :class:`Settings`.
_GROUPS: dict[str, type[_Group]] = {
    name: field.annotation for name, field in Settings.model_fields.items()  # type: ignore[misc]
}


def env_fields() -> dict[str, tuple[str, str, FieldInfo]]:
    """Every environment variable → ``(group, field name, field)``."""
    out = {}
    for group, cls in _GROUPS.items():
        prefix = cls.model_config.get("env_prefix", "")
        for name, field in cls.model_fields.items():
            alias = field.validation_alias
            out[alias if isinstance(alias, str) else (prefix + name).upper()] = (group, name, field)
    return out


#: A flat override's name (the variable without the prefix, lower-case) → group and field.
_FLAT = {env[len(PREFIX):].lower(): (group, name) for env, (group, name, _) in env_fields().items()}


def get_settings(**overrides: object) -> Settings:
    """Build the settings from the environment, with keyword overrides (flat names, see the
    module docstring) on top."""
    return Settings(**overrides)


def settings_error_text(exc: ValidationError) -> str:
    """A settings error in one line naming the variable, its value and the problem
    (``HELIOTWIN_ENERGY_MAX_GAP_S=3601: Input should be less than or equal to 3600``):
    ``serve`` printed pydantic's traceback."""
    err = exc.errors()[0]
    loc = str(err["loc"][0]) if err["loc"] else ""
    # the variable from the group that raised (exc.title, its class) and the field: a group's
    # prefix (HELIOTWIN_TWIN_…) is not in the error's location
    name = next((env for env, (group, field_name, field) in env_fields().items()
                 if _GROUPS[group].__name__ == exc.title
                 and loc in (field_name, field.validation_alias)), None)
    if name is None:
        name = loc.upper() if loc.upper().startswith(PREFIX) else PREFIX + loc.upper()
    msg = str(err["msg"]).removeprefix("Value error, ")
    value = err.get("input")
    if any(word in name for word in ("URL", "TOKEN", "SECRET", "PASSWORD")):
        # the value may hold a password: neither it nor a message quoting it is shown
        quoted = isinstance(value, str) and value and value in msg
        return f"{name} (value not shown): {'not valid' if quoted else msg}"
    return f"{name}={value!s}: {msg}"
