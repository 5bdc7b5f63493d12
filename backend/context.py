"""Everything the running service holds: built at start-up, closed at shutdown.

:func:`open_context` runs the migrations, loads the built-in sites from
``Settings.sites.user_dir`` into the database, and starts the writer; the FastAPI
lifespan (``backend/app.py``) keeps the result in ``app.state.ctx`` and the
dependencies in ``backend/api/deps.py`` hand its parts to the routes.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sqlalchemy import Engine, text
from sqlalchemy.orm import Session, sessionmaker

from backend.alerts.service import AlertService
from backend.auth import TokenCache
from backend.limits import Limits
from backend.measurements.writer import Writer
from backend.mqtt.service import MqttService
from backend.settings import Settings
from backend.sites import Registry, sync_sites
from backend.storage.engine import make_engine, make_sessionmaker, run_migrations
from backend.twin.service import TwinService
from backend.twin.simulations import SimulationRunner
from sim.sites import Site

logger = logging.getLogger(__name__)


@dataclass
class ServiceContext:
    """The service's long-lived parts."""

    settings: Settings
    engine: Engine
    sessions: sessionmaker[Session]
    registry: Registry
    writer: Writer
    tokens: TokenCache
    twin: TwinService
    simulations: SimulationRunner
    limits: Limits  # rate limits of anonymous work, the decode budget (backend/limits.py)
    mqtt: MqttService | None = None  # with Settings.mqtt.url (backend/mqtt/service.py)
    alerts: AlertService | None = None  # with Settings.alerts.enabled (backend/alerts/service.py)
    #: per site, its day in progress's diagnosis and what it rests on
    #: (``backend.diagnosis.service.in_progress_key``)
    diagnosis_today: dict[str, tuple[tuple[Any, ...], bytes]] = field(default_factory=dict)

    def close(self) -> None:
        """Stop alerts, MQTT, runs and the writer; dispose of the engine."""
        if self.alerts is not None:  # it writes through the writer and reads the database
            self.alerts.stop()
        if self.mqtt is not None:  # first: its last readings still reach the writer
            self.mqtt.stop()
        self.simulations.stop()
        self.registry.stop_watching()  # it may apply a site through the writer
        self.writer.stop()
        self.engine.dispose()


def _statistics(engine: Engine) -> None:
    """PostgreSQL: ANALYZE the readings' tables that have never been analysed. Without
    statistics (a back-fill on a server whose autovacuum is off or has not come round) the
    planner joined a year of hourly periods to the rollups in a nested loop: 3 s a
    statement, 12-15 s a year of hours; 154 ms with them (a tester's measurement)."""
    if engine.dialect.name != "postgresql":
        return
    with engine.connect() as conn:
        stale = conn.execute(text(
            "SELECT relname FROM pg_stat_user_tables WHERE schemaname = current_schema() "
            "AND relname IN ('measurements', 'measurement_rollups') "
            "AND last_analyze IS NULL AND last_autoanalyze IS NULL")).scalars().all()
    if stale:
        with engine.connect().execution_options(isolation_level="AUTOCOMMIT") as conn:
            for table in stale:
                conn.execute(text(f'ANALYZE "{table}"'))
        logger.info("tables %s analysed (they had no planner statistics)", ", ".join(stale))


def warn_sites_without_config(engine: Engine, known: set[str], sites_dir: Path) -> list[str]:
    """Log a warning for each site the database holds that no config file gives (a
    database restored from a backup without its ``HELIOTWIN_SITES_DIR``, or a site file
    removed): its readings stay stored but every request answers "unknown site" — an
    operator's finding, which no line of the start-up log explained. Returns their ids."""
    with engine.connect() as conn:
        rows = conn.execute(text(
            "SELECT s.site_id, COALESCE(SUM(r.n), 0) FROM sites s "
            "LEFT JOIN arrays a ON a.site_id = s.site_id "
            "LEFT JOIN measurement_rollups r ON r.array_id = a.id AND r.source = 0 "
            "GROUP BY s.site_id ORDER BY s.site_id")).all()
    orphans = [(site_id, int(n)) for site_id, n in rows if site_id not in known]
    for site_id, n in orphans:
        logger.warning(
            "site %s is in the database (%d measured readings) but no site config gives it: "
            "not served (\"unknown site\") until its file is back in HELIOTWIN_SITES_DIR (%s); "
            "the database keeps its last config in sites.config_json", site_id, n, sites_dir)
    return [site_id for site_id, _ in orphans]


def open_context(settings: Settings) -> ServiceContext:
    """Migrate, load sites, start the writer (and MQTT, if set, and the alert evaluator)."""
    engine = make_engine(settings)
    run_migrations(engine)
    registry = Registry.load_files(settings.sites.user_dir)
    sites = [info.site for info in registry.sites.values()]
    with engine.begin() as conn:
        sync_sites(conn, sites)
        registry.refresh_arrays(conn)
    logger.info("sites loaded: %s", ", ".join(registry.sites) or "none")
    warn_sites_without_config(engine, set(registry.sites), settings.sites.user_dir)
    writer = Writer(engine, registry.phase_of_array, settings.ingest.energy_max_gap_s,
                    settings.database.writer_max_group_rows)
    writer.start()
    # before serving: hours stored under another energy gap are recomputed (no time bound:
    # a large history takes what it takes, and the service must not answer from stale hours)
    writer.call(writer.match_rollups_to_gap).result()
    _statistics(engine)

    def store_sites(new: list[Site]) -> None:  # a site file read while running: its rows
        writer.call(lambda conn: sync_sites(conn, new)).result(timeout=60)  # not for ever

    registry.store_through(store_sites)
    registry.start_watching()
    twin = TwinService(registry, engine, writer, settings.twin.on_demand_max_days,
                       scene_site=settings.sites.default_site,
                       history_days=settings.twin.history_days)
    ctx = ServiceContext(
        settings=settings, engine=engine, sessions=make_sessionmaker(engine),
        registry=registry, writer=writer,
        tokens=TokenCache(engine, settings.server.token_cache_ttl_s), twin=twin,
        simulations=SimulationRunner(registry, engine, writer, settings),
        limits=Limits.from_settings(settings),
    )
    if settings.mqtt.url:
        ctx.mqtt = MqttService(ctx)
        ctx.mqtt.start()
    if settings.alerts.enabled:
        ctx.alerts = AlertService(ctx)
        ctx.alerts.start()
    return ctx
