// Plant: a plant of dual-axis trackers seen from above with each collector's shade through a
// clear-sky day, the strategies compared, and seed 004's sky map with the chosen orientation;
// below, the plant on an uploaded weather file (POST /api/v1/plants/{id}/weather) and a sweep
// of regular layouts and spacings at the plant's place (issue 26).
import { api, apiObjectUrl, storedToken } from "./api.js";
import { COLORS, baseLayout, draw, showEmpty, zeroBasedAxis } from "./charts.js";
import { addDays, fmtTime } from "./time.js";
import { banner, energy, num, pct, sayInvalid, skyTile, stowTile, tile, weatherWarning } from "./ui.js";

const $ = (id) => document.getElementById(id);
const enc = encodeURIComponent;

const view = { plants: [], plant: null, day: null, index: 0, token: 0 };

function localDateIn(tz) {
  return new Intl.DateTimeFormat("en-CA", { timeZone: tz, year: "numeric", month: "2-digit", day: "2-digit" })
    .format(new Date());
}

// the layout's colour scale of the shaded fraction: [0, 1] of [0, cmax]
const SHADE_SCALE = ["#d3f9d8", "#343a40"];

/** The colour Plotly gives `f` on SHADE_SCALE from 0 to `cmax` (RGB interpolation): the fill
 * of a collector's outline, which is a shape and not part of the trace's colour scale. */
function shadeColor(f, cmax) {
  const s = Math.min(1, Math.max(0, f / cmax));
  const [a, b] = SHADE_SCALE.map((hex) => [1, 3, 5].map((i) => parseInt(hex.slice(i, i + 2), 16)));
  return `rgb(${a.map((v, i) => Math.round(v + s * (b[i] - v))).join(",")})`;
}

/** The collectors' colour on a day without sun: no shade to show. */
const NIGHT_GREY = "#ced4da";

/** A polygon collector's outline (PlantRead.collector.outline_m, [u, v] m about the pivot)
 * laid flat at its pivot, u east and v north, as an SVG path in the chart's metres. */
function outlinePath(outline, t) {
  return `M${outline.map(([u, v]) => `${t.east_m + u},${t.north_m + v}`).join("L")}Z`;
}

async function drawLayout() {
  const p = view.plant;
  const d = view.day;
  if (!p || !d) return;                 // no day loaded (clearDay said why)
  // a polar night: the layout all the same (it was not drawn at all), grey, with no shade to
  // colour and the reason said over it; no instant, nor the previous plant's time under it
  const night = !d.times.length;
  const row = night ? [] : d.shaded_fraction[view.index] || [];
  const east = p.trackers.map((t) => t.east_m);
  const north = p.trackers.map((t) => t.north_m);
  const f = row.map((v) => (v > 0 ? v : 0));
  const cmax = Math.max(0.05, ...f);
  const text = p.trackers.map((t, k) => `tracker ${t.tracker_id}<br>`
    + (night ? "no sun on this day" : `shaded ${num(100 * (row[k] || 0), 1)} %`));
  const ids = p.trackers.map((t) => String(t.tracker_id));
  const marker = night ? { color: NIGHT_GREY, line: { color: "#495057", width: 1 } }
    : { color: f, cmin: 0, cmax, colorscale: [[0, SHADE_SCALE[0]], [1, SHADE_SCALE[1]]],
      line: { color: "#495057", width: 1 }, colorbar: { title: { text: "shaded [-]" }, thickness: 12 } };
  const pivots = { type: "scatter", x: east, y: north, hovertext: text, hoverinfo: "text", name: "shaded fraction" };
  // a rectangle: a square marker per collector; a polygon: its outline to scale, filled with
  // the shade's colour (shapes), a dot at the pivot and the id above the outline
  const outline = p.collector.outline_m;
  const top = outline ? Math.max(...outline.map(([, v]) => v)) : 0;
  const traces = outline ? [
    { ...pivots, mode: "markers", marker: { ...marker, symbol: "circle", size: 5 } },
    { type: "scatter", mode: "text", x: east, y: north.map((n) => n + top), text: ids, textposition: "top center", hoverinfo: "skip" },
  ] : [{ ...pivots, mode: "markers+text", text: ids, textposition: "top center", marker: { ...marker, symbol: "square", size: 22 } }];
  const shapes = outline ? p.trackers.map((t, k) => ({
    type: "path", layer: "between", path: outlinePath(outline, t),
    fillcolor: night ? NIGHT_GREY : shadeColor(f[k], cmax), line: { color: "#495057", width: 1 },
  })) : [];
  const annotations = night ? [{ text: "No daylight on this day: the sun stays below the horizon.",
    xref: "paper", yref: "paper", x: 0.5, y: 1, xanchor: "center", yanchor: "bottom", showarrow: false,
    font: { size: 13, color: "#495057" } }] : [];
  await draw("chart-plant-layout", traces, baseLayout({
    hovermode: "closest", showlegend: false, shapes, annotations,
    xaxis: { title: { text: "east [m]" }, gridcolor: "#e9edf1", zeroline: false, scaleanchor: "y" },
    yaxis: { title: { text: "north [m]" }, gridcolor: "#e9edf1", zeroline: false },
    margin: { l: 60, r: 20, t: night ? 30 : 10, b: 46 },
  }), {
    columns: ["tracker_id", "east_m", "north_m", "shaded_fraction"],
    rows: p.trackers.map((t, k) => [t.tracker_id, t.east_m, t.north_m, row[k] ?? null]),
    filename: night ? `${p.plant_id}-layout-${d.date}.csv` : `${p.plant_id}-shade-${d.times[view.index]}.csv`,
  });
  $("plant-time-label").textContent = night ? "" : `${fmtTime(p.timezone, d.times[view.index])} (${p.timezone})`;
}

