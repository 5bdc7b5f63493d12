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
script, on another port of the same host) that loads only the vendored
``plotly.min.js`` from the service and draws one chart of 1,440 points. The ratio says what the
dashboard costs on top of Plotly itself. Prints one Markdown section.

    .venv/bin/python benchmarks/bench_dashboard.py
"""

from __future__ import annotations

import contextlib
import http.server
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = os.environ.get("HELIOTWIN_CHROMIUM", "/usr/bin/chromium")
RUNS = 7
SITE = "tehuantepec"

BASELINE_HTML = """<!doctype html><html><head><meta charset="utf-8">
<script src="%s/vendor/plotly.min.js?v=%s"></script></head><body>
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


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


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


def serve_baseline(html: str) -> tuple[http.server.HTTPServer, str]:
    """The bare baseline page on a free port (no request routing: that would disable caching)."""
    body = html.encode()

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # noqa: N802 (http.server's name)
            self.send_response(200)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-cache")
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: object) -> None:
            pass

    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    return httpd, f"http://127.0.0.1:{httpd.server_address[1]}/baseline.html"


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


def main() -> int:
    import plotly
    from playwright.sync_api import sync_playwright

    if not Path(CHROMIUM).exists():
        log(f"Chromium not found at {CHROMIUM}")
        return 1
    with tempfile.TemporaryDirectory() as d:
        log("starting heliotwin serve with 28 back-filled days …")
        proc, url = start_server(Path(d))
        try:
            with sync_playwright() as pw:
                browser = pw.chromium.launch(
                    executable_path=CHROMIUM,
                    args=["--no-sandbox", "--disable-background-networking"])
                httpd, base_url = serve_baseline(BASELINE_HTML % (url, plotly.__version__))
                runs: dict[str, list[dict]] = {
                    k: [] for k in ("base", "dash", "base_warm", "dash_warm")}
                # one load first, so that the server's caches are as in steady use
                measure(browser, url + "/", "heliotwin:overview-loaded", False)
                for i in range(RUNS):
                    log(f"run {i + 1}/{RUNS}")
                    runs["base"].append(measure(browser, base_url, "heliotwin:first-chart", False))
                    runs["dash"].append(measure(browser, url + "/", "heliotwin:overview-loaded",
                                                False))
                runs["base_warm"].append(measure(browser, base_url, "heliotwin:first-chart", True))
                runs["dash_warm"].append(measure(browser, url + "/", "heliotwin:overview-loaded",
                                                 True))
                browser.close()
                httpd.shutdown()
        finally:
            proc.terminate()
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=15)
            if proc.poll() is None:
                proc.kill()
    b_first, d_first = median(runs["base"], "first"), median(runs["dash"], "first")
    d_loaded = median(runs["dash"], "loaded")
    b_bytes, d_bytes = median(runs["base"], "bytes"), median(runs["dash"], "bytes")
    d_warm = runs["dash_warm"][0]
    b_warm, d_warm = runs["base_warm"][0], runs["dash_warm"][0]
    load = os.getloadavg()[0]
    verdict = "meets" if d_first <= 1500 else "misses"
    rows = [
        ("Plotly loaded and run [ms]", "", f"{median(runs['dash'], 'plotly'):.0f}", ""),
        ("first chart drawn [ms]", f"{b_first:.0f}", f"{d_first:.0f}", f"{d_first / b_first:.2f}"),
        ("all charts, tiles and tables drawn [ms]", f"{b_first:.0f}", f"{d_loaded:.0f}",
         f"{d_loaded / b_first:.2f}"),
        ("transferred [kB]", f"{b_bytes / 1000:.0f}", f"{d_bytes / 1000:.0f}",
         f"{d_bytes / b_bytes:.2f}"),
        ("requests", str(runs["base"][0]["requests"]), str(runs["dash"][0]["requests"]), ""),
        ("warm cache (reload): first chart [ms]", f"{b_warm['first']:.0f}",
         f"{d_warm['first']:.0f}", f"{d_warm['first'] / b_warm['first']:.2f}"),
        ("warm cache (reload): transferred [kB]", f"{b_warm['bytes'] / 1000:.0f}",
         f"{d_warm['bytes'] / 1000:.0f}", ""),
    ]
    table = "\n".join(f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows)
    plotly_mb = runs["base"][0]["decoded"] / 1e6
    print(f"""## dashboard

Overview page (`/`, site `{SITE}`, today, 28 back-filled days) in headless Chromium on
localhost, a fresh browser context per load (cold cache), median of {RUNS} loads. Baseline:
a bare page that loads only the vendored `plotly.min.js` from the service and draws one
1,440-point chart. Times are `performance.mark`s, in ms after navigation start.

| figure | baseline (Plotly only) | dashboard | ratio |
|---|---|---|---|
{table}

Target: the first chart drawn ≤ 1,500 ms after navigation — {verdict} it ({d_first:.0f} ms).
Load average during the run: {load:.1f} on {os.cpu_count()} cores (shared with other work; the
bare Plotly page's time moves with it).
Plotly {plotly.__version__} travels gzip-compressed ({b_bytes / 1000:.0f} kB for
{plotly_mb:.1f} MB) with a one-year immutable cache header.""")
    return 0


if __name__ == "__main__":
    sys.exit(main())
