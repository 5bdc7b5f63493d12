"""Memory is bounded and given back (issue 23 items 4 and 5): what is worked on at once,
the caches' bounds, the heap pages freed by big requests returned to the system.

The whole-server figure (RSS at start, peak and idle after a year's series read as JSON
and CSV, plant days, diagnosis, a year-long run) is ``benchmarks/bench_service.py
--only memory``; these are the parts it rests on, each cheap.
"""

from __future__ import annotations

import asyncio
import datetime as dt
import subprocess
import sys
from pathlib import Path

import pytest
from live_service import run_in_own_thread

import backend.plants as plants_mod
from backend.limits import Busy, HeldBudget, Limits
from backend.plants import PlantService
from backend.settings import Settings

ROOT = Path(__file__).resolve().parents[2]


def test_held_budget_one_at_a_time_then_503() -> None:
    """Plant computations run one at a time; the next waits, and past the queue one is
    refused with 503 and a Retry-After from the work ahead of it."""
    budget = HeldBudget(1, 1, 0.5, "plant computations", "SETTING")
    order: list[str] = []

    async def main() -> Busy:
        release = asyncio.Event()

        async def first() -> None:
            async with budget.hold(1):
                order.append("first in")
                await release.wait()
            order.append("first out")

        async def second() -> None:
            async with budget.hold(1):
                order.append("second in")

        t1 = asyncio.create_task(first())
        await asyncio.sleep(0)
        t2 = asyncio.create_task(second())
        await asyncio.sleep(0)
        assert budget.held == 1 and order == ["first in"]      # the second waits
        try:
            async with budget.hold(1):
                raise AssertionError("a third was admitted past the queue")
        except Busy as exc:
            refused = exc
        release.set()
        await asyncio.gather(t1, t2)
        return refused

    refused = run_in_own_thread(main())
    assert order == ["first in", "first out", "second in"]
    assert budget.held == 0
    assert refused.status_code == 503 and "SETTING" in refused.message
    assert refused.headers == {"Retry-After": "4"}   # 1 held + 1 waiting at 0.5 a second


def test_service_limits_hold_one_plant_computation() -> None:
    limits = Limits.from_settings(Settings())
    assert limits.plants.capacity == 1 and limits.plants.max_waiting >= 1


def test_plant_day_cache_stays_within_its_bound(monkeypatch: pytest.MonkeyPatch) -> None:
    """Days of any dates are kept up to the bound in values; the least recently used goes
    first; a day too big for the bound is not kept at all."""
    monkeypatch.setattr(plants_mod, "DAY_CACHE_VALUES", 1000)
    service = PlantService()

    def day(steps: int, trackers: int = 10) -> dict:
        return {"times": ["t"] * steps, "tracker_ids": list(range(trackers))}

    dates = [dt.date(2024, 1, 1) + dt.timedelta(days=k) for k in range(30)]
    for d in dates:
        service._keep_day(service._day_key("penarroya", d, 300.0), day(30))
        if d == dates[1]:  # the first day used again: the second is now the oldest
            assert service.cached_day("penarroya", dates[0], 300.0) is not None
    assert service.cached_day_values <= 1000
    kept = [d for d in dates if service.cached_day("penarroya", d, 300.0) is not None]
    assert len(kept) == 3 and kept == dates[-3:]
    service._keep_day(service._day_key("penarroya", dates[0], 600.0), day(101))
    assert service.cached_day("penarroya", dates[0], 600.0) is None
    assert service.cached_day_values == 900


_FRAGMENT = """
import threading
from backend.limits import release_memory, tune_malloc

def rss_mb():
    return int(open("/proc/self/statm").read().split()[1]) * 4096 / 1e6

assert tune_malloc()
kept = []
def work():  # 400 x 256 KiB from a thread's heap; all freed but the last (the heap's top)
    blocks = [bytearray(256 * 1024) for _ in range(400)]
    kept.append(blocks[-1])
    del blocks
t = threading.Thread(target=work)
t.start()
t.join()
before = rss_mb()
assert release_memory()
print(before, rss_mb())
"""


def test_release_memory_gives_freed_heap_pages_back() -> None:
    """100 MB of blocks below the mmap threshold, freed but for the heap's top block, stay
    resident until ``release_memory`` (glibc's malloc_trim) returns them."""
    out = subprocess.run([sys.executable, "-c", _FRAGMENT], cwd=ROOT, capture_output=True,
                         text=True, timeout=60, check=True).stdout
    before_mb, after_mb = (float(v) for v in out.split())
    assert before_mb - after_mb > 80, (before_mb, after_mb)