async function drawShadeDay() {
  const d = view.day;
  if (!d.times.length) { showEmpty("chart-plant-shade", "No daylight on this day."); return; }
  const tz = view.plant.timezone;
  const x = d.times.map((t) => new Date(t).toLocaleString("sv-SE", { timeZone: tz }));
  const shaded = d.shaded_fraction.map((r) => r.filter((v) => v > 0).length);
  const mean = d.shaded_fraction.map((r) => r.reduce((a, b) => a + b, 0) / r.length);
  await draw("chart-plant-shade", [
    { type: "scatter", mode: "lines+markers", x, y: shaded, name: "collectors shaded", line: { color: COLORS.tracker } },
    { type: "scatter", mode: "lines", x, y: mean.map((v) => 100 * v), name: "mean shaded [%]", yaxis: "y2", line: { color: COLORS.grey } },
  ], baseLayout({ // the plant's wall clock, said (the axis had no title)
    xaxis: { title: { text: `Local time (${tz})` }, type: "date", gridcolor: "#e9edf1" },
    yaxis: { title: { text: "collectors shaded [-]" }, rangemode: "tozero", gridcolor: "#e9edf1" },
    // round ticks (Plotly's own fell on 10.9, 21.7, 32.6 …: a tester's finding)
    yaxis2: { title: { text: "mean shaded [%]" }, overlaying: "y", side: "right", showgrid: false,
      ...zeroBasedAxis(mean.map((v) => 100 * v)) },
  }), {
    columns: ["time_utc", "local_time", "collectors_shaded", "mean_shaded_pct"],
    rows: d.times.map((t, k) => [t, x[k], shaded[k], 100 * mean[k]]),
    filename: `${view.plant.plant_id}-shade-${d.date}.csv`,
  });
}

/** The plant's ground cover ratio (PlantRead.gcr): collector area over the ground it covers. */
function gcrTile(p) {
  return tile("Ground cover ratio", p.gcr == null ? "—" : num(p.gcr, 3),
    p.gcr == null ? "fewer than 3 trackers: no ground area"
      : `collector area / ${num(p.land_m2 / 1e4, 2)} ha of ground`);
}

