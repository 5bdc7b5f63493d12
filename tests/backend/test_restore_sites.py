"""A database restored without its site files: the start-up log says which sites it holds
that no config gives (``backend.context.warn_sites_without_config``)."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
from sqlalchemy import select

from backend.context import warn_sites_without_config
from backend.settings import get_settings
from backend.sites import Registry, sync_sites
from backend.storage.engine import make_engine, run_migrations
from backend.storage.tables import ArrayRow, MeasurementRollup


def test_a_site_of_the_database_without_its_file_is_named_at_start(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    engine = make_engine(get_settings(database_url=f"sqlite:///{tmp_path / 'restored.sqlite'}"))
    try:
        run_migrations(engine)
        registry = Registry.load_files(tmp_path / "user-sites")  # the built-in sites
        with engine.begin() as conn:
            sync_sites(conn, [info.site for info in registry.sites.values()])
            array_id = conn.execute(select(ArrayRow.id).where(
                ArrayRow.site_id == "tehuantepec", ArrayRow.name == "tracker")).scalar_one()
            table = MeasurementRollup.__table__
            zeros = {c.name: 0 for c in table.columns if not c.nullable}
            conn.execute(table.insert(), [
                {**zeros, "array_id": array_id, "source": 0, "bucket_s": 3600 * k, "n": n}
                for k, n in ((1, 60), (2, 40))] + [
                {**zeros, "array_id": array_id, "source": 1, "bucket_s": 3600, "n": 60}])
        sites_dir = tmp_path / "user-sites"
        with caplog.at_level(logging.WARNING, logger="backend.context"):
            orphans = warn_sites_without_config(engine, {"guadalajara_fisheye"}, sites_dir)
        assert orphans == ["tehuantepec"]
        [record] = [r for r in caplog.records if r.name == "backend.context"]
        msg = record.getMessage()
        assert "site tehuantepec is in the database (100 measured readings)" in msg
        assert str(sites_dir) in msg and "HELIOTWIN_SITES_DIR" in msg
    finally:
        engine.dispose()
