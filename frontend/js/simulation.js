// Simulation: run a twin scenario in the background, follow its progress, chart the result.
import { ApiError, api } from "./api.js";
import { COLORS, baseLayout, draw, showEmpty } from "./charts.js";
import { addDays, toLocalWall, zoneOffsetMs } from "./time.js";
import { viewerKey } from "./twin.js";
import { banner, energy, num, pct, tile } from "./ui.js";

const POLL_MS = 400;
// the series' columns as the API exports them (units in the names: backend/twin/export.py)
const SUN_ELEVATION = "solar_apparent_elevation_deg";
const SUN_AZIMUTH = "solar_azimuth_deg";
const MAX_POINTS = 2000;
const SERIES_RETRIES = 150; // × POLL_MS: a minute for a stored series to appear after "done"
// a run's status (SimulationRunRead): queued → running → done | failed
const FINAL = new Set(["done", "failed"]);

let st = null;
let running = false;

const $ = (id) => document.getElementById(id);
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/** A series point's column (SimulationSeriesRead: a number, or null where undefined). */
function colValue(row, name) {
  const v = row[name];
  return typeof v === "number" ? v : null;
}

/** ISO 8601 local time in `tz` with its offset ("2024-03-15T12:00:00-06:00"), for CSV files. */
function localIso(tz, iso) {
  const ms = Date.parse(iso);
  const off = Math.round(zoneOffsetMs(tz, ms) / 60000);
  const hhmm = `${String(Math.floor(Math.abs(off) / 60)).padStart(2, "0")}:${String(Math.abs(off) % 60).padStart(2, "0")}`;
  return `${toLocalWall(tz, ms).replace(" ", "T")}${off < 0 ? "-" : "+"}${hhmm}`;
}

function skyTile(summary, station) {
  if (!station) return tile("Sky", summary.sky === "weather" ? "weather" : "clear sky", "Ineichen clear sky with Linke turbidity");
  return tile("Sky", `${station.format.toUpperCase()} typical year`,
    `${station.name || "station"} (${num(station.latitude_deg, 2)}°, ${num(station.longitude_deg, 2)}°) · ${num(station.distance_km, 0)} km from the site`);
}

function summaryTiles(summary, station) {
  const box = $("sim-summary");
  box.innerHTML = "";
  if (!summary) return;
  box.append(skyTile(summary, station),
    tile("Tracker energy", energy(summary.tracker_energy_wh), `peak ${num(summary.tracker_peak_w, 0)} W`),
    tile("Fixed energy", energy(summary.fixed_energy_wh), `peak ${num(summary.fixed_peak_w, 0)} W`),
    tile("Tracking gain", pct(summary.gain_pct), "tracker over fixed, twin"),
    tile("Period", `${num((Date.parse(summary.end) - Date.parse(summary.start)) / 86400000, 1)} days`,
      `${summary.start.slice(0, 10)} → ${summary.end.slice(0, 10)} · step ${num(summary.step_s)} s · ${summary.controller}`),
  );
  box.append(
    tile("Pointing error", `${num(summary.pointing_error_rms_mrad, 1)} mrad`,
      `RMS over daylight · p95 ${num(summary.pointing_error_p95_mrad, 1)} · max ${num(summary.pointing_error_max_mrad, 1)} mrad`),
    tile("Pointing loss", energy(summary.pointing_loss_wh), `against ideal pointing · ${summary.receiver} receiver`),
    tile("Actuators", energy(summary.actuator_energy_wh), `${num(summary.moves, 0)} moves`),
    tile("Net gain", pct(summary.net_gain_pct), "tracking gain after the actuators' energy"),
  );
}

/** The machine parameters (disturbances, acceptance angle) as inputs, from the service's table. */
function machineFields(params) {
  const box = $("sim-machine-fields");
  box.innerHTML = "";
  for (const p of params || []) {
    const label = document.createElement("label");
    label.textContent = p.help;
    const input = document.createElement("input");
    Object.assign(input, { type: "number", step: "any", name: p.name, id: `sim-${p.name}`, value: p.default });
    if (p.minimum !== null) input.min = p.minimum;
    if (p.maximum !== null) input.max = p.maximum;
    input.dataset.default = p.default;
    label.append(input);
    box.append(label);
  }
}

function machineValues() {
  const out = {};
  for (const input of $("sim-machine-fields").querySelectorAll("input")) {
    if (input.value !== "" && Number(input.value) !== Number(input.dataset.default)) out[input.name] = Number(input.value);
  }
  return out;
}

