// Simulation: run a twin scenario in the background, follow its progress, chart the result.
import { api, pick, seriesRows } from "./api.js";
import { COLORS, baseLayout, draw, showEmpty } from "./charts.js";
import { addDays, toLocalWall } from "./time.js";
import { banner, energy, num, pct, tile } from "./ui.js";

const POLL_MS = 400;
const MAX_POINTS = 2000;
const DONE = new Set(["done", "succeeded", "success", "completed", "finished"]);
const FAILED = new Set(["failed", "error", "cancelled", "canceled"]);

let st = null;
let running = false;

const $ = (id) => document.getElementById(id);
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

function colValue(row, name) {
  const v = row[name];
  if (v && typeof v === "object") return v.mean ?? null;
  return typeof v === "number" ? v : null;
}

function firstKey(rows, ...names) {
  return names.find((n) => rows.some((r) => colValue(r, n) !== null));
}

function summaryTiles(summary) {
  const box = $("sim-summary");
  box.innerHTML = "";
  if (!summary) return;
  box.append(
    tile("Tracker energy", energy(summary.tracker_energy_wh), `peak ${num(summary.tracker_peak_w, 0)} W`),
    tile("Fixed energy", energy(summary.fixed_energy_wh), `peak ${num(summary.fixed_peak_w, 0)} W`),
    tile("Tracking gain", pct(summary.gain_pct), "tracker over fixed, twin"),
    tile("Period", `${num((Date.parse(summary.end) - Date.parse(summary.start)) / 86400000, 1)} days`,
      `${summary.start?.slice(0, 10) ?? "?"} → ${summary.end?.slice(0, 10) ?? "?"} · step ${num(summary.step_s)} s · ${summary.controller ?? "ideal"}`),
  );
}

/** Energy per local day [Wh] from mean power over steps of `stepS` seconds (rectangle rule). */
function dailyEnergy(rows, stepS) {
  const days = new Map();
  for (const r of rows) {
    const d = toLocalWall(st.tz, r.ts).slice(0, 10);
    const e = days.get(d) || { tracker: 0, fixed: 0 };
    e.tracker += ((colValue(r, "tracker_power_w") || 0) * stepS) / 3600;
    e.fixed += ((colValue(r, "fixed_power_w") || 0) * stepS) / 3600;
    days.set(d, e);
  }
  return [...days.entries()];
}

async function drawDaily(runId, rows, stepS) {
  const days = dailyEnergy(rows, stepS);
  $("sim-daily-card").hidden = days.length < 2;
  if (days.length < 2) return;
  const x = days.map(([d]) => d);
  const gain = days.map(([, e]) => (e.fixed > 0 ? (100 * (e.tracker - e.fixed)) / e.fixed : null));
  await draw("chart-sim-daily", [
    { x, y: days.map(([, e]) => e.tracker / 1000), name: "tracker", type: "bar", marker: { color: COLORS.tracker }, hovertemplate: "%{y:.2f} kWh" },
    { x, y: days.map(([, e]) => e.fixed / 1000), name: "fixed", type: "bar", marker: { color: COLORS.fixed }, hovertemplate: "%{y:.2f} kWh" },
    { x, y: gain, name: "gain", yaxis: "y2", type: "scatter", mode: "lines+markers", line: { color: COLORS.gain }, hovertemplate: "%{y:.1f} %" },
  ], baseLayout({
    barmode: "group",
    xaxis: { type: "date", title: { text: `Day (${st.tz})` }, tickformat: "%d %b", gridcolor: "#e9edf1" },
    yaxis: { title: { text: "Energy [kWh]" }, rangemode: "tozero", gridcolor: "#e9edf1" },
    yaxis2: { title: { text: "Tracking gain [%]" }, overlaying: "y", side: "right", showgrid: false, ticksuffix: " %", tickformat: ".1f" },
  }), {
    columns: ["date", "tracker_energy_wh", "fixed_energy_wh", "gain_pct"],
    rows: days.map(([d, e], i) => [d, e.tracker, e.fixed, gain[i]]),
    filename: `simulation_${runId}_daily_energy.csv`,
  });
}

