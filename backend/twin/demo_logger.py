"""A demo field logger: posts realistic minute readings over real HTTP.

It stands in for the Arduino loggers of seed 000 (one I/V reading per array per
minute): the twin's clear-sky expectation (``sim.twin.simulate``) times a cloud
factor shared by both arrays (passing clouds as smooth dips, some days partly
cloudy or overcast), plus 0.5 % sensor noise, the occasional missing minute
and now and then a logger outage of 10–40 minutes. Everything is drawn from a
generator seeded by the day, so re-sending a minute sends the same values and
the service counts it as a duplicate.

``heliotwin demo-logger`` runs it in the foreground; ``heliotwin serve`` runs it
on a thread (with ``HELIOTWIN_DEMO_TOKEN``, or a token it makes for itself by
:func:`demo_token`, which replaces the one of the previous start) unless ``--no-demo``.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import httpx
import numpy as np
import pandas as pd
from sqlalchemy import Connection, delete
from tenacity import Retrying, retry_if_exception_type, stop_after_attempt

from backend.auth import create_token
from backend.retry import Stopped, backoff, stoppable_sleep
from sim.sites import Site
from sim.twin import simulate

logger = logging.getLogger(__name__)


class _Retryable(Exception):
    """A failed post worth retrying: no connection, or a 5xx."""


class TokenRefused(Exception):
    """The service refused the token (401/403): no later batch would be taken either."""




logging.getLogger("httpx").setLevel(logging.WARNING)  # one line per post is noise

BATCH = 1000
#: The label of the token ``heliotwin serve`` makes for its demo logger.
DEMO_TOKEN_LABEL = "demo-logger (heliotwin serve)"


def demo_token(conn: Connection, site_id: str) -> str:
    """A new ``ingest`` token for the demo logger of ``site_id``, replacing those earlier
    starts made (their rows are deleted): one demo token is active, however many restarts.

    The database keeps only hashes, so the previous token cannot be read back and
    reused; set ``HELIOTWIN_DEMO_TOKEN`` to keep one token across restarts.
    """
    from backend.storage.tables import LoggerToken

    conn.execute(delete(LoggerToken).where(LoggerToken.site_id == site_id,
                                           LoggerToken.label == DEMO_TOKEN_LABEL))
    return create_token(conn, site_id, DEMO_TOKEN_LABEL)


def cloud_factor(day_number: int, minutes: np.ndarray, seed: int = 0) -> np.ndarray:
    """Fraction of clear-sky current left by clouds at the given minutes of one day (0.15…1)."""
    rng = np.random.default_rng([seed, day_number])
    kind = rng.choice(["clear", "partly", "overcast"], p=[0.55, 0.35, 0.10])
    base = 1.0 if kind != "overcast" else rng.uniform(0.3, 0.55)
    rate_per_h = {"clear": 0.15, "partly": 1.2, "overcast": 0.6}[kind]
    n_events = rng.poisson(rate_per_h * 24)
    starts = rng.uniform(0, 1440, n_events)
    lengths = rng.uniform(3, 25, n_events)
    depths = rng.uniform(0.3, 0.8, n_events)
    f = np.full(minutes.shape, base)
    for s, length, d in zip(starts, lengths, depths, strict=True):
        x = (minutes - s) / length
        inside = (x >= 0) & (x <= 1)
        f[inside] *= 1.0 - d * np.sin(np.pi * x[inside]) ** 2
    return np.clip(f, 0.15, 1.0)


def dropped(day_number: int, minutes: np.ndarray, seed: int = 0) -> np.ndarray:
    """Minutes the logger misses: 0.3 % at random and, some days, one outage of 10–40 min."""
    rng = np.random.default_rng([seed, day_number, 7])
    miss = rng.random(1440) < 0.003
    if rng.random() < 0.15:
        s = int(rng.integers(0, 1440))
        miss[s : s + int(rng.integers(10, 41))] = True
    return miss[minutes.astype(np.int64) % 1440]


class DemoLogger:
    """Posts readings of one site's arrays to ``{base_url}/api/v1/sites/{site}/measurements``."""

    def __init__(self, site: Site, base_url: str, token: str, seed: int = 0,
                 timeout_s: float = 30.0) -> None:
        self.site = site
        self.base_url = base_url.rstrip("/")
        self.token = token
        self.seed = seed
        self.client = httpx.Client(base_url=self.base_url, timeout=timeout_s,
                                   headers={"Authorization": f"Bearer {token}"})
        self.posted = 0
        self.readings_dropped = 0  # given up after retries or refused: each one logged
        self.stop = threading.Event()

    def close(self) -> None:
        """Close the HTTP connection."""
        self.client.close()

    def readings(self, start_s: int, end_s: int) -> list[dict[str, Any]]:
        """The readings the logger would have taken over ``[start_s, end_s)`` (minute steps)."""
        if end_s <= start_s:
            return []
        res = simulate(self.site, pd.Timestamp(start_s, unit="s", tz="UTC"),
                       pd.Timestamp(end_s, unit="s", tz="UTC"), step_s=60)
        s = res.series
        ts = s.index.as_unit("s").asi8
        local = s.index.tz_convert(self.site.timezone)
        day_number = (local.tz_localize(None).normalize().as_unit("s").asi8 // 86400)
        minute_of_day = (local.hour * 60 + local.minute).to_numpy()
        cloud = np.ones(len(s))
        miss = np.zeros(len(s), bool)
        for d in np.unique(day_number):
            sel = day_number == d
            cloud[sel] = cloud_factor(int(d), minute_of_day[sel], self.seed)
            miss[sel] = dropped(int(d), minute_of_day[sel], self.seed)
        out: list[dict[str, Any]] = []
        iso = [pd.Timestamp(t, unit="s", tz="UTC").isoformat() for t in ts]
        for name in self.site.arrays:
            if f"{name}_current_a" not in s.columns:
                continue
            rng = np.random.default_rng([self.seed, int(ts[0]) // 60, len(name)])
            noise_i = 1.0 + 0.005 * rng.standard_normal(len(s))
            noise_v = 1.0 + 0.002 * rng.standard_normal(len(s))
            i = np.nan_to_num(s[f"{name}_current_a"].to_numpy()) * cloud * noise_i
            v = np.nan_to_num(s[f"{name}_voltage_v"].to_numpy()) * (0.97 + 0.03 * cloud) * noise_v
            v = np.where(i > 0, v, 0.0)
            i = np.maximum(i, 0.0)
            encoder = self._encoder_angles(s, rng) if name == "tracker" else None
            for j in np.flatnonzero(~miss).tolist():
                vv, ii = round(float(v[j]), 3), round(float(i[j]), 4)
                reading = {"ts": iso[j], "array": name, "voltage_v": vv, "current_a": ii,
                           "power_w": round(vv * ii, 3)}
                if encoder is not None:
                    reading["azimuth_deg"], reading["elevation_deg"] = encoder[j]
                out.append(reading)
        out.sort(key=lambda r: r["ts"])
        return out

    @staticmethod
    def _encoder_angles(s: pd.DataFrame, rng: np.random.Generator) -> list[tuple[float, float]]:
        """The tracker's joint angles as its encoders would report them: the twin's, with
        0.02° of noise, to 0.01° (``backend/diagnosis/pointing.py`` charts them)."""
        az = s["azimuth_joint_deg"].to_numpy() + 0.02 * rng.standard_normal(len(s))
        el = s["elevation_joint_deg"].to_numpy() + 0.02 * rng.standard_normal(len(s))
        return list(zip(np.round(az % 360.0, 2).tolist(),
                        np.round(np.clip(el, -90.0, 90.0), 2).tolist(), strict=True))

    def post(self, readings: list[dict[str, Any]], attempts: int = 5) -> tuple[int, int]:
        """Post readings in batches of 1000, each tried ``attempts`` times on connection errors
        and 5xx, 1 s, 2 s, 4 s … (at most 10 s) apart (:func:`backend.retry.backoff`); a batch
        that still fails, or is refused with a 4xx, is dropped and logged with its size and
        time span; a stop during a wait drops the batch and ends the post."""
        accepted = duplicates = 0
        path = f"/api/v1/sites/{self.site.site_id}/measurements"
        retrying = Retrying(
            stop=stop_after_attempt(attempts),
            wait=backoff(1.0, 10.0),
            retry=retry_if_exception_type(_Retryable),
            sleep=stoppable_sleep(self.stop),
            before_sleep=lambda state: logger.warning(
                "demo logger: %s (attempt %d of %d)",
                state.outcome.exception() if state.outcome else "?", state.attempt_number,
                attempts),
            reraise=True,
        )
        for k in range(0, len(readings), BATCH):
            chunk = readings[k : k + BATCH]
            try:
                r = retrying(self._post_once, path, chunk)
            except (_Retryable, Stopped) as exc:
                self.readings_dropped += len(chunk)
                logger.error("demo logger: dropped %d readings %s..%s: %s", len(chunk),
                             chunk[0]["ts"], chunk[-1]["ts"], exc)
                if isinstance(exc, Stopped):
                    break
                continue
            if r.status_code in (401, 403):
                self.readings_dropped += len(readings) - k
                try:  # a proxy's own 401/403 page is not JSON
                    detail = r.json().get("detail", r.text[:200])
                except ValueError:
                    detail = r.text[:200]
                raise TokenRefused(f"{r.status_code} {detail}")
            if r.status_code != 200:
                self.readings_dropped += len(chunk)
                logger.error("demo logger: dropped %d readings %s..%s: %s %s", len(chunk),
                             chunk[0]["ts"], chunk[-1]["ts"], r.status_code, r.text[:300])
                continue
            body = r.json()
            accepted += body["accepted"]
            duplicates += body["duplicates"]
        self.posted += accepted
        return accepted, duplicates

    def _post_once(self, path: str, chunk: list[dict[str, Any]]) -> httpx.Response:
        try:
            r = self.client.post(path, json={"readings": chunk})
        except httpx.HTTPError as exc:
            raise _Retryable(f"{type(exc).__name__}: {exc}") from exc
        if r.status_code >= 500:
            raise _Retryable(f"{r.status_code} {r.text[:200]}")
        return r

    def backfill(self, days: float, now_s: float | None = None) -> tuple[int, int]:
        """Post the last ``days`` days up to the current minute."""
        now_min = int((time.time() if now_s is None else now_s) // 60 * 60)
        start = now_min - int(days * 86400) // 60 * 60  # whole minutes: no piece under a step
        total = (0, 0)
        for lo in range(start, now_min, 86400):
            a, d = self.post(self.readings(lo, min(lo + 86400, now_min)))
            total = (total[0] + a, total[1] + d)
        logger.info("demo logger back-filled %.1f days: %d accepted, %d duplicates",
                    days, *total)
        return total

    def wait_until_up(self, stop: threading.Event, timeout_s: float = 120.0) -> bool:
        """Wait for ``/healthz`` to answer (bounded; said once when it does not at once)."""
        deadline = time.monotonic() + timeout_s
        said = False
        while time.monotonic() < deadline and not stop.is_set():
            try:
                if self.client.get("/healthz").status_code == 200:
                    return True
            except httpx.HTTPError:
                pass
            if not said:
                # INFO: every start waits a second or two for uvicorn to bind, not a problem
                logger.info("demo logger: waiting up to %.0f s for %s to answer /healthz",
                            timeout_s, self.base_url)
                said = True
            stop.wait(0.25)
        return False

    def run(self, stop: threading.Event, backfill_days: float = 0.0,
            interval_s: float = 60.0) -> bool:
        """Back-fill, then post each new minute until ``stop`` is set → True; False when it
        could not: the service never answered, or it refuses the token (the CLI's exit
        status says so)."""
        self.stop = stop
        if not self.wait_until_up(stop):
            logger.error("demo logger: %s did not come up", self.base_url)
            return stop.is_set()
        try:
            if backfill_days > 0:
                self.backfill(backfill_days)
            last = int(time.time() // 60 * 60)
            while not stop.wait(max(0.5, interval_s - time.time() % interval_s + 1.0)):
                now_min = int(time.time() // 60 * 60)
                if now_min <= last:
                    continue
                lo = max(last + 60, now_min - 86400)
                self.post(self.readings(lo, now_min + 60))
                last = now_min
        except TokenRefused as exc:  # no reading would be taken: said once, not every minute
            logger.error("demo logger: the service refuses its token (%s); stopped", exc)
            return False
        return True

