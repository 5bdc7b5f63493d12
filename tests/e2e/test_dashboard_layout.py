"""The dashboard's layout at phone width in a real headless Chromium against the session's
``heliotwin serve`` (``conftest.py``): no page is wider than the viewport.

At 390 px (a phone held upright) the header's site picker, holding a long site name, made
every page scroll sideways (``scrollWidth`` 718-736 px); docs/dashboard.md, "Phone width".
"""

from __future__ import annotations

import datetime as dt

import pytest

from tests.e2e.conftest import ARTIFACTS, open_page

pytestmark = [pytest.mark.browser, pytest.mark.timeout(180)]

PHONE = {"width": 390, "height": 844}
#: What a page shows once it has drawn its data, for every page of the tab bar: a marker on
#: <body>, or its last chart's ``data-points`` (set when drawn or said empty: charts.js). A
#: page without one waited for the network to go quiet, up to 10 s on a page that polls.
LOADED = {"overview": "body[data-overview-loaded][data-report-loaded]",
          "simulation": "#chart-sim-power[data-points]",
          "sky": "#chart-sky-error[data-points]",
          "twin": "body[data-twin-view]", "plant": "body[data-plant-loaded]",
          "pointing": "body[data-pointing], [data-testid=pointing-empty]:not([hidden])",
          "sites": "body[data-sites-loaded]"}


def test_no_page_scrolls_sideways_at_phone_width(browser, server, request) -> None:  # type: ignore[no-untyped-def]
    """Every page of the tab bar, its data drawn: the document is no wider than the
    viewport (the elements that stick out are named when it is)."""
    with open_page(browser, request, timeout_ms=60_000) as page:
        page.set_viewport_size(PHONE)
        page.goto(server.url + "/#overview")
        names = page.eval_on_selector_all("nav.tabs a[data-page]",
                                          "links => links.map(a => a.dataset.page)")
        assert len(names) >= 7
        too_wide, squeezed = {}, {}
        for name in names:
            page.goto(f"{server.url}/#{name}")
            page.wait_for_selector(f'section.page[data-page="{name}"]:not([hidden])')
            assert name in LOADED, f"page {name!r}: no loaded marker in LOADED"
            page.wait_for_selector(LOADED[name], state="attached")
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


#: Per visible chart: the x tick labels of each x axis that touch or overlap their neighbour
#: (closer than 2 px, "07 Nov14 Nov"), and the axis titles whose box leaves the chart's SVG.
_CHART_DEFECTS = """() => [...document.querySelectorAll('.js-plotly-plot')]
  .filter(el => el.offsetParent !== null && el.querySelector('.cartesianlayer .xtick'))
  .map(el => {
    const svg = el.querySelector('svg.main-svg').getBoundingClientRect();
    const cut = [...el.querySelectorAll('.infolayer text[class$=title]')]
      .filter(t => t.textContent)
      .filter(t => { const r = t.getBoundingClientRect();
        return r.left < svg.left - 0.5 || r.right > svg.right + 0.5
          || r.top < svg.top - 0.5 || r.bottom > svg.bottom + 0.5; })
      .map(t => t.textContent);
    // a legend entry's text past the chart's edge is cut there ("… under 99 % of the da")
    for (const t of el.querySelectorAll('.legend text.legendtext')) {
      const r = t.getBoundingClientRect();
      if (t.textContent && r.width > 0 && (r.right > svg.right + 0.5 || r.left < svg.left - 0.5))
        cut.push(`legend: ${t.textContent}`);
    }
    const overlaps = [];
    for (const axis of el.querySelectorAll('.cartesianlayer g[class$=axislayer-above]')) {
      if (!/^x/.test(axis.getAttribute('class'))) continue;
      const boxes = [...axis.querySelectorAll('text')]
        .map(t => [t.textContent, t.getBoundingClientRect()])
        .filter(([, r]) => r.width > 0).sort((a, b) => a[1].left - b[1].left);
      for (let i = 1; i < boxes.length; i++)
        if (boxes[i][1].left < boxes[i - 1][1].right + 2)
          overlaps.push(`${boxes[i - 1][0]} | ${boxes[i][0]}`);
    }
    return { id: el.id, cut, overlaps };
  })"""


