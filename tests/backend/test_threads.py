"""The service's threads are the ones ``docs/architecture.md`` lists ("Threads and processes").

The app runs in process (``create_app`` + ``TestClient`` with its lifespan) with every
optional part on: viser, the live twin, the demo logger (aimed at a port nobody listens
on, so it waits for the service for two minutes), the alert evaluator with a webhook,
MQTT (a closed port: it keeps retrying). Thread names are compared with their digit
groups after ``-`` or ``_`` written ``N`` (``heliotwin-sim-0`` → ``heliotwin-sim-N``).
"""

from __future__ import annotations

import re
import socket
import threading
from pathlib import Path

from fastapi.testclient import TestClient

from backend.app import create_app
from backend.settings import get_settings

DOC = Path(__file__).resolve().parents[2] / "docs" / "architecture.md"


def _name(thread: threading.Thread) -> str:
    return re.sub(r"(?<=[-_])\d+\b", "N", thread.name)


def _tables() -> list[list[list[str]]]:
    """The Markdown tables of the doc's "Threads and processes" section, as rows of cells
    (header and rule lines dropped)."""
    text = DOC.read_text(encoding="utf-8")
    section = text.split("\n## Threads and processes\n", 1)[1].split("\n## ", 1)[0]
    tables: list[list[list[str]]] = []
    previous = ""
    for line in section.splitlines():
        if line.startswith("|"):
            if not previous.startswith("|"):
                tables.append([])
            cells = [c.strip() for c in line.strip("|").split("|")]
            if cells[0].startswith("`"):
                tables[-1].append(cells)
        previous = line
    return tables


def _documented() -> tuple[set[str], set[str], set[str]]:
    """Dedicated threads running from the start, those started at the first simulation, and
    the pools' thread names."""
    dedicated, pools = _tables()[:2]
    at_start = {r[0].strip("`") for r in dedicated if "first simulation" not in r[1]}
    later = {r[0].strip("`") for r in dedicated if "first simulation" in r[1]}
    return at_start, later, {r[0].strip("`") for r in pools}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_live_threads_are_the_documented_ones(tmp_path: Path) -> None:
    at_start, later, pools = _documented()
    assert {"MainThread", "heliotwin-writer", "heliotwin-sim-N"} <= at_start | later
    settings = get_settings(
        database_url=f"sqlite:///{tmp_path / 'threads.sqlite'}", port=_free_port(),
        viser=True, viser_port=_free_port(), live_twin=True, demo_logger=True,
        alerts=True, alert_interval_s=3600.0,
        alert_webhook_url=f"http://127.0.0.1:{_free_port()}/hook",
        mqtt_url=f"mqtt://127.0.0.1:{_free_port()}")
    before = {t.ident for t in threading.enumerate()}

    def started() -> list[threading.Thread]:  # TestClient's own event-loop thread left out
        return [t for t in threading.enumerate() if t.ident not in before
                and not t.name.startswith("asyncio-portal-")]

    with TestClient(create_app(settings)) as client:
        first = started()
        names = {_name(t) for t in first} | {"MainThread"}
        assert names - pools == at_start
        r = client.post("/api/v1/simulations", json={"site_id": "tehuantepec",
                                                     "start": "2024-03-15",
                                                     "end": "2024-03-16"})
        assert r.status_code == 200, r.text
        new = {_name(t) for t in started() if t not in first}
        assert new - pools == later
    dedicated = [t for t in first if _name(t) not in pools]
    for t in dedicated:
        t.join(10.0)  # stopped by the lifespan's exit; a bound, not a timing check
    assert [t.name for t in dedicated if t.is_alive()] == []
