"""Bounds on anonymous work: per-client token buckets, a pixel budget, retention.

- :class:`RateLimiter` — a token bucket per client address (``request.client.host``):
  a request without a write token spends its cost (simulated steps, image
  pixels) from a bucket that refills at ``per_min`` per minute up to one minute's
  worth; an empty bucket is a 429 whose ``Retry-After`` says when it will hold
  the cost again. Requests with a valid token are not rate-limited.
- :class:`WindowBudget` — a client's cost in any sliding window (an hour of simulation
  worker time for a caller without a token): charged the estimate when a run is
  admitted, trued up to the time the run took (:meth:`WindowBudget.settle`); past the
  ceiling a 429 whose ``Retry-After`` says when enough of the window has passed.
- :func:`metered`, :func:`metered_iter` and :class:`ReadMeter` — the CPU time a read
  without a token really cost (its handler's and its streamed body's threads), which
  ``backend.api.deps.anonymous_read`` charges to the caller's :class:`WindowBudget`
  ``Limits.reads``.
- :class:`HeldBudget` — what is worked on at once, whoever asks (with a token too):
  ``decode``, the pixels decoded across all vision requests (a decoded frame costs
  about 6 bytes per pixel at its peak — measured: a 6300×6300 PNG peaks at 225 MB
  in ``cv2.imdecode`` — so the budget bounds the memory of decoding whatever the
  concurrency), and ``plants``, the plant computations on request (a day, a sky
  map, a sweep's shaded day: one at a time, :data:`PLANT_COMPUTATIONS`, so their
  peak memory — up to ≈ 180 MB for a Peñarroya day at 300 s — is paid once, not
  once per concurrent caller). A request waits its turn in a bounded queue, and
  past it gets 503 with ``Retry-After``.
- :func:`prune_anonymous` — the retention of rows stored for anonymous callers
  (simulation runs and their series, vision detections and calibrations): the newest
  ``keep``.
- :func:`tune_malloc` and :func:`release_memory` — memory given back after big requests
  (issue 23 item 5): glibc keeps the pages that numpy and pandas buffers freed in its
  heaps (one per thread that allocated, up to 8 per core) and moves its mmap threshold
  up to 32 MiB after the first large free, so that later large arrays come from those
  heaps too; an idle server stayed 2.7× its start (244 → 668 MB after a year's series
  read four times as JSON and as CSV, 32 plant days and a year of diagnosis). ``serve``
  caps the heaps at two and fixes the mmap threshold at 1 MiB (arrays above it are
  unmapped when freed), and the service trims the heaps every
  :data:`TRIM_INTERVAL_S` (``malloc_trim(0)``).

:class:`Busy` is what these raise; the routes turn it into the 429/503 answer.
"""

from __future__ import annotations

import asyncio
import ctypes
import ctypes.util
import functools
import math
import threading
import time
from collections import OrderedDict
from collections.abc import AsyncIterator, Callable, Iterable, Iterator
from contextlib import asynccontextmanager, contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any, TypeVar

from sqlalchemy import Connection, delete, select

from backend.settings import Settings
from backend.storage.tables import (
    SimulationRun,
    SimulationSeries,
    VisionCalibration,
    VisionDetection,
)

#: Plant computations on request worked on at once: one (each ≤ ≈ 2 s of CPU for the
#: built-in Peñarroya at the finest step; see ``backend/plants``), so their memory peaks
#: do not add up across callers (32 concurrent days at 300 s held +2.4 GB, issue 23).
PLANT_COMPUTATIONS = 1
#: Plant computations waiting for their turn; more → 503 with ``Retry-After``.
PLANT_QUEUE = 16
#: The window of the anonymous read allowance (``HELIOTWIN_ANONYMOUS_READ_CPU_S_PER_MIN``) [s].
READ_WINDOW_S = 60.0
#: Reads a caller without a token may have in flight at once (a read is charged once it
#: has run, so a burst of slow reads would otherwise all be admitted before the first is
#: charged); more → 429. The dashboard's overview asks five at once (four series and the
#: daily energy), bench_load's mix ten.
READS_IN_FLIGHT = 16


