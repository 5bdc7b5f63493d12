"""The Overview's diagnosis panel in Chromium: the range's days charted and the faults listed
as the HTTP API answers them (the server's demo logger back-fills the days)."""

from __future__ import annotations

import datetime as dt
import json

import httpx
import pytest

from tests.e2e.conftest import BACKFILL_DAYS


def test_diagnosis_panel_matches_the_api(page, server) -> None:
    end = server.today() + dt.timedelta(days=1)  # today too: a day not over yet
    start = end - dt.timedelta(days=min(BACKFILL_DAYS, 3))
    body = httpx.get(f"{server.url}/api/v1/sites/{server.site['site_id']}/diagnosis",
                     params={"start": start.isoformat(), "end": end.isoformat()},
                     timeout=300).raise_for_status().json()
    page.goto(f"{server.url}/#overview")
    page.fill("#diag-start", start.isoformat())
    page.fill("#diag-end", end.isoformat())
    page.click("#diag-run")
    chart = page.locator("[data-testid=chart-diagnosis]")
    page.wait_for_function(
        "() => document.querySelector('#chart-diagnosis').dataset.points !== undefined",
        timeout=120_000)
    prs = [None if any(f["kind"] == "sky_unusable" for f in d["faults"])
           else d["tracker"]["performance_ratio"] for d in body["days"]]
    gains = [d[k] for d in body["days"] for k in ("gain_measured_pct", "gain_expected_pct")]
    expected_points = sum(v is not None for v in prs + gains)
    assert int(chart.get_attribute("data-points")) == expected_points > 0
    faults = {(f["kind"], f["since"]) for d in body["days"] for f in d["faults"]}
    if faults:
        assert page.locator("[data-testid=diag-fault]").count() == len(faults)
        text = page.locator("[data-testid=diag-faults]").inner_text()
        assert "confidence" in text
    else:
        assert page.locator("[data-testid=diag-none]").inner_text() == \
            "No fault found in this range."
    # what the skies rest on (the demo logger has no irradiance sensor)
    n_fixed = sum(d["sky"]["source"] == "fixed_array" for d in body["days"])
    sky = page.locator("[data-testid=diag-sky]").inner_text()
    assert sky.startswith("Sky: ") and (
        f"{n_fixed} day{'' if n_fixed == 1 else 's'} from the fixed array's power" in sky), sky
    assert [d["complete"] for d in body["days"]] == [True] * (len(body["days"]) - 1) + [False]
    assert "Not over yet, judged on the minutes so far: " in sky, sky
    # the days whose expected energy rests on a guessed beam for a tenth or more are named
    # with their share, as the API says (the demo logger's outages leave minutes unread)
    blind = [d for d in body["days"] if (d["sky"]["beam_unseen_expected_pct"] or 0) >= 10]
    assert ("Beam not seen by the sky instrument" in sky) == bool(blind), (sky, body["days"])
    for d in blind:
        assert f"{d['sky']['beam_unseen_expected_pct']:.0f} % on " in sky, sky
    page.locator("#diagnosis-card").screenshot(path="test-artifacts/e2e-diagnosis-card.png")
    # the demo logger reports the tracker's encoder angles: their pointing error is charted
    pointing = httpx.get(f"{server.url}/api/v1/sites/{server.site['site_id']}/pointing",
                         params={"start": start.isoformat(), "end": end.isoformat()},
                         timeout=60).raise_for_status().json()
    assert pointing["minutes"] > 0
    # drawn once its note is no longer "Loading…" (the chart's "Loading…" placeholder has
    # data-points 0: waiting for data-points alone read 0 points on a fresh clone's run)
    page.wait_for_function(
        "() => { const n = document.querySelector('#pointing-note');"
        " return n !== null && !n.textContent.startsWith('Loading'); }", timeout=60_000)
    drawn = int(page.locator("[data-testid=chart-pointing]").get_attribute("data-points"))
    assert drawn == 3 * len(pointing["points"])
    note = page.locator("[data-testid=pointing-note]").inner_text()
    assert f"RMS {pointing['summary']['rms_deg']:.2f}°" in note
    page.locator("#chart-pointing").screenshot(path="test-artifacts/e2e-pointing-chart.png")
    # its axis says what and in what unit (a bare string title is not drawn by this Plotly:
    # the axis had none; a tester's finding)
    assert page.locator("#chart-pointing .ytitle").text_content() == \
        "error against the ephemeris sun [°]"
    # and its times are the site's wall clock, said (the x axis had no title)
    tz = server.site["timezone"]
    assert page.locator("#chart-pointing .xtitle").text_content() == f"Local time ({tz})"
    assert page.locator("#chart-diagnosis .xtitle").text_content() == f"Day ({tz})"
    assert page.console_errors == []


