"""Retry with exponential backoff: the one policy, on tenacity, of every loop that retries.

The alert webhook sender (:mod:`backend.alerts.webhook`), the MQTT connection
(:mod:`backend.mqtt.service`), the demo logger (:mod:`backend.twin.demo_logger`) and
``heliotwin readings import`` (:mod:`backend.cli.readings`) wait ``first_s · 2^(k−1)``
before their k-th retry, never more than ``max_s`` (:func:`backoff`, a tenacity wait
strategy). Their waits end at once when
the service stops: tenacity sleeps through :func:`stoppable_sleep` /
:func:`stoppable_async_sleep`, which raise :class:`Stopped` when the stop event is
set, so a retrying loop never outlives the shutdown. How many attempts, which
failures are retried, and what happens on giving up are each caller's, in its
module docstring.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Awaitable, Callable

from tenacity import RetryCallState
from tenacity.wait import wait_base

__all__ = ["Backoff", "Stopped", "backoff", "stoppable_async_sleep", "stoppable_sleep"]


class Stopped(Exception):
    """The stop event was set while waiting to retry: give up at once."""


class Backoff(wait_base):
    """Wait ``first_s · 2^(k−1)`` [s] before retry k (k = 1, 2, …), at most ``max_s`` [s].

    A tenacity wait strategy (``Retrying(wait=Backoff(...))`` counts k as tenacity's
    attempt number); :meth:`seconds` is the rule itself, for a caller that counts k
    its own way (the MQTT connection starts again at k = 1 after each connection).
    """

    def __init__(self, first_s: float, max_s: float) -> None:
        if not (first_s >= 0 and max_s >= 0):
            raise ValueError(f"backoff waits must be ≥ 0, got first_s={first_s}, max_s={max_s}")
        self.first_s, self.max_s = first_s, max_s

    def seconds(self, k: int) -> float:
        """The wait before retry ``k`` [s] (the doubling stops at 2⁶², long past any cap)."""
        return min(self.first_s * 2.0 ** min(max(k - 1, 0), 62), self.max_s)

    def __call__(self, retry_state: RetryCallState) -> float:
        return self.seconds(retry_state.attempt_number)


def backoff(first_s: float, max_s: float) -> Backoff:
    """The policy of a retrying loop: :class:`Backoff` from ``first_s`` [s] up to ``max_s`` [s]."""
    return Backoff(first_s, max_s)


def stoppable_sleep(stop: threading.Event) -> Callable[[float], None]:
    """tenacity's ``sleep`` for a thread: waits on ``stop``; :class:`Stopped` when it is set."""

    def sleep(seconds: float) -> None:
        if stop.wait(seconds):
            raise Stopped("stopped while waiting to retry")

    return sleep


def stoppable_async_sleep(stop: asyncio.Event) -> Callable[[float], Awaitable[None]]:
    """tenacity's ``sleep`` for a coroutine: as :func:`stoppable_sleep` on an asyncio event."""

    async def sleep(seconds: float) -> None:
        try:
            await asyncio.wait_for(stop.wait(), seconds)
        except TimeoutError:
            return
        raise Stopped("stopped while waiting to retry")

    return sleep
