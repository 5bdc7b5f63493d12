// Simulation: run a twin scenario in the background, follow its progress, chart the result.
import { ApiError, api } from "./api.js";
import { COLORS, baseLayout, draw, roundStep, showEmpty, splitPartial, zeroBasedAxis } from "./charts.js";
import { addDays, localMidnightMs, toLocalWall, zoneOffsetMs } from "./time.js";
import { viewerKey } from "./twin.js";
import { banner, energy, num, pct, skyTile, stowTile, tile, weatherWarning } from "./ui.js";

const POLL_MS = 400;
// the series' columns as the API exports them (units in the names: backend/twin/export.py)
const SUN_ELEVATION = "solar_apparent_elevation_deg";
const SUN_AZIMUTH = "solar_azimuth_deg";
const MAX_POINTS = 2000;
const DAY_POINTS = 3000; // the first day's angles at full resolution (1 440 rows at 1 min)
const CONFIRM_S = 60; // a run expected to take (or wait) longer than this asks first
const SERIES_RETRIES = 150; // × POLL_MS: a minute for a stored series to appear after "done"
// a run's status (SimulationRunRead): queued → running → done | failed
const FINAL = new Set(["done", "failed"]);

let st = null;
let running = false;
let currentRun = null; // the run_id being followed, for the Cancel button

const $ = (id) => document.getElementById(id);
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/** A worker time for people: "40 s", "12 min", "1 h 13 min". */
function duration(seconds) {
  if (!(seconds >= 0)) return "—";
  if (seconds < 90) return `${num(Math.max(1, seconds), 0)} s`;
  const min = Math.round(seconds / 60);
  return min < 90 ? `${min} min` : `${Math.floor(min / 60)} h ${min % 60} min`;
}

/** Azimuths in 0–360° (the sun's convention, clockwise from north); the sample after a jump
 * across north is left out, so the line breaks there instead of crossing the chart. */
function azimuth360(values) {
  let prev = null;
  return values.map((v) => {
    if (v === null) { prev = null; return null; }
    const a = ((v % 360) + 360) % 360;
    const jump = prev !== null && Math.abs(a - prev) > 180;
    prev = a;
    return jump ? null : a;
  });
}

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