def test_the_overview_draws_the_twin_under_the_measured_sky(page, server) -> None:
    """A past day the fixed array reported: the dashed twin is the weather-aware one
    (source=twin_weather) and the clear-sky twin stays as a faint reference."""
    day = server.today() - dt.timedelta(days=1)
    site = server.site["site_id"]
    body = httpx.get(f"{server.url}/api/v1/sites/{site}/measurements", timeout=60, params={
        "array": "tracker", "source": "twin_weather", "start": day.isoformat(),
        "end": (day + dt.timedelta(days=1)).isoformat()}).raise_for_status().json()
    assert body["sky"]["source"] == "fixed_array"
    page.goto(f"{server.url}/#overview?site={site}&day={day.isoformat()}")
    page.wait_for_function(
        f"() => document.body.dataset.overviewWeather === '{site}/{day.isoformat()}'",
        timeout=60_000)
    names = page.evaluate("() => document.getElementById('chart-power').data.map(t => t.name)")
    assert "tracker twin (measured sky)" in names and "tracker twin (clear sky)" in names
    drawn = page.evaluate(
        "() => document.getElementById('chart-power').data"
        ".find(t => t.name === 'tracker twin (measured sky)').y.filter(v => v !== null)")
    assert drawn == pytest.approx([p["power_w"] for p in body["points"]], abs=1e-6)
    page.locator("#chart-power").screenshot(path="test-artifacts/e2e-overview-weather-twin.png")
    assert page.console_errors == []


def _diagnose_range(page, server, rng: dict[str, str]) -> None:
    """The Overview's diagnosis panel run on ``rng`` (``start``, ``end``): the range set
    before the panel first scrolls into view (typing would scroll it there and load the
    default week with the start already changed: over 400 days, a 422)."""
    page.goto(f"{server.url}/#overview")
    page.wait_for_selector("#diag-form")
    page.evaluate("([s, e]) => { document.getElementById('diag-start').value = s; "
                  "document.getElementById('diag-end').value = e; }",
                  [rng["start"], rng["end"]])
    page.click("#diag-run")


def test_the_panel_shows_the_mount_faults_from_the_camera(page, server) -> None:
    """A day of tracker-camera offsets of a misaligned mount (posted with a token, on a
    date before the demo logger's days): the diagnosis panel lists each mount fault the
    API names (``mount``), in its words."""
    import numpy as np
    import pandas as pd

    from tests.backend.test_diagnosis_mount import MOUNT, camera_readings

    day = dt.date(2022, 8, 9)
    token = server.write_token
    site = server.site["site_id"]
    readings = camera_readings(pd.Timestamp(day.isoformat(), tz=server.site["timezone"]), MOUNT,
                               np.random.default_rng(15))
    httpx.post(f"{server.url}/api/v1/sites/{site}/measurements", json={"readings": readings},
               headers={"Authorization": f"Bearer {token}"}, timeout=120).raise_for_status()
    rng = {"start": day.isoformat(), "end": (day + dt.timedelta(days=1)).isoformat()}
    body = httpx.get(f"{server.url}/api/v1/sites/{site}/diagnosis", params=rng,
                     timeout=300).raise_for_status().json()
    faults = body["mount"]["faults"]
    assert {f["term"] for f in faults} == set(MOUNT)
    _diagnose_range(page, server, rng)
    shown = page.locator("[data-testid=diag-mount-fault]")
    shown.first.wait_for(timeout=120_000)
    assert shown.all_inner_texts() == [
        f"Mount (from the tracker camera): {f['detail']}" for f in faults]
    page.locator("#diagnosis-card").screenshot(path="test-artifacts/e2e-diagnosis-mount.png")
    assert page.console_errors == []


