"""Migrations (``backend/storage/migrations``) build exactly the tables of ``tables.py``."""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from alembic.script import ScriptDirectory
from live_service import HELIOTWIN, ROOT, free_port, new_database, process_env
from sqlalchemy import inspect

from backend.settings import get_settings
from backend.storage.engine import SchemaTooNewError, alembic_config, make_engine, run_migrations
from backend.storage.tables import Base


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_migrations_match_models_and_rerun(backend: str, tmp_path: Path) -> None:
    db = new_database(backend, tmp_path)
    engine = make_engine(get_settings(database_url=db.url))
    try:
        run_migrations(engine)
        run_migrations(engine)  # idempotent: a restart finds the schema current
        with engine.connect() as conn:
            diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
            heads = ScriptDirectory.from_config(alembic_config(engine)).get_heads()
            current = set(MigrationContext.configure(conn).get_current_heads())
        assert diff == [], diff
        assert current == set(heads)
        tables = set(inspect(engine).get_table_names())
        assert {"sites", "arrays", "logger_tokens", "measurements", "measurement_rollups",
                "twin_coverage", "simulation_runs", "simulation_series"} <= tables
    finally:
        engine.dispose()
        db.drop()


def test_every_revision_chains_to_0001() -> None:
    engine = make_engine(get_settings(database_url="sqlite://"))
    script = ScriptDirectory.from_config(alembic_config(engine))
    bases = script.get_bases()
    assert bases == ["0001_initial"]
    for rev in script.walk_revisions():
        assert rev.revision == "0001_initial" or rev.down_revision is not None


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_a_database_of_a_newer_version_is_refused_by_name(
        backend: str, tmp_path: Path, heliotwin_cli: Callable[..., Any]) -> None:
    """A database migrated by a newer heliotwin (a revision this code lacks) is refused
    with a message saying so and what to do, and is left as it was (an operator's
    finding: Alembic's "Can't locate revision" under a 150-line traceback). ``heliotwin
    serve`` and ``token create`` say it in one line and exit 1 (they had printed it under
    uvicorn's 90-line traceback, exit 3, and Python's, exit 1)."""
    db = new_database(backend, tmp_path)
    engine = make_engine(get_settings(database_url=db.url))
    try:
        run_migrations(engine)
        with engine.begin() as conn:
            conn.exec_driver_sql("UPDATE alembic_version SET version_num = '0999_from_the_future'")
        with pytest.raises(SchemaTooNewError) as err:
            run_migrations(engine)
        msg = str(err.value)
        assert "0999_from_the_future" in msg and "newer heliotwin" in msg
        assert "restore a backup" in msg
        token = heliotwin_cli("token", "create", "--site", "tehuantepec",
                              env={"HELIOTWIN_DATABASE_URL": db.url})
        serve = subprocess.run(
            [*HELIOTWIN, "serve", "--port", str(free_port()), "--viser-port", "0",
             "--no-demo"], cwd=ROOT, env=process_env(db.url), capture_output=True,
            text=True, timeout=120)
        for name, run in (("token create", token), ("serve", serve)):
            assert (run.returncode, run.stdout) == (1, ""), (name, run)
            assert run.stderr.splitlines() == [f"heliotwin {name}: error: {msg}"], run.stderr
        with engine.connect() as conn:
            assert MigrationContext.configure(conn).get_current_heads() == (
                "0999_from_the_future",)
    finally:
        engine.dispose()
        db.drop()


def test_an_unreachable_postgresql_is_one_line(heliotwin_cli: Callable[..., Any]) -> None:
    """``heliotwin serve`` (and a command that opens the database) with no PostgreSQL at
    the URL says so in one line — the URL with its password hidden, the driver's reason,
    what to do — and exits 1 (serve had printed SQLAlchemy's traceback)."""
    url = f"postgresql+psycopg://heliotwin:s3cret@127.0.0.1:{free_port()}/heliotwin"
    serve = subprocess.run(
        [*HELIOTWIN, "serve", "--port", str(free_port()), "--viser-port", "0", "--no-demo"],
        cwd=ROOT, env=process_env(url), capture_output=True, text=True, timeout=120)
    token = heliotwin_cli("token", "list", env={"HELIOTWIN_DATABASE_URL": url})
    for name, run in (("serve", serve), ("token list", token)):
        assert (run.returncode, run.stdout) == (1, ""), (name, run)
        lines = run.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith(
            f"heliotwin {name}: error: cannot connect to the database "
            f"postgresql+psycopg://heliotwin:***@127.0.0.1:"), lines
        assert "s3cret" not in lines[0] and "Connection refused" in lines[0]
        assert "start PostgreSQL" in lines[0], lines[0]
