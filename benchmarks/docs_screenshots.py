"""Retake the dashboard screenshots of the docs from a running service with demo data.

Starts ``heliotwin serve`` on free ports with a throw-away SQLite file, the demo logger
back-filling a week (as ``make run`` does), waits until the back-fill reached the present,
then opens each page in Debian's Chromium (Playwright, as ``tests/e2e/conftest.py``) and
waits for the page's own "loaded" markers (``body[data-overview-loaded]``,
``…-weather``, ``…-alerts-loaded``, ``…-report-loaded``, ``…-plant-loaded``,
``…-sweep-loaded``, the charts' ``data-points``) before each screenshot, so that no card
is caught empty or "loading":

- ``docs/overview.png`` — the Overview of yesterday (a whole back-filled day), full page,
  1400 px wide, with the diagnosis and report cards computed;
- ``docs/sky-camera.jpg`` — the Sky camera page after a fisheye calibration fitted on the
  six real Wettermast frames of ``tests/data/real-sky`` and a detection on each (JPEG);
- ``docs/plant.png`` — the Plant page, Peñarroya on 21 December 2021, down to its charts;
- ``docs/plant-sweep.png`` — the page's sweep panel after a small sweep (3 layouts × 5
  GCRs × 2 strategies at an hour's step: a minute or two), the shade of its densest
  sun-tracking case.

    .venv/bin/python benchmarks/docs_screenshots.py            # all four
    .venv/bin/python benchmarks/docs_screenshots.py overview   # some: overview sky plant sweep
    .venv/bin/python benchmarks/docs_screenshots.py --port 8121 --viser-port 8131

``docs/twin3d.png``, ``docs/twin3d-plant.png``, ``docs/pointing.png`` and
``docs/plant-polygon.png`` come from the e2e tests' artefacts (``test-artifacts/``).
Look at every image before committing it: the data are the demo logger's simulated week,
so the pictures change from run to run.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime as dt
import io
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from zoneinfo import ZoneInfo

import httpx
from _common import free_port, heliotwin_cmd  # (bench scripts run from this folder)

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
REAL_SKY = ROOT / "tests" / "data" / "real-sky"
CHROMIUM = Path(os.environ.get("HELIOTWIN_CHROMIUM", "/usr/bin/chromium"))
CHROMIUM_ARGS = ["--no-sandbox", "--disable-background-networking",
                 "--use-gl=swiftshader", "--enable-unsafe-swiftshader"]
SITE_ID = "tehuantepec"
BACKFILL_DAYS = 7
WIDTH = 1400  # the width of the docs' dashboard pictures
SKY_WIDTH = 1050  # sky-camera.jpg: taken at WIDTH, scaled down
WETTERMAST = (53.519917, 10.105139)  # the Wettermast Hamburg roof (tests/data/real-sky/README.md)
PAGES = ("overview", "sky", "plant", "sweep")


def _wait(what: str, ok, timeout_s: float, proc: subprocess.Popen, log: Path) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"heliotwin serve exited {proc.returncode}:\n"
                               f"{log.read_text()[-3000:]}")
        with contextlib.suppress(httpx.HTTPError):
            if ok():
                return
        time.sleep(0.5)
    raise RuntimeError(f"{what} not within {timeout_s:.0f} s:\n{log.read_text()[-3000:]}")


@contextlib.contextmanager
def serve(tmp: Path, port: int = 0, viser_port: int = 0) -> Iterator[str]:
    """``heliotwin serve`` with the demo logger back-filling ``BACKFILL_DAYS``; its URL once
    the back-fill reached the present for both arrays (ports 0: free ones)."""
    port, viser_port = port or free_port(), viser_port or free_port()
    env = {**os.environ, "HELIOTWIN_DATABASE_URL": f"sqlite:///{tmp / 'heliotwin.sqlite'}",
           "HELIOTWIN_SITES_DIR": str(tmp / "user-sites"),
           "HELIOTWIN_DEMO_BACKFILL_DAYS": str(BACKFILL_DAYS), "PYTHONUNBUFFERED": "1"}
    log = tmp / "serve.log"
    with open(log, "wb") as out:
        proc = subprocess.Popen([*heliotwin_cmd(), "serve", "--port", str(port),
                                 "--viser-port", str(viser_port)],
                                cwd=ROOT, env=env, stdout=out, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    try:
        with httpx.Client(base_url=url, timeout=30) as client:
            _wait("/healthz", lambda: client.get("/healthz").status_code == 200, 90, proc, log)

            def backfilled() -> bool:
                r = client.get(f"/api/v1/sites/{SITE_ID}/status")
                ages = [a.get("age_s") for a in r.json().get("arrays", {}).values()]
                return bool(ages) and all(a is not None and a < 3600 for a in ages)

            _wait("the demo logger's back-fill", backfilled, 600, proc, log)
        print(f"service on {url} (log {log})", file=sys.stderr)
        yield url
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)


def _points(page, chart: str) -> str:  # type: ignore[no-untyped-def]
    return f"() => +(document.getElementById('{chart}').dataset.points || 0) > 0"


def overview(browser, url: str) -> None:  # type: ignore[no-untyped-def]
    tz = ZoneInfo(httpx.get(f"{url}/api/v1/sites/{SITE_ID}").json()["timezone"])
    day = (dt.datetime.now(tz).date() - dt.timedelta(days=1)).isoformat()
    page = browser.new_page(viewport={"width": WIDTH, "height": 1000})
    page.set_default_timeout(180_000)
    page.goto(f"{url}/#overview?site={SITE_ID}&day={day}")
    page.wait_for_selector(f'body[data-overview-loaded="{SITE_ID}/{day}"]')
    page.wait_for_selector(f'body[data-overview-weather="{SITE_ID}/{day}"]')
    page.wait_for_selector(f'body[data-alerts-loaded="{SITE_ID}"]')
    for chart in ("chart-power", "chart-daily", "chart-cumulative"):
        page.wait_for_function(_points(page, chart))
    # the diagnosis runs when its card scrolls into view; the report loads with the page
    page.locator("#diagnosis-card").scroll_into_view_if_needed()
    page.wait_for_function(_points(page, "chart-diagnosis"))
    page.wait_for_function(_points(page, "chart-pointing"))
    page.wait_for_selector("body[data-report-loaded]")
    page.evaluate("() => window.scrollTo(0, 0)")
    page.wait_for_timeout(500)  # Plotly's transitions
    page.screenshot(path=str(DOCS / "overview.png"), full_page=True)
    page.close()


def sky(browser, url: str) -> None:  # type: ignore[no-untyped-def]
    from PIL import Image

    frames = sorted(REAL_SKY.glob("Wettermast_*.jpg"))
    assert len(frames) == 6, frames
    page = browser.new_page(viewport={"width": WIDTH, "height": 1000})  # three frames a row
    page.set_default_timeout(120_000)
    page.goto(f"{url}/#sky")
    page.wait_for_selector("#sky-form")
    page.select_option("#sky-place", "coords")
    page.fill('#sky-coords [name="latitude_deg"]', str(WETTERMAST[0]))
    page.fill('#sky-coords [name="longitude_deg"]', str(WETTERMAST[1]))
    page.set_input_files("#sky-files", [str(f) for f in frames])
    page.wait_for_function("() => [...document.querySelectorAll('[data-testid=sky-row-zone]')]"
                           ".every(z => z.textContent.includes('from the file name'))")
    page.fill("#sky-calibration-name", "Wettermast roof, six frames")
    page.click("#sky-calibrate")
    page.wait_for_selector("[data-testid=calibration-result]")
    page.click("#sky-detect")
    page.wait_for_selector(f"[data-testid=sky-result] >> nth={len(frames) - 1}")
    page.wait_for_function(_points(page, "chart-sky-track"))
    page.wait_for_function(_points(page, "chart-sky-error"))
    page.wait_for_function("() => !document.getElementById('sky-status').textContent"
                           ".endsWith('…')")
    page.wait_for_timeout(500)
    png = page.screenshot(full_page=True)
    page.close()
    img = Image.open(io.BytesIO(png)).convert("RGB")
    img = img.resize((SKY_WIDTH, round(img.height * SKY_WIDTH / img.width)), Image.LANCZOS)
    img.save(DOCS / "sky-camera.jpg", quality=85, optimize=True)


def _plant_page(browser, url: str):  # type: ignore[no-untyped-def]
    page = browser.new_page(viewport={"width": WIDTH, "height": 1000})
    page.set_default_timeout(240_000)
    page.goto(f"{url}/#plant?day=2021-12-21")
    page.wait_for_selector('body[data-plant-loaded="penarroya/2021-12-21"]')
    return page


def plant(browser, url: str) -> None:  # type: ignore[no-untyped-def]
    page = _plant_page(browser, url)
    # a morning time with some shade, as in plants.md's text
    n = int(page.get_attribute("#plant-time", "max") or 0)
    page.fill("#plant-time", str(max(n // 8, 1)))
    page.dispatch_event("#plant-time", "input")
    page.wait_for_function(
        "() => { const i = document.getElementById('plant-sky-map');"
        " return i.complete && i.naturalWidth > 0 && i.dataset.loaded === i.dataset.time; }")
    page.wait_for_function("() => document.getElementById('plant-chosen').textContent"
                           ".includes('collectors shaded')")
    for chart in ("chart-plant-layout", "chart-plant-shade", "chart-plant-strategies"):
        page.wait_for_function(_points(page, chart))
    page.wait_for_timeout(500)
    # down to the day's charts: the sweep panel below is empty until a sweep ran
    bottom = page.evaluate("() => { const g = document.querySelectorAll('#page-plant > .grid');"
                           " return g[1].getBoundingClientRect().bottom + window.scrollY; }")
    page.screenshot(path=str(DOCS / "plant.png"), full_page=True,
                    clip={"x": 0, "y": 0, "width": WIDTH, "height": int(bottom) + 16})
    page.close()


def sweep(browser, url: str) -> None:  # type: ignore[no-untyped-def]
    page = _plant_page(browser, url)
    page.fill("#sweep-layouts", "square,diagonal,hexagonal_e_w")
    page.fill("#sweep-gcr", "0.15:0.35:0.05")
    page.fill("#sweep-strategies", "sun,backtrack")
    page.fill("#sweep-step", "3600")
    started = time.monotonic()
    page.click("#sweep-run")
    page.wait_for_selector("body[data-sweep-loaded]", timeout=600_000)
    for chart in ("chart-sweep-energy", "chart-sweep-tradeoff", "chart-sweep-shade"):
        page.wait_for_function(_points(page, chart))
    print(f"sweep: {time.monotonic() - started:.0f} s", file=sys.stderr)
    # the densest sun-tracking case: backtracking's shade is nil, a flat line
    case = page.evaluate("() => [...document.querySelectorAll('#sweep-case option')]"
                         ".map(o => [o.value, o.textContent])"
                         ".filter(([, t]) => t.endsWith(' sun')).pop()[0]")
    page.select_option("#sweep-case", case)
    page.wait_for_function("() => (document.getElementById('chart-sweep-shade').data || [])"
                           ".some(t => (t.y || []).some(v => v > 0) && t.name !== undefined"
                           " && !t.name.startsWith('sun'))")
    page.evaluate("() => document.activeElement && document.activeElement.blur()")
    page.wait_for_timeout(500)
    box = page.evaluate(
        "() => { const s = document.getElementById('page-plant');"
        " const h = [...s.children].find(e => e.tagName === 'H2');"
        " const last = s.lastElementChild;"
        " return [h.getBoundingClientRect().top + window.scrollY,"
        "         last.getBoundingClientRect().bottom + window.scrollY]; }")
    top, bottom = int(box[0]) - 12, int(box[1]) + 16
    page.screenshot(path=str(DOCS / "plant-sweep.png"), full_page=True,
                    clip={"x": 0, "y": top, "width": WIDTH, "height": bottom - top})
    page.close()


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("pages", nargs="*",
                        help=f"which pictures (default all): {', '.join(PAGES)}")
    parser.add_argument("--port", type=int, default=0, help="the service's port (default: free)")
    parser.add_argument("--viser-port", type=int, default=0,
                        help="its 3D twin's port (default: free)")
    args = parser.parse_args(argv)
    wanted = args.pages or list(PAGES)
    if set(wanted) - set(PAGES):
        parser.error(f"unknown page(s) {sorted(set(wanted) - set(PAGES))}; choose from {PAGES}")
    if not CHROMIUM.exists():
        print(f"no Chromium at {CHROMIUM} (apt-get install chromium, or set "
              "HELIOTWIN_CHROMIUM)", file=sys.stderr)
        return 1
    from playwright.sync_api import sync_playwright

    tmp = Path(tempfile.mkdtemp(prefix="heliotwin-shots-"))
    try:
        with serve(tmp, args.port, args.viser_port) as url, sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
            for name in wanted:
                started = time.monotonic()
                globals()[name](browser, url)
                print(f"{name}: {time.monotonic() - started:.0f} s", file=sys.stderr)
            browser.close()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
