"""Dashboard speed: the overview's first chart after navigation, and the bytes it costs.

Starts ``heliotwin serve`` on free ports with a temporary SQLite file (the demo
logger back-fills a few days, as at ``make run``), then loads the overview in
Debian's headless Chromium several times, each in a fresh browser context
(cold cache) and once more with a warm cache. In the browser it reads

- ``heliotwin:first-chart`` — a ``performance.mark`` the dashboard sets when its
  first Plotly chart has been drawn, in ms after navigation start;
- ``heliotwin:plotly-ready`` — when the Plotly script has run (its start-up is
  most of the first chart's time);
- ``heliotwin:overview-loaded`` — every chart, table and tile drawn;
- the page's total transferred bytes (navigation + resource timing
  ``transferSize``).

Baseline, in the same run: a bare page (served by a tiny HTTP server in this
script, on another port of the same host) that loads only the vendored Plotly
bundle (``frontend/vendor/plotly/``) from the service and draws one chart of
1,440 points. The ratio says what the dashboard costs on top of Plotly itself.
For reference, when the ``plotly`` Python package is installed, the same bare
page with its full ``plotly.min.js`` (served gzip-compressed by this script): what
the dashboard loaded before the partial bundle. Prints one Markdown section.

    .venv/bin/python benchmarks/bench_dashboard.py
"""

from __future__ import annotations

import contextlib
import gzip
import http.server
import os
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
from _common import Figures, free_port, log  # noqa: E402  (bench scripts run from this folder)

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = os.environ.get("HELIOTWIN_CHROMIUM", "/usr/bin/chromium")
RUNS = 7
SITE = "tehuantepec"

BASELINE_HTML = """<!doctype html><html><head><meta charset="utf-8">
<script src="%s"></script></head><body>
<div id="c" style="width:900px;height:380px"></div>
<script>
const x = [], y = [];
for (let i = 0; i < 1440; i++) {
  x.push(i);
  y.push(Math.max(0, Math.sin(Math.PI * (i - 390) / 720)) * 800);
}
Plotly.newPlot("c", [{x, y, type: "scatter", mode: "lines"}], {margin: {t: 10}}).then(() => {
  performance.mark("heliotwin:first-chart");
  performance.mark("heliotwin:overview-loaded");
});
</script></body></html>"""

MEASURE_JS = """() => {
  const t = (n) => {
    const e = performance.getEntriesByName(n);
    return e.length ? e[0].startTime : null;
  };
  const nav = performance.getEntriesByType("navigation")[0];
  let bytes = nav ? nav.transferSize : 0, decoded = nav ? nav.decodedBodySize : 0, n = 1;
  for (const r of performance.getEntriesByType("resource")) {
    bytes += r.transferSize; decoded += r.decodedBodySize; n++;
  }
  return {first: t("heliotwin:first-chart"), loaded: t("heliotwin:overview-loaded"),
          plotly: t("heliotwin:plotly-ready"), bytes, decoded, requests: n};
}"""


def _has_data(client: httpx.Client) -> bool:
    """Whether the demo logger has back-filled yesterday's readings."""
    r = client.get(f"/api/v1/sites/{SITE}/energy",
                   params={"start": "2000-01-01", "end": "2100-01-01", "interval": "month"})
    if r.status_code != 200:
        return False
    return any((row["arrays"].get("fixed") or {}).get("measured_wh") for row in r.json()["rows"])


def start_server(tmp: Path) -> tuple[subprocess.Popen, str]:
    port, viser_port = free_port(), free_port()
    env = {**os.environ, "HELIOTWIN_DATABASE_URL": f"sqlite:///{tmp / 'bench.sqlite'}",
           "HELIOTWIN_DEMO_BACKFILL_DAYS": "28"}
    exe = Path(sys.executable).with_name("heliotwin")
    proc = subprocess.Popen(
        [str(exe), "serve", "--host", "127.0.0.1", "--port", str(port),
         "--viser-port", str(viser_port)],
        cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=open(tmp / "serve.log", "wb"),
    )
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 120
    with httpx.Client(base_url=url) as c:
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                raise RuntimeError((tmp / "serve.log").read_text()[-2000:])
            with contextlib.suppress(httpx.HTTPError):
                if c.get("/healthz").status_code == 200:
                    if _has_data(c):
                        return proc, url
            time.sleep(0.5)
    raise RuntimeError("server did not come up with data in 120 s")


