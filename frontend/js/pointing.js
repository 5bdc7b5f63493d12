// Pointing: the tracker's mount fitted from the sun's offsets in its own camera
// (GET /api/v1/sites/{id}/pointing-model, docs/pointing-model.md): the terms with their
// standard errors, the offsets against azimuth and elevation before and after the model,
// and the pointing error through the day before and after it.
import { api } from "./api.js";
import { COLORS, baseLayout, draw, showEmpty } from "./charts.js";
import { addDays, toLocalWall } from "./time.js";
import { h, num, remember, sayInvalid } from "./ui.js";

/** The terms in words (docs/pointing-model.md, "Definitions"). */
export const TERM_WORDS = {
  azimuth_zero_deg: "azimuth zero (a pedestal yaw)",
  elevation_zero_deg: "elevation zero",
  pedestal_tilt_north_deg: "pedestal tilt toward north",
  pedestal_tilt_east_deg: "pedestal tilt toward east",
  collimation_deg: "camera collimation",
  nonperpendicularity_deg: "axis non-perpendicularity",
};

const CHARTS = ["chart-pointing-day", "chart-pointing-azimuth", "chart-pointing-elevation"];
const MRAD_PER_DEG = (Math.PI / 180) * 1000;
const $ = (id) => document.getElementById(id);

let st = null;
let requested = 0; // the latest load; an older answer that arrives later is dropped

const rms = (xs) => Math.sqrt(xs.reduce((s, v) => s + v * v, 0) / Math.max(xs.length, 1));

/** The terms table: value and standard error in degrees and milliradians, and whether the
 * sky coverage of the range separates the term from the others. */
export function termsTable(body) {
  const corr = new Map();
  for (const c of body.correlated) for (const t of c.terms) corr.set(t, c);
  const head = h("tr", {}, h("th", {}, "term"), h("th", {}, "value [°]"), h("th", {}, "± std [°]"),
    h("th", {}, "value [mrad]"), h("th", {}, "± std [mrad]"), h("th", {}, "separated by the data"));
  const rows = Object.entries(body.terms).map(([name, t]) => {
    const c = corr.get(name);
    const other = c ? c.terms.find((x) => x !== name) : null;
    const sep = body.identifiable.includes(name) ? "yes"
      : c ? `no: correlates with ${TERM_WORDS[other] || other} (r = ${num(c.correlation, 2)})`
        : t.std !== null ? `no: ± ${num(t.std * MRAD_PER_DEG, 2)} mrad, not determined` : "no";
    return h("tr", { "data-testid": "pointing-term", "data-term": name },
      h("td", { title: name }, TERM_WORDS[name] || name, " ", h("code", { class: "muted" }, name)),
      h("td", {}, num(t.value, 4)), h("td", {}, t.std === null ? "—" : num(t.std, 4)),
      h("td", {}, num(t.value * MRAD_PER_DEG, 2)), h("td", {}, t.std === null ? "—" : num(t.std * MRAD_PER_DEG, 2)),
      h("td", {}, sep));
  });
  return [head, ...rows];
}

const HOW_TO_SEND = "The model is fitted from the tracker's readings that carry the sun's offset in its "
  + "camera: send sun_offset_x_mrad and sun_offset_y_mrad with azimuth_deg and elevation_deg (the encoder angles) "
  + "in the readings (POST /api/v1/sites/{id}/measurements, JSON, CSV or MQTT), or post the tracker camera's "
  + "frames with their time and encoder angles to POST /api/v1/sites/{id}/pointing-model/observations; "
  + "at least 10 observations, best over a whole day of sky (docs/pointing-model.md).";

/** The page without a fit: `message` says why, then what to send (`hint`). */
function emptyState(message, hint = HOW_TO_SEND, chartText = "No camera offsets") {
  $("pointing-empty").replaceChildren(h("p", {}, message), h("p", { class: "muted" }, hint));
  $("pointing-empty").hidden = false;
  $("pointing-results").hidden = true;
  for (const id of CHARTS) showEmpty(id, chartText);
}

