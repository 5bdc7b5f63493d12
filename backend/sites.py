"""Sites known to the service: loaded from ``sim/data/sites/`` (``sim.sites``) into the database.

At start-up the built-in site files, and the user's of ``HELIOTWIN_SITES_DIR``
(which add to them, and win on a shared id), are written to the ``sites`` and
``arrays`` tables (inserted, or their config refreshed; a stored logger
calibration is kept). :class:`Registry` keeps what the hot path needs in memory:
for each site the ``sim.sites.Site``, its time zone, its rollup phase, and for
each array its id, kind and calibration.

:func:`save_site` creates or edits a site while the service runs (the
``PUT /api/v1/sites/{site_id}`` route): the config is validated
(:mod:`sim.site_config`), written to the user's folder, synced to the database
and the registry; :func:`sync_sites` drops the twin series cached for a site
whose config changed (:func:`drop_twin_cache`), here and at start-up after a
file was edited, so they are simulated again with the new config.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any
from zoneinfo import ZoneInfo

from sqlalchemy import Connection, Engine, delete, select, update
from sqlalchemy.dialects import postgresql, sqlite

from backend.errors import InputError
from backend.measurements.buckets import bucket_phase_s
from backend.measurements.parse import Calibration, IngestArray
from backend.storage.tables import (
    SOURCE_CODES,
    ArrayRow,
    DiagnosisDay,
    Measurement,
    MeasurementRollup,
    SiteRow,
    TwinCoverage,
    utcnow,
)
from sim.site_config import validate_site_config
from sim.sites import (
    Site,
    builtin_site_ids,
    list_sites,
    load_site,
    place_defaults,
    site_from_dict,
)

if TYPE_CHECKING:
    from backend.context import ServiceContext

logger = logging.getLogger(__name__)

CALIBRATION_FIELDS = (
    "adc_bits", "adc_vref_v", "current_zero_v", "current_sensitivity_mv_per_a", "divider_ratio",
)


@dataclass
class ArrayInfo:
    """An array as the service uses it."""

    array_id: int
    name: str
    kind: str
    calibration: Calibration


@dataclass
class SiteInfo:
    """A site as the service uses it."""

    site: Site
    zone: ZoneInfo
    phase_s: int
    arrays: dict[str, ArrayInfo] = field(default_factory=dict)

    @property
    def site_id(self) -> str:
        return self.site.site_id

    def ready(self) -> bool:
        """Whether every array of the config has its database row (id, kind, calibration):
        a site file read while running has none until they are written (:class:`Registry`)."""
        return set(self.site.arrays) <= set(self.arrays)

    def ingest_arrays(self) -> dict[str, IngestArray]:
        """``{name: (array_id, calibration, stc_power_w)}`` for
        :mod:`backend.measurements.parse` (the rating None for an array the site's config
        does not hold)."""
        config = self.site.arrays
        return {a.name: IngestArray(a.array_id, a.calibration,
                                    config[a.name].stc_power_w if a.name in config else None)
                for a in self.arrays.values()}

    def array_of_kind(self, kind: str) -> ArrayInfo | None:
        """The first array whose kind (mount) is ``kind``."""
        return next((a for a in self.arrays.values() if a.kind == kind), None)

    def has_twin(self) -> bool:
        """Whether the twin can simulate the site: arrays named ``tracker`` and ``fixed`` with
        those mounts (:func:`sim.twin.simulate`'s rule). A site may store readings of arrays
        named otherwise; it has no twin, diagnosis or sky from its fixed array."""
        from sim.twin import has_twin_arrays

        return has_twin_arrays({name: a.kind for name, a in self.arrays.items()})


def _kind(cfg: object) -> str:
    return str(getattr(cfg, "mount", "fixed"))


def drop_twin_cache(conn: Connection, site_id: str) -> int:
    """Delete the stored twin readings, twin rollups and twin coverage of ``site_id``, and
    its cached diagnosis days (its config changed: they were computed with the old one — a
    tilt, a module, ``readings_stamped``). Returns twin readings dropped."""
    arrays = select(ArrayRow.id).where(ArrayRow.site_id == site_id).scalar_subquery()
    n = conn.execute(delete(Measurement).where(
        Measurement.array_id.in_(arrays), Measurement.source == SOURCE_CODES["twin"])).rowcount
    conn.execute(delete(MeasurementRollup).where(
        MeasurementRollup.array_id.in_(arrays),
        MeasurementRollup.source == SOURCE_CODES["twin"]))
    conn.execute(delete(TwinCoverage).where(TwinCoverage.site_id == site_id))
    conn.execute(delete(DiagnosisDay).where(DiagnosisDay.site_id == site_id))
    return int(n or 0)


def sync_sites(conn: Connection, sites: list[Site]) -> dict[str, int]:
    """Insert or refresh ``sites`` and ``arrays`` rows for ``sites`` (calibrations kept).

    A site whose stored config differs from its file has its cached twin dropped
    (:func:`drop_twin_cache`); returns ``{site_id: twin readings dropped}`` for those.
    """
    ins = postgresql.insert if conn.dialect.name == "postgresql" else sqlite.insert
    stored = {sid: cfg for sid, cfg in conn.execute(select(SiteRow.site_id, SiteRow.config_json))}
    changed: dict[str, int] = {}
    for site in sites:
        values = {
            "site_id": site.site_id, "name": site.name, "latitude_deg": site.latitude,
            "longitude_deg": site.longitude, "altitude_m": site.altitude,
            "timezone": site.timezone, "bucket_phase_s": bucket_phase_s(site.timezone),
            "config_json": json.dumps(site.to_dict()), "updated_at": utcnow(),
        }
        if site.site_id in stored and stored[site.site_id] != values["config_json"]:
            changed[site.site_id] = drop_twin_cache(conn, site.site_id)
            logger.info("site %s changed: %d cached twin readings dropped", site.site_id,
                        changed[site.site_id])
        stmt = ins(SiteRow).values(**values)
        conn.execute(stmt.on_conflict_do_update(index_elements=["site_id"], set_={
            k: stmt.excluded[k] for k in values if k != "site_id"}))
        for name, cfg in site.arrays.items():
            cfg_json = json.dumps(cfg.to_dict())
            defaults = Calibration()
            stmt = ins(ArrayRow).values(
                site_id=site.site_id, name=name, kind=_kind(cfg), config_json=cfg_json,
                **{f: getattr(defaults, f) for f in CALIBRATION_FIELDS},
            )
            conn.execute(stmt.on_conflict_do_update(
                index_elements=["site_id", "name"],
                set_={"kind": stmt.excluded.kind, "config_json": stmt.excluded.config_json},
            ))
    return changed


class Registry:
    """In-memory view of the sites and arrays (thread-safe for reads).

    A site file that appears in (or changes in) the user's folder while the service runs
    (``heliotwin site create``, which also writes the site's rows to the database) is read
    at the next look at :attr:`sites` (at most once a second) or at a lookup of an unknown
    id (:meth:`rescan`): no restart needed.
    """

    RESCAN_S = 1.0
    """How often [s] a look at :attr:`sites` checks the user's folder for new files."""
    FORCED_RESCAN_S = 0.1
    """How often [s], at most, a lookup of an unknown id checks it."""
    SCAN_WAIT_S = 10.0
    """How long [s], at most, a lookup of an unknown id waits for a look already running
    (the watcher's, which may be storing that very site's rows)."""

    def __init__(self, sites: list[Site], user_dir: Path | None = None) -> None:
        self._lock = threading.Lock()
        self._sites: dict[str, SiteInfo] = {
            s.site_id: SiteInfo(s, ZoneInfo(s.timezone), bucket_phase_s(s.timezone))
            for s in sites
        }
        self._phase_of_array: dict[int, int] = {}
        self._user_dir = user_dir
        self._files = self._file_state() or {}
        self._dir_mtime_ns = self._folder_mtime_ns()
        self._checked = time.monotonic()
        self._scan_lock = threading.Lock()
        self._engine: Engine | None = None  # the database refresh_arrays read, for rescans
        self._store: Callable[[list[Site]], object] | None = None  # see store_through
        self._watcher: threading.Thread | None = None  # see start_watching
        self._stop_watching = threading.Event()

    @property
    def sites(self) -> dict[str, SiteInfo]:
        """Every site by id, with any site file added since the last look (:meth:`rescan`)."""
        self.rescan()
        return self._sites

    @classmethod
    def load_files(cls, sites_dir: Path) -> Registry:
        """Read every site file of ``sites_dir`` (``sim.sites.list_sites``), and watch it."""
        return cls(list_sites(sites_dir), sites_dir)

    def _file_state(self) -> dict[str, tuple[int, int]] | None:
        """``{file name: (mtime_ns, size)}`` of the user's site files; None when the folder
        cannot be read now (swapped in a deploy, a network file system's hiccup): not a
        reason to forget every site in it."""
        if self._user_dir is None:
            return {}
        if not self._user_dir.is_dir():
            return None
        out = {}
        for path in self._user_dir.glob("*.json"):
            try:
                st = path.stat()
            except OSError:  # removed meanwhile
                continue
            out[path.name] = (st.st_mtime_ns, st.st_size)
        return out

    def _folder_mtime_ns(self) -> int:
        """The user's folder's mtime (a file added, removed or renamed in it moves it), or -1."""
        try:
            return self._user_dir.stat().st_mtime_ns if self._user_dir is not None else -1
        except OSError:
            return -1

    def start_watching(self) -> None:
        """Look at the user's folder every :attr:`RESCAN_S` in a thread of its own: a file
        edited or deleted reaches lookups by id within that (:meth:`get` stays a dict
        read: a rescan applies a changed site through the writer, which must not hold up
        the event loop of an ingest request)."""
        self._stop_watching.clear()

        def watch() -> None:
            while not self._stop_watching.wait(self.RESCAN_S):
                try:
                    self.rescan()
                except Exception:  # a bad moment must not end the watching
                    logger.exception("site folder %s: rescan failed", self._user_dir)

        self._watcher = threading.Thread(target=watch, name="heliotwin-sites", daemon=True)
        self._watcher.start()

    def stop_watching(self) -> None:
        """Stop :meth:`start_watching`'s thread (before the writer stops)."""
        if self._watcher is not None:
            self._stop_watching.set()
            self._watcher.join(timeout=10)
            self._watcher = None

    def note_file(self, path: Path) -> None:
        """A site file this process wrote (and applied): not news to :meth:`rescan`."""
        try:
            st = path.stat()
        except OSError:
            return
        with self._lock:
            self._files[path.name] = (st.st_mtime_ns, st.st_size)

    def rescan(self, force: bool = False) -> bool:
        """Read the user's site files that are new or changed since the last look (at most
        every :attr:`RESCAN_S` unless ``force``); returns whether a site was added or
        replaced. Their arrays' ids come from the database (the CLI wrote the rows); a
        malformed file is logged and skipped, a changed time zone that would move the
        rollup grid too (``PUT`` refuses it with 409; restart to apply)."""
        if self._user_dir is None or self._engine is None:
            return False
        now = time.monotonic()
        # forced (an unknown id) still at most every FORCED_RESCAN_S: anyone can ask for
        # unknown ids (every site route's 404, MQTT topics), each would read the folder;
        # sooner only when a file was added to it since (one stat: a site created just after
        # a look is found by its id at once)
        gap = self.FORCED_RESCAN_S if force else self.RESCAN_S
        folder_moved = force and self._folder_mtime_ns() != self._dir_mtime_ns
        if force and self._scan_lock.locked():
            # a look already running (the watcher's) may be storing this very site's rows
            # through the writer: wait for its end, then look again if the folder moved
            # since it began (before, the lookup answered 404 right after `site create` on a
            # loaded test run, session 30)
            if self._scan_lock.acquire(timeout=self.SCAN_WAIT_S):
                self._scan_lock.release()
            now = time.monotonic()
            folder_moved = self._folder_mtime_ns() != self._dir_mtime_ns
        if (now - self._checked < gap and not folder_moved) \
                or not self._scan_lock.acquire(blocking=False):
            return False
        try:
            self._checked = now
            self._dir_mtime_ns = self._folder_mtime_ns()
            state = self._file_state()
            if state is None:
                return False
            with self._lock:  # note_file writes it too
                changed = [name for name, sig in state.items() if self._files.get(name) != sig]
                removed = [name for name in self._files if name not in state]
                self._files = state
            added = [site for name in sorted(changed)
                     if (site := self._read_new(name.removesuffix(".json"))) is not None]
            added += self._forget(sorted(name.removesuffix(".json") for name in removed))
            if added and self._store is not None:
                try:  # idempotent beside the rows the CLI writes
                    self._store(added)
                except Exception:  # the writer stopped (shutdown), the database refused
                    logger.exception("sites %s: their rows were not written",
                                     [s.site_id for s in added])
            for site in added:
                self.put(site)
            if added:
                with self._engine.connect() as conn:
                    self.refresh_arrays(conn)
                for site in added:
                    missing = set(site.arrays) - set(self._sites[site.site_id].arrays)
                    logger.info("site %s read from %s while running", site.site_id,
                                self._user_dir)
                    if missing:
                        logger.warning("site %s: arrays %s have no rows in the database: it "
                                       "answers 503 until a restart adds them", site.site_id,
                                       sorted(missing))
            return bool(added)
        finally:
            self._scan_lock.release()

    def _forget(self, site_ids: list[str]) -> list[Site]:
        """The sites whose user file was deleted: a built-in one of that id comes back (the
        running service kept the deleted override's config, labelled built-in; a tester's
        finding) and is returned to be put; a site of the user's alone leaves the service,
        as a restart would (its stored readings stay in the database)."""
        back = []
        builtin = builtin_site_ids()
        for site_id in site_ids:
            if site_id not in self._sites:
                continue
            if site_id in builtin:
                if (site := self._read_new(site_id)) is not None:
                    logger.info("site %s: its file was deleted from %s; the built-in one "
                                "again", site_id, self._user_dir)
                    back.append(site)
                continue
            with self._lock:
                self._sites.pop(site_id, None)
            logger.warning("site %s: its file was deleted from %s; the service no longer has "
                           "it (its readings stay stored)", site_id, self._user_dir)
        return back

    def _read_new(self, site_id: str) -> Site | None:
        """The site of a new or changed file, or None (unchanged, malformed, or a new zone)."""
        try:
            site = load_site(site_id, self._user_dir)
        except ValueError as exc:
            logger.warning("site file %s.json in %s not read: %s", site_id, self._user_dir, exc)
            return None
        old = self._sites.get(site_id)
        if old is not None and old.site == site:
            return None
        if old is not None and bucket_phase_s(site.timezone) != old.phase_s:
            logger.warning("site %s: its file's time zone %s moves the hourly rollup grid: "
                           "restart the service to apply it", site_id, site.timezone)
            return None
        return site

    def store_through(self, store: Callable[[list[Site]], object]) -> None:
        """How a site file read while running gets its rows: ``store(sites)`` writes them
        (the service's writer running :func:`sync_sites`). Without it, the rows had to be
        there already: a file the service read between ``site create``'s file and its
        rows, or made against another database, kept a site without arrays — and every
        ``GET /sites`` answered 500 until a restart."""
        self._store = store

    def refresh_arrays(self, conn: Connection) -> None:
        """Read array ids and calibrations from the database."""
        self._engine = conn.engine
        cols = [ArrayRow.id, ArrayRow.site_id, ArrayRow.name, ArrayRow.kind] + [
            getattr(ArrayRow, f) for f in CALIBRATION_FIELDS]
        rows = conn.execute(select(*cols)).all()
        with self._lock:
            for row in rows:
                info = self._sites.get(row.site_id)
                if info is None or row.name not in info.site.arrays:
                    continue  # an array no longer in the site's config takes no readings
                cal = Calibration(**{f: getattr(row, f) for f in CALIBRATION_FIELDS})
                info.arrays[row.name] = ArrayInfo(row.id, row.name, row.kind, cal)
                self._phase_of_array[row.id] = info.phase_s

    def put(self, site: Site) -> SiteInfo:
        """Add or replace a site (its arrays come from the next :meth:`refresh_arrays`)."""
        info = SiteInfo(site, ZoneInfo(site.timezone), bucket_phase_s(site.timezone))
        with self._lock:
            old = self._sites.get(site.site_id)
            if old is not None:  # kept meanwhile, so ingest never sees the site without them
                info.arrays = {n: a for n, a in old.arrays.items() if n in site.arrays}
            self._sites[site.site_id] = info
        return info

    def phase_of_array(self, array_id: int) -> int:
        """Rollup phase [s] of the site that owns ``array_id``."""
        return self._phase_of_array[array_id]

    def get(self, site_id: str) -> SiteInfo | None:
        """The site, or None; an unknown id first looks for a new site file (:meth:`rescan`).
        Edited and deleted files reach a known id through :meth:`start_watching` (a lookup
        by id saw an edited file only after some request had listed every site, 44 s later;
        a rescan here ran on the event loop of every ingest request)."""
        info = self._sites.get(site_id)
        if info is None:  # a look that waited for another may find its work done: read again
            self.rescan(force=True)
            info = self._sites.get(site_id)
        return info

    def set_calibration(self, conn: Connection, site_id: str, name: str, cal: Calibration) -> None:
        """Store a new calibration for an array (called in the writer's transaction)."""
        info = self._sites[site_id]
        conn.execute(
            update(ArrayRow)
            .where(ArrayRow.site_id == site_id, ArrayRow.name == name)
            .values(**{f: getattr(cal, f) for f in CALIBRATION_FIELDS})
        )
        with self._lock:
            info.arrays[name] = replace(info.arrays[name], calibration=cal)


def write_site_file(directory: Path, config: dict[str, Any]) -> Path:
    """Write a validated config as ``<directory>/<site_id>.json`` (atomically)."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{config['site_id']}.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(config, indent=2, ensure_ascii=False) + "\n")
    tmp.replace(path)
    return path


def save_site(ctx: ServiceContext, site_id: str, data: Any) -> tuple[SiteInfo, bool, int]:
    """Create or replace site ``site_id`` from a config dict while the service runs.

    Returns the new :class:`SiteInfo`, whether the site is new, and how many cached
    twin readings were dropped. InputError 422 names the bad field; 409 when the
    new time zone would move the hourly rollup grid under stored readings.
    """
    old = ctx.registry.get(site_id)
    if isinstance(data, dict):  # what the body leaves out, its place decides (marked)
        data = place_defaults(data)
        if old is not None:
            data = _settle_assumed(old.site.to_config(), data)
    try:
        cfg = validate_site_config(data, where="body")
        config = cfg.model_dump(mode="json", by_alias=True, exclude_unset=True)
        if cfg.site_id != site_id:
            raise ValueError(f"body: site_id: {cfg.site_id!r} does not match the path's "
                             f"{site_id!r}")
        site = site_from_dict(config, where="body")
    except ValueError as exc:
        raise InputError(422, str(exc)) from None
    if old is not None and bucket_phase_s(site.timezone) != old.phase_s:
        raise InputError(409, f"body: timezone: {site.timezone!r} is offset from the hour "
                              f"differently from {old.site.timezone!r}; the stored hourly "
                              "rollups are phased to the old zone: make a new site instead")
    config.pop("$schema", None)

    def sync(conn: Connection) -> int:
        return sync_sites(conn, [site]).get(site_id, 0)

    with ctx.twin.site_lock(site_id):  # no on-demand twin of the old config meanwhile
        # the database first: a config it refuses leaves no file behind for the next start
        dropped: int = ctx.writer.call(sync).result()
        path = write_site_file(ctx.settings.sites.user_dir, config)
        info = ctx.registry.put(site)
        with ctx.engine.connect() as conn:
            ctx.registry.refresh_arrays(conn)
        ctx.twin.forget(site_id)
    ctx.registry.note_file(path)  # applied here: not news to the rescan
    logger.info("site %s %s (%d cached twin readings dropped)", site_id,
                "created" if old is None else "updated", dropped)
    return info, old is None, dropped


def config_value(config: dict[str, Any], path: str) -> Any:
    """The value at a dotted path of a config (``arrays.fixed.surface_tilt_deg``; None
    when absent): the keys of ``assumed``."""
    value: Any = config
    for part in path.split("."):
        value = value.get(part) if isinstance(value, dict) else None
    return value


def _settle_assumed(old: dict[str, Any], new: dict[str, Any]) -> dict[str, Any]:
    """``new`` without the ``assumed`` marks of values it changes from ``old``: a value the
    user set is the site's own, no longer an assumption."""
    marks = new.get("assumed")
    if not isinstance(marks, dict):
        return new
    kept = {k: v for k, v in marks.items() if config_value(new, k) == config_value(old, k)}
    out = {k: v for k, v in new.items() if k != "assumed"}
    return {**out, "assumed": kept} if kept else out
