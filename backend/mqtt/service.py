"""The MQTT side of the service: readings in, rejections and Home Assistant out.

:class:`MqttService` runs in a thread of its own with its own asyncio loop
(``heliotwin-mqtt``), started and stopped by :class:`backend.context.ServiceContext`
when ``Settings.mqtt.url`` is set. While connected (aiomqtt) it:

- subscribes (QoS 1) to ``Settings.mqtt.state_topic`` (one JSON reading) and to
  ``Settings.mqtt.value_topic`` for each quantity (``voltage``, ``current``,
  ``power``: bare numbers, assembled per minute by :mod:`backend.mqtt.assemble`);
- maps each topic to a known site and array, validates the reading with the
  HTTP ingest validator (:mod:`backend.mqtt.ingest`) and stores it through the
  writer (idempotent: one row per array per minute);
- acknowledges a QoS 1 JSON reading only once it is committed (:class:`OrderedAcks`), so
  with a persistent session a service killed in between gets it again from the broker;
- publishes every rejected message with its reason to
  ``Settings.mqtt.errors_topic`` (``_unknown`` as site id for unknown sites),
  through an outbox that keeps what could not be sent until the next connection;
- speaks MQTT 5 and tells the broker the largest packet it takes
  (:data:`MAX_PACKET_BYTES`), so a huge message is dropped by the broker, never read;
- publishes the retained Home Assistant discovery configs at every connection and
  whenever the registry's sites change (added, arrays changed, removed), and the
  sensor states every ``Settings.mqtt.publish_interval_s``
  (:mod:`backend.mqtt.homeassistant`).

A lost or refused connection is retried for as long as the service runs, with
exponential backoff (:func:`backend.retry.backoff`, tenacity): 1 s, 2 s, 4 s, … at
most ``Settings.mqtt.retry_max_s``, back to 1 s after each successful connection;
each retry logged, a wait ended at once by the service's stop;
:attr:`MqttService.state` is ``connected`` or ``retrying`` (``/api/v1/meta`` shows it).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import ssl
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from importlib.metadata import PackageNotFoundError, version
from typing import TYPE_CHECKING, Any
from urllib.parse import unquote, urlsplit

import aiomqtt
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties
from tenacity import AsyncRetrying, RetryCallState, retry_if_exception

from backend.measurements.ingest import measured_job
from backend.measurements.parse import Batch
from backend.mqtt import homeassistant
from backend.mqtt.assemble import QUANTITIES, Closed, MinuteAssembler
from backend.mqtt.ingest import (
    MAX_PAYLOAD_BYTES,
    Rejection,
    limits,
    minute_batch,
    single_value,
    state_batch,
)
from backend.mqtt.topics import Topics
from backend.retry import Stopped, backoff, stoppable_async_sleep

if TYPE_CHECKING:
    from backend.context import ServiceContext

logger = logging.getLogger(__name__)

UNKNOWN_SITE = "_unknown"
#: Most rejections kept while the broker is away (the oldest go first, logged).
OUTBOX_MAX = 10_000
#: Most readings waiting for the writer before the receiver waits too.
MAX_IN_FLIGHT = 512
#: Largest packet the broker may send us [bytes]: a reading's payload at most
#: ``MAX_PAYLOAD_BYTES`` plus its topic, packet id and properties. MQTT 5's CONNECT
#: property Maximum Packet Size: the broker drops a larger message for this client
#: instead of sending it, so a 200 MiB publish is never read (paho itself reads any
#: packet whole before the size of its payload can be checked).
MAX_PACKET_BYTES = MAX_PAYLOAD_BYTES + 4096
#: How long the broker keeps a persistent session (client id set) while we are away [s].
SESSION_EXPIRY_S = 7 * 24 * 3600


def connect_properties(persistent: bool) -> Properties:
    """The MQTT 5 CONNECT properties: the packet size bound and, with a client id, a
    session the broker keeps for :data:`SESSION_EXPIRY_S` (MQTT 5 ends it at disconnect
    by default, where 3.1.1's ``clean_session=False`` kept it)."""
    props = Properties(PacketTypes.CONNECT)
    props.MaximumPacketSize = MAX_PACKET_BYTES
    if persistent:
        props.SessionExpiryInterval = SESSION_EXPIRY_S
    return props


#: The first wait before reconnecting [s]; it doubles up to ``Settings.mqtt.retry_max_s``.
_FIRST_RETRY_S = 1.0


def _version() -> str:
    try:
        return version("heliotwin")
    except PackageNotFoundError:
        return "0+unknown"


def broker_of(url: str) -> dict[str, Any]:
    """``mqtt://[user:password@]host[:port]`` (or ``mqtts://``) → aiomqtt ``Client`` arguments."""
    parts = urlsplit(url)
    if parts.scheme not in ("mqtt", "mqtts") or not parts.hostname:
        raise ValueError("HELIOTWIN_MQTT_URL: expected mqtt://[user:password@]host[:port]"
                         " or mqtts://…")
    tls = parts.scheme == "mqtts"
    return {
        "hostname": parts.hostname, "port": parts.port or (8883 if tls else 1883),
        "username": unquote(parts.username) if parts.username else None,
        "password": unquote(parts.password) if parts.password else None,
        "tls_context": ssl.create_default_context() if tls else None,
    }


def check_no_echo(topics: Topics) -> None:
    """ValueError when a topic the service publishes would come back as a reading."""
    published = [topics.errors.format(site_id="s"), homeassistant.service_availability(topics),
                 homeassistant.power_availability(topics, "s", "a")] + [
        topics.ha_state.format(site_id="s", array="a", sensor=x) for x in homeassistant.SENSORS]
    for topic in published:
        value = topics.value.match(topic)
        if topics.state.match(topic) is not None or (
                value is not None and value["quantity"] in QUANTITIES):
            raise ValueError(f"the service publishes to {topic!r}, which its reading templates "
                             f"({topics.state.text}, {topics.value.text}) would take back in: "
                             "change HELIOTWIN_MQTT_ERRORS_TOPIC or HELIOTWIN_MQTT_HA_STATE_TOPIC")


class OrderedAcks:
    """Acknowledges the QoS 1 messages of one connection once each is handled, in the
    order they came: MQTT 5.0 §4.6 has a client send its PUBACKs in the order of the
    PUBLISHes. Paho's automatic acknowledgement goes out as a message is received; a
    reading still waiting for the writer's commit would then be lost to a SIGKILL although
    the broker holds it as delivered. ``send(mid, qos)`` is paho's ``Client.ack`` (with
    ``manual_ack`` on), called on the connection's event loop like every paho call here."""

    def __init__(self, send: Callable[[int, int], object]) -> None:
        self._send = send
        self._waiting: deque[list[Any]] = deque()  # [mid, qos, handled], in order received

    def received(self, mid: int, qos: int) -> Callable[[], None]:
        """Note a message; call what this returns once it is handled (stored, a
        duplicate, rejected or assembled). QoS 0 has no acknowledgement."""
        if qos == 0:
            return lambda: None
        entry: list[Any] = [mid, qos, False]
        self._waiting.append(entry)

        def handled() -> None:
            entry[2] = True
            while self._waiting and self._waiting[0][2]:
                m, q, _ = self._waiting.popleft()
                self._send(m, q)
        return handled

    @property
    def waiting(self) -> int:
        """Messages received and not acknowledged yet."""
        return len(self._waiting)


def _manual_acks(client: aiomqtt.Client) -> OrderedAcks:
    """Turn paho's automatic acknowledgement off for ``client`` (before it connects: a
    persistent session's queued messages come right after the CONNACK) and acknowledge
    through :class:`OrderedAcks`. aiomqtt 2.5 has no option for it, so its paho client is
    reached directly, as aiomqtt's maintainers suggest (empicano/aiomqtt#345)."""
    paho = client._client  # noqa: SLF001
    paho.manual_ack_set(True)
    return OrderedAcks(paho.ack)


class MqttService:
    """MQTT ingestion and Home Assistant publishing (see the module docstring)."""

    def __init__(self, ctx: ServiceContext) -> None:
        s = ctx.settings
        if s.mqtt.url is None:
            raise ValueError("HELIOTWIN_MQTT_URL is not set")
        self.ctx = ctx
        self.broker = broker_of(s.mqtt.url.get_secret_value())
        self.where = f"{self.broker['hostname']}:{self.broker['port']}"
        self.topics = Topics.from_settings(s.mqtt.state_topic, s.mqtt.value_topic,
                                           s.mqtt.errors_topic, s.mqtt.ha_state_topic,
                                           s.mqtt.ha_prefix)
        check_no_echo(self.topics)
        self.limits = limits(s)
        self.assembler = MinuteAssembler(s.mqtt.minute_grace_s)
        self.state = "retrying"
        self.counts = {"received": 0, "stored": 0, "duplicates": 0, "rejected": 0,
                       "ignored": 0, "retries": 0}
        self._outbox: deque[tuple[str, bytes]] = deque()
        self._in_flight: set[asyncio.Task[None]] = set()
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._outbox_ready: asyncio.Event | None = None

    # -- lifecycle (called from other threads) -------------------------------
    def start(self) -> None:
        """Start the MQTT thread; returns once its loop runs (connecting goes on there)."""
        ready = threading.Event()
        self._thread = threading.Thread(target=lambda: asyncio.run(self._run(ready)),
                                        name="heliotwin-mqtt", daemon=True)
        self._thread.start()
        ready.wait(10.0)

    def stop(self, timeout_s: float = 20.0) -> None:
        """Close the open minutes, finish stores and rejections, disconnect, end the thread."""
        if self._thread is None or self._loop is None or self._stop is None:
            return
        self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(timeout_s)
        if self._thread.is_alive():  # said, not hidden: what it still does may fail later
            logger.warning("MQTT thread still running %.0f s after stop was asked; going on",
                           timeout_s)
        self._thread = None

    def status(self) -> dict[str, Any]:
        """State and counters for ``/api/v1/meta``."""
        return {"state": self.state, "broker": self.where, **self.counts,
                "superseded": self.assembler.superseded, "unsent_errors": len(self._outbox)}

    # -- the loop --------------------------------------------------------------
    async def _run(self, ready: threading.Event) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        self._outbox_ready = asyncio.Event()
        ready.set()
        closer = asyncio.create_task(self._close_minutes())
        s = self.ctx.settings
        policy = backoff(_FIRST_RETRY_S, s.mqtt.retry_max_s)
        attempts = 0
        connected_after = 0  # attempts made before the last connection came up

        async def connect_and_serve() -> None:
            """One connection: serve until stopped (returns) or lost (raises)."""
            nonlocal attempts, connected_after
            attempts += 1
            client = aiomqtt.Client(
                **self.broker, identifier=s.mqtt.client_id, protocol=aiomqtt.ProtocolVersion.V5,
                clean_start=s.mqtt.client_id is None,
                properties=connect_properties(persistent=s.mqtt.client_id is not None),
                will=aiomqtt.Will(homeassistant.service_availability(self.topics),
                                  homeassistant.OFFLINE, qos=1, retain=True),
                keepalive=30, timeout=10.0)
            acks = _manual_acks(client)
            async with client:
                connected_after = attempts - 1
                await self._session(client, acks)

        def wait(state: RetryCallState) -> float:  # k counts from the last connection
            return policy.seconds(state.attempt_number - connected_after)

        def before_sleep(state: RetryCallState) -> None:
            exc = state.outcome.exception() if state.outcome is not None else None
            if not isinstance(exc, aiomqtt.MqttError):
                logger.error("MQTT session failed", exc_info=exc)
            self.state = "retrying"
            self.counts["retries"] += 1
            wait_s = state.next_action.sleep if state.next_action is not None else 0.0
            logger.warning("MQTT broker %s: %s; retry %d in %.0f s", self.where, exc,
                           self.counts["retries"], wait_s)

        stop = self._stop
        retrying = AsyncRetrying(  # any failure but a cancellation, until stopped
            wait=wait, retry=retry_if_exception(
                lambda exc: isinstance(exc, Exception) and not stop.is_set()),
            sleep=stoppable_async_sleep(stop), before_sleep=before_sleep, reraise=True)
        try:
            if not stop.is_set():
                await retrying(connect_and_serve)
        except Stopped:
            pass
        except Exception:  # noqa: BLE001 - failed while stopping: nothing to retry
            if not stop.is_set():
                raise
        finally:
            closer.cancel()
            for closed in self.assembler.flush():  # not connected any more: logged below
                self._take_minute(closed)
            if self._in_flight:
                await asyncio.wait(self._in_flight)
            for topic, payload in self._outbox:
                logger.warning("MQTT rejection not published (broker away) to %s: %s", topic,
                               payload[:300].decode("utf-8", "replace"))
            logger.info("MQTT stopped: %s", self.status())

    async def _session(self, client: aiomqtt.Client, acks: OrderedAcks) -> None:
        assert self._stop is not None
        filters = [(self.topics.state.filter(), 1)] + [
            (self.topics.value.filter(quantity=q), 1) for q in QUANTITIES]
        await client.subscribe(filters)
        self.state = "connected"
        logger.info("MQTT connected to %s; subscribed to %s", self.where,
                    ", ".join(f for f, _ in filters))
        tasks = [asyncio.create_task(c) for c in (
            self._receive(client, acks), self._send_outbox(client), self._publish_ha(client))]
        stop = asyncio.create_task(self._stop.wait())
        done, _ = await asyncio.wait([*tasks, stop], return_when=asyncio.FIRST_COMPLETED)
        if stop in done:  # shutdown: last minutes and rejections out while still connected
            tasks[0].cancel()
            tasks[2].cancel()
            await asyncio.gather(tasks[0], tasks[2], return_exceptions=True)
            while len(client.messages):  # received but not handled yet
                self._take(await anext(client.messages), acks)
            for closed in self.assembler.flush():
                self._take_minute(closed)
            if self._in_flight:
                await asyncio.wait(self._in_flight, timeout=10.0)
            await self._drain(client, time.monotonic() + 5.0)
            with contextlib.suppress(aiomqtt.MqttError, TimeoutError):  # the Will is for a
                await client.publish(  # lost connection, not for a graceful disconnect
                    homeassistant.service_availability(self.topics), homeassistant.OFFLINE,
                    qos=1, retain=True, timeout=5.0)
            tasks[1].cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            return
        stop.cancel()
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        for finished in done:
            finished.result()  # re-raise (MqttError → reconnect)
        raise aiomqtt.MqttError("MQTT session ended")

    # -- readings in -----------------------------------------------------------
    async def _receive(self, client: aiomqtt.Client, acks: OrderedAcks) -> None:
        async for message in client.messages:
            self._take(message, acks)
            if len(self._in_flight) >= MAX_IN_FLIGHT:
                await asyncio.wait(self._in_flight, return_when=asyncio.FIRST_COMPLETED)

    def _take(self, message: aiomqtt.Message, acks: OrderedAcks) -> None:
        """Handle one message; acknowledge it once handled (a JSON reading: committed)."""
        handled = acks.received(message.mid, message.qos)
        payload = message.payload
        raw = bytes(payload) if isinstance(payload, bytes | bytearray) else (
            b"" if payload is None else str(payload).encode())
        self.counts["received"] += 1
        topic = message.topic.value
        # no reading, and not an error: an empty payload (how a retained message is
        # deleted), and a retained single value — it has no time of its own and would be
        # stored again as the minute of every (re)connection; a retained JSON reading
        # carries its ``ts`` and is a duplicate then
        if not raw or (message.retain and self.topics.value.match(topic) is not None
                       and self.topics.state.match(topic) is None):
            self.counts["ignored"] += 1
            handled()
            return
        try:
            storing = self._handle(topic, raw, time.time(), handled)
        except Exception as exc:  # a bug must not drop the message silently
            logger.exception("MQTT message on %s not handled", topic)
            self._reject(UNKNOWN_SITE, Rejection(
                topic, f"internal error ({type(exc).__name__}); not stored", raw))
            storing = False
        if not storing:
            handled()

    def _handle(self, topic: str, payload: bytes, now_s: float,
                handled: Callable[[], None]) -> bool:
        """Store or reject one message. True when a JSON reading went to the writer, which
        calls ``handled`` once committed; else the caller calls it at once (a single value
        once added to its minute: the minute is written when it closes, and holding the
        acknowledgements that long would stall the broker's in-flight window)."""
        fields = self.topics.state.match(topic)
        quantity = None
        if fields is None:
            fields = self.topics.value.match(topic)
            quantity = None if fields is None else fields["quantity"]
        if fields is None or (quantity is not None and quantity not in QUANTITIES):
            self._reject(UNKNOWN_SITE, Rejection(topic, "topic matches no reading template "
                                                        f"({self.topics.state.text}, "
                                                        f"{self.topics.value.text})", payload))
            return False
        site_id, array = fields["site_id"], fields["array"]
        info = self.ctx.registry.get(site_id)
        if info is None:
            known = ", ".join(self.ctx.registry.sites) or "none"
            self._reject(UNKNOWN_SITE, Rejection(
                topic, f"unknown site {site_id[:64]!r}; known sites: {known}", payload))
            return False
        if array not in info.arrays:
            self._reject(site_id, Rejection(
                topic, f"unknown array {array[:64]!r}; this site has "
                       f"{', '.join(info.arrays) or 'no arrays'}", payload))
            return False
        if quantity is None:
            return self._store(site_id, topic,
                               state_batch(info, array, topic, payload, self.limits), payload,
                               handled)
        value = single_value(topic, payload, quantity)
        if isinstance(value, Rejection):
            self._reject(site_id, value)
            return False
        for closed in self.assembler.add(site_id, array, quantity, value, topic, now_s):
            self._take_minute(closed)
        return False

    def _take_minute(self, closed: Closed) -> None:
        info = self.ctx.registry.get(closed.site_id)
        if info is not None:
            self._store(closed.site_id, ", ".join(sorted(set(closed.topics))),
                        minute_batch(info, closed, self.limits), b"")

    async def _close_minutes(self) -> None:
        while True:
            await asyncio.sleep(1.0)
            for closed in self.assembler.due(time.time()):
                self._take_minute(closed)

    def _store(self, site_id: str, topic: str, result: Batch | Rejection, payload: bytes,
               handled: Callable[[], None] = lambda: None) -> bool:
        """Hand ``result`` to the writer (True; ``handled`` is called once it is
        committed or failed) or reject it (False)."""
        if isinstance(result, Rejection):
            self._reject(site_id, result)
            return False
        job = measured_job(result)
        task = asyncio.create_task(self._committed(site_id, topic, self.ctx.writer.submit(job),
                                                   payload, handled))
        self._in_flight.add(task)
        task.add_done_callback(self._in_flight.discard)
        return True

    async def _committed(self, site_id: str, topic: str, future: Future[tuple[int, int]],
                         payload: bytes, handled: Callable[[], None]) -> None:
        try:
            accepted, duplicates = await asyncio.wrap_future(future)
        except Exception as exc:  # noqa: BLE001 - nothing stored: the logger must send again
            logger.error("storing an MQTT reading of %s failed: %r", site_id, exc)
            self._reject(site_id, Rejection(
                topic, f"storage unavailable ({type(exc).__name__}); nothing "
                                       "was stored, publish the reading again", payload))
        else:
            self.counts["stored"] += accepted
            self.counts["duplicates"] += duplicates
        handled()

    # -- rejections and Home Assistant out ---------------------------------------
    def _reject(self, site_id: str, rejection: Rejection) -> None:
        self.counts["rejected"] += 1
        topic = self.topics.errors.format(site_id=site_id)
        logger.info("MQTT message on %s rejected: %s", rejection.topic, rejection.reason)
        if len(self._outbox) >= OUTBOX_MAX:
            old_topic, old = self._outbox.popleft()
            logger.warning("MQTT outbox full: rejection for %s dropped: %s", old_topic,
                           old[:300].decode("utf-8", "replace"))
        self._outbox.append((topic, rejection.message(time.time())))
        if self._outbox_ready is not None:
            self._outbox_ready.set()

    async def _send_outbox(self, client: aiomqtt.Client) -> None:
        assert self._outbox_ready is not None
        while True:
            await self._drain(client, None)
            self._outbox_ready.clear()
            if not self._outbox:
                await self._outbox_ready.wait()

    async def _drain(self, client: aiomqtt.Client, deadline: float | None) -> None:
        while self._outbox and (deadline is None or time.monotonic() < deadline):
            topic, payload = self._outbox[0]
            await client.publish(topic, payload, qos=1)
            self._outbox.popleft()  # only once the broker has it

    async def _publish_ha(self, client: aiomqtt.Client) -> None:
        """Every publish interval: the discovery configs of the registry's sites as they
        are now (a site added or whose arrays changed gets its configs then, not at the
        next connection; the configs of a site or array gone, published on this
        connection, are removed with an empty retained payload), then their states."""
        published: dict[str, bytes] = {}  # config topic → payload, on this connection
        await client.publish(homeassistant.service_availability(self.topics),
                             homeassistant.ONLINE, qos=1, retain=True)
        while True:
            sites = [i for i in self.ctx.registry.sites.values() if i.arrays]
            configs = dict(pair for info in sites
                           for pair in homeassistant.discovery(self.topics, info, _version()))
            for topic, config in configs.items():
                if published.get(topic) != config:
                    await client.publish(topic, config, qos=1, retain=True)
                    published[topic] = config
            for topic in [t for t in published if t not in configs]:
                await client.publish(topic, b"", qos=1, retain=True)
                del published[topic]
            for info in sites:
                if self._stop is not None and self._stop.is_set():
                    break  # stopping (this task is cancelled next): no new states — the
                    # twin they may compute needs the writer, which stops after this thread
                try:
                    pubs = await asyncio.to_thread(homeassistant.states, self.ctx, info,
                                                   self.topics)
                except Exception:  # a database hiccup: try again next period
                    logger.exception("Home Assistant states of %s not computed", info.site_id)
                    continue
                for topic, value in pubs:
                    await client.publish(topic, value, qos=1, retain=True)
            await asyncio.sleep(self.ctx.settings.mqtt.publish_interval_s)
