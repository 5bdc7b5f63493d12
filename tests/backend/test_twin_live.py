"""The live twin loop and the on-demand twin share one coverage (``backend/twin/service.py``)."""

from __future__ import annotations

import datetime as dt
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from live_service import LiveServer

TZ = dt.timezone(dt.timedelta(hours=-6))  # tehuantepec's zone, no DST


def test_minutes_the_live_loop_stored_are_not_simulated_again(live_server: LiveServer) -> None:
    """Each read of today (the tiles, Home Assistant every minute) asks the twin up to the
    current minute, after that minute's tick of the live loop: the minutes the loop stored
    tick after tick count as covered, so such a read simulates nothing."""
    twin = live_server.process.ctx.twin
    day = dt.datetime.combine(dt.datetime.now(TZ).date() - dt.timedelta(days=300),
                              dt.time(), TZ)
    day_s, noon_s = int(day.timestamp()), int(day.timestamp()) + 12 * 3600

    def read(at_s: int) -> int:  # a read of today at at_s: the readings it simulated
        return twin.ensure("tehuantepec", day_s, day_s + 86400, now_s=at_s)

    assert read(noon_s + 30) == 720  # 00:00–11:59
    twin.live_step(noon_s + 60)      # the loop's first tick: 12:01 (12:00 it never stored)
    assert read(noon_s + 90) == 1    # 12:00
    for minute in (2, 3, 4):         # tick, then a read in that minute
        twin.live_step(noon_s + 60 * minute)
        assert read(noon_s + 60 * minute + 30) == 0
    twin.live_step(noon_s + 60 * 6)  # 12:05 missed (a late tick): only it is simulated
    assert read(noon_s + 60 * 6 + 30) == 1
    twin.live_step(noon_s + 60 * 7)
    assert read(noon_s + 60 * 7 + 30) == 0
