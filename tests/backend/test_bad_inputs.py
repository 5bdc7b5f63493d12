"""The bad-input corpus (``tests/data/bad/*.json``) against a running service, and the
input forms of issue 9 that must work: gzip back-fill, emonCMS rows, resuming.

Each corpus case is one request (method, path, headers, body; ``repeat`` expands
``{{repeat}}`` in the body, ``encoding`` the body's bytes (UTF-8 unless said), ``gzip``
compresses it, ``auth`` sends the site's write token — ``"site"``: one of scope
``site``) with the status it must
get — a 4xx, never a 5xx — and the words its answer must contain to name the
problem. Every answer stays small, whatever was sent.
"""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import httpx
import orjson
import pytest
from live_service import LiveServer

CASES = sorted((Path(__file__).parents[1] / "data" / "bad").glob("*.json"))
PATH = "/api/v1/sites/tehuantepec/measurements"
MAX_ANSWER_BYTES = 16 * 1024


def _request(case: dict, live_server: LiveServer) -> tuple[str, str, dict[str, str], bytes]:
    body = case.get("body", "")
    if "repeat" in case:
        text, times = case["repeat"]
        body = body.replace("{{repeat}}", text * times)
    data = body.encode(case.get("encoding", "utf-8"))
    if case.get("gzip"):
        data = gzip.compress(data)
    headers = dict(case.get("headers", {}))
    if case.get("auth") == "site":
        headers["Authorization"] = f"Bearer {live_server.process.token(scope='site')}"
    elif case.get("auth"):
        headers["Authorization"] = f"Bearer {live_server.write_token}"
    return case["method"], case["path"], headers, data


def test_the_corpus_covers_each_issue_item() -> None:
    abouts = " ".join(json.loads(p.read_text())["about"] for p in CASES)
    for item in ("issue 9.1", "issue 9.2", "issue 9.6", "issue 9.10", "issue 14.6"):
        assert item in abouts


@pytest.mark.parametrize("path", CASES, ids=[p.stem for p in CASES])
def test_bad_input_gets_a_4xx_naming_the_problem(path: Path, client: httpx.Client,
                                                 live_server: LiveServer) -> None:
    case = json.loads(path.read_text())
    method, url, headers, data = _request(case, live_server)
    r = client.request(method, url, headers=headers, content=data)
    assert r.status_code == case["status"], r.text[:500]
    assert 400 <= r.status_code < 500
    assert len(r.content) <= MAX_ANSWER_BYTES
    text = json.dumps(r.json()["detail"], ensure_ascii=False)
    for words in case["expect"]:
        assert words in text, text[:500]


def test_405_allow_names_every_method_of_the_path(client: httpx.Client) -> None:
    r = client.put(PATH)
    assert r.status_code == 405
    assert r.headers["allow"] == "GET, HEAD, POST"
    r = client.post("/api/v1/twin3d/replay")
    assert r.status_code == 405
    assert r.headers["allow"] == "DELETE, PUT"


def test_head_is_answered_as_get_without_a_body(client: httpx.Client) -> None:
    """The HEAD that a 405's Allow names beside GET is served: it was itself a 405
    (``curl -I /healthz``, an uptime probe)."""
    for path in ("/healthz", "/api/v1/sites/tehuantepec/config"):
        got, head = client.get(path), client.head(path)
        assert head.status_code == got.status_code == 200, head.text
        assert head.content == b""
        assert head.headers["content-type"] == got.headers["content-type"]
        assert head.headers["content-length"] == got.headers["content-length"]
    head = client.head("/api/v1/sites/nowhere")  # an error's status too, headers only
    assert head.status_code == 404 and head.content == b""


def _emoncms_day(day_s: int, array: str) -> list[list]:
    """Minute rows of a day, emonCMS-style, power from V·I (power-line noise free)."""
    return [[day_s + 60 * k, array, 20.0 + k % 7, 3.0 + (k % 5) / 10, (20.0 + k % 7) *
             (3.0 + (k % 5) / 10)] for k in range(1440)]


def test_gzip_emoncms_backfill_resumes_after_stored_through(client: httpx.Client,
                                                           live_server: LiveServer) -> None:
    """Issue 9.10: a logger that buffered a day offline sends it gzipped in two parts;
    each answer says up to when everything is stored; a resend counts as duplicates."""
    day_s = 1_577_836_800  # 2020-01-01T00:00:00Z, a range no other test uses
    rows = _emoncms_day(day_s, "fixed")
    auth = {"Authorization": f"Bearer {live_server.write_token}",
            "Content-Type": "application/json", "Content-Encoding": "gzip"}
    first = client.post(PATH, headers=auth, content=gzip.compress(orjson.dumps(rows[:1000])))
    assert first.status_code == 200, first.text
    assert first.json() == {"accepted": 1000, "duplicates": 0,
                            "stored_through": "2020-01-01T16:39:00Z",
                            "stored_through_unix_s": day_s + 999 * 60}
    resume = first.json()["stored_through_unix_s"]
    rest = [r for r in rows if r[0] > resume]
    second = client.post(PATH, headers=auth, content=gzip.compress(orjson.dumps(rest)))
    assert second.json()["accepted"] == 440
    again = client.post(PATH, headers=auth, content=gzip.compress(orjson.dumps(rows)))
    assert (again.json()["accepted"], again.json()["duplicates"]) == (0, 1440)
    got = client.get(PATH, params={"array": "fixed", "start": "2020-01-01T00:00:00Z",
                                   "end": "2020-01-02T00:00:00Z", "max_points": 2000}).json()
    assert [p["power_w"] for p in got["points"]] == pytest.approx([r[4] for r in rows])


def test_gzip_csv_is_the_same_as_plain_csv(client: httpx.Client,
                                          live_server: LiveServer) -> None:
    text = "ts,array,voltage_v,current_a\n2020-01-03T12:00:00Z,tracker,25.5,4\n"
    auth = {"Authorization": f"Bearer {live_server.write_token}", "Content-Type": "text/csv"}
    r = client.post(PATH, headers={**auth, "Content-Encoding": "gzip"},
                    content=gzip.compress(text.encode()))
    assert r.json()["accepted"] == 1
    assert client.post(PATH, headers=auth, content=text).json()["duplicates"] == 1