/** The run's days (SimulationDayRead: the service's energy rule split at local midnights, so
 * they add up to its totals, and its gain formula), as bars and a gain line. */
async function drawDaily(runId, days) {
  $("sim-daily-card").hidden = days.length < 2;
  if (days.length < 2) return;
  const x = days.map((d) => d.date);
  await draw("chart-sim-daily", [
    { x, y: days.map((d) => d.tracker_energy_wh / 1000), name: "tracker", type: "bar", marker: { color: COLORS.tracker }, hovertemplate: "%{y:.2f} kWh" },
    { x, y: days.map((d) => d.fixed_energy_wh / 1000), name: "fixed", type: "bar", marker: { color: COLORS.fixed }, hovertemplate: "%{y:.2f} kWh" },
    { x, y: days.map((d) => d.gain_pct), name: "gain", yaxis: "y2", type: "scatter", mode: "lines+markers", line: { color: COLORS.gain }, hovertemplate: "%{y:.1f} %" },
  ], baseLayout({
    barmode: "group",
    xaxis: { type: "date", title: { text: `Day (${st.tz})` }, tickformat: "%d %b", gridcolor: "#e9edf1" },
    yaxis: { title: { text: "Energy [kWh]" }, rangemode: "tozero", gridcolor: "#e9edf1" },
    yaxis2: { title: { text: "Tracking gain [%]" }, overlaying: "y", side: "right", showgrid: false, ticksuffix: " %", tickformat: ".1f" },
  }), {
    columns: ["date", "tracker_energy_wh", "fixed_energy_wh", "gain_pct"],
    rows: days.map((d) => [d.date, d.tracker_energy_wh, d.fixed_energy_wh, d.gain_pct]),
    filename: `simulation_${runId}_daily_energy.csv`,
  });
}

async function drawResult(runId, allRows, days) {
  const tz = st.tz;
  let rows = allRows;
  if (!rows.length) {
    showEmpty("chart-sim-power", "The run returned no series.");
    showEmpty("chart-sim-angles", "The run returned no series.");
    return;
  }
  const x = allRows.map((r) => toLocalWall(tz, r.ts));
  const xaxis = { type: "date", title: { text: `Local time (${tz})` }, gridcolor: "#e9edf1" };
  const powerCols = ["tracker_power_w", "fixed_power_w"];
  await draw("chart-sim-power", powerCols.map((c) => ({
    x, y: allRows.map((r) => colValue(r, c)), name: c.startsWith("tracker") ? "tracker" : "fixed", type: "scatter", mode: "lines",
    line: { color: c.startsWith("tracker") ? COLORS.tracker : COLORS.fixed, width: 1.8 }, hovertemplate: "%{y:.0f} W",
  })), baseLayout({ xaxis, yaxis: { title: { text: "Power [W]" }, rangemode: "tozero", gridcolor: "#e9edf1" } }), {
    columns: ["time_utc", "time_local", ...powerCols],
    rows: allRows.map((r) => [r.ts, localIso(tz, r.ts), ...powerCols.map((c) => colValue(r, c))]),
    filename: `simulation_${runId}_power.csv`,
  });
  await drawDaily(runId, days);
  const firstDay = allRows.length ? toLocalWall(tz, allRows[0].ts).slice(0, 10) : "";
  const lastDay = allRows.length ? toLocalWall(tz, allRows[allRows.length - 1].ts).slice(0, 10) : "";
  const long = firstDay && addDays(firstDay, 2) <= lastDay;
  if (long) rows = allRows.filter((r) => toLocalWall(tz, r.ts).startsWith(firstDay));
  $("sim-angles-title").textContent = long ? `Sun and tracker angles on ${firstDay}, the run's first day` : "Sun and tracker angles";
  const xa = long ? rows.map((r) => toLocalWall(tz, r.ts)) : x;
  const sunEl = SUN_ELEVATION;
  const sunAz = SUN_AZIMUTH;
  const commanded = rows.some((r) => colValue(r, "elevation_command_deg") !== null);
  const angleCols = [
    [sunEl, "sun elevation", COLORS.sun, "solid", "y"],
    ["elevation_joint_deg", "tracker elevation (actual)", COLORS.tracker, "dash", "y"],
    ...(commanded ? [["elevation_command_deg", "elevation commanded", COLORS.tracker, "dot", "y"]] : []),
    [sunAz, "sun azimuth", COLORS.sun, "dot", "y2"],
    ["azimuth_joint_deg", "tracker azimuth (actual)", COLORS.fixed, "dash", "y2"],
    ...(commanded ? [["azimuth_command_deg", "azimuth commanded", COLORS.fixed, "dot", "y2"]] : []),
  ];
  await draw("chart-sim-angles", angleCols.map(([c, name, color, dash, yaxis]) => ({
    x: xa, y: rows.map((r) => colValue(r, c)), name, yaxis, type: "scatter", mode: "lines",
    line: { color, dash, width: 1.6 }, hovertemplate: "%{y:.1f}°",
  })), baseLayout({
    xaxis,
    yaxis: { title: { text: "Elevation [°]" }, gridcolor: "#e9edf1", range: [-10, 90], dtick: 30 },
    yaxis2: { title: { text: "Azimuth [°] (from N, clockwise)" }, overlaying: "y", side: "right", showgrid: false,
      tickmode: "linear", tick0: 0, dtick: 45 },
  }), {
    columns: ["time_utc", "time_local", ...angleCols.map((a) => a[0])],
    rows: rows.map((r) => [r.ts, localIso(tz, r.ts), ...angleCols.map((a) => colValue(r, a[0]))]),
    filename: `simulation_${runId}_angles.csv`,
  });
  await drawPointing(runId, rows, xa, long ? firstDay : "");
}

