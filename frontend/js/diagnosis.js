// Overview: the diagnosis panel — per day the tracker against the weather-aware twin
// (GET /api/v1/sites/{id}/diagnosis), faults in plain words, a daily PR / gain chart.
import { api } from "./api.js";
import { COLORS, baseLayout, draw, showEmpty, zeroBasedAxis } from "./charts.js";
import { toLocalWall } from "./time.js";
import { h, num } from "./ui.js";

function addDays(iso, n) {
  const d = new Date(`${iso}T12:00:00Z`);
  d.setUTCDate(d.getUTCDate() + n);
  return d.toISOString().slice(0, 10);
}

function shortDate(iso) {
  return new Date(`${iso}T12:00:00Z`).toLocaleDateString(undefined, { day: "numeric", month: "short", timeZone: "UTC" });
}

/** One line per fault (the latest day it was seen), e.g. "tracker stuck since 12 Mar …", or
 * "tracker stuck on 4 Dec, not on 5 Dec: …" when a later day of the range was judged without
 * it: "since 4 Dec" alone read as a tracker still stuck on a range whose last day was fine (a
 * tester's finding). A later day judges only when both arrays reported and its sky was usable. */
export function faultLines(days) {
  const last = new Map();
  const lastSeen = new Map();
  for (const d of days) {
    for (const f of d.faults) {
      last.set(`${f.kind}|${f.since}`, f);
      lastSeen.set(`${f.kind}|${f.since}`, d.date);
    }
  }
  const judged = (d) => d.tracker?.measured_wh != null && d.fixed?.measured_wh != null
    && !(d.faults || []).some((g) => g.kind === "sky_unusable");
  // under 0.5 a finding is a possibility, not a fault (the alerts' default threshold,
  // HELIOTWIN_ALERT_FAULT_CONFIDENCE_MIN): a healthy broken-cloud day listed "azimuth
  // offset … confidence 0.48" as plainly as a stuck tracker (a tester's finding)
  return [...last.entries()].map(([key, f]) => {
    const seen = lastSeen.get(key);
    const after = days.find((d) => d.date > seen && judged(d) && !d.faults.some((g) => g.kind === f.kind));
    const when = !after ? `since ${shortDate(f.since)}`
      : `${f.since === seen ? `on ${shortDate(seen)}` : `${shortDate(f.since)} to ${shortDate(seen)}`}, `
        + `not on ${shortDate(after.date)}`;
    return `${f.confidence < 0.5 ? "possibly " : ""}${f.title} ${when}: ${f.detail}; confidence ${num(f.confidence, 2)}`;
  });
}

/** The mount faults the tracker camera's sun offsets show (GET …/diagnosis `mount`): an
 * step of a term (an encoder slip, a pedestal that moved: the detail says which) with its
 * first day, then each significant term with its uncertainty. */
export function mountLines(mount) {
  if (!mount) return [];
  return mount.faults.map((f) => (f.kind === "encoder_slip"
    ? `Mount step since ${shortDate(f.since)}: ${f.detail}`
    : `Mount (from the tracker camera): ${f.detail}`));
}

/** The fixed array's PR per day, only under a sensor's sky (null elsewhere): from its own
 * power it is 1 by construction (a snowed-in reference array read 0.24 under its POA sensor,
 * the fixed_underperformance finding). */
export function fixedPerformanceRatios(days) {
  return days.map((d) => (d.sky.source === "sensor" ? d.fixed.performance_ratio ?? null : null));
}

const SKY_WORDS = {
  sensor: "an irradiance sensor",
  fixed_array: "the fixed array's power",
  clear_sky: "the clear sky (too few readings)",
  // a clear-sky day whose fixed readings were there but refused (the sky_unusable finding)
  refused: "the clear sky (the fixed array's readings refused)",
};

/** The words for what a day's sky rests on. */
function skySource(d) {
  if (d.sky.source === "sensor" && d.sky.sensor) return `${SKY_WORDS.sensor} (${d.sky.sensor})`;
  if (d.sky.source === "clear_sky" && (d.faults || []).some((f) => f.kind === "sky_unusable")) return SKY_WORDS.refused;
  return SKY_WORDS[d.sky.source] || d.sky.source;
}