async function drawStrategies() {
  const s = view.day.strategies;
  if (!view.day.times.length) {  // a polar night: no energy to compare (a tester's finding:
    // empty axes and a "0.0 %" shaded tile from 100 × null)
    showEmpty("chart-plant-strategies", "No daylight on this day.");
    $("plant-summary").replaceChildren(tile("Trackers", String(view.plant.trackers.length), view.plant.name),
      gcrTile(view.plant), tile("Daylight shaded", "—", "no daylight on this day"));
    return;
  }
  // PlantDayRead: the strategies the plant can take (PlantRead.strategies) and fixed
  const names = [...view.plant.strategies, "fixed"].filter((n) => s[n]);
  const y = names.map((n) => s[n].plant_energy_wh);
  const color = { sun: COLORS.sun, backtrack: COLORS.tracker, sky_scan: COLORS.gain, fixed: COLORS.fixed };
  await draw("chart-plant-strategies", [{
    type: "bar", x: names, y: y.map((v) => v / 1000), name: "plant energy",
    marker: { color: names.map((n) => color[n]) },
    text: y.map((v) => energy(v)), textposition: "auto",
  }], baseLayout({ hovermode: "closest", showlegend: false, yaxis: { title: { text: "plant energy [kWh]" }, rangemode: "tozero" } }), {
    columns: ["strategy", "plant_energy_wh"], rows: names.map((n, k) => [n, y[k]]),
    filename: `${view.plant.plant_id}-strategies-${view.day.date}.csv`,
  });
  const box = $("plant-summary");
  box.innerHTML = "";
  const sun = s.sun;
  box.append(
    tile("Trackers", String(view.plant.trackers.length), view.plant.name),
    gcrTile(view.plant),
    tile("Shading loss (sun)", `${num(sun.shading_loss_electrical_pct, 2)} %`, `bypass diodes; ${num(sun.shading_loss_area_pct, 2)} % by area`),
    tile("Daylight shaded", sun.fraction_of_daylight_any_shaded == null ? "—"
      : `${num(100 * sun.fraction_of_daylight_any_shaded, 1)} %`, "of steps, any collector"),
    s.backtrack
      ? tile("Backtrack vs sun", sun.plant_energy_wh > 0 ? `${num(100 * (s.backtrack.plant_energy_wh / sun.plant_energy_wh - 1), 2)} %` : "—", "clear sky")
      : tile("Backtrack vs sun", "—", "a polygon collector takes sun tracking only"),
  );
}

function drawSkyMap() {
  const p = view.plant;
  const d = view.day;
  const img = $("plant-sky-map");
  if (!d || !d.times.length) {  // no instant to map: no image (its alt text showed as broken)
    img.removeAttribute("src");
    img.hidden = true;
    $("plant-chosen").textContent = d ? "No daylight on this day." : "";
    return;
  }
  const t = d.times[view.index];
  const strategy = $("plant-strategy").value;
  // the 3D page's plant view at this instant and strategy (frontend/js/twin.js)
  $("plant-3d").href = `#twin?plant=${enc(p.plant_id)}&strategy=${enc(strategy)}&time=${enc(t)}`;
  img.dataset.time = t;
  img.dataset.loaded = "";
  // the previous instant's (or plant's) map is not shown under this one's caption while
  // the new one loads (a tester's finding: 10–15 s of another plant's sky for a large plant)
  img.style.opacity = "0.25";
  img.onload = () => { img.dataset.loaded = t; img.style.opacity = ""; };
  // PlantRead.strategies: the sky map's grey region is the rectangle's shade-free test
  img.hidden = !p.strategies.includes("sky_scan");
  if (img.hidden) img.removeAttribute("src");
  else {
    const src = `/api/v1/plants/${enc(p.plant_id)}/sky-map?time=${enc(t)}&strategy=${enc(strategy)}&format=png`;
    if (!storedToken()) img.src = src;
    else {
      // an <img> sends no token (HELIOTWIN_READ_REQUIRE_TOKEN): fetched with it, shown from a blob
      apiObjectUrl(src).then((url) => {
        if (img.dataset.time !== t) { URL.revokeObjectURL(url); return; }  // another instant's by now
        if (img.src.startsWith("blob:")) URL.revokeObjectURL(img.src);
        img.src = url;
      }).catch((err) => banner(`Sky map: ${err.message}`, "error"));
    }
  }
  api(`/api/v1/plants/${enc(p.plant_id)}/positions`, { params: { time: t, strategy } }).then((pos) => {
    if (view.day !== d) return;   // another day (or none) was loaded meanwhile: not its instant
    const tr = pos.trackers[0];
    $("plant-chosen").textContent = `${strategy}: azimuth ${num(tr.azimuth_deg, 1)}°, elevation ${num(tr.elevation_deg, 1)}° · ` +
      `sun ${num(pos.sun.azimuth_deg, 1)}°, ${num(pos.sun.elevation_deg, 1)}° · ${pos.trackers_shaded} collectors shaded` +
      (img.hidden ? " · no sky map: its grey region is the shade-free test of a rectangular collector, and this one is a polygon" : "");
  }).catch((err) => banner(`Positions: ${err.message}`, "error"));
}