/** The angle between panel normal and sun through the (first) day [mrad], daylight only. */
async function drawPointing(runId, rows, x, day) {
  const has = rows.some((r) => colValue(r, "pointing_error_mrad") !== null);
  $("sim-pointing-card").hidden = !has;
  if (!has) return;
  $("sim-pointing-title").textContent = day ? `Pointing error on ${day}, the run's first day` : "Pointing error";
  const sunEl = (r) => colValue(r, SUN_ELEVATION);
  const y = rows.map((r) => (sunEl(r) > 0 ? colValue(r, "pointing_error_mrad") : null));
  // an ideal tracker's error is rounding noise (1e-13 mrad): drawn flat on a 0–1 mrad axis,
  // not autoscaled into femto-units
  const peak = y.reduce((m, v) => (v !== null && v > m ? v : m), 0);
  const scale = peak < 0.05 ? { range: [0, 1], autorange: false } : { rangemode: "tozero" };
  await draw("chart-sim-pointing", [{
    x, y, name: "pointing error", type: "scatter", mode: "lines", line: { color: COLORS.tracker, width: 1.6 },
    hovertemplate: "%{y:.2f} mrad",
  }], baseLayout({
    xaxis: { type: "date", title: { text: `Local time (${st.tz})` }, gridcolor: "#e9edf1" },
    yaxis: { title: { text: "Panel normal to sun [mrad]" }, ...scale, gridcolor: "#e9edf1" },
  }), {
    columns: ["time_utc", "time_local", "pointing_error_mrad"],
    rows: rows.map((r, i) => [r.ts, localIso(st.tz, r.ts), y[i]]),
    filename: `simulation_${runId}_pointing.csv`,
  });
}

function setProgress(fraction, text) {
  $("sim-progress-wrap").hidden = false;
  $("sim-progress").value = Math.max(0, Math.min(1, fraction || 0));
  $("sim-progress-text").textContent = text;
}

const elapsed = (t0) => `${num((performance.now() - t0) / 1000, 1)} s`;

/** Poll a background run until its status is final (not merely until a summary appears: the
 * summary can be set while the series is still being stored). Throws on a failed run. */
async function waitForRun(first, t0) {
  let res = first;
  const runId = res.run_id;
  while (!FINAL.has(res.status)) {
    const frac = res.progress ?? 0;
    const what = res.status === "queued" ? "queued" : frac >= 0.999 ? "storing the series" : "running";
    setProgress(frac, `${what} · ${num(100 * frac, 0)} % · ${elapsed(t0)}`);
    await sleep(POLL_MS);
    res = await api(`/api/v1/simulations/${encodeURIComponent(runId)}`);
  }
  if (res.status === "failed") throw new Error(res.error || `run ${runId} failed`);
  return res;
}

