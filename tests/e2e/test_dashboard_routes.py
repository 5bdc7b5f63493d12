"""The dashboard router on its own (no browser): page, static files, vendored Plotly.

Checks what a browser relies on: the page links the vendored Plotly bundle under
a URL carrying its version and hash, every module and stylesheet it references
is served, Plotly comes gzip-compressed with a long immutable cache and answers
304 to its ETag, the bytes are the vendored file, and that file holds every
trace type the pages draw.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import re
from pathlib import Path

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from backend.api.routes import dashboard

ROOT = Path(__file__).resolve().parents[2]
VENDOR = ROOT / "frontend" / "vendor" / "plotly"
PLOTLY_FILE = VENDOR / "plotly.min.js"


@pytest.fixture(scope="module")
def client() -> TestClient:
    app = FastAPI()
    app.include_router(dashboard.router)
    return TestClient(app)


def test_index_links_the_vendored_plotly_and_existing_files(client: TestClient) -> None:
    r = client.get("/")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    html = r.text
    version = json.loads((VENDOR / "package.json").read_text())["dependencies"]["plotly.js"]
    digest = hashlib.sha256(PLOTLY_FILE.read_bytes()).hexdigest()[:8]
    assert f"/vendor/plotly.min.js?v={version}-{digest}" in html
    banner = PLOTLY_FILE.read_text()[:200]
    assert f"plotly.js v{version}," in banner, "package.json matches the build"
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


def test_plotly_is_gzipped_cached_and_the_vendored_file(client: TestClient) -> None:
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


def test_the_bundle_holds_every_trace_type_the_pages_draw() -> None:
    """A trace type missing from the partial bundle would not be drawn: compare with the code."""
    used = set()
    for path in (ROOT / "frontend" / "js").glob("*.js"):
        used |= set(re.findall(r'type: "(scatter\w*|bar\w*|pie|box|violin|heatmap\w*|histogram\w*|'
                               r'contour\w*|surface|mesh3d|scatter3d|candlestick|ohlc|waterfall|'
                               r'funnel\w*|sunburst|treemap|sankey|indicator|table|image)"',
                               path.read_text()))
    assert {"scatter", "bar", "scatterpolar"} <= used, used
    entry = (VENDOR / "entry.js").read_text()
    bundled = {"scatter"} | set(re.findall(r'require\("plotly\.js/lib/(\w+)"\)', entry)) - {"core"}
    missing = sorted(used - bundled)
    assert not missing, f"add {missing} to frontend/vendor/plotly/entry.js and rebuild"
    for name in ("LICENSE", "README.md", "build.sh", "package-lock.json"):
        assert (VENDOR / name).is_file(), name
