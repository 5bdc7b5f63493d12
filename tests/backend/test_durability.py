"""Nothing acknowledged is lost: SIGKILL in the middle of sustained ingestion.

Several loggers post batches as fast as they can; every reading of a batch
answered 200 is remembered. The server is killed with SIGKILL (no shutdown code
runs) while requests are in flight, once it has acknowledged enough readings to
prove something, not after a set time (the machine may be slow). The service is then
started again on the same database (in this process: only the killed one's process
matters) and must hold every remembered reading with its values — and the hourly rollups
committed with them must still agree with the readings.
"""

from __future__ import annotations

import datetime as dt
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

import httpx
import numpy as np
import pytest
from live_service import InProcessServer, ServerProcess

if TYPE_CHECKING:
    from live_service import Database

PATH = "/api/v1/sites/tehuantepec/measurements"
T0 = int(dt.datetime(2023, 9, 1, tzinfo=dt.UTC).timestamp())
ACKED_BEFORE_KILL = 1000  # readings acknowledged while the loggers run, before the kill


def _batch(logger: int, k: int, size: int) -> list[dict]:
    base = T0 + (logger * 100_000 + k * size) * 60
    return [{"ts": dt.datetime.fromtimestamp(base + 60 * j, dt.UTC).isoformat(),
             "array": "tracker" if logger % 2 == 0 else "fixed",
             "voltage_v": 25.0, "current_a": round(1 + ((k * size + j) % 500) / 100, 2)}
            for j in range(size)]


def _no_process_left(port: int, timeout_s: float = 10.0) -> bool:
    """True once no process runs with the killed server's command line (its forked
    parser workers carry the same one)."""
    marker = f"--port\x00{port}\x00".encode()
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        left = []
        for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
            try:
                if marker in cmdline.read_bytes():
                    left.append(cmdline.parent.name)
            except OSError:
                continue
        if not left:
            return True
        time.sleep(0.2)
    return False


@pytest.mark.slow
def test_sigkill_loses_nothing_acknowledged(database: Database, tmp_path: Path) -> None:
    server = ServerProcess(database.url, tmp_path / "server.log").start()
    token = server.token()
    acked: dict[str, list[dict]] = {"tracker": [], "fixed": []}
    lock = threading.Lock()
    stop = threading.Event()
    errors: list[str] = []

    def logger_loop(n: int) -> None:
        with httpx.Client(base_url=server.base_url, timeout=10.0,
                          headers={"Authorization": f"Bearer {token}"}) as c:
            for k in range(10_000):
                if stop.is_set():
                    return
                batch = _batch(n, k, 50 if n < 3 else 1)
                try:
                    r = c.post(PATH, json={"readings": batch})
                except httpx.HTTPError:
                    return  # the server died under us: this batch was never acknowledged
                if r.status_code == 200:
                    assert r.json()["accepted"] == len(batch)
                    with lock:
                        acked[batch[0]["array"]].extend(batch)
                else:
                    errors.append(f"{r.status_code} {r.text[:200]}")
                    return

    threads = [threading.Thread(target=logger_loop, args=(n,)) for n in range(6)]
    for t in threads:
        t.start()
    deadline = time.monotonic() + 300.0
    while True:
        with lock:
            before_kill = sum(len(v) for v in acked.values())
        if before_kill > ACKED_BEFORE_KILL or errors or time.monotonic() > deadline \
                or not any(t.is_alive() for t in threads):
            break
        time.sleep(0.05)
    killed_port = server.port
    server.kill()  # SIGKILL while the loggers are still posting
    stop.set()
    for t in threads:
        t.join(15)
    assert not errors, errors[:3]
    assert before_kill > ACKED_BEFORE_KILL, "too little traffic before the kill to prove anything"
    assert _no_process_left(killed_port), "a worker process outlived the killed server"

    with InProcessServer(database.url) as again, again.client(timeout_s=60.0) as c:
        for array, readings in acked.items():
            if not readings:
                continue
            ts = np.array([dt.datetime.fromisoformat(r["ts"]).timestamp()
                           for r in readings], np.int64)
            start = dt.datetime.fromtimestamp(int(ts.min()), dt.UTC).isoformat()
            end = dt.datetime.fromtimestamp(int(ts.max()) + 60, dt.UTC).isoformat()
            got = c.get(PATH, params={"array": array, "start": start, "end": end,
                                      "format": "csv"}).text.splitlines()[1:]
            stored = {}
            for line in got:
                stamp, _v, i, _p = line.split(",")
                stored[int(dt.datetime.fromisoformat(stamp).timestamp())] = float(i)
            missing = [r["ts"] for r, t in zip(readings, ts, strict=True)
                       if int(t) not in stored]
            assert not missing, f"{len(missing)} acknowledged {array} readings lost"
            for r, t in zip(readings, ts, strict=True):
                assert stored[int(t)] == r["current_a"]
            # the rollups were committed with the rows: counts agree
            n = c.get(PATH, params={"array": array, "start": start, "end": end,
                                    "max_points": 5}).json()
            assert sum(p["n"] for p in n["points"]) == len(stored)