/** The run's series; a 409 (series not stored yet) is waited out, a bounded number of times. */
async function seriesWhenReady(url, t0) {
  for (let attempt = 0; ; attempt += 1) {
    try {
      return await api(url, { params: { max_points: MAX_POINTS } });
    } catch (err) {
      if (!(err instanceof ApiError) || err.status !== 409 || attempt >= SERIES_RETRIES) throw err;
      setProgress(1, `done · waiting for the series · ${elapsed(t0)}`);
      await sleep(POLL_MS);
    }
  }
}

/** POST the scenario: as JSON, or as multipart with the chosen TMY3/EPW file (clear sky
 * without one). */
function submit(body) {
  const file = $("sim-weather").files[0];
  if (!file) return api("/api/v1/simulations", { method: "POST", json: body });
  const form = new FormData();
  for (const [k, v] of Object.entries(body)) form.append(k, String(v));
  form.append("force", String($("sim-force").checked));
  form.append("file", file, file.name);
  return api("/api/v1/simulations/weather", { method: "POST", form });
}

async function run(ev) {
  ev.preventDefault();
  if (running || !st.site) return;
  const start = $("sim-start").value;
  const end = $("sim-end").value;
  if (!start || !end || end <= start) {
    banner("Simulation: the end date must be after the start date.", "error");
    return;
  }
  running = true;
  $("sim-run").disabled = true;
  banner("");
  $("sim-csv").hidden = true;
  $("sim-3d").hidden = true;
  setProgress(0, "starting…");
  try {
    const body = {
      site_id: st.site.site_id, start, end, step_s: Number($("sim-step").value),
      controller: $("sim-controller").value, receiver: $("sim-receiver").value,
      ...machineValues(), background: true,
    };
    const t0 = performance.now();
    const res = await waitForRun(await submit(body), t0);
    const runId = res.run_id;
    const summary = res.summary;
    summaryTiles(summary, res.params.weather_station);
    const seriesUrl = `/api/v1/simulations/${encodeURIComponent(runId)}/series`;
    setProgress(1, `${num(summary.steps, 0)} steps done · loading the series…`);
    const series = await seriesWhenReady(seriesUrl, t0);
    await drawResult(runId, series.points, summary.days);
    setProgress(1, `done in ${num((performance.now() - t0) / 1000, 1)} s`);
    const csv = $("sim-csv");
    csv.href = `${seriesUrl}?format=csv`;
    csv.setAttribute("download", `simulation_${runId}.csv`);
    csv.hidden = false;
    const show3d = $("sim-3d");
    show3d.dataset.runId = runId;
    show3d.hidden = st.meta?.viser_enabled === false; // each viewer shows the run's own site
    document.body.dataset.simulationDone = runId;
  } catch (err) {
    setProgress(0, "failed");
    banner(`Simulation failed: ${err.message}`, "error");
  } finally {
    running = false;
    $("sim-run").disabled = false;
  }
}

/** Pose the 3D twin as the run did (actual joints, disturbed base, ideal ghost) and go there. */
async function showIn3d() {
  const runId = $("sim-3d").dataset.runId;
  try {
    await api("/api/v1/twin3d/replay", { method: "PUT", json: { run_id: runId, viewer: viewerKey() } });
    location.hash = "#twin";
  } catch (err) {
    banner(`3D twin: ${err.message}`, "error");
  }
}

function defaults() {
  $("sim-start").value = st.day;
  $("sim-end").value = addDays(st.day, 1);
  const noArrays = st.site?.arrays && !Object.keys(st.site.arrays).length;
  $("sim-run").disabled = Boolean(noArrays);
  $("sim-run").title = noArrays ? "This site has no PV arrays to simulate." : "";
}

export function init(state) {
  st = state;
  defaults();
  const controllers = st.meta?.controllers ?? []; // MetaRead; {} when /meta failed
  if (controllers.length) {
    const sel = $("sim-controller");
    sel.innerHTML = "";
    for (const c of controllers) sel.add(new Option(c, c));
  }
  const receivers = st.meta?.receivers ?? [];
  if (receivers.length) {
    const sel = $("sim-receiver");
    sel.innerHTML = "";
    for (const r of receivers) sel.add(new Option(r === "cpv" ? "CPV (acceptance angle)" : "flat PV", r));
  }
  machineFields(st.meta?.machine_parameters);
  $("sim-form").addEventListener("submit", run);
  $("sim-3d").addEventListener("click", showIn3d);
  showEmpty("chart-sim-power", "Run a simulation to see its power.");
  showEmpty("chart-sim-angles", "Run a simulation to see the sun and tracker angles.");
}

export function siteChanged(state) {
  st = state;
  defaults();
}