async function loadDay() {
  const p = view.plant;
  const date = $("plant-day").value;
  if (!p || !date) return;
  const token = ++view.token;
  document.body.removeAttribute("data-plant-loaded");
  showEmpty("chart-plant-layout", "Loading…");
  try {
    const d = await api(`/api/v1/plants/${enc(p.plant_id)}/day`, { params: { date } });
    if (token !== view.token) return;
    view.day = d;
    // start at the first step with shade, else at noon
    const first = d.shaded_fraction.findIndex((r) => r.some((v) => v > 0));
    view.index = first >= 0 ? first : Math.floor(d.times.length / 2);
    const slider = $("plant-time");
    slider.max = String(Math.max(0, d.times.length - 1));
    slider.value = String(view.index);
    await Promise.all([drawLayout(), drawShadeDay(), drawStrategies()]);
    drawSkyMap();
    document.body.dataset.plantLoaded = `${p.plant_id}/${date}`;
  } catch (err) {
    if (token !== view.token) return;
    clearDay(`No day: ${err.message}`);
    banner(`Plant day: ${err.message}`, "error");
  }
}

/** Empty the day's tiles, charts and sky map (a day that failed to load must not leave the
 * previous day's figures under the new date). */
function clearDay(message) {
  view.day = null;
  view.index = 0;
  $("plant-time").max = "0";
  $("plant-time").value = "0";
  $("plant-time-label").textContent = "";
  $("plant-summary").replaceChildren();
  for (const id of ["chart-plant-layout", "chart-plant-shade", "chart-plant-strategies"]) showEmpty(id, message);
  $("plant-sky-map").removeAttribute("src");
  $("plant-chosen").textContent = "";
}

async function selectPlant(id) {
  const before = view.plant?.plant_id;
  view.plant = await api(`/api/v1/plants/${enc(id)}`);
  if (before && before !== id) {
    // the sweep panel is "at this plant's place": another plant's curves and case shade
    // (its solstice, its zone) stayed under the new plant (a tester's finding); a sweep
    // still running there is no longer followed here
    sweep.token++;
    sweepIdle();
    clearSweep(NO_SWEEP);
    sweepSay({ status: "", message: "" });
  }
  // the strategies this plant's collector can take (sun alone for a polygon)
  const select = $("plant-strategy");
  const keep = select.value;
  select.replaceChildren(...view.plant.strategies.map((s) => new Option(s, s)));
  select.value = view.plant.strategies.includes(keep) ? keep : view.plant.strategies.at(-1);
  if (!$("plant-day").value) $("plant-day").value = localDateIn(view.plant.timezone);
  weatherForPlant(before !== id);
  await loadDay();
}

// ── the plant on a weather file (POST /api/v1/plants/{plant_id}/weather) ──
let weatherToken = 0;

function weatherSay(status, message = "") {
  $("plant-weather-status").textContent = status;
  $("plant-weather-message").textContent = message;
  $("plant-weather-message").hidden = !message;
}

/** The weather form for the selected plant: its strategies, the day shown as the default
 * range; another plant's result is not left under this one (`changed`). */
function weatherForPlant(changed) {
  const select = $("plant-weather-strategy");
  const keep = select.value;
  select.replaceChildren(...view.plant.strategies.map((s) => new Option(s, s)));
  select.value = view.plant.strategies.includes(keep) ? keep : "sun";
  if (!$("plant-weather-start").value) {
    $("plant-weather-start").value = $("plant-day").value;
    $("plant-weather-end").value = addDays($("plant-day").value, 1);
  }
  if (changed) {
    weatherToken++;
    $("plant-weather-summary").replaceChildren();
    weatherSay("");
  }
}

/** The run's summary (PlantWeatherRunRead) as tiles: the weather warning first, the sky, the
 * strategy's energy against the fixed plant, the shading loss and the wind stow. */
function weatherTiles(s) {
  $("plant-weather-summary").replaceChildren(
    ...weatherWarning(s), skyTile(s, s.weather_station, "plant"),
    tile(`Plant energy (${s.strategy})`, energy(s.plant_energy_wh), `peak ${num(s.plant_peak_w / 1000, 1)} kW · bypass diodes`),
    tile("Fixed plant", energy(s.fixed_energy_wh), `gain ${pct(s.gain_vs_fixed_pct, 2)}`),
    tile("Shading loss", s.shading_loss_electrical_pct == null ? "—" : `${num(s.shading_loss_electrical_pct, 2)} %`,
      s.shading_loss_area_pct == null ? "no daylight" : `bypass diodes; ${num(s.shading_loss_area_pct, 2)} % by area`),
    ...stowTile(s));
}

