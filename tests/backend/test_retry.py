"""backend.retry: the one backoff policy (waits, cap) and the waits a stop ends."""

from __future__ import annotations

import asyncio
import concurrent.futures
import threading

import pytest
from tenacity import RetryCallState, Retrying, retry_if_exception_type, stop_after_attempt

from backend.retry import Stopped, backoff, stoppable_async_sleep, stoppable_sleep


def _waits(first_s: float, max_s: float, retries: int) -> list[float]:
    """The waits tenacity takes with the policy, recorded instead of slept."""
    slept: list[float] = []
    retrying = Retrying(stop=stop_after_attempt(retries + 1), wait=backoff(first_s, max_s),
                        retry=retry_if_exception_type(OSError), sleep=slept.append,
                        reraise=True)
    with pytest.raises(OSError):
        retrying(_always_fails)
    return slept


def _always_fails() -> None:
    raise OSError("refused")


def test_backoff_doubles_from_the_first_wait_up_to_the_cap() -> None:
    assert _waits(1.0, 10.0, 6) == [1.0, 2.0, 4.0, 8.0, 10.0, 10.0]
    assert _waits(0.3, 300.0, 3) == pytest.approx([0.3, 0.6, 1.2], rel=1e-12)
    assert backoff(1.0, 30.0).seconds(5000) == 30.0  # hours of retries: no overflow
    with pytest.raises(ValueError, match="≥ 0"):
        backoff(-1.0, 10.0)


def test_a_set_stop_ends_the_wait_with_stopped() -> None:
    stop = threading.Event()
    stoppable_sleep(stop)(0.0)  # not stopped: returns
    stop.set()
    with pytest.raises(Stopped):
        stoppable_sleep(stop)(3600.0)


def test_a_set_stop_ends_the_async_wait_with_stopped() -> None:
    async def run() -> None:
        stop = asyncio.Event()
        await stoppable_async_sleep(stop)(0.0)
        stop.set()
        with pytest.raises(Stopped):
            await stoppable_async_sleep(stop)(3600.0)

    # a loop of its own on a thread of its own: a test that ran before in this process (the
    # browser tests' Playwright) may have left this thread's event loop running
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        pool.submit(asyncio.run, run()).result()


def test_a_stop_during_the_retries_ends_them_with_stopped() -> None:
    stop = threading.Event()
    calls: list[int] = []

    def fail_and_stop() -> None:
        calls.append(1)
        stop.set()  # shutdown while the attempt runs: no wait, no further attempt
        raise OSError("refused")

    def wait(state: RetryCallState) -> float:
        return 3600.0

    retrying = Retrying(stop=stop_after_attempt(5), wait=wait,
                        retry=retry_if_exception_type(OSError), sleep=stoppable_sleep(stop))
    with pytest.raises(Stopped):
        retrying(fail_and_stop)
    assert calls == [1]
