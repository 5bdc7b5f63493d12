"""Mixed load: paced loggers, back-fill writers and month readers at once (issue 23 item 9).

Starts a real ``heliotwin serve --no-demo`` (SQLite in a temp dir, the live twin on with
a 5 s tick so a run holds several ticks, no viser), seeds a month of minute readings of
both arrays (and reads it once, which stores the month's twin), then runs the writes
alone for ``--seconds`` (30), then the whole mix as long:

- 200 paced loggers, one single-reading request a second each, each on its own
  keep-alive connection, appending to its own stretch of time;
- 50 back-fill writers, one request of an hour of both arrays (120 readings) a second
  each, each filling its own stretch of an earlier year;
- (the mix only) 10 readers asking back to back for the seeded month's energy per day
  (``GET /api/v1/sites/{id}/energy``, 30 rows);
- a probe reading ``GET /api/v1/live-twin`` twice a second (the live loop's lag).

Reports write p50/p99 of both runs, read p50/p99, errors, the live loop's lag and the
server's CPU time per second, with the load average. Then, in this process on a copy of
the database, what does not depend on the machine's load as much: the CPU time one month
read costs the thread that serves it, and how late the event loop wakes beside 10
readers on their own threads and with the energy route's limit of reads at once.

Prints one Markdown section to stdout; progress on stderr.
"""

from __future__ import annotations

import argparse
import asyncio
import datetime as dt
import gc
import os
import shutil
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import orjson
from _common import Figures, log  # noqa: E402  (bench scripts run from this folder)
from bench_service import Server, bodies, exchange, post_all  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SITE = "tehuantepec"
TZ = dt.timezone(dt.timedelta(hours=-6))  # the site's zone (America/Mexico_City, no DST)
PATH = f"/api/v1/sites/{SITE}/measurements"
MONTH = ("2025-06-01", "2025-07-01")
ENERGY = f"/api/v1/sites/{SITE}/energy?start={MONTH[0]}&end={MONTH[1]}&interval=day"
LIVE = "/api/v1/live-twin"
TICK_S = 5.0


def month_payloads() -> list[bytes]:
    """The seeded month: minute readings of both arrays, a daily bell, 1,000 a request."""
    t0 = int(dt.datetime.fromisoformat(MONTH[0]).replace(tzinfo=TZ).timestamp())
    t1 = int(dt.datetime.fromisoformat(MONTH[1]).replace(tzinfo=TZ).timestamp())
    ts = np.arange(t0, t1, 60, dtype=np.int64)
    h = ((ts - t0) % 86400) / 3600.0
    s = np.where((h > 6.5) & (h < 18.5), np.sin(np.pi * (h - 6.5) / 12.0), 0.0)
    return bodies(ts, 720.0 * s**1.2, 560.0 * s**1.4, 1000)


def backfill_payloads(writers: int, count: int) -> list[list[bytes]]:
    """Per back-fill writer, ``count`` hours of both arrays (120 readings a request) in its
    own stretch of 2024, oldest first."""
    base = int(dt.datetime(2024, 1, 1, tzinfo=TZ).timestamp())
    out = []
    for w in range(writers):
        ts = base + w * 7 * 86400 + np.arange(count * 60, dtype=np.int64) * 60
        p = 300.0 + 200.0 * np.sin(ts / 3600.0)
        out.append(bodies(ts, p, 0.8 * p, 120))
    return out


def _request(method: str, path: str, token: str | None = None, body: bytes = b"") -> bytes:
    head = f"{method} {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n"
    if token:
        head += f"Authorization: Bearer {token}\r\nContent-Type: application/json\r\n"
    return (head + f"Content-Length: {len(body)}\r\n\r\n").encode() + body