function summaryTiles(summary, station) {
  const box = $("sim-summary");
  box.innerHTML = "";
  if (!summary) return;
  box.append(...weatherWarning(summary), skyTile(summary, station, "site"),
    tile("Tracker energy", energy(summary.tracker_energy_wh), `peak ${num(summary.tracker_peak_w, 0)} W`),
    tile("Fixed energy", energy(summary.fixed_energy_wh), `peak ${num(summary.fixed_peak_w, 0)} W`),
    // a polar night (or a dark run) has no gain: say why rather than a bare "—"
    tile("Tracking gain", pct(summary.gain_pct), summary.gain_pct === null && !(summary.fixed_energy_wh > 0)
      ? "none: the fixed array made no energy (the sun below the horizon?)" : "tracker over fixed, twin"),
    ...stowTile(summary),
    tile("Period", `${num((Date.parse(summary.end) - Date.parse(summary.start)) / 86400000, 1)} days`,
      `${summary.start.slice(0, 10)} → ${summary.end.slice(0, 10)} · step ${num(summary.step_s)} s · ${summary.controller}`),
  );
  // what the headline covers: the tracking minutes with the sun above the stated elevation
  const minutes = summary.pointing_error_minutes;
  const cover = typeof minutes === "number"
    ? `RMS over ${num(minutes, 0)} tracking minutes with the sun ≥ ${num(summary.pointing_min_elevation_deg, 0)}°`
    : "RMS while tracking";
  box.append(
    tile("Pointing error", `${num(summary.pointing_error_rms_mrad, 1)} mrad`,
      `${cover} · energy-weighted ${num(summary.pointing_error_energy_weighted_rms_mrad, 1)} · p95 ${num(summary.pointing_error_p95_mrad, 1)} · max ${num(summary.pointing_error_max_mrad, 1)} mrad`),
    tile("Pointing loss", energy(summary.pointing_loss_wh), `against ideal pointing · ${summary.receiver} receiver`),
    // the ideal controller follows the sun exactly, with no drive: its "0 Wh · 0 moves"
    // beside a tracker turning through 360° read as a measured zero (a tester's finding)
    ...(summary.controller === "ideal"
      ? [tile("Actuators", "—", "not modelled: the ideal controller follows the sun exactly"),
        tile("Net gain", "—", "needs the actuators' energy: pick another controller")]
      : [tile("Actuators", energy(summary.actuator_energy_wh),
        summary.actuator_warning || `${num(summary.moves, 0)} moves`),
        tile("Net gain", pct(summary.net_gain_pct), "tracking gain after the actuators' energy")]),
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
 * they add up to its totals, and its gain formula), as bars and a gain line. A day the run
 * covers only in part (a start or end inside it) is drawn faint and sets no axis; the axes
 * start at zero with round ticks, one label a day (or every few days on a long run). */
async function drawDaily(runId, summary) {
  const days = summary.days || [];
  $("sim-daily-card").hidden = days.length < 2;
  if (days.length < 2) return;
  const tz = st.tz;
  const t0 = Date.parse(summary.start);
  const t1 = Date.parse(summary.end);
  const partial = days.map((d) => localMidnightMs(tz, d.date) < t0 || localMidnightMs(tz, addDays(d.date, 1)) > t1);
  const x = days.map((d) => d.date);
  const gain = days.map((d) => d.gain_pct);
  const whole = (v) => v.filter((_, i) => !partial[i]);
  const gainAxis = zeroBasedAxis(whole(gain));
  const split = splitPartial(x, gain, partial, gainAxis.range);
  const faint = partial.map((p) => (p ? 0.35 : 1));
  const everyDays = Math.max(1, roundStep(days.length, 8));
  const kwh = (k) => days.map((d) => d[k] / 1000);
  // a site that stows: each day's energy lost to the wind beside its energies (sim/stow.py)
  const stow = days.every((d) => typeof d.stow_loss_wh === "number");
  await draw("chart-sim-daily", [
    { x, y: kwh("tracker_energy_wh"), name: "tracker", type: "bar", marker: { color: COLORS.tracker, opacity: faint }, hovertemplate: "%{y:.2f} kWh" },
    { x, y: kwh("fixed_energy_wh"), name: "fixed", type: "bar", marker: { color: COLORS.fixed, opacity: faint }, hovertemplate: "%{y:.2f} kWh" },
    ...(stow ? [{ x, y: kwh("stow_loss_wh"), name: "lost to wind stow", type: "bar", marker: { color: COLORS.grey, opacity: faint }, hovertemplate: "%{y:.2f} kWh" }] : []),
    { ...split.whole, name: "gain", yaxis: "y2", type: "scatter", mode: "lines+markers", line: { color: COLORS.gain }, hovertemplate: "%{y:.1f} %" },
    ...(split.part.x.length ? [{ x: split.part.x, y: split.part.y, customdata: split.part.value, name: "gain (partial day)", yaxis: "y2", type: "scatter", mode: "markers",
      marker: { color: COLORS.gain, opacity: 0.35, symbol: "circle-open" }, hovertemplate: "%{customdata:.1f} % (partial day)" }] : []),
  ], baseLayout({
    barmode: "group",
    xaxis: { type: "date", title: { text: `Day (${tz})` }, tickformat: "%d %b", dtick: everyDays * 86400000, gridcolor: "#e9edf1" },
    // both arrays' bars: a fixed array beating the tracker (a CPV receiver with a yawed
    // pedestal, a stuck tracker) ran off the top of an axis set by the tracker's alone
    // and the stow's: a cloudy day's is negative (the flat panel gained) and hid below 0
    yaxis: { title: { text: "Energy [kWh]" }, ...zeroBasedAxis([...whole(kwh("tracker_energy_wh")), ...whole(kwh("fixed_energy_wh")),
      ...(stow ? whole(kwh("stow_loss_wh")) : [])]), gridcolor: "#e9edf1" },
    yaxis2: { title: { text: "Tracking gain [%]" }, overlaying: "y", side: "right", showgrid: false, ticksuffix: " %", ...gainAxis },
  }), {
    columns: ["date", "tracker_energy_wh", "fixed_energy_wh", "gain_pct", ...(stow ? ["stow_loss_wh"] : []), "partial_day"],
    rows: days.map((d, i) => [d.date, d.tracker_energy_wh, d.fixed_energy_wh, d.gain_pct, ...(stow ? [d.stow_loss_wh] : []), partial[i]]),
    filename: `simulation_${runId}_daily_energy.csv`,
  });
}

async function drawResult(runId, summary, allRows, dayRows) {
  const tz = st.tz;
  if (!allRows.length) {
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
  await drawDaily(runId, summary);
  const rows = dayRows.rows;
  const xa = rows.map((r) => toLocalWall(tz, r.ts));
  const commanded = rows.some((r) => colValue(r, "elevation_command_deg") !== null);
  // the sun only while it is up; both azimuths in 0–360°, clockwise from north. A day it
  // never rises (a polar night) draws its path below the horizon and says so: the chart
  // showed the stowed tracker alone (a tester's finding)
  const elevations = rows.map((r) => colValue(r, SUN_ELEVATION)).filter((v) => v !== null);
  const highest = elevations.length ? Math.max(...elevations) : null;
  const polarNight = highest !== null && highest <= 0;
  const up = rows.map((r) => polarNight || colValue(r, SUN_ELEVATION) > 0);
  const sunOnly = (c) => rows.map((r, i) => (up[i] ? colValue(r, c) : null));
  const title = dayRows.day ? `Sun and tracker angles on ${dayRows.day}, the run's first day` : "Sun and tracker angles";
  $("sim-angles-title").textContent = polarNight
    ? `Polar night: the sun at most ${num(highest, 1)}°` : title;
  const lowest = polarNight ? Math.min(-10, 10 * Math.floor(Math.min(...elevations) / 10)) : 0;
  const az = (c) => azimuth360(rows.map((r) => colValue(r, c)));
  const angleCols = [
    [SUN_ELEVATION, "sun elevation", COLORS.sun, "solid", "y", sunOnly(SUN_ELEVATION)],
    ["elevation_joint_deg", "tracker elevation (actual)", COLORS.tracker, "dash", "y", rows.map((r) => colValue(r, "elevation_joint_deg"))],
    ...(commanded ? [["elevation_command_deg", "elevation commanded", COLORS.tracker, "dot", "y", rows.map((r) => colValue(r, "elevation_command_deg"))]] : []),
    [SUN_AZIMUTH, "sun azimuth", COLORS.sun, "dot", "y2", azimuth360(sunOnly(SUN_AZIMUTH))],
    ["azimuth_joint_deg", "tracker azimuth (actual)", COLORS.fixed, "dash", "y2", az("azimuth_joint_deg")],
    ...(commanded ? [["azimuth_command_deg", "azimuth commanded", COLORS.fixed, "dot", "y2", az("azimuth_command_deg")]] : []),
  ];
  await draw("chart-sim-angles", angleCols.map(([, name, color, dash, yaxis, y]) => ({
    x: xa, y, name, yaxis, type: "scatter", mode: "lines",
    line: { color, dash, width: 1.6 }, hovertemplate: "%{y:.1f}°",
  })), baseLayout({
    xaxis,
    yaxis: { title: { text: "Elevation [°]" }, gridcolor: "#e9edf1", range: [lowest, 90], dtick: 30, tick0: 0, autorange: false },
    yaxis2: { title: { text: "Azimuth [°] (0–360, from N, clockwise)" }, overlaying: "y", side: "right", showgrid: false,
      range: [0, 360], autorange: false, tickmode: "linear", tick0: 0, dtick: 45 },
  }), {
    columns: ["time_utc", "time_local", ...angleCols.map((a) => a[0])],
    rows: rows.map((r, i) => [r.ts, localIso(tz, r.ts), ...angleCols.map((a) => a[5][i])]),
    filename: `simulation_${runId}_angles.csv`,
  });
  await drawPointing(runId, rows, xa, dayRows.day);
}

/** The angle between panel normal and sun through the (first) day [mrad], while tracking. */
async function drawPointing(runId, rows, x, day) {
  const has = rows.some((r) => colValue(r, "pointing_error_mrad") !== null);
  $("sim-pointing-card").hidden = !has;
  if (!has) return;
  $("sim-pointing-title").textContent = day ? `Pointing error on ${day}, the run's first day` : "Pointing error";
  // null where the pointing error is not defined (night, stow, the sun low: the twin's
  // rule, sim/twin.py): drawn as gaps
  const y = rows.map((r) => colValue(r, "pointing_error_mrad"));
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

/** What a queued or running run is waiting for, in words (SimulationRunRead's estimates). */
function progressText(res, t0) {
  const frac = res.progress ?? 0;
  if (res.status === "queued") {
    const ahead = res.queue_position ?? 0;
    const wait = res.estimated_wait_s;
    return `queued · ${ahead === 0 ? "next" : `${ahead + 1}th in line`}${wait > 0 ? ` · starts in about ${duration(wait)}` : ""}`
      + `${res.estimated_run_s ? ` · then about ${duration(res.estimated_run_s)} of work` : ""} · ${elapsed(t0)}`;
  }
  if (frac >= 0.999) return `storing the series · ${elapsed(t0)}`;
  // a run reports at the end of each 65,536 steps (≈ 45 days at 1 min): before its first
  // report no percentage ("0 % of about 1 s" stayed there for a 4-day run to its end)
  if (frac <= 0) return `running${res.estimated_run_s ? ` · about ${duration(res.estimated_run_s)} expected` : ""} · ${elapsed(t0)}`;
  return `running · ${num(100 * frac, 0)} %${res.estimated_run_s ? ` of about ${duration(res.estimated_run_s)}` : ""} · ${elapsed(t0)}`;
}

/** Poll a background run until its status is final (not merely until a summary appears: the
 * summary can be set while the series is still being stored). Throws on a failed run. */
async function waitForRun(first, t0) {
  let res = first;
  const runId = res.run_id;
  currentRun = runId;
  $("sim-cancel").hidden = false;
  try {
    while (!FINAL.has(res.status)) {
      setProgress(res.progress ?? 0, progressText(res, t0));
      await sleep(POLL_MS);
      res = await api(`/api/v1/simulations/${encodeURIComponent(runId)}`);
    }
  } finally {
    currentRun = null;
    $("sim-cancel").hidden = true;
  }
  if (res.status === "failed") throw new Error(res.error === "cancelled" ? "cancelled" : res.error || `run ${runId} failed`);
  return res;
}

/** A series read (SimulationSeriesRead); a 409 (not stored yet) is waited out, a bounded
 * number of times. */
async function seriesWhenReady(url, params, t0) {
  for (let attempt = 0; ; attempt += 1) {
    try {
      return await api(url, { params });
    } catch (err) {
      if (!(err instanceof ApiError) || err.status !== 409 || attempt >= SERIES_RETRIES) throw err;
      setProgress(1, `done · waiting for the series · ${elapsed(t0)}`);
      await sleep(POLL_MS);
    }
  }
}

/** The rows the angle and pointing charts show: the run's first local day at full
 * resolution (its own read with `start`/`end`, not the thinned whole) when the run is
 * longer than a day, else the whole run. */
async function firstDayRows(url, summary, t0) {
  const first = toLocalWall(st.tz, summary.start).slice(0, 10);
  const long = Date.parse(summary.end) - Date.parse(summary.start) > 86400000 + 1;
  const params = long ? { start: first, end: addDays(first, 1), max_points: DAY_POINTS } : { max_points: DAY_POINTS };
  const got = await seriesWhenReady(url, params, t0);
  return { rows: got.points, day: long ? first : "" };
}

/** POST the scenario: as JSON, or as multipart with the chosen weather file — TMY3/EPW or
 * measured CSV, with the zone of its times when given (clear sky without one). */
function submit(body) {
  const file = $("sim-weather").files[0];
  if (!file) return api("/api/v1/simulations", { method: "POST", json: body });
  const form = new FormData();
  for (const [k, v] of Object.entries(body)) form.append(k, String(v));
  form.append("force", String($("sim-force").checked));
  form.append("weather_stamped", $("sim-weather-stamped").value);
  // a measured CSV of local times without offsets needs their zone: the service refused it
  // naming weather_timezone, which the page had no field for (a tester's finding)
  const zone = $("sim-weather-timezone").value.trim();
  if (zone) form.append("weather_timezone", zone);
  form.append("file", file, file.name);
  return api("/api/v1/simulations/weather", { method: "POST", form });
}

/** Ask the service what the run would cost (SimulationEstimateRead) and, when it would be
 * refused or is long, tell the user first: false when the run should not be sent. */
async function confirmCost(body) {
  const est = await api("/api/v1/simulations/estimate", { method: "POST", json: body });
  if (!est.allowed) {
    banner(`Simulation not started: ${est.reason}`, "error");
    return false;
  }
  const total = est.estimated_run_s + est.estimated_wait_s;
  if (total <= CONFIRM_S) return true;
  const wait = est.estimated_wait_s > 5 ? `, starting in about ${duration(est.estimated_wait_s)} (${est.runs_ahead} run${est.runs_ahead === 1 ? "" : "s"} ahead)` : "";
  return window.confirm(`This run (${num(est.steps, 0)} steps, ${est.controller}) is expected to take about ${duration(est.estimated_run_s)}${wait}: run anyway?`);
}

/** Nothing of an earlier run stays on screen: tiles, charts, links. */
function clearResults() {
  $("sim-summary").innerHTML = "";
  $("sim-csv").hidden = true;
  $("sim-3d").hidden = true;
  $("sim-daily-card").hidden = true;
  $("sim-pointing-card").hidden = true;
  $("sim-angles-title").textContent = "Sun and tracker angles";
  showEmpty("chart-sim-power", "Run a simulation to see its power.");
  showEmpty("chart-sim-angles", "Run a simulation to see the sun and tracker angles.");
  delete document.body.dataset.simulationDone;
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
  try {
    const body = {
      site_id: st.site.site_id, start, end, step_s: Number($("sim-step").value),
      controller: $("sim-controller").value, receiver: $("sim-receiver").value,
      ...machineValues(), background: true,
    };
    setProgress(0, "estimating…");
    if (!(await confirmCost(body))) {
      $("sim-progress-wrap").hidden = true;
      return;
    }
    clearResults();
    setProgress(0, "starting…");
    const t0 = performance.now();
    const res = await waitForRun(await submit(body), t0);
    const runId = res.run_id;
    const summary = res.summary;
    summaryTiles(summary, res.params.weather_station);
    const seriesUrl = `/api/v1/simulations/${encodeURIComponent(runId)}/series`;
    setProgress(1, `${num(summary.steps, 0)} steps done · loading the series…`);
    const series = await seriesWhenReady(seriesUrl, { max_points: MAX_POINTS }, t0);
    const dayRows = await firstDayRows(seriesUrl, summary, t0);
    await drawResult(runId, summary, series.points, dayRows);
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
    clearResults(); // the failure banner never sits above an earlier run's results
    const cancelled = err.message === "cancelled";
    setProgress(0, cancelled ? "cancelled" : "failed");
    banner(cancelled ? "Simulation cancelled." : `Simulation failed: ${err.message}`, cancelled ? "warn" : "error");
  } finally {
    running = false;
    $("sim-run").disabled = false;
  }
}

/** Cancel the run being followed (DELETE /api/v1/simulations/{id}); the poll then sees it
 * end "failed" with the error "cancelled". */
async function cancelRun() {
  if (!currentRun) return;
  $("sim-cancel").disabled = true;
  try {
    await api(`/api/v1/simulations/${encodeURIComponent(currentRun)}`, { method: "DELETE" });
  } catch (err) {
    banner(`Cancel: ${err.message}`, "error");
  } finally {
    $("sim-cancel").disabled = false;
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
  $("sim-cancel").addEventListener("click", cancelRun);
  showEmpty("chart-sim-power", "Run a simulation to see its power.");
  showEmpty("chart-sim-angles", "Run a simulation to see the sun and tracker angles.");
}

export function siteChanged(state) {
  st = state;
  defaults();
}
