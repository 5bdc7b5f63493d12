"""``heliotwin token create|revoke`` while loggers write to the same SQLite file (issue 23,
item 6): every command succeeds, and ``sites`` is not rewritten by them.

Four writer threads commit small ``BEGIN IMMEDIATE`` transactions of 20 rows, 4 ms apart
(≈ 90–110 commits, ≈ 2,000 rows per second on the shared test machine) on a real
SQLite file in WAL mode, while the CLI's ``create`` and ``revoke`` run ten times
each in this process. A deferred transaction that reads and then writes fails at once
with "database is locked" when a writer commits between its read and its write.
"""

from __future__ import annotations

import argparse
import sqlite3
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import select

from backend.cli import CliError
from backend.cli.token import create, revoke
from backend.settings import get_settings
from backend.sites import Registry, sync_sites
from backend.storage.engine import make_engine, run_migrations
from backend.storage.tables import LoggerToken, SiteRow

WRITERS = 4
PAUSE_S = 0.004  # between one writer's commits: 4 writers make ≈ 500–800 commits/s


@pytest.fixture
def database(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A migrated SQLite file with the built-in sites, named by HELIOTWIN_DATABASE_URL."""
    path = tmp_path / "load.sqlite"
    url = f"sqlite:///{path}"
    monkeypatch.setenv("HELIOTWIN_DATABASE_URL", url)
    monkeypatch.setenv("HELIOTWIN_SITES_DIR", str(tmp_path / "sites"))
    engine = make_engine(get_settings())
    run_migrations(engine)
    with engine.begin() as conn:
        sync_sites(conn, [i.site for i in Registry.load_files(tmp_path / "sites").sites.values()])
        conn.exec_driver_sql("CREATE TABLE probe (id INTEGER PRIMARY KEY, v REAL)")
    engine.dispose()
    yield path


def _write(path: Path, stop: threading.Event, commits: list[int]) -> None:
    """Commit one small write after another until ``stop`` (as the ingest writer does)."""
    conn = sqlite3.connect(path, timeout=30, isolation_level=None)
    conn.execute("PRAGMA busy_timeout=30000")
    n = 0
    while not stop.is_set():
        conn.execute("BEGIN IMMEDIATE")
        conn.executemany("INSERT INTO probe (v) VALUES (?)", [(float(i),) for i in range(20)])
        conn.execute("COMMIT")
        n += 1
        stop.wait(PAUSE_S)
    conn.close()
    commits.append(n)


def _sites_updated(path: Path) -> list[object]:
    engine = make_engine(get_settings(database_url=f"sqlite:///{path}"))
    try:
        with engine.connect() as conn:
            return list(conn.execute(select(SiteRow.updated_at).order_by(SiteRow.site_id))
                        .scalars())
    finally:
        engine.dispose()


def test_create_and_revoke_succeed_while_loggers_write(
        database: Path, capsys: pytest.CaptureFixture[str]) -> None:
    before = _sites_updated(database)
    stop = threading.Event()
    commits: list[int] = []
    threads = [threading.Thread(target=_write, args=(database, stop, commits))
               for _ in range(WRITERS)]
    for t in threads:
        t.start()
    failures: list[str] = []
    started = time.monotonic()
    try:
        for _ in range(10):
            try:
                create(argparse.Namespace(site="tehuantepec", label="load", scope="ingest",
                                          expires_in_days=None, expires=None))
                token = capsys.readouterr().out.strip().splitlines()[-1]
                revoke(argparse.Namespace(token_or_id=token))
            except (CliError, Exception) as exc:  # what an operator would see
                failures.append(f"{type(exc).__name__}: {exc}")
    finally:
        stop.set()
        for t in threads:
            t.join(60)
    elapsed = time.monotonic() - started
    print(f"{sum(commits) / elapsed:.0f} commits/s for {elapsed:.1f} s")
    assert failures == []
    assert sum(commits) >= 50  # the writers really were committing meanwhile
    assert _sites_updated(database) == before  # the commands did not rewrite `sites`
    engine = make_engine(get_settings(database_url=f"sqlite:///{database}"))
    with engine.connect() as conn:
        rows = conn.execute(select(LoggerToken.revoked_at, LoggerToken.scope)).all()
    engine.dispose()
    assert len(rows) == 10 and all(r.revoked_at is not None and r.scope == "ingest"
                                   for r in rows)