async function drawResult(runId, allRows, stepS) {
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
    columns: ["ts_utc", "local_time", ...powerCols],
    rows: allRows.map((r, i) => [r.ts, x[i], ...powerCols.map((c) => colValue(r, c))]),
    filename: `simulation_${runId}_power.csv`,
  });
  await drawDaily(runId, allRows, stepS);
  const firstDay = allRows.length ? toLocalWall(tz, allRows[0].ts).slice(0, 10) : "";
  const lastDay = allRows.length ? toLocalWall(tz, allRows[allRows.length - 1].ts).slice(0, 10) : "";
  const long = firstDay && addDays(firstDay, 2) <= lastDay;
  if (long) rows = allRows.filter((r) => toLocalWall(tz, r.ts).startsWith(firstDay));
  $("sim-angles-title").textContent = long ? `Sun and tracker angles on ${firstDay}, the run's first day` : "Sun and tracker angles";
  const xa = long ? rows.map((r) => toLocalWall(tz, r.ts)) : x;
  const sunEl = firstKey(rows, "apparent_elevation", "sun_elevation_deg", "apparent_elevation_deg") || "apparent_elevation";
  const sunAz = firstKey(rows, "solar_azimuth", "sun_azimuth_deg", "azimuth_deg") || "solar_azimuth";
  const angleCols = [
    [sunEl, "sun elevation", COLORS.sun, "solid", "y"],
    ["elevation_joint_deg", "tracker elevation", COLORS.tracker, "dash", "y"],
    [sunAz, "sun azimuth", COLORS.sun, "dot", "y2"],
    ["azimuth_joint_deg", "tracker azimuth", COLORS.fixed, "dash", "y2"],
  ];
  await draw("chart-sim-angles", angleCols.map(([c, name, color, dash, yaxis]) => ({
    x: xa, y: rows.map((r) => colValue(r, c)), name, yaxis, type: "scatter", mode: "lines",
    line: { color, dash, width: 1.6 }, hovertemplate: "%{y:.1f}°",
  })), baseLayout({
    xaxis,
    yaxis: { title: { text: "Elevation [°]" }, gridcolor: "#e9edf1", range: [-10, 90], dtick: 30 },
    yaxis2: { title: { text: "Azimuth [°] (from N, clockwise)" }, overlaying: "y", side: "right", showgrid: false,
      nticks: 7 },
  }), {
    columns: ["ts_utc", "local_time", ...angleCols.map((a) => a[0])],
    rows: rows.map((r, i) => [r.ts, xa[i], ...angleCols.map((a) => colValue(r, a[0]))]),
    filename: `simulation_${runId}_angles.csv`,
  });
}

function setProgress(fraction, text) {
  $("sim-progress-wrap").hidden = false;
  $("sim-progress").value = Math.max(0, Math.min(1, fraction || 0));
  $("sim-progress-text").textContent = text;
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
  setProgress(0, "starting…");
  try {
    const body = {
      site_id: st.site.site_id, start, end, step_s: Number($("sim-step").value),
      controller: $("sim-controller").value, background: true,
    };
    let res = await api("/api/v1/simulations", { method: "POST", json: body });
    const runId = res.run_id;
    const t0 = performance.now();
    while (runId && !DONE.has(res.status) && !FAILED.has(res.status) && !res.summary?.tracker_energy_wh) {
      await sleep(POLL_MS);
      res = await api(`/api/v1/simulations/${encodeURIComponent(runId)}`);
      const frac = res.progress ?? 0;
      setProgress(frac, `${res.status || "running"} · ${num(100 * frac, 0)} % · ${num((performance.now() - t0) / 1000, 1)} s`);
    }
    if (FAILED.has(res.status)) throw new Error(res.error || res.detail || `run ${runId} ${res.status}`);
    const summary = res.summary || res;
    summaryTiles(summary);
    setProgress(1, `done in ${num((performance.now() - t0) / 1000, 1)} s`);
    if (runId) {
      const seriesUrl = `/api/v1/simulations/${encodeURIComponent(runId)}/series`;
      const series = await api(seriesUrl, { params: { max_points: MAX_POINTS } });
      await drawResult(runId, seriesRows(series), series?.bucket_s || summary.step_s || 60);
      const csv = $("sim-csv");
      csv.href = `${seriesUrl}?format=csv`;
      csv.setAttribute("download", `simulation_${runId}.csv`);
      csv.hidden = false;
    }
    document.body.dataset.simulationDone = runId || "sync";
  } catch (err) {
    setProgress(0, "failed");
    banner(`Simulation failed: ${err.message}`, "error");
  } finally {
    running = false;
    $("sim-run").disabled = false;
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
  const controllers = pick(st.meta, "controllers");
  if (Array.isArray(controllers) && controllers.length) {
    const sel = $("sim-controller");
    sel.innerHTML = "";
    for (const c of controllers) sel.add(new Option(c, c));
  }
  $("sim-form").addEventListener("submit", run);
  showEmpty("chart-sim-power", "Run a simulation to see its power.");
  showEmpty("chart-sim-angles", "Run a simulation to see the sun and tracker angles.");
}

export function siteChanged(state) {
  st = state;
  defaults();
}