async function runWeather(ev) {
  ev.preventDefault();
  const p = view.plant;
  const file = $("plant-weather-file").files[0];
  if (!p || !file) return;
  const form = new FormData();
  form.append("start", $("plant-weather-start").value);
  form.append("end", $("plant-weather-end").value);
  form.append("step_s", $("plant-weather-step").value);
  form.append("strategy", $("plant-weather-strategy").value);
  form.append("force", String($("plant-weather-force").checked));
  form.append("weather_stamped", $("plant-weather-stamped").value);
  const zone = $("plant-weather-timezone").value.trim();
  if (zone) form.append("weather_timezone", zone);
  form.append("file", file, file.name);
  const token = ++weatherToken;
  $("plant-weather-summary").replaceChildren();  // no previous run's figures under this one
  weatherSay(`Running ${p.plant_id} on ${file.name}…`);
  $("plant-weather-run").disabled = true;
  try {
    const s = await api(`/api/v1/plants/${enc(p.plant_id)}/weather`, { method: "POST", form });
    if (token !== weatherToken) return;
    weatherTiles(s);
    weatherSay(`${s.plant_id} on ${file.name}, ${s.start.slice(0, 10)} → ${s.end.slice(0, 10)} at ${num(s.step_s, 0)} s`);
  } catch (err) {
    if (token !== weatherToken) return;
    weatherSay("Not run.", err.message);   // the service's reason, naming the field
  } finally {
    $("plant-weather-run").disabled = false;
  }
}

export async function init() {
  initSweep();
  $("plant-weather-form").addEventListener("submit", runWeather);
  sayInvalid($("plant-weather-form"), (m) => weatherSay("", m));
  $("plant-day").addEventListener("change", loadDay);
  $("plant-time").addEventListener("input", () => {
    view.index = Number($("plant-time").value);
    drawLayout();
    drawSkyMap();
  });
  $("plant-strategy").addEventListener("change", drawSkyMap);
  $("plant-select").addEventListener("change", () => selectPlant($("plant-select").value));
  let skipped = [];
  try {
    [view.plants, skipped] = await Promise.all([api("/api/v1/plants"), api("/api/v1/plants/skipped")]);
  } catch (err) {
    banner(`Could not load the plants: ${err.message}`, "error");
    return;
  }
  // the plant files the service does not serve, and why (they were left out silently)
  $("plant-skipped").textContent = skipped.length
    ? `Not served (the file is invalid): ${skipped.map((s) => `${s.file}: ${s.reason}`).join("; ")}` : "";
  $("plant-skipped").hidden = !skipped.length;
  if (!view.plants.length) { banner("The service has no plants configured (data/plants/).", "warn"); return; }
  for (const p of view.plants) $("plant-select").add(new Option(`${p.plant_id} (${p.trackers})`, p.plant_id));
  const day = new URLSearchParams(location.hash.split("?")[1] || "").get("day");
  if (day && /^\d{4}-\d{2}-\d{2}$/.test(day)) $("plant-day").value = day;
  await selectPlant(view.plants[0].plant_id);
}

// ── the layout and spacing sweep (POST /api/v1/plants/sweeps, issue 26) ──
// id: the sweep whose rows are drawn; following: the one being polled (the Cancel button's);
// stopping: its cancel was accepted
const sweep = { id: null, rows: [], token: 0, following: null, stopping: false };
const SWEEP_CHARTS = ["chart-sweep-energy", "chart-sweep-tradeoff", "chart-sweep-shade"];
const NO_SWEEP = "Run a sweep at this plant's place.";

/** The sweep's words in the panel: `status` its progress and outcome, `message` what went
 * wrong (a refused request, a cancel that failed), kept until the next sweep is asked for. */
function sweepSay({ status, message } = {}) {
  if (status !== undefined) $("sweep-status").textContent = status;
  if (message !== undefined) {
    $("sweep-message").textContent = message;
    $("sweep-message").hidden = !message;
  }
}

/** No sweep followed: its Cancel hidden, Run offered again. */
function sweepIdle() {
  sweep.following = null;
  $("sweep-cancel").hidden = true;
  $("sweep-run").disabled = false;
}

/** Nothing of an earlier sweep stays while another is asked for, nor after it is refused: a
 * refused sweep left the previous one's curves and cases under its error. */
function clearSweep(message) {
  sweep.id = null;
  sweep.rows = [];
  for (const id of SWEEP_CHARTS) showEmpty(id, message);
  $("sweep-case").replaceChildren();
  document.body.removeAttribute("data-sweep-loaded");
}

const DASH = { sun: "solid", backtrack: "dash", sky_scan: "dot" };
const LAYOUT_COLORS = { square: COLORS.tracker, diagonal: COLORS.fixed, hexagonal_n_s: COLORS.gain,
  hexagonal_e_w: COLORS.sun, custom: COLORS.grey, plant: COLORS.grey };