class Mix:
    """The clients of one run and what they measured."""

    def __init__(self, port: int, token: str, seconds: float) -> None:
        self.port, self.token, self.seconds = port, token, seconds
        self.latencies: dict[str, list[float]] = {"logger": [], "backfill": [], "read": []}
        self.errors: dict[str, int] = {"logger": 0, "backfill": 0, "read": 0, "live": 0}
        self.lags: list[float] = []
        self.ticks: dict[str, tuple[float, float]] = {}
        self.first_error = ""

    def _note(self, kind: str, status: int, body: bytes, seconds: float) -> None:
        self.latencies[kind].append(seconds)
        if status != 200:
            self.errors[kind] += 1
            self.first_error = self.first_error or f"{kind} {status}: {body[:200]!r}"

    async def paced(self, kind: str, requests: list[bytes], offset_s: float) -> None:
        """Send ``requests`` one a second from ``offset_s`` on, on one connection."""
        reader, writer = await asyncio.open_connection("127.0.0.1", self.port)
        start = time.perf_counter() + offset_s
        for j, req in enumerate(requests):
            delay = start + j - time.perf_counter()
            if delay > 0:
                await asyncio.sleep(delay)
            self._note(kind, *await exchange(reader, writer, req))
        writer.close()

    async def reader(self, end: float) -> None:
        reader, writer = await asyncio.open_connection("127.0.0.1", self.port)
        req = _request("GET", ENERGY)
        while time.perf_counter() < end:
            self._note("read", *await exchange(reader, writer, req))
        writer.close()

    async def probe(self, end: float) -> None:
        reader, writer = await asyncio.open_connection("127.0.0.1", self.port)
        req = _request("GET", LIVE)
        while time.perf_counter() < end:
            status, body, _ = await exchange(reader, writer, req)
            if status == 404:  # a service from before the route (a baseline run)
                break
            if status != 200:
                self.errors["live"] += 1
            else:
                live = orjson.loads(body)
                if live["lag_s"] is not None:
                    self.lags.append(float(live["lag_s"]))
                if live.get("last_step_s") is not None:  # per finished tick
                    self.ticks[live["last_done_utc"]] = (live["last_start_delay_s"],
                                                         live["last_step_s"])
            await asyncio.sleep(0.5)
        writer.close()

    async def run(self, loggers: int, backfill: list[list[bytes]], readers: int,
                  phase: int) -> float:
        """The mix for :attr:`seconds`; ``phase`` keeps each run's logger readings apart."""
        n = int(self.seconds)
        t_base = int(dt.datetime(2026, 1, 1, tzinfo=dt.UTC).timestamp()) + phase * 100 * 86400

        def logger_requests(k: int) -> list[bytes]:
            out = []
            for j in range(n):
                ts = dt.datetime.fromtimestamp(t_base + 60 * (k * 1000 + j), dt.UTC).isoformat()
                body = orjson.dumps({"readings": [{
                    "ts": ts, "array": "fixed" if k % 2 else "tracker",
                    "voltage_v": 25.0, "current_a": 4.0}]})
                out.append(_request("POST", PATH, self.token, body))
            return out

        end = time.perf_counter() + self.seconds + 1.0
        tasks = [self.paced("logger", logger_requests(k), k / loggers) for k in range(loggers)]
        tasks += [self.paced("backfill", [_request("POST", PATH, self.token, b)
                                          for b in payloads[phase * n:(phase + 1) * n]],
                             w / len(backfill))
                  for w, payloads in enumerate(backfill)]
        tasks += [self.reader(end) for _ in range(readers)]
        tasks.append(self.probe(end))
        t = time.perf_counter()
        await asyncio.gather(*tasks)
        return time.perf_counter() - t


def cpu_s(pid: int) -> float:
    """User + system CPU time of a process so far [s]."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(np.array(values) * 1000, q)) if values else float("nan")


async def _loop_lag(read: Callable[[], object], readers: int, tokens: int | None,
                    seconds: float) -> tuple[float, int]:
    """p99 [ms] of how late an asyncio probe (a 2 ms sleep, then 2,000 additions, as a
    small request) wakes while ``readers`` read back to back on AnyIO's pool (at most
    ``tokens`` at once; None: AnyIO's default 40), and how many reads they made."""
    import anyio

    limiter = anyio.CapacityLimiter(tokens) if tokens else None
    end = time.perf_counter() + seconds
    lags: list[float] = []
    reads = 0

    async def reader() -> None:
        nonlocal reads
        while time.perf_counter() < end:
            await anyio.to_thread.run_sync(read, limiter=limiter)
            reads += 1

    async def probe() -> None:
        while time.perf_counter() < end:
            t = time.perf_counter()
            await asyncio.sleep(0.002)
            sum(range(2000))
            lags.append(time.perf_counter() - t - 0.002)

    await asyncio.gather(probe(), *[reader() for _ in range(readers)])
    return _pct(lags, 99), reads