/** A day's share of the expected tracker energy whose beam the sky instrument did not see
 * (`sky.beam_unseen_expected_pct`) from which the sky line names it [%]. */
const BLIND_NOTE_PCT = 10;

/** What the days' skies rest on, e.g. "Sky: 5 days from an irradiance sensor (ghi_w_m2), 2 from …",
 * which days are not over yet (judged on their minutes so far), and the days whose
 * expectation rests on a guessed beam for BLIND_NOTE_PCT or more of it. */
export function skyLine(days) {
  const count = new Map();
  const future = days.filter((d) => d.status === "future").length;
  for (const d of days.filter((x) => x.status !== "future")) {
    const key = skySource(d);
    count.set(key, (count.get(key) || 0) + 1);
  }
  const open = days.filter((d) => d.complete === false && d.status !== "future").map((d) => shortDate(d.date));
  // the days whose expectation rests on a guessed beam for a tenth of it or more (summer
  // dawns behind a fixed plane facing the equator: a day below its band may be the sky)
  const blind = days.filter((d) => d.status !== "future" && (d.sky.beam_unseen_expected_pct ?? 0) >= BLIND_NOTE_PCT);
  const note = (open.length ? ` Not over yet, judged on the minutes so far: ${open.join(", ")}.` : "")
    + (future ? ` ${future} day${future === 1 ? "" : "s"} still to come: nothing to judge yet.` : "")
    + (blind.length ? ` Beam not seen by the sky instrument (the sun behind or grazing the fixed plane, low for a pyranometer, or readings missing), its share of the expected energy guessed: `
      + `${blind.map((d) => `${num(d.sky.beam_unseen_expected_pct, 0)} % on ${shortDate(d.date)}`).join(", ")}.` : "");
  return `Sky: ${[...count].map(([k, n]) => `${n} day${n === 1 ? "" : "s"} from ${k}`).join(", ") || "no day judged"}.${note}`;
}

/** The days too few readings left untested for a stuck tracker or a clock offset
 * (GET …/diagnosis `shape_untested`), e.g. "Not tested for a stuck tracker or a clock offset
 * (too few readings under the sun, 20 needed): 2 Dec (16), 3 Dec (16)." */
export function untestedLines(days) {
  const few = days.filter((d) => d.shape_untested);
  if (!few.length) return [];
  return [`Not tested for a stuck tracker, a clock offset or an azimuth offset (too few tracker readings under the sun, ${few[0].shape_untested.needed} needed): `
    + `${few.map((d) => `${shortDate(d.date)} (${num(d.shape_untested.readings, 0)})`).join(", ")}.`];
}

let requested = 0; // the latest load; an older one that answers later is dropped