def test_a_day_whose_fixed_readings_were_refused_says_so(page, server) -> None:
    """Both arrays at 0 W all day (a tripped site breaker; a date before the demo logger's
    days): the panel lists the ``sky_unusable`` finding, its sky line says the fixed
    array's readings were refused (it said "too few readings" of a day read every 5
    minutes), and the chart draws no PR for it (a PR of 0 beside "the tracker is not
    judged": a tester's findings)."""
    day = dt.date(2022, 6, 14)
    token = server.write_token
    site = server.site["site_id"]
    t0 = dt.datetime(day.year, day.month, day.day, tzinfo=server.tz)
    readings = [{"ts": (t0 + dt.timedelta(minutes=m)).isoformat(), "array": a, "power_w": 0.0}
                for m in range(0, 1440, 5) for a in ("tracker", "fixed")]
    httpx.post(f"{server.url}/api/v1/sites/{site}/measurements", json={"readings": readings},
               headers={"Authorization": f"Bearer {token}"}, timeout=120).raise_for_status()
    rng = {"start": day.isoformat(), "end": (day + dt.timedelta(days=1)).isoformat()}
    body = httpx.get(f"{server.url}/api/v1/sites/{site}/diagnosis", params=rng,
                     timeout=300).raise_for_status().json()
    (d,) = body["days"]
    assert [f["kind"] for f in d["faults"]] == ["sky_unusable"], d["faults"]
    _diagnose_range(page, server, rng)
    page.wait_for_function(
        "() => document.querySelector('#chart-diagnosis').dataset.points !== undefined",
        timeout=120_000)
    faults = page.locator("[data-testid=diag-fault]").all_inner_texts()
    assert len(faults) == 1 and "readings unusable" in faults[0], faults
    sky = page.locator("[data-testid=diag-sky]").inner_text()
    assert "1 day from the clear sky (the fixed array's readings refused)" in sky, sky
    # the two gains (measured: none, both 0 Wh; expected: the clear sky's), no PR
    gains = [v for v in (d["gain_measured_pct"], d["gain_expected_pct"]) if v is not None]
    drawn = int(page.locator("[data-testid=chart-diagnosis]").get_attribute("data-points"))
    assert drawn == len(gains), (drawn, gains, d["tracker"]["performance_ratio"])
    page.locator("#diagnosis-card").screenshot(path="test-artifacts/e2e-diagnosis-refused.png")
    assert page.console_errors == []


def test_the_panel_follows_the_site_picker_and_an_edited_address(page, server) -> None:
    """The panel is loaded once it scrolls into view; picking another site shows that
    site's seven days (a camera site: that there is nothing to diagnose, no request that
    would be refused), and an address edited to another site and day loads those (it kept
    the previous site's days under the new site's name: a tester's finding)."""
    site = server.site["site_id"]
    sites = page.context.request.get(f"{server.url}/api/v1/sites").json()
    assert server.site["has_twin"] is True
    camera = next(o for o in sites if not o["has_twin"])["site_id"]
    page.goto(f"{server.url}/#overview?site={site}")
    with page.expect_request(lambda r: f"/sites/{site}/diagnosis" in r.url, timeout=60_000):
        page.locator("#diagnosis-card").scroll_into_view_if_needed()
    page.wait_for_selector("[data-testid=diag-sky]", timeout=120_000)
    page.wait_for_function("() => document.getElementById('pointing-note').textContent"
                           ".includes('readings with the sun up')", timeout=60_000)
    page.select_option("#site-select", camera)
    page.wait_for_selector("[data-testid=diag-no-twin]", timeout=10_000)
    assert page.locator("[data-testid=diag-sky]").count() == 0   # the old site's days gone
    # and its pointing error too (it stayed, under the camera site's name)
    page.wait_for_function("() => !document.getElementById('pointing-note').textContent"
                           ".includes('readings with the sun up') && !document.getElementById("
                           "'pointing-note').textContent.startsWith('Loading')",
                           timeout=30_000)
    today = server.today()
    assert (page.input_value("#diag-start"), page.input_value("#diag-end")) == (
        (today - dt.timedelta(days=6)).isoformat(), (today + dt.timedelta(days=1)).isoformat())
    day = today - dt.timedelta(days=10)
    with page.expect_request(lambda r: f"/sites/{site}/diagnosis" in r.url
                             and f"start={(day - dt.timedelta(days=6)).isoformat()}" in r.url,
                             timeout=60_000):
        page.evaluate(f"() => {{ location.hash = '#overview?site={site}&day={day}'; }}")
    assert page.input_value("#diag-end") == (day + dt.timedelta(days=1)).isoformat()
    assert page.console_errors == []


