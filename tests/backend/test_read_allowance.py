"""The anonymous read allowance (issue 23, item 4): every read of a site's data without a
token — measurements (JSON, CSV, line protocol; measured, twin, twin_weather), energy, the
report (JSON, CSV, PNG), diagnosis, pointing, the pointing model and its command — is
charged the CPU time it took to its caller's address, and past
``HELIOTWIN_ANONYMOUS_READ_CPU_S_PER_MIN`` in the last minute the address gets 429 with
``Retry-After`` (``backend.api.deps.anonymous_read``, ``backend/limits.py``).

The service runs in this process on a SQLite file, with an allowance of 1 µs a minute: any
read spends it, so the next read of that address is refused (no timing is asserted). The
readings are a day of the demo logger's (the twin with clouds and noise), the tracker's with
the sun's offsets in its camera (small noise about zero) so that the pointing model fits.
"""

from __future__ import annotations

import contextvars
import datetime as dt
import time
from collections.abc import Iterator
from typing import Any

import httpx
import numpy as np
import pytest
from live_service import InProcessServer, _ASGIBridge, new_database

from backend.limits import (
    READS_IN_FLIGHT,
    Busy,
    Limits,
    metered,
    metered_iter,
    start_meter,
)
from backend.settings import Settings
from backend.twin.demo_logger import DemoLogger
from sim.sites import load_site

SITE = "tehuantepec"
SETTING = "HELIOTWIN_ANONYMOUS_READ_CPU_S_PER_MIN"
#: A past day of the site (in the twin's history; its date is local, UTC-6).
DAY = dt.date.today() - dt.timedelta(days=10)
NEXT = DAY + dt.timedelta(days=1)
_RANGE = f"start={DAY}&end={NEXT}"
_SITE = f"/api/v1/sites/{SITE}"
#: One read of each family that a caller without a token may ask.
READS = {
    "measurements_json": f"{_SITE}/measurements?array=tracker&{_RANGE}",
    "measurements_csv": f"{_SITE}/measurements?array=fixed&{_RANGE}&format=csv",
    "measurements_influx": f"{_SITE}/measurements?array=tracker&{_RANGE}&format=influx",
    "measurements_twin": f"{_SITE}/measurements?array=tracker&{_RANGE}&source=twin"
                         "&max_points=100",
    "measurements_twin_weather": f"{_SITE}/measurements?array=tracker&{_RANGE}"
                                 "&source=twin_weather&max_points=100",
    "energy": f"{_SITE}/energy?{_RANGE}&interval=hour",
    "report": f"{_SITE}/report?{_RANGE}",
    "report_csv": f"{_SITE}/report.csv?{_RANGE}",
    "report_png": f"{_SITE}/report.png?{_RANGE}",
    "diagnosis": f"{_SITE}/diagnosis?{_RANGE}",
    "pointing": f"{_SITE}/pointing?{_RANGE}",
    "pointing_model": f"{_SITE}/pointing-model?{_RANGE}",
    "pointing_model_coverage": f"{_SITE}/pointing-model/coverage?{_RANGE}",
    "pointing_model_command": f"{_SITE}/pointing-model/command?{_RANGE}"
                              f"&time={NEXT}T12:00:00-06:00",
}


class _Clock:
    """A monotonic clock a test moves on (the allowance's window passing)."""

    def __init__(self) -> None:
        self.ahead_s = 0.0

    def __call__(self) -> float:
        return time.monotonic() + self.ahead_s


def _readings() -> list[dict[str, Any]]:
    """DAY of the demo logger, the tracker's readings in daylight with sun offsets."""
    t0 = int(dt.datetime(DAY.year, DAY.month, DAY.day, 6,
                         tzinfo=dt.timezone(dt.timedelta(hours=-6))).timestamp())
    logger = DemoLogger(load_site(SITE), "http://unused", "unused")
    try:
        rows = logger.readings(t0, t0 + 12 * 3600)
    finally:
        logger.close()
    rng = np.random.default_rng(23)
    for r in rows:
        if r["array"] == "tracker" and r.get("elevation_deg", 0.0) > 10.0:
            r["sun_offset_x_mrad"], r["sun_offset_y_mrad"] = np.round(
                0.3 * rng.standard_normal(2), 3).tolist()
    return rows


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[InProcessServer]:
    db = new_database("sqlite", tmp_path_factory.mktemp("read-allowance"))
    proc = InProcessServer(db.url, extra_env={SETTING: "0.000001"}).start()
    try:
        proc.ctx.limits.reads.clock = _Clock()
        with proc.client() as c:
            r = c.post(f"{_SITE}/measurements", json={"readings": _readings()},
                       headers={"Authorization": f"Bearer {proc.token()}"})
            assert r.status_code == 200 and r.json()["accepted"] > 1000, r.text
        yield proc
    finally:
        proc.stop()


def _client(server: InProcessServer, host: str) -> httpx.Client:
    """A client on the service in this process whose requests come from ``host``: the
    bridge of ``InProcessServer.client`` onto an ASGI transport that says so."""
    bridge = _ASGIBridge(server.app, server._loop)
    bridge._asgi = httpx.ASGITransport(app=server.app, raise_app_exceptions=False,
                                       client=(host, 40000))
    return httpx.Client(transport=bridge, base_url=server.base_url, timeout=60.0)