async function load(state) {
  const start = document.getElementById("diag-start").value;
  const end = document.getElementById("diag-end").value;
  const list = document.getElementById("diag-faults");
  const mine = ++requested;
  if (!state.site.has_twin) { // a camera site, or arrays not named tracker and fixed
    const camera = !Object.keys(state.site.arrays || {}).length;
    list.replaceChildren(h("li", { class: "muted", "data-testid": "diag-no-twin" },
      camera ? "This site has no PV arrays (a camera site): nothing to diagnose."
        : "This site has no pair of arrays named tracker and fixed for the twin: no diagnosis from the power."));
    showEmpty("chart-diagnosis", "No diagnosis for this site");
    await loadPointing(state, start, end, mine); // a tracker's encoders still say where it points
    return;
  }
  list.replaceChildren(h("li", { class: "muted" }, "Computing… (days not seen before take about a second each)"));
  let body;
  try {
    body = await api(`/api/v1/sites/${encodeURIComponent(state.site.site_id)}/diagnosis`, { params: { start, end } });
    if (mine !== requested) return;
  } catch (err) {
    if (mine !== requested) return;
    list.replaceChildren(h("li", { class: "error" }, `Diagnosis failed: ${err.message}`));
    showEmpty("chart-diagnosis", "No diagnosis");
    // the encoders' own answer for this range: the range before's pointing error stayed
    // under a refused range's error, read as this one's
    await loadPointing(state, start, end, mine);
    return;
  }
  const lines = faultLines(body.days);
  const mount = mountLines(body.mount);
  list.replaceChildren(...mount.map((t) => h("li", { "data-testid": "diag-mount-fault" }, t)),
    ...(lines.length ? lines.map((t) => h("li", { "data-testid": "diag-fault" }, t))
      : [h("li", { class: "muted", "data-testid": "diag-none" },
        // a site that never sent a reading was "no fault found" (a tester's finding)
        !body.days.some((d) => d.tracker.measured_wh !== null || d.fixed.measured_wh !== null)
          ? "No readings in this range: nothing measured to diagnose."
          : mount.length ? "No fault found from the power in this range." : "No fault found in this range.")]),
    ...(body.mount && body.mount.undetermined.length ? [h("li", { class: "muted", "data-testid": "diag-mount-undetermined" },
      `Mount: ${body.mount.n_observations} camera observations since ${shortDate(body.mount.since)} do not determine `
      + `${body.mount.undetermined.join(", ")} (too little of the sky: send frames over more of the day); `
      + "not named, and not found sound.")] : []),
    ...(body.mount && !mount.length && !body.mount.undetermined.length ? [h("li", { class: "muted", "data-testid": "diag-mount-none" },
      `Mount: no significant term in ${body.mount.n_observations} camera observations since ${shortDate(body.mount.since)} (residual ${num(body.mount.residual_rms_mrad, 2)} mrad RMS).`)] : []),
    ...untestedLines(body.days).map((t) => h("li", { class: "muted", "data-testid": "diag-untested" }, t)),
    h("li", { class: "muted", "data-testid": "diag-sky" }, skyLine(body.days)));
  const x = body.days.map((d) => d.date);
  const partial = body.days.map((d) => d.partial === true);
  // no PR where the diagnosis does not judge the tracker: its fixed readings were refused
  // (sky_unusable; a 0 W day drew PR 0 beside "the tracker is not judged")
  const pr = body.days.map((d) => ((d.faults || []).some((f) => f.kind === "sky_unusable") ? null : d.tracker.performance_ratio));
  const fixedPr = fixedPerformanceRatios(body.days);
  // the axes from the whole days only: a partial day's gain (readings over part of the day,
  // e.g. +220 % at 07:30) is drawn apart — hatched, faint, clamped to the axis — and never
  // sets the range; both axes from zero with round ticks
  const gainAxis = zeroBasedAxis(body.days.filter((d, i) => !partial[i])
    .flatMap((d) => [d.gain_measured_pct, d.gain_expected_pct]));
  const prAxis = zeroBasedAxis([1.2, ...[...pr, ...fixedPr].filter((v, i) => !partial[i % pr.length])]);
  const clamp = (v) => (v === null || v === undefined ? v : Math.min(Math.max(v, gainAxis.range[0]), gainAxis.range[1]));
  const measured = body.days.map((d, i) => (partial[i] ? clamp(d.gain_measured_pct) : d.gain_measured_pct));
  await draw("chart-diagnosis", [
    // "partial" here: readings under 99 % of the day's expected energy (the diagnosis'
    // rule), stricter than the daily energy chart's 95 %: a day whole there is hatched here
    // (a tester read it as a contradiction)
    // on two lines: on one it ran past a phone's chart, cut mid-word ("… of the da")
    { x, y: measured, name: "gain measured %<br>(hatched: readings under 99 % of the day)", type: "bar",
      marker: { color: COLORS.gain, opacity: partial.map((p) => (p ? 0.4 : 1)), pattern: { shape: partial.map((p) => (p ? "/" : "")) } },
      customdata: body.days.map((d, i) => (partial[i] ? ` (partial day: ${num(d.gain_measured_pct, 1)} %)` : "")),
      hovertemplate: "%{y:.1f} %%{customdata}" },
    { x, y: body.days.map((d) => d.gain_expected_pct), name: "gain expected for that sky %", type: "bar", marker: { color: COLORS.grey } },
    { x, y: pr, name: "tracker PR", yaxis: "y2", mode: "lines+markers", line: { color: COLORS.tracker } },
    ...(fixedPr.some((v) => v != null) ? [{ x, y: fixedPr, name: "fixed PR (sensor's sky)", yaxis: "y2",
      mode: "lines+markers", line: { color: COLORS.fixed, dash: "dot" } }] : []),
  ], baseLayout({ barmode: "group", margin: { l: 64, r: 84, t: 10, b: 52 },
    xaxis: { title: { text: `Day (${state.site.timezone})` }, type: "category", gridcolor: "#e9edf1" },
    yaxis: { title: { text: "tracking gain over the fixed array [%]" }, gridcolor: "#e9edf1", zeroline: true, ...gainAxis },
    yaxis2: { title: { text: "performance ratio (measured / expected)" }, overlaying: "y", side: "right", showgrid: false, ...prAxis } }),
  { columns: ["date", "complete", "partial", "sky_source", "clearness_index", "tracker_measured_wh", "tracker_expected_wh",
    "tracker_expected_wh_low", "tracker_expected_wh_high", "beam_unseen_expected_pct", "performance_ratio", "gain_measured_pct",
    "gain_expected_pct", "fixed_measured_wh", "fixed_expected_wh", "fixed_performance_ratio",
    "tracker_voltage_ratio", "tracker_current_ratio", "fixed_voltage_ratio", "fixed_current_ratio",
    "fixed_iec_performance_ratio"],
  rows: body.days.map((d) => [d.date, d.complete, d.partial, d.sky.sensor || d.sky.source, d.sky.clearness_index,
    d.tracker.measured_wh, d.tracker.expected_wh, d.tracker.expected_wh_low, d.tracker.expected_wh_high,
    d.sky.beam_unseen_expected_pct, d.tracker.performance_ratio, d.gain_measured_pct, d.gain_expected_pct,
    d.fixed.measured_wh, d.fixed.expected_wh, d.fixed.performance_ratio,
    d.tracker.voltage_ratio ?? null, d.tracker.current_ratio ?? null, d.fixed.voltage_ratio ?? null,
    d.fixed.current_ratio ?? null, d.fixed.iec_performance_ratio ?? null]),
  filename: `${state.site.site_id}_diagnosis_${start}_${end}.csv` });
  // no tracker reading at all in the range: the pointing card says so, not that its logger
  // sends no encoder angles (a tester's empty database)
  const trackerRead = body.days.some((d) => d.tracker.measured_wh !== null);
  if (mine === requested) await loadPointing(state, start, end, mine, trackerRead);
}