#: How often the service gives freed heap pages back (:func:`release_memory`) [s].
TRIM_INTERVAL_S = 10.0
#: glibc ``mallopt`` parameters (``malloc.h``).
_M_MMAP_THRESHOLD, _M_ARENA_MAX = -3, -8
#: Allocations at or above this are mapped on their own and unmapped when freed [bytes].
MMAP_THRESHOLD_BYTES = 1 << 20
#: Heaps (arenas) glibc may make for the threads (its default: 8 per core).
ARENA_MAX = 2


@functools.lru_cache(maxsize=1)  # one library; find_library runs ldconfig
def _libc() -> ctypes.CDLL | None:
    """glibc, or None elsewhere (musl, macOS: the functions below do nothing there)."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
    except OSError:
        return None
    return libc if libc is not None and hasattr(libc, "malloc_trim") else None


def tune_malloc() -> bool:
    """Cap glibc's heaps at :data:`ARENA_MAX` and fix its mmap threshold at
    :data:`MMAP_THRESHOLD_BYTES` (no dynamic raise); call once, before the threads start.
    Whether glibc took both."""
    libc = _libc()
    if libc is None:
        return False
    return bool(libc.mallopt(_M_ARENA_MAX, ARENA_MAX)) and bool(
        libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES))


def release_memory() -> bool:
    """Give the free pages of every glibc heap back to the system (``malloc_trim(0)``);
    whether any were. Python objects are not touched: only memory already freed."""
    libc = _libc()
    return libc is not None and bool(libc.malloc_trim(0))


class Busy(Exception):
    """Refused for now: ``status_code`` 429 (this client) or 503 (the service), retry later."""

    def __init__(self, status_code: int, message: str, retry_after_s: float) -> None:
        super().__init__(message)
        self.status_code = status_code
        self.message = message
        self.retry_after_s = max(1, math.ceil(retry_after_s))

    @property
    def headers(self) -> dict[str, str]:
        return {"Retry-After": str(self.retry_after_s)}


class RateLimiter:
    """Token buckets keyed by client address: ``per_min`` cost units a minute, burst one minute.

    A cost above one minute's worth is charged as one minute's worth (a full
    bucket always admits one request the service accepts at all). At most
    ``max_clients`` buckets are kept; the least recently used is forgotten
    first (a forgotten client starts again with a full bucket).
    """

    def __init__(self, per_min: float, what: str, setting: str, max_clients: int = 10_000
                 ) -> None:
        self.capacity = float(per_min)
        self.rate_per_s = per_min / 60.0
        self.what = what
        self.setting = setting
        self.max_clients = max_clients
        self._buckets: OrderedDict[str, tuple[float, float]] = OrderedDict()
        self._lock = threading.Lock()

    def take(self, client: str, cost: float) -> None:
        """Spend ``cost`` from ``client``'s bucket, or raise :class:`Busy` (429)."""
        cost = min(float(cost), self.capacity)
        now = time.monotonic()
        with self._lock:
            level, then = self._buckets.pop(client, (self.capacity, now))
            level = min(self.capacity, level + (now - then) * self.rate_per_s)
            if level < cost:
                self._buckets[client] = (level, now)
                wait_s = (cost - level) / self.rate_per_s
                raise Busy(429, f"rate limit: without a write token a client may ask "
                                f"{self.capacity:.0f} {self.what} per minute ({self.setting}); "
                                f"send 'Authorization: Bearer <token>' or retry in "
                                f"{math.ceil(wait_s)} s", wait_s)
            self._buckets[client] = (level - cost, now)
            while len(self._buckets) > self.max_clients:
                self._buckets.popitem(last=False)

    def refund(self, client: str, cost: float) -> None:
        """Give back what :meth:`take` spent on a request refused after it (nothing done)."""
        cost = min(float(cost), self.capacity)
        with self._lock:
            if client in self._buckets:
                level, then = self._buckets[client]
                self._buckets[client] = (min(self.capacity, level + cost), then)


