"""The dashboard: ``frontend/`` served at ``/`` and ``/static/``, Plotly at ``/vendor/``.

The dashboard is static HTML, CSS and JavaScript modules (no build step). Its
charts use Plotly.js, a partial bundle vendored in ``frontend/vendor/plotly/``
(plotly.js from npm with only the traces the pages draw; how it was built is in
its README), so the page needs no CDN, npm or internet at run time. Plotly is
served under a URL that carries its version and a hash of the file, with a
one-year immutable cache header, gzip-compressed once in memory (≈1.2 MB → ≈0.4 MB).

``create_app`` includes this router last, so its ``/`` never shadows the API.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import logging
from functools import lru_cache
from pathlib import Path

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import HTMLResponse, Response
from fastapi.staticfiles import StaticFiles

from sim.paths import checkout_root, package_dir

logger = logging.getLogger(__name__)


def _frontend_dir() -> Path:
    """The dashboard's files: package data ``backend/frontend/`` in an installed wheel (setup.py
    maps the top-level ``frontend/`` there), the checkout's ``frontend/`` otherwise."""
    root = checkout_root()
    return package_dir("backend", "frontend") if root is None else root / "frontend"


FRONTEND_DIR = _frontend_dir()
PLOTLY_DIR = FRONTEND_DIR / "vendor" / "plotly"
PLOTLY_JS = PLOTLY_DIR / "plotly.min.js"
VERSION_TOKEN = "__PLOTLY_VERSION__"
IMMUTABLE = "public, max-age=31536000, immutable"

router = APIRouter(include_in_schema=False)


class _RevalidatedStaticFiles(StaticFiles):
    """Static files that the browser revalidates (ETag/Last-Modified → 304).

    The dashboard's own files change with the code, so they are never cached
    blindly; a reload costs one 304 per file.
    """

    def file_response(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        response = super().file_response(*args, **kwargs)
        response.headers["Cache-Control"] = "no-cache"
        return response


@lru_cache(maxsize=1)
def _plotly_bytes() -> tuple[bytes, bytes, str]:
    """The Plotly bundle, its gzip encoding and a strong ETag (read once)."""
    raw = PLOTLY_JS.read_bytes()
    packed = gzip.compress(raw, compresslevel=9, mtime=0)
    etag = '"' + hashlib.sha256(raw).hexdigest()[:32] + '"'
    logger.info("plotly.min.js: %d bytes, %d gzipped", len(raw), len(packed))
    return raw, packed, etag


@lru_cache(maxsize=1)
def plotly_version() -> str:
    """``<plotly.js version>-<8 hex of the file's sha256>``: the cache-busting token in its URL.

    The version comes from ``frontend/vendor/plotly/package.json`` (what the bundle
    was built from); the hash changes when the bundle is rebuilt with other traces.
    """
    try:
        pinned = json.loads((PLOTLY_DIR / "package.json").read_text(encoding="utf-8"))
        version = str(pinned["dependencies"]["plotly.js"])
        digest = hashlib.sha256(PLOTLY_JS.read_bytes()).hexdigest()[:8]
    except (OSError, ValueError, KeyError) as exc:
        logger.warning("vendored Plotly not readable in %s: %s", PLOTLY_DIR, exc)
        return "missing"
    return f"{version}-{digest}"


@router.get("/", response_class=HTMLResponse)
def dashboard_index() -> HTMLResponse:
    """The dashboard page (the Plotly URL carries the vendored bundle's version)."""
    index = FRONTEND_DIR / "index.html"
    if not index.is_file():
        raise HTTPException(status_code=404, detail=f"dashboard not found at {index}")
    html = index.read_text(encoding="utf-8").replace(VERSION_TOKEN, plotly_version())
    return HTMLResponse(html, headers={"Cache-Control": "no-cache"})


@router.get("/vendor/plotly.min.js")
def plotly_bundle(request: Request) -> Response:
    """The vendored Plotly.js bundle, gzip when accepted (any ``?v=`` is the same file)."""
    if not PLOTLY_JS.is_file():
        raise HTTPException(status_code=404, detail=f"plotly bundle missing at {PLOTLY_JS}")
    raw, packed, etag = _plotly_bytes()
    headers = {"Cache-Control": IMMUTABLE, "ETag": etag, "Vary": "Accept-Encoding",
               # lets a page on another port (the speed benchmark's baseline) see the bytes
               "Timing-Allow-Origin": "*"}
    if request.headers.get("if-none-match") == etag:
        return Response(status_code=304, headers=headers)
    if "gzip" in request.headers.get("accept-encoding", ""):
        headers["Content-Encoding"] = "gzip"
        return Response(packed, media_type="text/javascript", headers=headers)
    return Response(raw, media_type="text/javascript", headers=headers)


if FRONTEND_DIR.is_dir():
    router.mount("/static", _RevalidatedStaticFiles(directory=FRONTEND_DIR), name="dashboard")
else:  # a wheel without the frontend still serves the API
    logger.warning("frontend directory %s not found; dashboard disabled", FRONTEND_DIR)
