"""Strict request input for every route: body encodings, repeated JSON keys, 405s, 422s.

- :class:`StrictBodies` (ASGI middleware, ahead of everything): ``Content-Encoding``
  ``identity`` passes through, ``gzip`` is decompressed (the decompressed body at
  most ``HELIOTWIN_MAX_UPLOAD_BYTES``, else 413; a corrupt stream is a 400), any
  other encoding is a 415; a gzip body of more than :data:`GZIP_MAX_MEMBERS` members
  is a 413, and a gzip body to an operation that needs a token (its OpenAPI
  ``security``) is decompressed only after the token is found valid (401 first,
  :func:`backend.api.deps.authenticated_first`).
  A JSON body with a key given twice in one object is a 422.
  Paths given as ``own_body`` (logger ingest) pass untouched: their route checks the
  write token first and then reads the body by :func:`read_body`, the same rules, and
  checks repeated keys itself, in bulk.
- :func:`http_error`: FastAPI's HTTP-error answer, except that a 405 lists in
  ``Allow`` every method of the path (Starlette names only the first route's), and
  :class:`HeadAsGet` answers the HEAD that ``Allow`` names beside every GET.
- :func:`document_errors`: the OpenAPI's 422 body says what the service sends
  (``detail`` a message, or a list of ``{loc, msg, type}``).
"""

from __future__ import annotations

import functools
import re
import zlib
from collections.abc import AsyncIterator, Mapping
from typing import Any

import anyio
import orjson
from fastapi import HTTPException, Request
from fastapi.exception_handlers import http_exception_handler
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.requests import ClientDisconnect
from starlette.responses import Response
from starlette.routing import compile_path
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from backend.api.deps import authenticated_first
from backend.errors import InputError, bounded_detail, load_json_pairs, repeated_keys

_BODY_METHODS = frozenset(("POST", "PUT", "PATCH"))
_HTTP_METHODS = frozenset(("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS"))
_OFFLOAD_BYTES = 64 * 1024  # decompress bigger bodies in a worker thread


#: Most gzip members one body may hold. Several members come from concatenated files
#: (``cat a.gz b.gz``, a logger appending one member per batch): a week of one member
#: a minute is 10,080. Each member costs a decompressor, a few µs, so 10,000 stay
#: within tens of milliseconds; 400,000 empty ones (7.6 MiB) are an attack.
GZIP_MAX_MEMBERS = 10_000
_FEED_FIRST, _FEED_MAX = 256, 64 * 1024  # compressed bytes given to zlib at once


def gunzip(data: bytes, limit: int, max_members: int = GZIP_MAX_MEMBERS) -> bytes:
    """A gzip body (one or more members) decompressed: 413 past ``limit`` bytes out or past
    ``max_members`` members, 400 for data that is not gzip or ends early.

    Linear in the body: zlib gets a member's input in pieces that start at 256 bytes and
    double, so a member's end copies (``unused_data``) at most about what the member
    read, not the whole rest of the body as one ``decompress(rest)`` per member did.
    """
    view = memoryview(data)
    out: list[bytes] = []
    size = pos = members = 0
    while pos < len(view):
        members += 1
        if members > max_members:
            raise InputError(413, f"Content-Encoding gzip: more than {max_members} gzip "
                                  "members in one body; send one member (or a few)")
        d = zlib.decompressobj(wbits=31)
        feed = _FEED_FIRST
        while not d.eof:
            if pos >= len(view):
                raise InputError(400, "Content-Encoding gzip: the gzip stream is truncated")
            piece = view[pos:pos + feed]
            feed = min(2 * feed, _FEED_MAX)
            try:
                part = d.decompress(piece, limit + 1 - size)
            except zlib.error as exc:
                raise InputError(400, f"Content-Encoding gzip: the body is not gzip data "
                                      f"({exc})") from None
            size += len(part)
            if size > limit:  # also when zlib stopped at max_length with input left
                raise InputError(413, f"body over {limit} bytes once decompressed "
                                      "(HELIOTWIN_MAX_UPLOAD_BYTES): split the batch")
            out.append(part)
            pos += len(piece) - len(d.unused_data) - len(d.unconsumed_tail)
    return b"".join(out)


def _check_encoding(encoding: str) -> None:
    if encoding not in ("", "identity", "gzip"):
        raise InputError(415, f"Content-Encoding {encoding[:40]!r}: send the body as is "
                              "(identity) or gzip")


async def _bounded(chunks: AsyncIterator[bytes], limit: int) -> bytes:
    """The body's chunks joined; 413 as soon as they pass ``limit`` bytes."""
    parts: list[bytes] = []
    size = 0
    async for chunk in chunks:
        size += len(chunk)
        if size > limit:
            raise InputError(413, f"body over {limit} bytes (HELIOTWIN_MAX_UPLOAD_BYTES)")
        parts.append(chunk)
    return b"".join(parts)


