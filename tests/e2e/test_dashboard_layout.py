"""The dashboard's layout at phone width in a real headless Chromium against the session's
``heliotwin serve`` (``conftest.py``): no page is wider than the viewport.

At 390 px (a phone held upright) the header's site picker, holding a long site name, made
every page scroll sideways (``scrollWidth`` 718-736 px); docs/dashboard.md, "Phone width".
"""

from __future__ import annotations

import pytest
from playwright.sync_api import TimeoutError as PlaywrightTimeout

from tests.e2e.conftest import open_page

pytestmark = [pytest.mark.browser, pytest.mark.timeout(180)]

PHONE = {"width": 390, "height": 844}
#: What a page sets on <body> once it has drawn its data (the others draw forms, or wait for
#: the network to go quiet).
LOADED = {"overview": "body[data-overview-loaded][data-report-loaded]",
          "twin": "body[data-twin-view]", "plant": "body[data-plant-loaded]",
          "pointing": "body[data-pointing], [data-testid=pointing-empty]:not([hidden])"}


def _pointing_empty_state(text: str) -> bool:
    """The Pointing page's empty state (too few observations) answers 422, which Chromium
    logs as a failed load (tests/e2e/test_pointing_page.py); no other page asks for one."""
    return "the server responded with a status of 422" in text


def test_no_page_scrolls_sideways_at_phone_width(browser, server, request) -> None:  # type: ignore[no-untyped-def]
    """Every page of the tab bar, its data drawn: the document is no wider than the
    viewport (the elements that stick out are named when it is)."""
    with open_page(browser, request, timeout_ms=60_000, ignore=_pointing_empty_state) as page:
        page.set_viewport_size(PHONE)
        page.goto(server.url + "/#overview")
        names = page.eval_on_selector_all("nav.tabs a[data-page]",
                                          "links => links.map(a => a.dataset.page)")
        assert len(names) >= 7
        too_wide, squeezed = {}, {}
        for name in names:
            page.goto(f"{server.url}/#{name}")
            page.wait_for_selector(f'section.page[data-page="{name}"]:not([hidden])')
            if name in LOADED:
                page.wait_for_selector(LOADED[name], state="attached")
            else:  # the network quiet, or 10 s for a page that keeps polling
                try:
                    page.wait_for_load_state("networkidle", timeout=10_000)
                except PlaywrightTimeout:
                    pass
            # a visible card title keeps some width (they shrank to 0 px beside a select)
            titles = page.evaluate(
                f"""() => [...document.querySelectorAll('section.page[data-page="{name}"] '
                       + '.card > header h2')].filter(h => h.offsetParent !== null
                       && h.getBoundingClientRect().width < 40).map(h => h.textContent)""")
            if titles:
                squeezed[name] = titles
            width = page.evaluate("() => document.documentElement.scrollWidth")
            if width > PHONE["width"]:
                too_wide[name] = (width, page.evaluate(
                    """() => [...document.querySelectorAll('body *')]
                         .filter(el => el.offsetParent !== null
                                 && el.getBoundingClientRect().right > innerWidth + 0.5)
                         .slice(0, 5).map(el => `${el.tagName}#${el.id}.${el.className}`)"""))
        assert not too_wide, f"pages wider than {PHONE['width']} px: {too_wide}"
        assert not squeezed, f"card titles squeezed under 40 px: {squeezed}"


def test_the_header_scrolls_away_on_a_phone_and_the_days_energy_fits_a_desktop(
        browser, server, request) -> None:  # type: ignore[no-untyped-def]
    """On a phone the header (two rows of tabs, the site picker: ~220 px) scrolls away with
    the page: stuck to the top it hid a quarter of the screen and the Sites form's message
    under it. On a desktop the day's energy table is not cut (its last column lost 10 px
    at 1280–1920 px; a tester's findings)."""
    with open_page(browser, request, timeout_ms=60_000) as page:
        page.set_viewport_size(PHONE)
        page.goto(server.url + "/#overview")
        page.wait_for_selector(LOADED["overview"], state="attached")
        page.evaluate("() => window.scrollTo(0, document.body.scrollHeight)")
        bottom = page.evaluate("() => document.querySelector('.topbar')"
                               ".getBoundingClientRect().bottom")
        assert bottom <= 0, f"the header still covers {bottom:.0f} px of the screen"
        for width in (1280, 1440, 1920):
            page.set_viewport_size({"width": width, "height": 900})
            page.evaluate("() => window.scrollTo(0, 0)")
            cut = page.evaluate("() => { const b = document.getElementById('day-energy');"
                                " return b.scrollWidth - b.clientWidth; }")
            assert cut <= 0, f"the day's energy table is cut by {cut} px at {width} px"