def test_a_range_without_readings_says_there_is_nothing_to_diagnose(page, server) -> None:
    """A site that never sent a reading said "No fault found in this range" beside
    expected-gain bars (a tester's finding). The service's own answer for a range, with its
    readings taken out (a range without any depends on what the session's other tests
    posted: after a logger's first reading, days without one are a dropout)."""
    end = server.today()
    start = end - dt.timedelta(days=3)
    body = httpx.get(f"{server.url}/api/v1/sites/{server.site['site_id']}/diagnosis",
                     params={"start": start.isoformat(), "end": end.isoformat()},
                     timeout=300).raise_for_status().json()
    for d in body["days"]:
        d["tracker"]["measured_wh"] = d["fixed"]["measured_wh"] = None
        d["faults"] = []
    page.route("**/diagnosis?*", lambda route: route.fulfill(
        status=200, content_type="application/json", body=json.dumps(body)))
    page.goto(f"{server.url}/#overview")
    page.click("#diag-run")  # the card runs when first scrolled into view
    none = page.locator("[data-testid=diag-none]")
    for _ in range(600):
        if none.count() and none.first.text_content().startswith("No readings"):
            break
        page.wait_for_timeout(100)
    assert none.count() and none.first.text_content() == \
        "No readings in this range: nothing measured to diagnose.", \
        page.locator("[data-testid=diag-faults]").inner_text()


def _day(date: str, tracker_wh: float | None, faults: list[dict]) -> dict:
    return {"date": date, "tracker": {"measured_wh": tracker_wh},
            "fixed": {"measured_wh": None if tracker_wh is None else 6222.0}, "faults": faults}


_STUCK = {"kind": "stuck", "title": "tracker stuck", "since": "2026-12-04", "confidence": 0.97,
          "detail": "stuck at azimuth 0°, elevation 73°"}


def test_a_fault_a_later_day_was_judged_without_is_not_said_to_go_on(page, server) -> None:
    """Santiago, a tracker stuck on 4 December and fine on the 5th: the card said "tracker
    stuck since Dec 4", read as still stuck. Over, it says on which day and that the next
    judged day had none; still on (or nothing judged after it), "since" as before."""
    page.goto(f"{server.url}/#overview")
    page.wait_for_selector('body[data-overview-loaded]', state="attached")
    cases = {
        "over": [_day("2026-12-03", 10230.0, []), _day("2026-12-04", 6820.0, [_STUCK]),
                 _day("2026-12-05", 10253.0, [])],
        "on": [_day("2026-12-04", 6820.0, [_STUCK]), _day("2026-12-05", 6800.0, [_STUCK])],
        "unjudged": [_day("2026-12-04", 6820.0, [_STUCK]), _day("2026-12-05", None, [])],
        "two days": [_day("2026-12-04", 6820.0, [_STUCK]), _day("2026-12-05", 6800.0, [_STUCK]),
                     _day("2026-12-06", 10250.0, [])],
    }
    lines = page.evaluate("""async (cases) => {
      const m = await import('/static/js/diagnosis.js');
      return Object.fromEntries(Object.entries(cases).map(([k, days]) => [k, m.faultLines(days)]));
    }""", cases)
    tail = ": stuck at azimuth 0°, elevation 73°; confidence 0.97"
    assert lines["over"] == ["tracker stuck on Dec 4, not on Dec 5" + tail]
    assert lines["on"] == ["tracker stuck since Dec 4" + tail]
    assert lines["unjudged"] == ["tracker stuck since Dec 4" + tail]
    assert lines["two days"] == ["tracker stuck Dec 4 to Dec 5, not on Dec 6" + tail]