/** The pointing error the tracker's own encoders report (GET …/pointing), beside the
 * power-based diagnosis: every sunlit minute, split into azimuth and elevation. */
async function loadPointing(state, start, end, mine, trackerRead = true) {
  const note = document.getElementById("pointing-note");
  if (!note) return;
  const tz = state.site.timezone;
  note.textContent = "Loading the pointing error…";
  showEmpty("chart-pointing", "Loading…"); // never the previous site's under this one's name
  let body;
  try {
    body = await api(`/api/v1/sites/${encodeURIComponent(state.site.site_id)}/pointing`, { params: { start, end } });
    if (mine !== requested) return; // a later load (another site, range) draws instead
  } catch (err) {
    if (mine !== requested) return;
    note.textContent = `Pointing error failed: ${err.message}`;
    showEmpty("chart-pointing", "No pointing data");
    return;
  }
  if (!body.minutes) {
    note.textContent = !body.array ? "This site has no tracker."
      : !trackerRead ? "No readings from the tracker's logger in this range: no encoder angles to compare with the sun."
      : "The tracker's logger reports no encoder angles (azimuth_deg, elevation_deg) while the sun is up in this range: send them with the readings to see the pointing error measured directly.";
    showEmpty("chart-pointing", body.array && !trackerRead ? "No readings" : "No encoder angles");
    return;
  }
  const s = body.summary;
  // readings, not minutes (a 1-s logger's 72 readings had read "72 sunlit minutes"); the
  // encoders' own view: a mount error they cannot see is the camera's (a researcher read
  // "cosine loss 0.00 %" beside a camera that saw 45 mrad)
  note.textContent = `${body.minutes} readings with the sun up: RMS ${num(s.rms_deg, 2)}°, 95 % under ${num(s.p95_deg, 2)}°, `
    + `max ${num(s.max_deg, 2)}°; mean azimuth error ${num(s.mean_azimuth_error_deg, 2)}°, `
    + `elevation ${num(s.mean_elevation_error_deg, 2)}°; cosine loss ${num(s.mean_cos_loss_pct, 2)} %`
    + (body.points_step > 1 ? ` (chart: every ${body.points_step}th reading)` : "")
    + ". The encoders' angles against the sun: a mount error they cannot see (a tilted pedestal, an"
    + " encoder's zero) is measured by the tracker's camera, on the Pointing page.";
  // a gap (night, a dropout) breaks the lines instead of bridging it
  const gapMs = 10 * 60_000 * body.points_step;
  const x = [];
  const ys = { error_deg: [], azimuth_error_deg: [], elevation_error_deg: [] };
  let last = null;
  for (const p of body.points) {
    const ms = Date.parse(p.ts);
    if (last !== null && ms - last > gapMs) {
      x.push(toLocalWall(tz, last + 60_000));
      for (const k in ys) ys[k].push(null);
    }
    x.push(toLocalWall(tz, ms));
    for (const k in ys) ys[k].push(p[k]);
    last = ms;
  }
  await draw("chart-pointing", [
    { x, y: ys.error_deg, name: "pointing error °", mode: "lines", line: { color: COLORS.tracker } },
    { x, y: ys.azimuth_error_deg, name: "azimuth error °", mode: "lines", line: { color: COLORS.fixed, width: 1 } },
    { x, y: ys.elevation_error_deg, name: "elevation error °", mode: "lines", line: { color: COLORS.sun, width: 1 } },
  ], baseLayout({ // the times are the site's wall clock: the axis says so (it had no title)
    xaxis: { title: { text: `Local time (${tz})` }, type: "date", gridcolor: "#e9edf1" },
    yaxis: { title: { text: "error against the ephemeris sun [°]" }, gridcolor: "#e9edf1", rangemode: "normal" } }),
  { columns: ["time_utc", "azimuth_deg", "elevation_deg", "sun_azimuth_deg", "sun_elevation_deg", "error_deg",
    "azimuth_error_deg", "elevation_error_deg"],
  rows: body.points.map((p) => [p.ts, p.azimuth_deg, p.elevation_deg, p.sun_azimuth_deg, p.sun_elevation_deg,
    p.error_deg, p.azimuth_error_deg, p.elevation_error_deg]),
  filename: `${state.site.site_id}_pointing_${start}_${end}.csv` });
}