def in_process_reads(db: Path, tmp: Path, readers: int, n: int = 30
                     ) -> tuple[float, float, dict[str, tuple[float, int]]]:
    """On a copy of the run's database, in this process: the CPU time [ms] of one month
    read on its thread (``time.thread_time``: this thread's work only, not the time it
    waited for the CPU), median of ``n`` after a first call; the share of a profile of the
    same reads spent in SQLite's calls (which release the GIL); and the event loop's lag
    beside ``readers`` readers, alone / on their own threads / :data:`READS_AT_ONCE` at
    once, 4 s each in turn (ratios in one run, the load alike)."""
    import cProfile
    import pstats

    from backend.api.routes.energy import READS_AT_ONCE
    from backend.context import open_context
    from backend.measurements.energy import energy_rows
    from backend.settings import get_settings
    from backend.timestamps import parse_range

    copy = tmp / "copy.sqlite"
    shutil.copy(db, copy)
    settings = get_settings(database_url=f"sqlite:///{copy}", live_twin=False,
                            alerts=False)
    ctx = open_context(settings)
    try:
        info = ctx.registry.sites[SITE]
        t0, t1 = parse_range(*MONTH, info.zone)

        def read() -> object:
            return energy_rows(ctx, info, t0, t1, "day")

        read()
        times = []
        for _ in range(n):
            c = time.thread_time()
            read()
            times.append((time.thread_time() - c) * 1000)
        prof = cProfile.Profile()
        prof.enable()
        for _ in range(n):
            read()
        prof.disable()
        stats = pstats.Stats(prof)
        total = stats.total_tt  # type: ignore[attr-defined]
        in_sqlite = sum(tt for (_, _, name), (_, _, tt, _, _) in
                        stats.stats.items()  # type: ignore[attr-defined]
                        if "sqlite3.Cursor" in name or "sqlite3.Connection" in name)
        lag = {label: asyncio.run(_loop_lag(read, k, tokens, 4.0)) for label, k, tokens in (
            ("alone", 0, None), ("threads", readers, None),
            ("limited", readers, READS_AT_ONCE))}
        lag["limit"] = (READS_AT_ONCE, 0)
    finally:
        ctx.close()
    return (statistics.median(times), 100.0 * in_sqlite / total if total else float("nan"),
            lag)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--loggers", type=int, default=200)
    parser.add_argument("--writers", type=int, default=50)
    parser.add_argument("--readers", type=int, default=10)
    args = parser.parse_args(argv)
    fig = Figures("load")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        server = Server(tmp, HELIOTWIN_LIVE_TWIN="true",
                        HELIOTWIN_LIVE_TWIN_INTERVAL_S=str(TICK_S))
        try:
            log("seeding a month of both arrays")
            post_all(server.port, server.token, month_payloads(), workers=4)
            backfill = backfill_payloads(args.writers, 2 * int(args.seconds))
            log("first month read (stores the month's twin)")
            import http.client

            c = http.client.HTTPConnection("127.0.0.1", server.port, timeout=600)
            c.request("GET", ENERGY)
            r = c.getresponse()
            idle = []
            if r.status != 200:
                raise RuntimeError(r.read()[:300])
            r.read()
            for _ in range(10):
                t = time.perf_counter()
                c.request("GET", ENERGY)
                c.getresponse().read()
                idle.append((time.perf_counter() - t) * 1000)
            c.close()
            runs = {}
            for phase, readers in enumerate((0, args.readers)):
                label = "with readers" if phase else "writes alone"
                load = os.getloadavg()[0]
                log(f"{label} for {args.seconds:g} s (load {load:.1f})")
                mix = Mix(server.port, server.token, args.seconds)
                cpu0 = cpu_s(server.proc.pid)
                # the client's own objects out of its collector's reach while it times:
                # a full collection of this process stopped every client for ~0.5 s
                gc.collect()
                gc.freeze()
                try:
                    wall = asyncio.run(mix.run(args.loggers, backfill, readers, phase))
                finally:
                    gc.unfreeze()
                runs[label] = (mix, wall, (cpu_s(server.proc.pid) - cpu0) / wall, load,
                               os.getloadavg()[0])
            db_mb = (tmp / "bench.sqlite").stat().st_size / 1e6
            wal = tmp / "bench.sqlite-wal"
            wal_mb = wal.stat().st_size / 1e6 if wal.exists() else 0.0
            c = http.client.HTTPConnection("127.0.0.1", server.port, timeout=60)
            c.request("GET", LIVE)
            r = c.getresponse()
            live = orjson.loads(r.read()) if r.status == 200 else {"ticks": 0, "max_lag_s": None}
            c.close()
        finally:
            server.stop()
        log("a month read in this process: its CPU time, the event loop beside readers")
        cpu_ms, sqlite_pct, loop = in_process_reads(tmp / "bench.sqlite", tmp, args.readers)
    alone, alone_wall, alone_cpu, _, _ = runs["writes alone"]
    mix, wall, mix_cpu, load0, load1 = runs["with readers"]
    lat = mix.latencies
    writes = lat["logger"] + lat["backfill"]
    alone_writes = alone.latencies["logger"] + alone.latencies["backfill"]
    errors = sum(mix.errors.values()) + sum(alone.errors.values())
    w99, r99 = _pct(writes, 99), _pct(lat["read"], 99)
    max_lag = max([*mix.lags, *alone.lags, live["max_lag_s"] or 0.0])
    sent = {k: len(v) for k, v in lat.items()}
    rows = [
        (f"writes: {args.loggers} loggers × 1 req/s + {args.writers} back-fill writers × "
         f"1 req/s of 120 readings, with {args.readers} readers "
         f"({sent['logger'] + sent['backfill']:,} requests in {wall:.1f} s)",
         f"p50 {_pct(writes, 50):.1f} ms, p99 "
         + fig.add("write_p99_ms", w99, "ms", f"{w99:.0f} ms", "≤ 250 ms", w99 <= 250)
         + f" (loggers p99 {_pct(lat['logger'], 99):.0f} ms, back-fill p99 "
         f"{_pct(lat['backfill'], 99):.0f} ms)", "write_p99_ms"),
        (f"the same writes alone, just before ({len(alone_writes):,} requests in "
         f"{alone_wall:.1f} s)",
         f"p50 {_pct(alone_writes, 50):.1f} ms, p99 "
         + fig.add("write_alone_p99_ms", _pct(alone_writes, 99), "ms",
                   f"{_pct(alone_writes, 99):.0f} ms"), "—"),
        (f"reads: {args.readers} readers back to back, a month's energy per day "
         f"({sent['read']:,} reads, {sent['read'] / wall:.0f}/s)",
         f"p50 {_pct(lat['read'], 50):.0f} ms, p99 "
         + fig.add("read_p99_ms", r99, "ms", f"{r99:.0f} ms")
         + f" (idle, before the mix: median {statistics.median(idle):.0f} ms)", "—"),
        ("errors (non-200 answers) of every request of both runs",
         fig.add("errors", errors, "", f"{errors}", "0", errors == 0)
         + (f" (first: {mix.first_error or alone.first_error})"
            if mix.first_error or alone.first_error else ""), "errors"),
        (f"the live twin loop's lag (a {TICK_S:g} s tick; `GET {LIVE}`: its tick's "
         f"commit after the time it was due, {live['ticks']} ticks in both runs)",
         "max " + fig.add("live_lag_max_s", max_lag, "s", f"{max_lag:.1f} s", "≤ 5 s",
                          max_lag <= 5.0)
         + (f"; of the ticks seen with readers, the longest wait for a thread "
            f"{max(t[0] for t in mix.ticks.values()):.2f} s, the longest step (a lookup "
            f"and the writer's commit) {max(t[1] for t in mix.ticks.values()):.2f} s"
            if mix.ticks else ""), "live_lag_max_s"),
        ("the SQLite files after both runs (database + WAL; the WAL is copied into the "
         "database every second, readers or not)", f"{db_mb:.0f} MB + {wal_mb:.0f} MB", "—"),
        ("the server's CPU time per second of the run (user + system, all its threads; "
         "its Python work is bounded by one core, the GIL)",
         f"writes alone {alone_cpu:.2f} s/s, with readers "
         + fig.add("server_cpu_per_s", mix_cpu, "s/s", f"{mix_cpu:.2f} s/s"), "—"),
        ("CPU time of one month read (energy per day, both arrays, measured + twin) on the "
         "thread that serves it, in process, median of 30: the event loop holds none of it",
         fig.add("read_cpu_ms", cpu_ms, "ms", f"{cpu_ms:.1f} ms")
         + f", {sqlite_pct:.0f} % of it in SQLite's calls (GIL released)", "—"),
        (f"in process: how late an asyncio probe wakes (p99) beside {args.readers} month "
         "readers back to back, 4 s each in turn: alone / each reader on its own thread / "
         f"at most {loop['limit'][0]} at once (the energy route's limit)",
         f"{loop['alone'][0]:.1f} ms / {loop['threads'][0]:.1f} ms ({loop['threads'][1]} "
         "reads) / " + fig.add("loop_lag_limited_p99_ms", loop["limited"][0], "ms",
                               f"{loop['limited'][0]:.1f} ms")
         + f" ({loop['limited'][1]} reads)", "—"),
    ]
    rows = [(a, b, c if c == "—" else f"{fig.figures['load.' + c]['target']}: "
             + fig.verdict(c)) for a, b, c in rows]
    print("## load\n")
    print("One `heliotwin serve` process on SQLite (WAL), the client (one asyncio process) on\n"
          "the same 2 cores with whatever else runs on the machine; latencies are the client's,\n"
          "over HTTP on localhost. The writes run alone first, then with the readers. Load\n"
          f"average (1 min) {load0:.1f} before the run with readers, {load1:.1f} after it.\n")
    print("| figure | value | target |\n|---|---|---|")
    for figure, value, target in rows:
        print(f"| {figure} | {value} | {target} |")
    fig.write()
    return 0


if __name__ == "__main__":
    sys.exit(main())
