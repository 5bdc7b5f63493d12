"""The live twin loop and the on-demand twin share one coverage (``backend/twin/service.py``)."""

from __future__ import annotations

import datetime as dt
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from live_service import LiveServer

TZ = dt.timezone(dt.timedelta(hours=-6))  # tehuantepec's zone, no DST


def test_a_minute_the_live_loop_stored_is_not_simulated_again(live_server: LiveServer) -> None:
    """Each read of today (the tiles, Home Assistant every minute) asks the twin up to now;
    the minutes the live loop stored count as covered, so the read simulates nothing."""
    twin = live_server.process.ctx.twin
    day = dt.datetime.combine(dt.datetime.now(TZ).date() - dt.timedelta(days=300),
                              dt.time(), TZ)
    day_s, noon_s = int(day.timestamp()), int(day.timestamp()) + 12 * 3600
    tomorrow_s = day_s + 86400
    assert twin.ensure("tehuantepec", day_s, tomorrow_s, now_s=noon_s) == 720  # 00:00–11:59
    twin.live_step(noon_s)                                                       # 12:00
    assert twin.ensure("tehuantepec", day_s, tomorrow_s, now_s=noon_s + 90) == 0
    twin.live_step(noon_s + 60)                                                  # 12:01
    twin.live_step(noon_s + 180)                           # 12:03: 12:02 missed (a late tick)
    # the gap is simulated, and only the gap
    assert twin.ensure("tehuantepec", day_s, tomorrow_s, now_s=noon_s + 230) == 1
