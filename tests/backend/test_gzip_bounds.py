"""gzip request bodies cost what they hold (issue 23, item 1): decompression is linear in
the body, at most ``GZIP_MAX_MEMBERS`` members (413 past it), and a route that needs a
token checks it before decompressing (401 first). Work is counted, never timed.
"""

from __future__ import annotations

import gzip
import zlib
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from backend.api import strict
from backend.errors import InputError

MEMBER = gzip.compress(b"", mtime=0)  # 20 bytes: an empty gzip member
BOMB = MEMBER * 400_000  # 7.6 MiB: what cost 60 s of CPU before a 422
_DECOMPRESSOBJ = zlib.decompressobj


class _Counting:
    """``zlib.decompressobj`` that counts the decompressors made and the bytes fed."""

    def __init__(self) -> None:
        self.made = 0
        self.fed = 0

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        self.made += 1
        real = _DECOMPRESSOBJ(*args, **kwargs)
        counter = self

        class Proxy:
            def decompress(self, data: Any, max_length: int = 0) -> bytes:
                counter.fed += len(data)
                return real.decompress(data, max_length)

            def __getattr__(self, name: str) -> Any:
                return getattr(real, name)

        return Proxy()


@pytest.fixture
def counting(monkeypatch: pytest.MonkeyPatch) -> _Counting:
    c = _Counting()
    monkeypatch.setattr(strict.zlib, "decompressobj", c)
    return c


def test_members_are_joined_and_fed_once(counting: _Counting) -> None:
    parts = [b"ts,array,voltage_v\n", b"2024-01-01T00:00:00Z,tracker,30.1\n" * 500, b""]
    body = b"".join(gzip.compress(p) for p in parts) * 1000  # 3,000 members
    assert strict.gunzip(body, 10**8) == b"".join(parts) * 1000
    assert counting.made == 3000
    # each byte once, plus at most the first piece of a member read past its end
    assert counting.fed <= len(body) + 3000 * strict._FEED_FIRST


def test_a_member_bomb_is_refused_at_the_member_cap(counting: _Counting) -> None:
    with pytest.raises(InputError) as err:
        strict.gunzip(BOMB, 10 * 2**20)
    assert err.value.status_code == 413
    assert f"more than {strict.GZIP_MAX_MEMBERS} gzip members" in err.value.detail
    assert counting.made == strict.GZIP_MAX_MEMBERS  # refused before the next one
    assert counting.fed <= strict.GZIP_MAX_MEMBERS * strict._FEED_FIRST


def test_bad_gzip_is_still_a_400_and_the_output_bound_a_413() -> None:
    with pytest.raises(InputError) as err:
        strict.gunzip(MEMBER + b"not gzip", 100)
    assert err.value.status_code == 400
    with pytest.raises(InputError) as err:
        strict.gunzip(gzip.compress(b"x" * 1000)[:-9], 10_000)
    assert err.value.status_code == 400 and "truncated" in err.value.detail
    with pytest.raises(InputError) as err:
        strict.gunzip(gzip.compress(b"x" * 1001), 1000)
    assert err.value.status_code == 413


@pytest.fixture
def gunzips(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[int]]:
    """How many bodies the service decompressed (``strict.gunzip`` calls)."""
    calls: list[int] = []
    real = strict.gunzip

    def counted(data: bytes, limit: int, *args: Any) -> bytes:
        calls.append(len(data))
        return real(data, limit, *args)

    monkeypatch.setattr(strict, "gunzip", counted)
    yield calls


GZ_JSON = {"Content-Encoding": "gzip", "Content-Type": "application/json"}


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # gzip, not storage
def test_the_bomb_gets_a_4xx_over_http(client: httpx.Client, gunzips: list[int]) -> None:
    r = client.post("/api/v1/simulations", content=BOMB, headers=GZ_JSON)
    assert r.status_code == 413 and "gzip members" in r.json()["detail"]
    assert gunzips == [len(BOMB)]


def test_token_routes_answer_401_before_decompressing(client: httpx.Client,
                                                      live_server: Any,
                                                      gunzips: list[int]) -> None:
    for method, path in (("PUT", "/api/v1/sites/tehuantepec"),
                         ("PUT", "/api/v1/sites/tehuantepec/arrays/fixed/calibration"),
                         ("POST", "/api/v1/sites/tehuantepec/measurements")):
        r = client.request(method, path, content=BOMB, headers=GZ_JSON)
        assert r.status_code == 401, (path, r.text)
        r = client.request(method, path, content=BOMB,
                           headers={**GZ_JSON, "Authorization": "Bearer ht_unknown"})
        assert r.status_code == 401 and r.json()["detail"] == "unknown write token"
    assert gunzips == []  # not one byte decompressed for a caller without a valid token
    r = client.put("/api/v1/sites/tehuantepec", content=BOMB,
                   headers={**GZ_JSON, "Authorization": f"Bearer {live_server.write_token}"})
    assert r.status_code == 413 and "gzip members" in r.json()["detail"]
    assert gunzips == [len(BOMB)]