def test_charts_are_readable_at_phone_width(browser, server, request) -> None:  # type: ignore[no-untyped-def]
    """At 390 px no two x tick labels of a chart touch or overlap and every axis title lies
    inside its chart: the Overview's (yesterday's power, the daily bars with the gain on a
    second axis, the diagnosis's dates), the Plant page's and a simulation's (its angles'
    second axis has a title longer than the axis), nor a legend's entry past its edge (the
    diagnosis's was cut mid-word). Drawn with the desktop's fixed margins
    and every tick, the titles were cut at the chart's edge and the dates' labels slanted
    over each other (docs/dashboard.md, "Phone width")."""
    with open_page(browser, request, timeout_ms=90_000) as page:
        page.set_viewport_size(PHONE)
        found: dict[str, dict] = {}

        def collect(where: str) -> None:
            for chart in page.evaluate(_CHART_DEFECTS):
                found[chart["id"]] = {"page": where, **chart}

        yesterday = (server.today() - dt.timedelta(days=1)).isoformat()
        page.goto(f"{server.url}/#overview?day={yesterday}")
        page.wait_for_selector(LOADED["overview"], state="attached")
        page.locator("#diag-form").scroll_into_view_if_needed()  # the diagnosis draws in view
        page.wait_for_function("() => Number(document.getElementById('chart-diagnosis')"
                               ".dataset.points || 0) > 0")
        collect("overview")
        page.goto(f"{server.url}/#plant")
        page.wait_for_selector(LOADED["plant"], state="attached")
        collect("plant")
        page.goto(f"{server.url}/#simulation")
        page.fill("#sim-start", yesterday)
        page.fill("#sim-end", server.today().isoformat())
        page.select_option("#sim-step", "300")
        page.click("#sim-run")
        page.wait_for_selector("body[data-simulation-done]", timeout=90_000)
        collect("simulation")
        page.screenshot(path=str(ARTIFACTS / "phone-simulation.png"), full_page=True)

        expected = {"chart-power", "chart-daily", "chart-cumulative", "chart-diagnosis",
                    "chart-plant-shade", "chart-plant-strategies", "chart-sim-power",
                    "chart-sim-angles"}
        assert expected <= set(found), f"charts not drawn: {expected - set(found)}"
        bad = {k: v for k, v in found.items() if v["cut"] or v["overlaps"]}
        assert not bad, f"charts unreadable at {PHONE['width']} px: {bad}"


_POLAR_DEFECTS = """(id) => {
  const el = document.getElementById(id);
  const svg = el.querySelector('svg.main-svg').getBoundingClientRect();
  const ticks = [...el.querySelectorAll(
      '.polarlayer .angularaxistick text, .polarlayer .angulartick text')]
    .map(t => [t.textContent, t.getBoundingClientRect()]).filter(([, r]) => r.width > 0);
  const legend = [...el.querySelectorAll('.legend .traces')].map(t => t.getBoundingClientRect());
  const cut = ticks.filter(([, r]) => r.left < svg.left - 0.5 || r.right > svg.right + 0.5
    || r.top < svg.top - 0.5 || r.bottom > svg.bottom + 0.5).map(([t]) => t);
  const hit = (a, b) => a.left < b.right && b.left < a.right
    && a.top < b.bottom && b.top < a.bottom;
  const underLegend = ticks.filter(([, r]) => legend.some(l => hit(r, l))).map(([t]) => t);
  return { ticks: ticks.map(([t]) => t), cut, underLegend };
}"""


def test_the_sky_map_is_readable_at_phone_width(browser, server, request) -> None:  # type: ignore[no-untyped-def]
    """At 390 px the sky map's compass labels lie inside the chart, clear of its legend: "W 270°"
    was cut at the left edge and the legend's "ephemeris (SPA)" lay over "N 0°"."""
    frame = (ARTIFACTS.parent / "tests" / "data" / "real-sky"
             / "Wettermast_20160615_093900UTCp1_sunrow1202_suncol535.jpg")
    with open_page(browser, request, timeout_ms=90_000) as page:
        page.set_viewport_size(PHONE)
        page.goto(f"{server.url}/#sky")
        page.wait_for_selector(LOADED["sky"], state="attached")
        page.set_input_files("#sky-files", str(frame))
        page.select_option("#sky-place", "coords")
        page.fill("#sky-coords input[name=latitude_deg]", "53.52")
        page.fill("#sky-coords input[name=longitude_deg]", "10.105")
        page.click("#sky-detect")
        page.wait_for_function(
            "() => document.querySelector('#chart-sky-track .polarlayer .angularaxistick text, "
            "#chart-sky-track .polarlayer .angulartick text')")
        page.locator("#chart-sky-track").scroll_into_view_if_needed()
        page.locator("#chart-sky-track").screenshot(path=str(ARTIFACTS / "phone-sky-map.png"))
        found = page.evaluate(_POLAR_DEFECTS, "chart-sky-track")
        assert set(found["ticks"]) == {"N 0°", "E 90°", "S 180°", "W 270°"}, found
        assert not found["cut"] and not found["underLegend"], found