def test_days_too_short_of_readings_for_the_shape_fits_are_named(page, server) -> None:
    """A 30-minute logger's December days at 40° N (about 17 readings under the sun of the 20
    the shape fits need) were never fitted, and the card said only "No fault found": it
    names the days not tested for a stuck tracker or a clock offset, with their readings."""
    page.goto(f"{server.url}/#overview")
    page.wait_for_selector('body[data-overview-loaded]', state="attached")
    few = {"readings": 16.7, "needed": 20, "detail": "…"}
    days = [{"date": "2025-12-01", "shape_untested": few},
            {"date": "2025-12-02", "shape_untested": {**few, "readings": 16.5}},
            {"date": "2025-12-03", "shape_untested": None}]
    lines = page.evaluate("""async (days) => {
      const m = await import('/static/js/diagnosis.js');
      return [m.untestedLines(days), m.untestedLines([days[2]])];
    }""", days)
    assert lines == [["Not tested for a stuck tracker, a clock offset or an azimuth offset (too "
                      "few tracker readings under the sun, 20 needed): Dec 1 (17), Dec 2 (17)."],
                     []]


def test_days_whose_beam_the_sky_instrument_did_not_see_are_named(page, server) -> None:
    """A summer day at Payerne behind a fixed plane facing south (the sun behind or grazing it
    from dawn to 08:36 and from 18:33, docs/diagnosis.md "Held-out real skies") rests on a
    guessed beam for a sixth of its expectation (14-21 % measured on 20-27 June 2016 over
    HTTP, docs/diagnosis.md "Any site"): a day under its band may be the sky, so
    the sky line names such days (a tenth or more, ``sky.beam_unseen_expected_pct``), not
    those under a tenth nor a clear-sky day (null: no instrument)."""
    page.goto(f"{server.url}/#overview")
    page.wait_for_selector('body[data-overview-loaded]', state="attached")
    sky = {"source": "sensor", "sensor": "poa_irradiance_w_m2", "clearness_index": 1.0,
           "valid_minutes_pct": 100.0}
    days = [{"date": "2016-06-22", "complete": True, "faults": [],
             "sky": {**sky, "beam_unseen_expected_pct": 17.7}},
            {"date": "2016-06-23", "complete": True, "faults": [],
             "sky": {**sky, "beam_unseen_expected_pct": 9.9}},
            {"date": "2016-06-24", "complete": True, "faults": [],
             "sky": {**sky, "source": "clear_sky", "sensor": None,
                     "beam_unseen_expected_pct": None}}]
    lines = page.evaluate("""async (days) => {
      const m = await import('/static/js/diagnosis.js');
      return [m.skyLine(days), m.skyLine(days.slice(1))];
    }""", days)
    assert lines[0].endswith(
        " Beam not seen by the sky instrument (the sun behind or grazing the fixed plane, low "
        "for a pyranometer, or readings missing), its share of the expected energy guessed: "
        "18 % on Jun 22."), lines[0]
    assert "Beam not seen" not in lines[1], lines[1]


def test_the_fixed_arrays_pr_is_drawn_only_under_a_sensors_sky(page, server) -> None:
    """Under a POA sensor the fixed array is judged too (``fixed_underperformance``): the
    chart draws its PR there (a snowed-in array's 0.29), and not on a day whose sky is the
    array's own power (1 by construction) or the clear sky."""
    page.goto(f"{server.url}/#overview")
    page.wait_for_selector('body[data-overview-loaded]', state="attached")
    days = [{"sky": {"source": "sensor"}, "fixed": {"performance_ratio": 0.287}},
            {"sky": {"source": "fixed_array"}, "fixed": {"performance_ratio": 1.0}},
            {"sky": {"source": "clear_sky"}, "fixed": {"performance_ratio": 0.6}},
            {"sky": {"source": "sensor"}, "fixed": {"performance_ratio": None}}]
    got = page.evaluate("""async (days) => {
      const m = await import('/static/js/diagnosis.js');
      return m.fixedPerformanceRatios(days);
    }""", days)
    assert got == [0.287, None, None, None]