function curves() {
  const groups = new Map();
  for (const r of sweep.rows) {
    const key = `${r.layout} · ${r.strategy}`;
    if (!groups.has(key)) groups.set(key, []);
    groups.get(key).push(r);
  }
  for (const rows of groups.values()) rows.sort((a, b) => a.gcr - b.gcr);
  return groups;
}

// The sweep's curves are the interior collector's energy (interior_energy_*): what a large
// plant's collectors get. The field average (energy_*) of a 5x5 field, 16 of whose 25
// collectors are on its edge, ranked sun above backtrack where the interior ranks them the
// other way (a tester's finding); it stays in the hover and the CSV.
async function drawSweep() {
  const groups = curves();
  const style = (rows) => ({ color: LAYOUT_COLORS[rows[0].layout] || COLORS.grey, dash: DASH[rows[0].strategy] || "solid" });
  const hover = (r) => `GCR ${r.gcr}: interior collector ${num(r.interior_energy_kwh / 1000, 2)} MWh, ` +
    `${num(r.interior_energy_mwh_per_ha, 0)} MWh/ha; field average (${r.collectors} collectors) ` +
    `${num(r.energy_kwh_per_collector / 1000, 2)} MWh, ${num(r.energy_mwh_per_ha, 0)} MWh/ha; ` +
    `${num(r.land_m2_per_collector, 0)} m² per collector, interior ${num(r.interior_beam_shaded_pct, 2)} % of beam shaded`;
  const perCollector = [...groups].map(([name, rows]) => ({
    type: "scatter", mode: "lines+markers", name: `${name}, per collector`, x: rows.map((r) => r.gcr),
    y: rows.map((r) => r.interior_energy_kwh / 1000), line: style(rows), legendgroup: name,
    text: rows.map(hover), hoverinfo: "text+name",
  }));
  const perHa = [...groups].map(([name, rows]) => ({
    type: "scatter", mode: "lines", name: `${name}, per ha`, x: rows.map((r) => r.gcr), yaxis: "y2",
    y: rows.map((r) => r.interior_energy_mwh_per_ha), line: { ...style(rows), width: 1 }, legendgroup: name, showlegend: false,
    text: rows.map(hover), hoverinfo: "text+name",
  }));
  const columns = ["layout", "strategy", "gcr", "interior_beam_shaded_pct", "field_beam_shaded_pct",
    "interior_energy_kwh", "interior_energy_mwh_per_ha", "energy_kwh_per_collector", "energy_mwh_per_ha",
    "land_m2_per_collector", "collectors"];
  const table = { columns, rows: sweep.rows.map((r) => columns.map((c) => r[c])), filename: `sweep-${sweep.id}.csv` };
  await draw("chart-sweep-energy", [...perCollector, ...perHa], baseLayout({
    xaxis: { title: { text: "ground cover ratio [-]" }, gridcolor: "#e9edf1" },
    yaxis: { title: { text: "interior collector [MWh] (thick)" }, gridcolor: "#e9edf1" },
    // round ticks on the right too (Plotly's own fell on 112, 336, 560…: a tester's finding)
    // short: the long "interior collector per hectare …" ran past a plot made low by a
    // legend of two rows and was cut at both ends (a tester's screenshot)
    yaxis2: { title: { text: "per hectare [MWh/ha] (thin)" }, overlaying: "y", side: "right",
      ...zeroBasedAxis(sweep.rows.map((r) => r.interior_energy_mwh_per_ha)) },
    hovermode: "closest",
  }), table);
  await draw("chart-sweep-tradeoff", [...groups].map(([name, rows]) => ({
    type: "scatter", mode: "lines+markers", name, x: rows.map((r) => r.interior_energy_mwh_per_ha),
    y: rows.map((r) => r.interior_energy_kwh / 1000), line: style(rows),
    text: rows.map(hover), hoverinfo: "text+name",
  })), baseLayout({
    xaxis: { title: { text: "interior collector's energy per hectare [MWh/ha]" }, gridcolor: "#e9edf1" },
    yaxis: { title: { text: "interior collector's energy [MWh]" }, gridcolor: "#e9edf1" },
    hovermode: "closest",
  }), table);
  const select = $("sweep-case");
  select.innerHTML = "";
  for (const r of sweep.rows) select.add(new Option(`${r.layout} · GCR ${r.gcr} · ${r.strategy}`, JSON.stringify([r.layout, r.gcr, r.strategy])));
  const densest = sweep.rows.reduce((a, r) => (r.gcr > a.gcr ? r : a), sweep.rows[0]);
  select.value = JSON.stringify([densest.layout, densest.gcr, densest.strategy]);
  await drawSweepShade().catch((err) => {  // the sweep's curves stand without its shade
    showEmpty("chart-sweep-shade", `Shade unavailable: ${err.message}`);
    banner(`Sweep shade: ${err.message}`, "error");
  });
}