def full_plotly() -> tuple[Path, str] | None:
    """The ``plotly`` Python package's full ``plotly.min.js`` and its version, if installed."""
    try:
        import plotly
    except ImportError:
        return None
    path = Path(plotly.__file__).parent / "package_data" / "plotly.min.js"
    return (path, plotly.__version__) if path.is_file() else None


def serve_baseline(plotly_url: str, full_js: Path | None) -> tuple[http.server.HTTPServer, str]:
    """The bare pages on a free port: ``/baseline.html`` and, with ``full_js``, ``/full.html``.

    ``/full.js`` is ``full_js`` gzip-compressed with a one-year immutable cache, as
    the service used to serve it.
    """
    pages = {"/baseline.html": (BASELINE_HTML % plotly_url).encode(),
             "/full.html": (BASELINE_HTML % "/full.js").encode()}
    packed = gzip.compress(full_js.read_bytes(), 6, mtime=0) if full_js else b""

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # noqa: N802 (http.server's name)
            if self.path == "/full.js" and packed:
                body, kind = packed, "text/javascript"
                cache = "public, max-age=31536000, immutable"
            elif self.path in pages:
                body, kind, cache = pages[self.path], "text/html; charset=utf-8", "no-cache"
            else:
                self.send_error(404)
                return
            self.send_response(200)
            self.send_header("Content-Type", kind)
            if body is packed:
                self.send_header("Content-Encoding", "gzip")
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", cache)
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: object) -> None:
            pass

    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    return httpd, f"http://127.0.0.1:{httpd.server_address[1]}"


def measure(browser, url: str, wait_mark: str, warm: bool) -> dict:
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    page = context.new_page()
    page.goto(url)
    page.wait_for_function(f"() => performance.getEntriesByName('{wait_mark}').length > 0",
                           timeout=30_000)
    if warm:
        page.reload()
        page.wait_for_function(f"() => performance.getEntriesByName('{wait_mark}').length > 0",
                               timeout=30_000)
    result = page.evaluate(MEASURE_JS)
    context.close()
    return result


def median(rows: list[dict], key: str) -> float:
    return statistics.median(r[key] for r in rows if r[key] is not None)


def worst(rows: list[dict], key: str) -> float:
    return max(r[key] for r in rows if r[key] is not None)


def plotly_url(service: str) -> str:
    """The versioned Plotly URL that the dashboard page links (absolute)."""
    html = httpx.get(service + "/").text
    found = re.search(r'href="(/vendor/plotly\.min\.js\?v=[^"]+)"', html)
    if not found:
        raise RuntimeError("the dashboard page links no /vendor/plotly.min.js")
    return service + found.group(1)