async def _decoded(body: bytes, encoding: str, limit: int) -> bytes:
    if encoding != "gzip":
        return body
    if len(body) > _OFFLOAD_BYTES:
        return await anyio.to_thread.run_sync(gunzip, body, limit)
    return gunzip(body, limit)


async def read_body(request: Request, limit: int) -> bytes:
    """The body of a route that reads its own (``own_body`` of :class:`StrictBodies`),
    by the middleware's rules: 415 for an encoding other than identity or gzip, 413 past
    ``limit`` bytes (sent, announced or decompressed), 400 for corrupt gzip."""
    encoding = request.headers.get("content-encoding", "").strip().lower()
    _check_encoding(encoding)
    length = request.headers.get("content-length", "")
    if length.isdigit() and int(length) > limit:
        raise InputError(413, f"body of {length} bytes; the limit is {limit} bytes "
                              "(HELIOTWIN_MAX_UPLOAD_BYTES): split the batch")
    try:
        body = await _bounded(request.stream(), limit)
    except ClientDisconnect:  # nobody is left to answer; nothing was stored
        raise InputError(400, "the client hung up before the body ended") from None
    return await _decoded(body, encoding, limit)


def _answer(status: int, detail: Any, headers: Mapping[str, str] | None = None
            ) -> tuple[Message, Message]:
    body = orjson.dumps({"detail": detail})
    extra = [(k.lower().encode(), v.encode()) for k, v in (headers or {}).items()]
    return ({"type": "http.response.start", "status": status,
             "headers": [(b"content-type", b"application/json"),
                         (b"content-length", str(len(body)).encode()), *extra]},
            {"type": "http.response.body", "body": body})


class StrictBodies:
    """ASGI middleware: request encodings and repeated JSON keys (see the module docstring).

    A request with neither an encoding nor a JSON body to check passes untouched;
    the others are read whole (bounded), checked and replayed to the app.
    """

    def __init__(self, app: ASGIApp, own_body: re.Pattern[str] | None = None) -> None:
        self.app = app
        self.own_body = own_body

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if (scope["type"] != "http" or scope["method"] not in _BODY_METHODS
                or (self.own_body is not None and self.own_body.match(scope["path"]))):
            await self.app(scope, receive, send)
            return
        encoding = b""
        ctype = b""
        for k, v in scope["headers"]:
            if k == b"content-encoding":
                encoding = v.strip().lower()
            elif k == b"content-type":
                ctype = v.split(b";")[0].strip().lower()
        check_json = ctype == b"application/json" or ctype.endswith(b"+json")
        if encoding in (b"", b"identity") and not check_json:
            await self.app(scope, receive, send)
            return
        if encoding == b"gzip" and _needs_token(scope):
            try:  # the cheap check first: no anonymous caller makes us decompress
                await authenticated_first(scope["app"].state.ctx, _header(scope, b"authorization"))
            except HTTPException as exc:
                for message in _answer(exc.status_code, exc.detail, exc.headers):
                    await send(message)
                return
        try:
            body = await self._checked(scope, receive, encoding, check_json)
        except InputError as exc:
            for message in _answer(exc.status_code, exc.detail):
                await send(message)
            return
        except _Repeated as exc:
            for message in _answer(422, [{"loc": ["body", *exc.path], "type": "duplicate_key",
                                          "msg": f"key {exc.key[:40]!r} given twice in one "
                                                 "object"}]):
                await send(message)
            return
        if body is None:  # the client hung up
            return
        headers = [(k, v) for k, v in scope["headers"]
                   if k not in (b"content-encoding", b"content-length")]
        headers.append((b"content-length", str(len(body)).encode()))
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        await self.app({**scope, "headers": headers}, replay, send)

    @staticmethod
    async def _checked(scope: Scope, receive: Receive, encoding: bytes, check_json: bool
                       ) -> bytes | None:
        text = encoding.decode("latin-1")
        _check_encoding(text)
        limit = int(scope["app"].state.settings.server.max_upload_bytes)

        async def chunks() -> AsyncIterator[bytes]:
            more = True
            while more:
                message = await receive()
                if message["type"] == "http.disconnect":
                    raise ClientDisconnect
                more = message.get("more_body", False)
                yield message.get("body", b"")

        try:
            body = await _decoded(await _bounded(chunks(), limit), text, limit)
        except ClientDisconnect:
            return None
        if check_json and body:
            try:
                doc = load_json_pairs(body)
            except RecursionError:
                raise InputError(422, "body: JSON nested too deeply") from None
            except UnicodeDecodeError as exc:  # FastAPI would answer a bare 400
                raise InputError(422, f"body: JSON must be UTF-8 ({exc.reason} at byte "
                                      f"{exc.start})") from None
            except ValueError as exc:
                if "digits" in str(exc):  # Python reads integers of at most 4300 digits
                    raise InputError(422, "body: an integer of more than 4300 digits") from None
                return body  # invalid JSON: FastAPI reports where
            for path, key in repeated_keys(doc):
                raise _Repeated(path, key)
        return body


