"""The MQTT connection's retry policy, in process: a broker that refuses is retried with
backend.retry's doubling waits up to ``mqtt_retry_max_s``, and a stop ends the waiting.

The waits are recorded instead of slept (the policy's numbers, not the clock's); the
reconnection after a lost session against a real broker is tests/backend/test_mqtt.py's.
"""

from __future__ import annotations

import socket
import threading
from collections.abc import Awaitable, Callable
from types import SimpleNamespace

import pytest

import backend.mqtt.service as service
from backend.retry import stoppable_async_sleep
from backend.settings import get_settings


def _closed_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])  # nothing listens once closed: connections refused


def test_a_refusing_broker_is_retried_with_doubling_waits_until_stopped(
        monkeypatch: pytest.MonkeyPatch) -> None:
    waits: list[float] = []
    enough = threading.Event()

    def recording_sleep(stop):  # type: ignore[no-untyped-def]
        real: Callable[[float], Awaitable[None]] = stoppable_async_sleep(stop)

        async def sleep(seconds: float) -> None:
            waits.append(seconds)
            if len(waits) >= 6:
                enough.set()
            await real(0.0)  # a stop set meanwhile still ends the retrying

        return sleep

    monkeypatch.setattr(service, "stoppable_async_sleep", recording_sleep)
    settings = get_settings(mqtt_url=f"mqtt://127.0.0.1:{_closed_port()}",
                            mqtt_retry_max_s=5.0)
    mqtt = service.MqttService(SimpleNamespace(settings=settings))  # type: ignore[arg-type]
    mqtt.start()
    thread = mqtt._thread
    assert thread is not None
    try:
        assert enough.wait(60.0), waits
    finally:
        mqtt.stop()
    assert waits[:6] == [1.0, 2.0, 4.0, 5.0, 5.0, 5.0]  # first 1 s, doubling, capped
    status = mqtt.status()
    assert status["state"] == "retrying" and status["retries"] == len(waits)
    assert not thread.is_alive()  # the stop ended the retrying and the thread
