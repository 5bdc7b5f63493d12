"""The dashboard: ``frontend/`` served at ``/`` and ``/static/``, Plotly at ``/vendor/``.

The dashboard is static HTML, CSS and JavaScript modules (no build step). Its
charts use Plotly.js, taken from the ``plotly`` Python package that is already a
dependency (``plotly/package_data/plotly.min.js``), so the page needs no CDN and
works without internet. Plotly is served under a versioned URL with a one-year,
immutable cache header and gzip-compressed once in memory (≈4.8 MB → ≈1.4 MB).

``create_app`` includes this router last, so its ``/`` never shadows the API.
"""

from __future__ import annotations

import gzip
import hashlib
import logging
from functools import lru_cache
from pathlib import Path

import plotly
from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import HTMLResponse, Response
from fastapi.staticfiles import StaticFiles

logger = logging.getLogger(__name__)

FRONTEND_DIR = Path(__file__).resolve().parents[3] / "frontend"
PLOTLY_JS = Path(plotly.__file__).resolve().parent / "package_data" / "plotly.min.js"
PLOTLY_VERSION = plotly.__version__
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
    packed = gzip.compress(raw, compresslevel=6, mtime=0)
    etag = '"' + hashlib.sha256(raw).hexdigest()[:32] + '"'
    logger.info("plotly.min.js %s: %d bytes, %d gzipped", PLOTLY_VERSION, len(raw), len(packed))
    return raw, packed, etag


@router.get("/", response_class=HTMLResponse)
def dashboard_index() -> HTMLResponse:
    """The dashboard page (the Plotly URL carries the installed version)."""
    index = FRONTEND_DIR / "index.html"
    if not index.is_file():
        raise HTTPException(status_code=404, detail=f"dashboard not found at {index}")
    html = index.read_text(encoding="utf-8").replace(VERSION_TOKEN, PLOTLY_VERSION)
    return HTMLResponse(html, headers={"Cache-Control": "no-cache"})


@router.get("/vendor/plotly.min.js")
def plotly_bundle(request: Request) -> Response:
    """Plotly.js from the installed ``plotly`` package, gzip when accepted."""
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