@pytest.mark.parametrize("family", list(READS))
def test_an_anonymous_address_past_its_allowance_is_refused_until_the_minute_passes(
        server: InProcessServer, family: str) -> None:
    url = READS[family]
    n = list(READS).index(family)
    token = {"Authorization": f"Bearer {server.token()}"}
    host = f"10.23.{n}.1"
    with _client(server, host) as c, _client(server, f"10.23.{n}.2") as other:
        first = c.get(url)
        assert first.status_code == 200, first.text
        refused = c.get(url)
        assert refused.status_code == 429, refused.text
        assert int(refused.headers["Retry-After"]) >= 1
        assert SETTING in refused.json()["detail"]
        assert other.get(url).status_code == 200  # another address has its own allowance
        # with a token the same address is not limited, and that read is not charged to it
        spent_s = server.ctx.limits.reads.used(host)
        assert c.get(url, headers=token).status_code == 200
        assert server.ctx.limits.reads.used(host) == spent_s
        assert c.get(url).status_code == 429
        clock = server.ctx.limits.reads.clock
        assert isinstance(clock, _Clock)
        clock.ahead_s += 61.0  # the minute has passed: the allowance is back
        assert c.get(url).status_code == 200


def test_a_bad_token_is_a_401_not_an_anonymous_read(server: InProcessServer) -> None:
    with _client(server, "10.24.0.1") as c:
        r = c.get(READS["energy"], headers={"Authorization": "Bearer not-a-token"})
    assert r.status_code == 401
    assert server.ctx.limits.reads.used("10.24.0.1") == 0.0


def test_an_address_has_at_most_reads_in_flight_and_spends_what_they_cost() -> None:
    """A burst of slow reads is not all admitted before the first is charged: at most
    READS_IN_FLIGHT of an address are in flight; each settled read frees its place and
    is charged its CPU time, and past the allowance the address is refused."""
    limits = Limits.from_settings(Settings(anonymous_read_cpu_s_per_min=16.0))
    held = [limits.admit_read("10.25.0.1") for _ in range(READS_IN_FLIGHT)]
    with pytest.raises(Busy) as refused:
        limits.admit_read("10.25.0.1")
    assert refused.value.status_code == 429 and SETTING in refused.value.message
    limits.admit_read("10.25.0.2")  # another address
    for charge in held[:4]:
        limits.reads.settle(charge, 3.0)  # 12 s of the 16 s spent; four places free
    assert limits.reads.used("10.25.0.1") == 12.0
    held[4:] = [limits.admit_read("10.25.0.1") for _ in range(4)]
    with pytest.raises(Busy):
        limits.admit_read("10.25.0.1")
    limits.reads.settle(held[4], 4.5)  # 16.5 s: over the allowance
    with pytest.raises(Busy) as spent:
        limits.admit_read("10.25.0.1")
    assert "16.5 spent" in spent.value.message and spent.value.retry_after_s >= 1


def test_a_read_longer_than_the_window_stays_in_flight_and_is_charged_when_it_ends() -> None:
    """A read streamed slowly for more than the minute does not drop out of the window
    while it runs (it still holds its place in flight) and its CPU time is charged from
    when it ended, not from its admission a minute before."""
    clock = _Clock()
    limits = Limits.from_settings(Settings(anonymous_read_cpu_s_per_min=16.0))
    limits.reads.clock = clock
    held = [limits.admit_read("10.25.0.3") for _ in range(READS_IN_FLIGHT)]
    clock.ahead_s += 120.0  # two minutes of slow streaming
    with pytest.raises(Busy):
        limits.admit_read("10.25.0.3")  # all 16 are still in flight
    for charge in held:
        limits.reads.settle(charge, 1.5)  # 24 s of CPU, over the 16 s allowance
    assert limits.reads.used("10.25.0.3") == 24.0
    with pytest.raises(Busy) as spent:
        limits.admit_read("10.25.0.3")
    assert 59 <= spent.value.retry_after_s <= 60
    clock.ahead_s += 61.0
    limits.admit_read("10.25.0.3")


def _busy_work(n: int) -> int:
    return sum(i * i for i in range(n))


def test_a_streamed_body_is_charged_and_nested_blocks_once() -> None:
    """The CPU time of a streamed body's pieces counts to the request's meter, as the
    handler's does; a metered block inside another is counted once, not twice."""
    def body() -> Iterator[int]:
        for _ in range(5):
            yield _busy_work(200_000)

    def in_request() -> tuple[float, float, float]:
        meter = start_meter()
        parts = list(metered_iter(body()))
        streamed_s = meter.cpu_s
        assert len(parts) == 5
        start_s = time.thread_time()
        with metered(), metered():
            _busy_work(1_000_000)
        outer_s = time.thread_time() - start_s
        return streamed_s, meter.cpu_s - streamed_s, outer_s

    streamed_s, nested_s, outer_s = contextvars.copy_context().run(in_request)
    assert streamed_s > 0.0
    assert 0.0 < nested_s <= outer_s  # the two blocks were one block of CPU time
