"""The 3D twin page in a real headless Chromium: per-viewer state, the selected site, shadows
that move with the sun, and the plant view reached from the Plant page.

Two browser contexts are two users (each tab has its own viewer key in sessionStorage).
They act through viser's own panel inside the dashboard's iframe; what each viewer shows
is read back from the panel's readout and from ``GET /api/v1/twin3d``. Screenshots go to
``test-artifacts/``.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Iterator

import cv2
import httpx
import numpy as np
import pytest
import shapely

from tests.e2e.conftest import ARTIFACTS, call_failed, open_page

#: SwiftShader renders the viser iframe on the CPU: on a loaded machine a click on the
#: dashboard beside it can wait this long for the page's main thread.
SLOW_MS = 60_000


@pytest.fixture()
def two_pages(browser, server, request) -> Iterator[tuple[object, object]]:  # type: ignore[no-untyped-def]
    """Two users' pages; a failed test leaves their screenshots (as ``open_page``)."""
    contexts, pages, errors = [], [], []
    for _ in range(2):
        ctx = browser.new_context(viewport={"width": 1400, "height": 1000})
        pg = ctx.new_page()
        pg.on("pageerror", lambda e: errors.append(f"pageerror: {e}"))
        pg.set_default_timeout(SLOW_MS)
        contexts.append(ctx)
        pages.append(pg)
    yield pages[0], pages[1]
    if call_failed(request):
        ARTIFACTS.mkdir(exist_ok=True)
        for i, pg in enumerate(pages):
            with contextlib.suppress(Exception):
                pg.screenshot(path=str(ARTIFACTS / f"e2e-twin3d-two-viewers-{i}-final.png"))
    for ctx in contexts:
        with contextlib.suppress(Exception):
            ctx.close()
    assert not errors, "\n".join(errors)


def _viewer_key(pg) -> str:  # type: ignore[no-untyped-def]
    return str(pg.evaluate("sessionStorage.getItem('heliotwin.viewer')"))


def _viewers(server) -> dict[str, dict]:  # type: ignore[no-untyped-def]
    rows = httpx.get(server.url + "/api/v1/twin3d", timeout=10).json()["viewers"]
    return {r["viewer"]: r for r in rows}


def _wait_for(pred, what: str, timeout_s: float = 30.0):  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        got = pred()
        if got:
            return got
        time.sleep(0.2)
    raise AssertionError(f"timed out waiting for {what}")


def _open_twin(pg, server):  # type: ignore[no-untyped-def]
    pg.goto(server.url + "/#twin")
    pg.wait_for_selector("#twin-frame[src*='websocket=']")
    frame = pg.frame_locator("#twin-frame")
    frame.locator("text=Readouts").first.wait_for()
    return frame


def _input(frame, label: str):  # type: ignore[no-untyped-def]
    """The input of a viser control, found by its label (label → Text → Box → Flex row)."""
    row = frame.locator("label", has_text=label).first.locator("xpath=ancestor::div[2]")
    return row.locator("input:not([type=hidden])").last


def _scrub(frame, day: str, hours: float) -> None:  # type: ignore[no-untyped-def]
    """Type a day, wait until the viewer shows it, then type the hour (as a person would:
    one field at a time, each answered by the scene)."""
    _input(frame, "Date (local)").fill(day)
    frame.locator(f"text={day}").first.wait_for()
    _input(frame, "Local time [h]").fill(f"{hours:g}")
    hh, mm = int(hours), round(60 * (hours % 1))
    frame.locator(f"text={day} {hh:02d}:{mm:02d}").first.wait_for()


def _drawn(pg) -> bytes:  # type: ignore[no-untyped-def]
    """A screenshot of the iframe once WebGL has drawn the scene (not blank)."""
    el = pg.locator("#twin-frame")
    for close in pg.frame_locator("#twin-frame").locator(
            ".mantine-Notification-closeButton").all():  # "software WebGL" notice
        with contextlib.suppress(Exception):
            close.click(timeout=5_000)
    png = b""
    for _ in range(80):  # up to 20 s, looked at every 0.25 s
        pg.wait_for_timeout(250)
        png = el.screenshot()
        img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_GRAYSCALE)
        if float(img.std()) > 8.0 and len(np.unique(img)) > 32:
            return png
    pytest.fail("the viser iframe stayed blank")


