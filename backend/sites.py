"""Sites known to the service: loaded from ``data/sites/`` (``sim.sites``) into the database.

At start-up the built-in site files are written to the ``sites`` and ``arrays``
tables (inserted, or their config refreshed; a stored logger calibration is
kept). :class:`Registry` keeps what the hot path needs in memory: for each site
the ``sim.sites.Site``, its time zone, its rollup phase, and for each array its
id, kind and calibration.
"""

from __future__ import annotations

import json
import logging
import threading
from dataclasses import dataclass, field, replace
from pathlib import Path
from zoneinfo import ZoneInfo

from sqlalchemy import Connection, select, update
from sqlalchemy.dialects import postgresql, sqlite

from backend.measurements.buckets import bucket_phase_s
from backend.measurements.parse import Calibration
from backend.storage.tables import ArrayRow, SiteRow, utcnow
from sim.sites import Site, list_sites

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

    def ingest_arrays(self) -> dict[str, tuple[int, Calibration]]:
        """``{name: (array_id, calibration)}`` for :mod:`backend.measurements.parse`."""
        return {a.name: (a.array_id, a.calibration) for a in self.arrays.values()}

    def array_of_kind(self, kind: str) -> ArrayInfo | None:
        """The first array whose kind (mount) is ``kind``."""
        return next((a for a in self.arrays.values() if a.kind == kind), None)


def _kind(cfg: object) -> str:
    return str(getattr(cfg, "mount", "fixed"))


def sync_sites(conn: Connection, sites: list[Site]) -> None:
    """Insert or refresh ``sites`` and ``arrays`` rows for ``sites`` (calibrations kept)."""
    ins = postgresql.insert if conn.dialect.name == "postgresql" else sqlite.insert
    for site in sites:
        values = {
            "site_id": site.site_id, "name": site.name, "latitude_deg": site.latitude,
            "longitude_deg": site.longitude, "altitude_m": site.altitude,
            "timezone": site.timezone, "bucket_phase_s": bucket_phase_s(site.timezone),
            "config_json": json.dumps(site.to_dict()), "updated_at": utcnow(),
        }
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


class Registry:
    """In-memory view of the sites and arrays (thread-safe for reads)."""

    def __init__(self, sites: list[Site]) -> None:
        self._lock = threading.Lock()
        self.sites: dict[str, SiteInfo] = {
            s.site_id: SiteInfo(s, ZoneInfo(s.timezone), bucket_phase_s(s.timezone))
            for s in sites
        }
        self._phase_of_array: dict[int, int] = {}

    @classmethod
    def load_files(cls, sites_dir: Path) -> Registry:
        """Read every site file of ``sites_dir`` (``sim.sites.list_sites``)."""
        return cls(list_sites(sites_dir))

    def refresh_arrays(self, conn: Connection) -> None:
        """Read array ids and calibrations from the database."""
        cols = [ArrayRow.id, ArrayRow.site_id, ArrayRow.name, ArrayRow.kind] + [
            getattr(ArrayRow, f) for f in CALIBRATION_FIELDS]
        rows = conn.execute(select(*cols)).all()
        with self._lock:
            for row in rows:
                info = self.sites.get(row.site_id)
                if info is None:
                    continue
                cal = Calibration(**{f: getattr(row, f) for f in CALIBRATION_FIELDS})
                info.arrays[row.name] = ArrayInfo(row.id, row.name, row.kind, cal)
                self._phase_of_array[row.id] = info.phase_s

    def phase_of_array(self, array_id: int) -> int:
        """Rollup phase [s] of the site that owns ``array_id``."""
        return self._phase_of_array[array_id]

    def get(self, site_id: str) -> SiteInfo | None:
        return self.sites.get(site_id)

    def set_calibration(self, conn: Connection, site_id: str, name: str, cal: Calibration) -> None:
        """Store a new calibration for an array (called in the writer's transaction)."""
        info = self.sites[site_id]
        conn.execute(
            update(ArrayRow)
            .where(ArrayRow.site_id == site_id, ArrayRow.name == name)
            .values(**{f: getattr(cal, f) for f in CALIBRATION_FIELDS})
        )
        with self._lock:
            info.arrays[name] = replace(info.arrays[name], calibration=cal)