def _header(scope: Scope, name: bytes) -> str | None:
    for k, v in scope["headers"]:
        if k == name:
            return v.decode("latin-1")  # type: ignore[no-any-return]
    return None


#: the OpenAPI ``security`` of an operation that needs a token
_REQUIRED: list[dict[str, list[str]]] = [{"bearerAuth": []}]


def _needs_token(scope: Scope) -> bool:
    """Whether the operation this request reaches needs a token: its OpenAPI ``security``
    says so (``backend.api.security.declare_bearer``: one that answers 401 and does not
    declare the token optional)."""
    method = scope["method"].lower()
    matching = [(template.count("{"), ops)
                for template, ops in scope["app"].openapi().get("paths", {}).items()
                if _compiled(template).match(scope["path"]) and method in ops]
    fewest = min((n for n, _ in matching), default=0)
    return any(n == fewest and ops[method].get("security") == _REQUIRED
               for n, ops in matching)


@functools.lru_cache(maxsize=512)
def _compiled(template: str) -> re.Pattern[str]:
    return compile_path(template)[0]


class _Repeated(Exception):
    def __init__(self, path: tuple[str | int, ...], key: str) -> None:
        self.path, self.key = path, key


class HeadAsGet:
    """ASGI middleware: a HEAD request is answered as its GET would be, without the body
    (RFC 9110 §9.3.2). FastAPI's routes take only the methods they declare, so ``HEAD
    /healthz`` (``curl -I``, an uptime probe) was a 405 whose ``Allow`` named HEAD."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "HEAD":
            await self.app(scope, receive, send)
            return

        async def headers_only(message: Message) -> None:
            if message["type"] == "http.response.body":  # the length header stays the GET's
                message = {**message, "body": b""}
            await send(message)

        await self.app({**scope, "method": "GET"}, receive, headers_only)


def allowed_methods(request: Request, also: str = "") -> list[str]:
    """Every method the OpenAPI document gives this request's path, with HEAD beside GET,
    and those of ``also`` (an ``Allow`` value)."""
    methods = {m.strip().upper() for m in also.split(",") if m.strip()}
    matching = [(template.count("{"), ops)
                for template, ops in request.app.openapi().get("paths", {}).items()
                if compile_path(template)[0].match(request.url.path)]
    # a literal path (``/simulations/weather``) is its own resource, not ``/simulations/{run_id}``
    fewest = min((n for n, _ in matching), default=0)
    if matching:  # the document is the authority; starlette's Allow names one route only
        methods = set()
    for n, ops in matching:
        if n == fewest:
            methods |= {m.upper() for m in ops if m.upper() in _HTTP_METHODS}
    if "GET" in methods:
        methods.add("HEAD")
    return sorted(methods)


async def http_error(request: Request, exc: StarletteHTTPException) -> Response:
    """FastAPI's answer to an HTTP error, its message bounded (:func:`bounded_detail`); a
    405's ``Allow`` names every method of the path."""
    if exc.status_code != 405:
        detail = bounded_detail(exc.detail)
        if detail is not exc.detail:
            exc = StarletteHTTPException(exc.status_code, detail, exc.headers)
        return await http_exception_handler(request, exc)
    allow = allowed_methods(request, (exc.headers or {}).get("Allow", ""))
    body = orjson.dumps({"detail": f"method {request.method} is not allowed here; "
                                   f"allowed: {', '.join(allow)}"})
    return Response(body, status_code=405, media_type="application/json",
                    headers={**(exc.headers or {}), "Allow": ", ".join(allow)})


def document_errors(schema: dict[str, Any]) -> dict[str, Any]:
    """Make the OpenAPI 422 body honest: ``detail`` is a message or a list of problems."""
    comps = schema.get("components", {}).get("schemas", {})
    hve = comps.get("HTTPValidationError")
    if hve is not None:
        listed = hve.get("properties", {}).get("detail", {"type": "array", "items": {
            "$ref": "#/components/schemas/ValidationError"}})
        hve["properties"]["detail"] = {"anyOf": [
            {"type": "string", "description": "what was wrong, naming the field"}, listed]}
    return schema