def main() -> int:
    from playwright.sync_api import sync_playwright

    if not Path(CHROMIUM).exists():
        log(f"Chromium not found at {CHROMIUM}")
        return 1
    full = full_plotly()
    load_start = os.getloadavg()
    with tempfile.TemporaryDirectory() as d:
        log("starting heliotwin serve with 28 back-filled days …")
        proc, url = start_server(Path(d))
        try:
            vendored = plotly_url(url)
            with sync_playwright() as pw:
                browser = pw.chromium.launch(
                    executable_path=CHROMIUM,
                    args=["--no-sandbox", "--disable-background-networking"])
                httpd, bare = serve_baseline(vendored, full[0] if full else None)
                kinds = ("base", "dash", "full") if full else ("base", "dash")
                pages = {"base": bare + "/baseline.html", "full": bare + "/full.html",
                         "dash": url + "/"}
                marks = {"base": "heliotwin:first-chart", "full": "heliotwin:first-chart",
                         "dash": "heliotwin:overview-loaded"}
                runs: dict[str, list[dict]] = {k: [] for k in kinds}
                # one load first, so that the server's caches are as in steady use
                measure(browser, url + "/", "heliotwin:overview-loaded", False)
                for i in range(RUNS):
                    log(f"run {i + 1}/{RUNS}")
                    for k in kinds:  # interleaved: a change in the machine's load hits all alike
                        runs[k].append(measure(browser, pages[k], marks[k], False))
                warm = {k: measure(browser, pages[k], marks[k], True) for k in kinds}
                browser.close()
                httpd.shutdown()
        finally:
            proc.terminate()
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=15)
            if proc.poll() is None:
                proc.kill()
    load_end = os.getloadavg()
    base, dash = runs["base"], runs["dash"]
    b_first, d_first = median(base, "first"), median(dash, "first")
    d_worst = worst(dash, "first")
    d_loaded = median(dash, "loaded")
    b_bytes, d_bytes = median(base, "bytes"), median(dash, "bytes")
    fig = Figures("dashboard")
    first = fig.add("first_chart_ms", d_first, "ms", f"{d_first:.0f}", "≤ 1,500 ms",
                    d_first <= 1500)
    worst_first = fig.add("first_chart_worst_ms", d_worst, "ms", f"{d_worst:.0f}",
                          "≤ 1,500 ms", d_worst <= 1500)
    loaded = fig.add("overview_loaded_ms", d_loaded, "ms", f"{d_loaded:.0f}")
    kb = fig.add("transferred_kb", d_bytes / 1000, "kB", f"{d_bytes / 1000:.0f}")
    rows = [
        ("Plotly loaded and run [ms]", "", f"{median(dash, 'plotly'):.0f}", ""),
        ("first chart drawn [ms]", f"{b_first:.0f}", first, f"{d_first / b_first:.2f}"),
        (f"first chart drawn, slowest of {RUNS} [ms]", f"{worst(base, 'first'):.0f}",
         worst_first, f"{d_worst / worst(base, 'first'):.2f}"),
        ("all charts, tiles and tables drawn [ms]", f"{b_first:.0f}", loaded,
         f"{d_loaded / b_first:.2f}"),
        ("transferred [kB]", f"{b_bytes / 1000:.0f}", kb,
         f"{d_bytes / b_bytes:.2f}"),
        ("requests", str(base[0]["requests"]), str(dash[0]["requests"]), ""),
        ("warm cache (reload): first chart [ms]", f"{warm['base']['first']:.0f}",
         f"{warm['dash']['first']:.0f}", f"{warm['dash']['first'] / warm['base']['first']:.2f}"),
        ("warm cache (reload): transferred [kB]", f"{warm['base']['bytes'] / 1000:.0f}",
         f"{warm['dash']['bytes'] / 1000:.0f}", ""),
    ]
    table = "\n".join(f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows)
    bundle_mb = base[0]["decoded"] / 1e6
    reference = ""
    if full:
        f_first, f_worst = median(runs["full"], "first"), worst(runs["full"], "first")
        f_mb, f_kb = runs["full"][0]["decoded"] / 1e6, median(runs["full"], "bytes") / 1000
        reference = f"""
For reference, the same bare page with the full Plotly bundle (`plotly` {full[1]}'s
`plotly.min.js`, {f_mb:.1f} MB, {f_kb:.0f} kB gzip), which the dashboard loaded
before: first chart {f_first:.0f} ms (slowest {f_worst:.0f} ms), {f_first / b_first:.1f}× the
partial bundle's; warm reload {warm['full']['first']:.0f} ms."""
    print(f"""## dashboard

Overview page (`/`, site `{SITE}`, today, 28 back-filled days) in headless Chromium on
localhost, a fresh browser context per load (cold cache), median of {RUNS} loads. Baseline:
a bare page that loads only the vendored Plotly bundle from the service and draws one
1,440-point chart. Times are `performance.mark`s, in ms after navigation start.

| figure | baseline (Plotly only) | dashboard | ratio |
|---|---|---|---|
{table}

Target: the first chart drawn ≤ 1,500 ms after navigation — median: {fig.verdict("first_chart_ms")},
slowest of {RUNS}: {fig.verdict("first_chart_worst_ms")}.
Load average (1 min) {load_start[0]:.1f} at the start and {load_end[0]:.1f} at the end, on
{os.cpu_count()} cores shared with other work (the bare page's time moves with it).
Plotly is the vendored partial bundle (`frontend/vendor/plotly/`: core + scatter, bar,
scatterpolar; {bundle_mb:.2f} MB, {b_bytes / 1000:.0f} kB gzip) with a one-year immutable
cache header.{reference}""")
    fig.write()
    return 0


if __name__ == "__main__":
    sys.exit(main())