def test_two_viewers_scrub_independently_and_shadows_follow_the_sun(two_pages, server) -> None:  # type: ignore[no-untyped-def]
    a, b = two_pages
    fa, fb = _open_twin(a, server), _open_twin(b, server)
    ka, kb = _viewer_key(a), _viewer_key(b)
    assert ka != kb and ka in a.get_attribute("#twin-frame", "src")
    _wait_for(lambda: {ka, kb} <= set(_viewers(server)), "both viewers to connect")
    assert _viewers(server)[kb]["mode"] == "live"

    _scrub(fa, "2024-03-15", 7.5)
    row = _wait_for(lambda: (r := _viewers(server)[ka])["time"] == "2024-03-15T13:30:00+00:00"
                    and r, "viewer A at 07:30")
    assert row["mode"] == "scrubbing"
    assert "Power at 07:30" in fa.locator("text=Power at").first.inner_text()
    morning = shapely.Polygon(row["tracker_shadow_m"])
    png_morning = _drawn(a)
    # B saw none of it: still live, its own time
    assert _viewers(server)[kb]["mode"] == "live"
    assert fb.locator("text=(live)").count() >= 1

    _scrub(fa, "2024-03-15", 17.5)
    row = _wait_for(lambda: (r := _viewers(server)[ka])["time"] == "2024-03-15T23:30:00+00:00"
                    and r, "viewer A at 17:30")
    evening = shapely.Polygon(row["tracker_shadow_m"])
    png_evening = _drawn(a)
    # the shadow is cast away from the sun: west of the tracker at 07:30, east at 17:30
    assert morning.centroid.x < -4.0 < 4.0 < evening.centroid.x
    # and at 17:30 the tracker's shadow falls on the fixed array: a loss the readout names
    assert row["fixed_shaded_fraction"] > 0.5
    assert "Tracker shades the fixed array" in fa.locator("text=Tracker shades").first.inner_text()
    img_m = cv2.imdecode(np.frombuffer(png_morning, np.uint8), cv2.IMREAD_GRAYSCALE)
    img_e = cv2.imdecode(np.frombuffer(png_evening, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert img_m.shape == img_e.shape
    assert float(np.mean(np.abs(img_m.astype(int) - img_e.astype(int)) > 40)) > 0.01
    ARTIFACTS.mkdir(exist_ok=True)
    (ARTIFACTS / "twin3d-0730.png").write_bytes(png_morning)
    (ARTIFACTS / "twin3d-1730.png").write_bytes(png_evening)

    _scrub(fb, "2024-06-21", 12.0)  # B scrubs; A stays at its evening
    _wait_for(lambda: _viewers(server)[kb]["time"] == "2024-06-21T18:00:00+00:00",
              "viewer B at noon")
    assert _viewers(server)[ka]["time"] == "2024-03-15T23:30:00+00:00"


def test_the_twin_follows_the_selected_site(page, server) -> None:  # type: ignore[no-untyped-def]
    page.set_default_timeout(SLOW_MS)
    frame = _open_twin(page, server)
    key = _viewer_key(page)
    _wait_for(lambda: _viewers(server).get(key, {}).get("site_id") == "tehuantepec",
              "a tehuantepec viewer")
    page.select_option("#site-select", "guadalajara_fisheye")
    page.wait_for_selector("#twin-frame[src*='guadalajara_fisheye']")
    frame = page.frame_locator("#twin-frame")
    frame.locator("text=Guadalajara").first.wait_for()
    _wait_for(lambda: any(r["site_id"] == "guadalajara_fisheye" and k == key
                          for k, r in _viewers(server).items()), "a guadalajara viewer")
    # a camera site has no PV arrays: no power, no fixed array to shade
    assert "tracker —, fixed —" in frame.locator("text=Power at").first.inner_text()
    page.select_option("#site-select", "tehuantepec")
    page.wait_for_selector("#twin-frame[src*='tehuantepec']")


def test_the_plant_page_opens_the_plant_in_3d(page, server) -> None:  # type: ignore[no-untyped-def]
    page.set_default_timeout(SLOW_MS)
    page.goto(server.url + "/#plant?day=2024-12-21")
    page.wait_for_selector("body[data-plant-loaded]", timeout=60_000)
    page.select_option("#plant-strategy", "sun")
    href = page.get_attribute("#plant-3d", "href")
    assert href.startswith("#twin?plant=penarroya&strategy=sun&time=2024-12-21")
    page.click("#plant-3d")
    page.wait_for_selector("#twin-frame[src*='plant']")
    # the view list fills after GET /plants answers, a moment after the frame's src is set
    page.wait_for_function(
        "() => document.getElementById('twin-view').value === 'plant:penarroya'")
    frame = page.frame_locator("#twin-frame")
    frame.locator("text=plant view").first.wait_for()
    text = frame.locator("text=Shaded:").first.inner_text()
    assert "of 29 collectors" in text and not text.startswith("Shaded: 0 ")  # seed 004 morning
    png = _drawn(page)
    (ARTIFACTS / "twin3d-plant.png").write_bytes(png)
    page.select_option("#twin-view", "site")
    page.wait_for_selector("#twin-frame[src*='%2Fsite%2F']")



def _forward(listen: socket.socket, to_port: int) -> None:
    """Copy every connection accepted on ``listen`` to 127.0.0.1:``to_port`` both ways (the
    port Docker Compose publishes for the container's viser port)."""
    def pipe(a: socket.socket, b: socket.socket) -> None:
        with contextlib.suppress(OSError):
            while data := a.recv(65536):
                b.sendall(data)
        with contextlib.suppress(OSError):
            b.shutdown(socket.SHUT_WR)

    with contextlib.suppress(OSError):
        while True:
            client, _ = listen.accept()
            upstream = socket.create_connection(("127.0.0.1", to_port))
            for a, b in ((client, upstream), (upstream, client)):
                threading.Thread(target=pipe, args=(a, b), daemon=True).start()


def test_the_3d_tab_frames_viser_at_its_public_port(browser, tmp_path, request) -> None:  # type: ignore[no-untyped-def]
    """Published on another port than it listens on (Compose's 8081 for the container's
    8080), viser is framed at HELIOTWIN_VISER_PUBLIC_PORT, which the CSP allows: the scene
    draws through the published port (it was framed at the inside port, another service's
    or nothing)."""
    from tests.backend.live_service import ServerProcess, free_port, new_database

    published = socket.create_server(("127.0.0.1", 0))
    public = published.getsockname()[1]
    inside = free_port()
    threading.Thread(target=_forward, args=(published, inside), daemon=True).start()
    proc = ServerProcess(new_database("sqlite", tmp_path).url, tmp_path / "server.log",
                         viser_port=inside,
                         extra_env={"HELIOTWIN_VISER": "true",
                                    "HELIOTWIN_VISER_PUBLIC_PORT": str(public)}).start()
    try:
        meta = httpx.get(proc.base_url + "/api/v1/meta", timeout=30).json()
        assert (meta["viser_port"], meta["viser_public_port"]) == (inside, public)
        with open_page(browser, request, timeout_ms=60_000) as pg:
            pg.goto(proc.base_url + "/#twin")
            src = pg.wait_for_selector("#twin-frame[src*='websocket=']").get_attribute("src")
            assert src.startswith(f"http://127.0.0.1:{public}/?websocket=ws%3A%2F%2F127.0.0.1"
                                  f"%3A{public}%2Fsite%2F"), src
            pg.frame_locator("#twin-frame").locator("text=Readouts").first.wait_for()
    finally:
        proc.stop()
        published.close()