class Charge:
    """One admitted cost in a :class:`WindowBudget`: when, how much, whether the work is
    still going (``open``: not yet settled) and whether it is counted while it goes
    (``held``: taken with ``max_open``)."""

    __slots__ = ("at", "cost", "held", "open")

    def __init__(self, at: float, cost: float, held: bool = False) -> None:
        self.at = at
        self.cost = cost
        self.held = held
        self.open = True

    @property
    def in_flight(self) -> bool:
        """A held charge whose work still runs: it stays in the window until settled."""
        return self.held and self.open


class WindowBudget:
    """At most ``capacity`` cost units per client in any ``window_s``; thread-safe.

    A cost above the capacity is admitted as the capacity (what the service admits at all,
    a full window always admits). A charge taken with ``max_open`` (work counted while in
    flight: the reads) stays in the window while its work runs, however long, and counts
    from its settling once done (:meth:`settle`): a read streamed for longer than the
    window stays in flight and is charged when it ends. At most ``max_clients`` clients
    are remembered, the least recently charged forgotten first.
    """

    def __init__(self, capacity: float, window_s: float, what: str, setting: str,
                 max_clients: int = 10_000, clock: Callable[[], float] = time.monotonic
                 ) -> None:
        self.capacity = float(capacity)
        self.window_s = float(window_s)
        self.what = what
        self.setting = setting
        self.max_clients = max_clients
        #: Seconds on a monotonic clock (a test moves it on to see the window pass).
        self.clock = clock
        self._charges: OrderedDict[str, list[Charge]] = OrderedDict()
        self._lock = threading.Lock()

    def used(self, client: str) -> float:
        """The cost ``client`` has spent in the window ending now."""
        with self._lock:
            return sum(c.cost for c in self._live(client, self.clock()))

    def _live(self, client: str, now: float) -> list[Charge]:
        charges = [c for c in self._charges.get(client, [])
                   if c.in_flight or c.at > now - self.window_s]
        if client in self._charges:
            self._charges[client] = charges
        return charges

    def take(self, client: str, cost: float, max_open: int | None = None) -> Charge:
        """Charge ``cost`` to ``client``, or raise :class:`Busy` (429); with ``max_open``,
        also when ``client`` has that many charges not yet settled (work in flight)."""
        cost = min(float(cost), self.capacity)
        now = self.clock()
        with self._lock:
            charges = self._live(client, now)
            if max_open is not None and sum(c.open for c in charges) >= max_open:
                raise Busy(429, f"rate limit: without a write token a client may have "
                                f"{max_open} requests in flight at once here ({self.setting} "
                                "counts what they cost): send 'Authorization: Bearer "
                                "<token>' or retry in 1 s", 1.0)
            used = sum(c.cost for c in charges)
            if used + cost > self.capacity:
                freed, wait_s = 0.0, self.window_s
                for c in sorted((c for c in charges if not c.in_flight), key=lambda c: c.at):
                    freed += c.cost    # a read still running frees nothing by waiting
                    if used - freed + cost <= self.capacity:
                        wait_s = max(1.0, c.at + self.window_s - now)
                        break
                raise Busy(429, f"rate limit: without a write token a client may ask "
                                f"{amount(self.capacity)} {self.what} per "
                                f"{self.window_s / 60:.0f} min ({self.setting}); "
                                f"{amount(used)} spent"
                                f"{f', this asks {amount(cost)}' if cost else ''}: send "
                                f"'Authorization: Bearer <token>' or retry in "
                                f"{math.ceil(wait_s)} s", wait_s)
            charge = Charge(now, cost, held=max_open is not None)
            self._charges[client] = [*charges, charge]
            self._charges.move_to_end(client)
            while len(self._charges) > self.max_clients:
                self._charges.popitem(last=False)
        return charge

    def settle(self, charge: Charge, cost: float) -> None:
        """The charged work cost ``cost`` after all (0: it never ran); a held charge counts
        from now, when its work ended."""
        with self._lock:
            charge.cost = max(0.0, float(cost))
            if charge.held:
                charge.at = self.clock()
            charge.open = False