let seen = false; // the panel has scrolled into view once: later changes reload it at once
let shownFor = ""; // the site and day its range was set for

function setRange(state) {
  document.getElementById("diag-end").value = addDays(state.day, 1);
  document.getElementById("diag-start").value = addDays(state.day, -6);
  shownFor = `${state.site?.site_id}/${state.day}`;
}

/** Another site, or another day in an edited address: the 7 days up to it, loaded again (the
 * panel kept the previous site's days under the new site's name). */
function follow(state) {
  if (!state.site || `${state.site.site_id}/${state.day}` === shownFor) return;
  setRange(state);
  if (seen) load(state);
}

/** Wire the panel once; the range defaults to the 7 days up to the selected day. */
export function init(state) {
  const form = document.getElementById("diag-form");
  if (!form || !state.site) return;
  setRange(state);
  form.addEventListener("submit", (ev) => { ev.preventDefault(); load(state); });
  // main.js and the Overview update the shared state in their listeners, registered first
  document.getElementById("site-select").addEventListener("change", () => follow(state));
  window.addEventListener("hashchange", () => { if (state.page === "overview") follow(state); });
  // computed when the panel first scrolls into view, not on every page load
  const card = document.getElementById("diagnosis-card");
  const observer = new IntersectionObserver((entries) => {
    if (entries.some((e) => e.isIntersecting)) { observer.disconnect(); seen = true; load(state); }
  });
  observer.observe(card);
}