/** Whether the site has a tracker array to fit (the site list's arrays, `kind`). */
const hasTracker = (site) => Object.values(site.arrays || {}).some((a) => a.kind === "tracker");

/** Two panels on one x axis: the offsets before the model (top) and after it (bottom),
 * x (toward increasing azimuth) and y (toward increasing elevation) in each. */
function offsetTraces(xs, p, inl, out) {
  const pick = (arr, idx) => idx.map((i) => arr[i]);
  const marker = (color, opacity) => ({ color, size: 4, opacity });
  return [
    { x: pick(xs, inl), y: pick(p.sun_offset_x_mrad, inl), name: "x before", mode: "markers", type: "scatter", marker: marker(COLORS.tracker, 0.6) },
    { x: pick(xs, inl), y: pick(p.sun_offset_y_mrad, inl), name: "y before", mode: "markers", type: "scatter", marker: marker(COLORS.fixed, 0.6) },
    { x: pick(xs, out), y: pick(p.sun_offset_x_mrad, out), name: "outliers (glints), left out", mode: "markers", type: "scatter",
      marker: { color: COLORS.grey, size: 6, symbol: "x" } },
    { x: pick(xs, inl), y: pick(p.residual_x_mrad, inl), name: "x after", mode: "markers", type: "scatter", yaxis: "y2", marker: marker(COLORS.tracker, 0.9) },
    { x: pick(xs, inl), y: pick(p.residual_y_mrad, inl), name: "y after", mode: "markers", type: "scatter", yaxis: "y2", marker: marker(COLORS.fixed, 0.9) },
  ];
}

function offsetLayout(xTitle) {
  return baseLayout({
    hovermode: "closest", margin: { l: 64, r: 20, t: 10, b: 46 },
    xaxis: { title: { text: xTitle }, anchor: "y2", gridcolor: "#e9edf1", zeroline: false },
    yaxis: { title: { text: "before [mrad]" }, domain: [0.54, 1], gridcolor: "#e9edf1", zeroline: true, rangemode: "normal" },
    yaxis2: { title: { text: "after [mrad]" }, domain: [0, 0.44], anchor: "x", gridcolor: "#e9edf1", zeroline: true, rangemode: "normal" },
  });
}