def amount(x: float) -> str:
    """A cost for a message: whole units from 100 up (``2,200,000``), else three digits
    (``16.5``, ``0.125``)."""
    return f"{x:,.0f}" if abs(x) >= 100 else f"{x:.3g}"


class ReadMeter:
    """The CPU time [s] the threads of one request spent in :func:`metered` work."""

    def __init__(self) -> None:
        self.cpu_s = 0.0
        self._lock = threading.Lock()

    def add(self, cpu_s: float) -> None:
        with self._lock:
            self.cpu_s += cpu_s


#: The meter of the request being served (set by ``backend.api.deps.anonymous_read`` for a
#: caller without a token): the request's task and the worker threads it hands work to
#: (AnyIO copies the context into them) all see it.
_READ_METER: ContextVar[ReadMeter | None] = ContextVar("heliotwin_read_meter", default=None)
_metering = threading.local()
_T = TypeVar("_T")


def start_meter() -> ReadMeter:
    """A new meter for the request being served: what :func:`metered` blocks then cost."""
    meter = ReadMeter()
    _READ_METER.set(meter)
    return meter


@contextmanager
def metered() -> Iterator[None]:
    """Count this block's CPU time on this thread (``time.thread_time``: the time the
    thread ran, not the time it waited for the GIL, a lock or another request) to the
    request's meter; nothing to count without one (a caller with a token). A block inside
    another is counted once."""
    meter = _READ_METER.get()
    if meter is None or getattr(_metering, "active", False):
        yield
        return
    _metering.active = True
    start_s = time.thread_time()
    try:
        yield
    finally:
        meter.add(time.thread_time() - start_s)
        _metering.active = False


def run_metered(work: Callable[..., _T], *args: Any) -> _T:
    """``work(*args)`` inside :func:`metered` (for ``anyio.to_thread.run_sync``)."""
    with metered():
        return work(*args)


def metered_iter(parts: Iterable[_T]) -> Iterator[_T]:
    """A streamed body whose pieces are each made inside :func:`metered` (a body of a sync
    iterator is made piece by piece on worker threads, after the handler has returned)."""
    it = iter(parts)
    while True:
        with metered():
            try:
                part = next(it)
            except StopIteration:
                return
        yield part


class HeldBudget:
    """At most ``capacity`` units (pixels decoded, plant computations) held at once; up to
    ``max_waiting`` requests queue, more get 503 with ``Retry-After``.

    First come, first served: a request waits while an earlier one waits, so a
    stream of small requests cannot starve a large one. ``units_per_s`` is how fast
    held units are done, for ``Retry-After``.
    """

    def __init__(self, capacity: int, max_waiting: int, units_per_s: float, what: str,
                 setting: str) -> None:
        self.capacity = capacity
        self.max_waiting = max_waiting
        self.units_per_s = units_per_s
        self.what = what
        self.setting = setting
        self._held = 0
        self._waiting: list[tuple[int, asyncio.Future[None]]] = []

    @property
    def held(self) -> int:
        return self._held

    def _retry_after_s(self) -> float:
        queued = self._held + sum(units for units, _ in self._waiting)
        return queued / self.units_per_s

    @asynccontextmanager
    async def hold(self, units: int) -> AsyncIterator[None]:
        """Hold ``units`` of the budget (more than the budget holds all of it)."""
        units = min(int(units), self.capacity)
        if self._waiting or self._held + units > self.capacity:
            if len(self._waiting) >= self.max_waiting:
                raise Busy(503, f"busy: {len(self._waiting)} requests are waiting for "
                                f"the budget of {self.capacity} {self.what} held at once "
                                f"({self.setting})", self._retry_after_s())
            turn: asyncio.Future[None] = asyncio.get_running_loop().create_future()
            entry = (units, turn)
            self._waiting.append(entry)
            try:
                await turn
            except BaseException:
                if entry in self._waiting:
                    self._waiting.remove(entry)
                elif not turn.cancelled():  # granted, then cancelled: give it back
                    self._release(units)
                raise
        else:
            self._held += units
        try:
            yield
        finally:
            self._release(units)

    def _release(self, units: int) -> None:
        self._held -= units
        while self._waiting:
            n, turn = self._waiting[0]
            if self._held + n > self.capacity:
                break
            self._waiting.pop(0)
            if not turn.done():
                self._held += n
                turn.set_result(None)