async function drawSweepShade() {
  if (!sweep.id || !$("sweep-case").value) return;
  const [layout, gcr, strategy] = JSON.parse($("sweep-case").value);
  const tz = view.plant.timezone;
  // the service's day: the winter solstice of the place's hemisphere in the sweep's year (the
  // longest shadows), or the day nearest to it with daylight (a polar night drew bare axes)
  const d = await api(`/api/v1/plants/sweeps/${enc(sweep.id)}/shade`, { params: { layout, gcr, strategy } });
  $("sweep-shade-day").textContent = new Date(`${d.date}T12:00:00Z`)
    .toLocaleDateString("en-GB", { day: "numeric", month: "long", year: "numeric", timeZone: "UTC" });
  if (!d.times.length) { showEmpty("chart-sweep-shade", "No daylight on this day."); return; }
  const x = d.times.map((t) => fmtTime(tz, t));
  await draw("chart-sweep-shade", [
    { type: "scatter", mode: "lines+markers", x, y: d.interior_shaded_fraction.map((v) => 100 * v), name: "interior collector", line: { color: COLORS.tracker } },
    { type: "scatter", mode: "lines", x, y: d.field_mean_shaded_fraction.map((v) => 100 * v), name: `field average (${d.positions_m.length} collectors)`, line: { color: COLORS.grey } },
    { type: "scatter", mode: "lines", x, y: d.sun_elevation_deg, name: "sun elevation [°]", yaxis: "y2", line: { color: COLORS.sun, dash: "dot" } },
  ], baseLayout({
    xaxis: { title: { text: `time (${tz})` }, type: "category" },
    // a share is 0–100 % (an unshaded case drew 0–1 "%"); round ticks on the sun's axis
    yaxis: { title: { text: "shaded [%]" }, range: [0, 100], dtick: 20, autorange: false, gridcolor: "#e9edf1" },
    yaxis2: { title: { text: "sun elevation [°]" }, overlaying: "y", side: "right", showgrid: false, ...zeroBasedAxis(d.sun_elevation_deg) },
  }), {
    columns: ["time_utc", "interior_shaded_pct", "field_mean_shaded_pct", "sun_elevation_deg"],
    rows: d.times.map((t, k) => [t, 100 * d.interior_shaded_fraction[k], 100 * d.field_mean_shaded_fraction[k], d.sun_elevation_deg[k]]),
    filename: `sweep-${layout}-${gcr}-${strategy}-shade.csv`,
  });
}