async function load() {
  const state = st;
  if (!state?.site) return;
  const start = $("pointing-start").value;
  const end = $("pointing-end").value;
  const status = $("pointing-status");
  const mine = ++requested;
  const siteId = encodeURIComponent(state.site.site_id);
  // an empty state asks for no fit that must fail (a 422 in the console): a site without a
  // tracker asks nothing, a range is first counted (…/coverage), and a range the service
  // would refuse is said here
  if (!hasTracker(state.site)) {
    status.textContent = "";
    emptyState(`${state.site.name || state.site.site_id} has no tracker array (a camera site, or fixed arrays `
      + "only): there is no mount to fit.", "The Pointing page fits a tracker's mount from the sun's offsets in "
      + "the tracker's own camera; choose a site with a tracker in the header.", "No tracker at this site");
    return;
  }
  if (!start || !end || end <= start) {
    status.textContent = !start || !end ? "Give the range's start and end." : "The end must come after the start.";
    return;
  }
  status.textContent = "Fitting…";
  let body;
  try {
    const cover = await api(`/api/v1/sites/${siteId}/pointing-model/coverage`, { params: { start, end } });
    if (mine !== requested) return;
    if (cover.n_observations < cover.min_observations) {
      status.textContent = "";
      emptyState(`No pointing model for ${start} to ${end}: ${cover.n_observations} observations with sun offsets `
        + `(sun_offset_x_mrad, sun_offset_y_mrad and the encoder angles) in the range; the fit needs at least `
        + `${cover.min_observations}.`);
      return;
    }
    body = await api(`/api/v1/sites/${siteId}/pointing-model`, { params: { start, end } });
  } catch (err) {
    if (mine !== requested) return;
    status.textContent = `Pointing model failed: ${err.message}`;
    for (const id of CHARTS) showEmpty(id, "No pointing model");
    $("pointing-empty").hidden = true;
    $("pointing-results").hidden = true;  // the previous range's fit is not this one's
    return;
  }
  if (mine !== requested) return;
  $("pointing-empty").hidden = true;
  $("pointing-results").hidden = false;
  const p = body.points;
  const n = p.ts.length;
  const all = [...Array(n).keys()];
  const inl = all.filter((i) => !p.outlier[i]);
  const out = all.filter((i) => p.outlier[i]);
  const before = inl.map((i) => Math.hypot(p.sun_offset_x_mrad[i], p.sun_offset_y_mrad[i]));
  const after = inl.map((i) => Math.hypot(p.residual_x_mrad[i], p.residual_y_mrad[i]));
  status.textContent = "";
  $("pointing-summary").textContent = `${body.n_observations} camera observations, ${body.n_outliers} rejected as outliers; `
    + `pointing error RMS ${num(rms(before), 1)} mrad as the mount is, ${num(rms(after), 2)} mrad after the model `
    + `(the residual RMS per axis: ${num(body.residual_rms_mrad, 2)} mrad)`
    + (p.stride > 1 ? `; the charts show every ${p.stride}th observation` : "") + ".";
  $("pointing-terms").replaceChildren(...termsTable(body));
  const tz = state.site.timezone;
  const when = p.ts.map((t) => toLocalWall(tz, t));
  const table = (filename) => ({
    columns: ["time_utc", "time_local", "azimuth_deg", "elevation_deg", "sun_offset_x_mrad", "sun_offset_y_mrad",
      "residual_x_mrad", "residual_y_mrad", "outlier"],
    rows: all.map((i) => [p.ts[i], when[i], p.azimuth_deg[i], p.elevation_deg[i], p.sun_offset_x_mrad[i],
      p.sun_offset_y_mrad[i], p.residual_x_mrad[i], p.residual_y_mrad[i], p.outlier[i]]),
    filename: `${state.site.site_id}_pointing_model_${start}_${end}_${filename}.csv`,
  });
  const pick = (arr, idx) => idx.map((i) => arr[i]);
  await draw("chart-pointing-day", [
    { x: pick(when, inl), y: before, name: "as the mount is (|offset|)", mode: "markers", type: "scatter",
      marker: { color: COLORS.grey, size: 4 } },
    { x: pick(when, inl), y: after, name: "after the model (|residual|)", mode: "markers", type: "scatter",
      marker: { color: COLORS.gain, size: 4 } },
    { x: pick(when, out), y: out.map((i) => Math.hypot(p.sun_offset_x_mrad[i], p.sun_offset_y_mrad[i])),
      name: "outliers (glints), left out", mode: "markers", type: "scatter", marker: { color: COLORS.sun, size: 6, symbol: "x" } },
  ], baseLayout({ hovermode: "closest",
    xaxis: { title: { text: `site time (${tz})` }, gridcolor: "#e9edf1" },
    yaxis: { title: { text: "pointing error [mrad] (log)" }, type: "log", dtick: 1, gridcolor: "#e9edf1" } }), table("day"));
  await draw("chart-pointing-azimuth", offsetTraces(p.azimuth_deg, p, inl, out), offsetLayout("encoder azimuth [°]"), table("azimuth"));
  await draw("chart-pointing-elevation", offsetTraces(p.elevation_deg, p, inl, out), offsetLayout("encoder elevation [°]"), table("elevation"));
  document.body.dataset.pointing = `${state.site.site_id}/${start}/${end}`;
}

function setRange(state) {
  $("pointing-end").value = addDays(state.day, 1);
  $("pointing-start").value = addDays(state.day, -6);
}

/** Wire the page once; the range defaults to the 7 days up to the selected day. */
export function init(state) {
  st = state;
  setRange(state);
  $("pointing-form").addEventListener("submit", (ev) => {
    ev.preventDefault();
    remember(st, "pointing");
    load();
  });
  sayInvalid($("pointing-form"), (message) => { $("pointing-status").textContent = message; });
  load();
}

export function show(state) {
  st = state;
}

export function siteChanged(state, visible) {
  st = state;
  setRange(state);
  if (visible) load();
}
