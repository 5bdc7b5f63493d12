"""The dashboard router on its own (no browser): page, static files, vendored Plotly.

Checks what a browser relies on: the page links the Plotly version that is
installed, every module and stylesheet it references is served, Plotly comes
gzip-compressed with a long immutable cache and answers 304 to its ETag, and
the bytes are the installed package's own file.
"""

from __future__ import annotations

import gzip
import re
from pathlib import Path

import plotly
import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from backend.api.routes import dashboard

ROOT = Path(__file__).resolve().parents[2]
PLOTLY_FILE = Path(plotly.__file__).parent / "package_data" / "plotly.min.js"


@pytest.fixture(scope="module")
def client() -> TestClient:
    app = FastAPI()
    app.include_router(dashboard.router)
    return TestClient(app)


def test_index_links_the_installed_plotly_and_existing_files(client: TestClient) -> None:
    r = client.get("/")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    html = r.text
    assert f"/vendor/plotly.min.js?v={plotly.__version__}" in html
    assert "__PLOTLY_VERSION__" not in html
    assert "cdn" not in html.lower() and "https://" not in html, "no run-time download"
    refs = re.findall(r'(?:href|src)="(/static/[^"]+)"', html)
    assert refs, "the page references no static files"
    for ref in refs:
        assert client.get(ref).status_code == 200, ref


def test_every_module_import_resolves(client: TestClient) -> None:
    js = sorted((ROOT / "frontend" / "js").glob("*.js"))
    assert js
    for path in js:
        for dep in re.findall(r'from "\./([\w.-]+)"', path.read_text()):
            assert client.get(f"/static/js/{dep}").status_code == 200, f"{path.name} → {dep}"


def test_plotly_is_gzipped_cached_and_the_package_file(client: TestClient) -> None:
    r = client.get("/vendor/plotly.min.js", headers={"Accept-Encoding": "gzip"})
    assert r.status_code == 200
    assert r.headers["content-encoding"] == "gzip"
    cache = r.headers["cache-control"]
    assert "immutable" in cache and "max-age=31536000" in cache
    raw = PLOTLY_FILE.read_bytes()
    assert r.content == raw  # httpx decodes gzip: the same bytes as the package's file
    assert int(r.headers["content-length"]) < len(gzip.compress(raw, 1))
    again = client.get("/vendor/plotly.min.js", headers={"If-None-Match": r.headers["etag"]})
    assert again.status_code == 304 and not again.content


def test_plotly_without_gzip(client: TestClient) -> None:
    r = client.get("/vendor/plotly.min.js", headers={"Accept-Encoding": "identity"})
    assert r.status_code == 200 and "content-encoding" not in r.headers
    assert len(r.content) == PLOTLY_FILE.stat().st_size


def test_static_files_revalidate(client: TestClient) -> None:
    r = client.get("/static/js/main.js")
    assert r.status_code == 200 and r.headers["cache-control"] == "no-cache"
    assert r.headers["content-type"].startswith(("text/javascript", "application/javascript"))
    assert client.get("/static/js/main.js",
                      headers={"If-None-Match": r.headers["etag"]}).status_code == 304
    assert client.get("/static/js/nope.js").status_code == 404
    assert client.get("/static/%2e%2e/backend/app.py").status_code == 404  # no way out of frontend/