async function runSweep(ev) {
  ev.preventDefault();
  const p = view.plant;
  if (!p || sweep.following) return;   // one sweep followed at a time (Cancel stops it)
  const token = ++sweep.token;
  const year = Number($("sweep-year").value);
  // the collector: WIDTHxHEIGHT, or a polygon "u,v;u,v;…" [m] about the pivot (the CLI's --collector-polygon)
  const collector = $("sweep-collector").value.trim();
  const polygon = collector.includes(";")
    ? collector.split(";").map((s) => s.trim()).filter(Boolean).map((pair) => pair.split(",").map(Number))
    : null;
  const body = {
    layouts: $("sweep-layouts").value.split(",").map((s) => s.trim()).filter(Boolean),
    // sent as typed ("0.15,0.25" or "0.1:0.5:0.05"): the service reads it by the CLI's rule
    // and names what is wrong (a copy of that rule here changed what was typed, silently)
    gcr: $("sweep-gcr").value.trim(), strategies: $("sweep-strategies").value.split(",").map((s) => s.trim()).filter(Boolean),
    ...(polygon ? { collector_polygon_m: polygon } : { collector_m: collector }),
    latitude_deg: p.latitude_deg, longitude_deg: p.longitude_deg, timezone: p.timezone,
    altitude_m: p.altitude_m, start: `${year}-01-01`, end: `${year + 1}-01-01`, step_s: Number($("sweep-step").value),
  };
  clearSweep("Running the sweep…");
  sweepSay({ status: "starting…", message: "" });
  banner(""); // a refusal of the sweep before is said again if it still holds
  $("sweep-run").disabled = true;
  try {
    const acc = await api("/api/v1/plants/sweeps", { method: "POST", json: body });
    sweep.following = acc.sweep_id;
    sweep.stopping = false;
    $("sweep-cancel").disabled = false;
    $("sweep-cancel").hidden = false;
    sweepSay({ status: `queued: ${acc.cases} cases` });
    for (let missed = 0; ; ) {
      await new Promise((r) => setTimeout(r, 1000));
      if (token !== sweep.token) return;
      let run;
      try {
        run = await api(`/api/v1/plants/sweeps/${enc(acc.sweep_id)}`);
        missed = 0;
      } catch (err) {
        // a poll the service could not answer now (429, 5xx, the network) leaves the sweep
        // running there: keep following it (and its Cancel); a 404 or a 10th miss ends it
        const busy = !err.status || err.status === 429 || err.status >= 500;
        if (!busy || ++missed >= 10) throw err;
        sweepSay({ status: `${$("sweep-status").textContent.split(" · ")[0]} · no answer (${err.message}); asking again` });
        continue;
      }
      if (run.status === "done" || run.status === "failed") {
        await sweepEnded(run);
        return;
      }
      const stopping = sweep.stopping ? " · cancelling: the cases still running are dropped" : "";
      sweepSay({ status: `${run.status}: ${run.cases_done} of ${run.cases} cases${stopping}` });
    }
  } catch (err) {
    if (token !== sweep.token) return;
    clearSweep(`No sweep: ${err.message}`);
    sweepSay({ status: "", message: `Sweep: ${err.message}` });
    banner(`Sweep: ${err.message}`, "error");
  } finally {
    if (token === sweep.token) sweepIdle();
  }
}

/** A sweep that ended (SweepRunRead): done, or failed — cancelled, or its cluster lost —
 * with the cases it finished, which are drawn all the same and said to be a part. */
async function sweepEnded(run) {
  const rows = run.result?.rows || [];
  if (run.status === "done") {
    const res = run.result;
    // a cancel refused earlier says nothing of a sweep that ended well: its message goes
    sweepSay({ status: `${res.cases} cases on ${res.engine} (${res.workers} workers) in ${num(res.wall_s, 1)} s`, message: "" });
  } else {
    const cancelled = run.error === "cancelled";
    const kept = !rows.length ? "none had finished"
      : `the ${rows.length} finished ${rows.length === 1 ? "is" : "are"} drawn below`;
    sweepSay({ status: `${cancelled ? "Cancelled" : "Failed"} after ${rows.length} of ${run.cases} cases; ${kept}.`,
      message: cancelled ? "" : `Sweep: ${run.error}` });
    if (!cancelled) banner(`Sweep: ${run.error}`, "error");
  }
  if (!rows.length) {
    clearSweep(run.status === "done" ? "No case." : `No case finished before the sweep ${run.error === "cancelled" ? "was cancelled" : "failed"}.`);
    return;
  }
  sweep.id = run.sweep_id;
  sweep.rows = rows;
  await drawSweep();
  document.body.dataset.sweepLoaded = sweep.id;
}

/** Cancel the sweep being followed (DELETE /api/v1/plants/sweeps/{id}; no token: the id is
 * the capability, docs/service.md). A running sweep stops at once (its running cases dropped) and
 * the poll then finds it ended with the cases it finished; a refused cancel is said in the
 * panel and the button offered again. */
async function cancelSweep() {
  const id = sweep.following;
  if (!id) return;
  $("sweep-cancel").disabled = true;
  try {
    await api(`/api/v1/plants/sweeps/${enc(id)}`, { method: "DELETE" });
    if (sweep.following !== id) return;
    sweep.stopping = true;
    sweepSay({ message: "" });
  } catch (err) {
    if (sweep.following !== id) return;
    sweepSay({ message: `Cancel: ${err.message}` });
    $("sweep-cancel").disabled = false;
  }
}

export function initSweep() {
  // the panel's charts say what fills them, not three blank boxes under the form
  clearSweep(NO_SWEEP);
  $("sweep-form").addEventListener("submit", runSweep);
  $("sweep-cancel").addEventListener("click", cancelSweep);
  // a field the browser refuses is the sweep's news now: the last refusal's words went
  // (they stayed beside it, and in the page's banner, after the field was corrected)
  sayInvalid($("sweep-form"), (message) => { sweepSay({ status: message, message: "" }); banner(""); });
  $("sweep-case").addEventListener("change", () => drawSweepShade().catch((err) => banner(`Sweep shade: ${err.message}`, "error")));
}