def prune_anonymous(conn: Connection, table: Any, keep: int) -> int:
    """Delete the anonymous rows of ``table`` beyond the newest ``keep``; returns how many.

    ``table`` is :class:`SimulationRun` (its series go with it), :class:`VisionDetection`
    or :class:`VisionCalibration` (the detections made with it go with it, as when it is
    deleted: their angles came from a camera that no longer exists).
    """
    key = SimulationRun.run_id if table is SimulationRun else table.id
    q = select(key).where(table.anonymous.is_(True))
    if table is SimulationRun:  # never a run still queued or running
        q = q.where(SimulationRun.status.in_(("done", "failed")))
    old = [r[0] for r in conn.execute(
        q.order_by(table.created_at.desc(), key.desc()).offset(keep))]
    for i in range(0, len(old), 500):
        chunk = old[i:i + 500]
        if table is SimulationRun:
            conn.execute(delete(SimulationSeries).where(SimulationSeries.run_id.in_(chunk)))
        if table is VisionCalibration:
            conn.execute(delete(VisionDetection).where(VisionDetection.calibration_id.in_(chunk)))
        conn.execute(delete(table).where(key.in_(chunk)))
    return len(old)


@dataclass
class Limits:
    """The service's bounds on anonymous work (``ServiceContext.limits``)."""

    simulation_steps: RateLimiter
    series_cells: RateLimiter
    vision_pixels: RateLimiter
    decode: HeldBudget
    plants: HeldBudget
    reads: WindowBudget

    def admit_read(self, client: str) -> Charge:
        """Admit a read without a token from ``client`` — :class:`Busy` 429 when its
        allowance is spent or :data:`READS_IN_FLIGHT` of its reads are in flight — to be
        settled to the CPU time it took."""
        return self.reads.take(client, 0.0, max_open=READS_IN_FLIGHT)

    @classmethod
    def from_settings(cls, s: Settings) -> Limits:
        return cls(
            RateLimiter(s.simulations.anonymous_steps_per_min, "simulated time steps",
                        "HELIOTWIN_ANONYMOUS_SIMULATION_STEPS_PER_MIN"),
            RateLimiter(s.simulations.anonymous_series_cells_per_min,
                        "simulation series values (rows × columns)",
                        "HELIOTWIN_ANONYMOUS_SERIES_CELLS_PER_MIN"),
            RateLimiter(s.vision.anonymous_pixels_per_min, "image pixels",
                        "HELIOTWIN_ANONYMOUS_VISION_PIXELS_PER_MIN"),
            # decode + analysis speed ≈ 38 Mpx/s (measured), for Retry-After
            HeldBudget(s.vision.decode_pixels, s.vision.queue, 40e6, "pixels decoded",
                       "HELIOTWIN_VISION_DECODE_PIXELS, HELIOTWIN_VISION_QUEUE"),
            HeldBudget(PLANT_COMPUTATIONS, PLANT_QUEUE, 1.0, "plant computations",
                       "one plant day, sky map or sweep shade at a time"),
            WindowBudget(s.ingest.anonymous_read_cpu_s_per_min, READ_WINDOW_S,
                         "CPU seconds of reads (measurements, energy, reports, diagnosis, "
                         "pointing, pointing model)", "HELIOTWIN_ANONYMOUS_READ_CPU_S_PER_MIN"),
        )
