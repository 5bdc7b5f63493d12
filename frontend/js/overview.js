// Overview: one site and one day — power (measured and twin), energies, gain, tiles, loggers.
import { getEnergy, getMeasurements, getStatus } from "./api.js";
import { COLORS, baseLayout, draw, showEmpty, splitPartial, zeroBasedAxis } from "./charts.js";
import { addDays, fmtAge, fmtDate, fmtDateTime, fmtTime, localDate, toLocalWall } from "./time.js";
import { banner, energy, h, num, pct, remember, tile } from "./ui.js";
import * as report from "./report.js";

let ARRAYS = []; // the selected site's array names, tracker first
const SOURCES = ["measured", "twin"];
const LIVE_MS = 30000;
const HISTORY_DAYS = 28;
const MAX_POINTS = 1440;

let st = null;
let timer = null;
let controller = null;
// failed: why the selected day's readings could not be loaded ("" when they were)
const lastDay = { measured: {}, status: null, followToday: true, failed: "" };

const $ = (id) => document.getElementById(id);

function siteArrays(site) {
  const arrays = site?.arrays || {};
  const rank = (n) => (arrays[n]?.mount === "tracker" ? 0 : arrays[n]?.mount === "fixed" ? 1 : 2);
  return Object.keys(arrays).sort((a, b) => rank(a) - rank(b) || a.localeCompare(b));
}

function colorOf(arr) {
  return COLORS[st.site.arrays?.[arr]?.mount] || COLORS[arr] || COLORS.grey;
}

function bandOf(arr) {
  const c = colorOf(arr);
  const [r, g, b] = [1, 3, 5].map((i) => parseInt(c.slice(i, i + 2), 16));
  return `rgba(${r},${g},${b},0.15)`;
}

/** A point's field (MeasurementsRead): the reading or the bucket's mean (`stat` "mean"), or a
 * bucket's `<name>_min` / `<name>_max` (a stored reading is its own min and max). */
function fieldOf(p, name, stat = "mean") {
  const v = stat === "mean" ? p[name] : p[`${name}_${stat}`] ?? p[name];
  return typeof v === "number" ? v : null;
}

/** Points → {x, y, ymin, ymax, ts, gaps}; nulls inserted at gaps so lines do not bridge them. */
function toSeries(body, tz) {
  const pts = body?.points ?? [];
  const bucket = body?.bucket_s || 0;
  const times = pts.map((p) => Date.parse(p.ts));
  const diffs = times.slice(1).map((t, i) => t - times[i]).sort((a, b) => a - b);
  const step = bucket > 0 ? bucket * 1000 : diffs.length ? diffs[Math.floor(diffs.length / 2)] : 60000;
  const gapMs = Math.max(3 * step, 5 * 60000);
  // count: the readings of the range (the answer's), not the points drawn: past max_points
  // a 10-s logger's day comes as minute buckets
  const out = { x: [], y: [], ymin: [], ymax: [], rows: [], gaps: [], bucket, count: body?.count ?? pts.length };
  pts.forEach((p, i) => {
    if (i > 0 && times[i] - times[i - 1] > gapMs) {
      out.gaps.push([pts[i - 1].ts, p.ts, (times[i] - times[i - 1]) / 60000]);
      out.x.push(toLocalWall(tz, times[i - 1] + step)); out.y.push(null); out.ymin.push(null); out.ymax.push(null);
    }
    const mean = fieldOf(p, "power_w");
    out.x.push(toLocalWall(tz, times[i]));
    out.y.push(mean);
    out.ymin.push(fieldOf(p, "power_w", "min"));
    out.ymax.push(fieldOf(p, "power_w", "max"));
    out.rows.push([p.ts, toLocalWall(tz, times[i]), mean]);
  });
  return out;
}

function powerTraces(series) {
  const traces = [];
  for (const arr of ARRAYS) {
    const color = colorOf(arr);
    const m = series[`${arr}-measured`];
    const t = series[`${arr}-twin`];
    if (m && m.bucket > 0 && m.ymax.some((v, i) => v !== m.y[i])) {
      traces.push({ x: m.x, y: m.ymax, type: "scatter", mode: "lines", line: { width: 0 }, hoverinfo: "skip", showlegend: false });
      traces.push({ x: m.x, y: m.ymin, type: "scatter", mode: "lines", line: { width: 0 }, fill: "tonexty",
        fillcolor: bandOf(arr), hoverinfo: "skip", showlegend: false });
    }
    if (m && m.count) {
      traces.push({ x: m.x, y: m.y, name: `${arr} measured`, type: "scatter", mode: "lines", line: { color, width: 2 },
        hovertemplate: "%{y:.0f} W", connectgaps: false });
    }
    const w = series[`${arr}-twin_weather`];
    if (w && w.count) {
      // the fixed array reported: the twin under that sky is the expectation, the clear-sky
      // twin stays as a faint reference
      traces.push({ x: w.x, y: w.y, name: `${arr} twin (measured sky)`, type: "scatter", mode: "lines",
        line: { color, width: 1.5, dash: "dash" }, hovertemplate: "%{y:.0f} W", connectgaps: false });
    }
    if (t && t.count) {
      traces.push({ x: t.x, y: t.y, name: w && w.count ? `${arr} twin (clear sky)` : `${arr} twin`, type: "scatter",
        mode: "lines", opacity: w && w.count ? 0.6 : 1, line: { color, width: w && w.count ? 1.2 : 1.5, dash: w && w.count ? "dot" : "dash" },
        hovertemplate: "%{y:.0f} W", connectgaps: false });
    }
  }
  return traces;
}

async function drawPower(series) {
  const day = st.day;
  const traces = powerTraces(series);
  if (!traces.length) {
    const noArrays = st.site.arrays && !Object.keys(st.site.arrays).length;
    showEmpty("chart-power", noArrays ? "This site has no PV arrays (a camera site): see the Sky camera page."
      : lastDay.failed ? `The readings of ${fmtDate(day)} could not be loaded: ${lastDay.failed}`
        : `No readings for ${fmtDate(day)} — pick another day.`);
    return;
  }
  const shapes = [];
  if (day === localDate(st.tz)) {
    const now = toLocalWall(st.tz, Date.now());
    shapes.push({ type: "line", xref: "x", yref: "paper", x0: now, x1: now, y0: 0, y1: 1, line: { color: COLORS.grey, width: 1, dash: "dot" } });
  }
  const layout = baseLayout({
    xaxis: { title: { text: `Local time (${st.tz})` }, type: "date", range: [`${day} 00:00`, `${addDays(day, 1)} 00:00`],
      tickformat: "%H:%M", gridcolor: "#e9edf1" },
    yaxis: { title: { text: "Power [W]" }, rangemode: "tozero", gridcolor: "#e9edf1" },
    shapes,
  });
  const rows = [];
  for (const key of Object.keys(series)) {
    const [arr, source] = key.split("-");
    for (const r of series[key].rows) rows.push([r[0], r[1], arr, source, r[2]]);
  }
  await draw("chart-power", traces, layout, {
    columns: ["ts_utc", "local_time", "array", "source", "power_w"], rows, filename: `power_${st.site.site_id}_${day}.csv`,
  });
}

function energyOf(row, arr, source) {
  const v = row.arrays[arr]?.[`${source}_wh`];
  return typeof v === "number" ? v : null;
}

/** The tracking gain the service computed (EnergyRowRead; one gain formula, server side). */
function gainOf(row, source) {
  return (source === "measured" ? row.gain_pct : row.twin_gain_pct) ?? null;
}

/** Why a period has no twin ("—" alone says nothing): the service's note, or a generic one. */
function twinNote(row) {
  return row?.twin_note || "";
}

function drawDayEnergy(row, failed = "") {
  const box = $("day-energy");
  box.innerHTML = "";
  $("day-energy-title").textContent = `Energy of ${fmtDate(st.day)}`;
  if (!row) {
    box.append(h("p", { class: failed ? "error" : "muted" },
      failed ? `The energy could not be loaded: ${failed}` : "No energy recorded for this day."));
    return;
  }
  const partial = row.partial === true;
  // today's twin is stored up to the current minute (the live twin): say so, or 0 Wh at
  // 01:10 reads as a day expected to give nothing
  const today = st.day === localDate(st.tz);
  const table = h("table", {}, h("tr", {}, h("th", {}, ""), h("th", {}, "Measured"),
    h("th", today ? { title: "the twin up to the current minute (the whole day once it is over)" } : {}, today ? "Twin so far" : "Twin"),
    h("th", { title: "the twin over only the minutes with a reading of this array" }, "Twin, same minutes"),
    h("th", { title: "measured over the twin of the same minutes (performance ratio)" }, "of twin")));
  for (const arr of ARRAYS) {
    const m = energyOf(row, arr, "measured");
    const t = energyOf(row, arr, "twin");
    const tm = row.arrays[arr]?.twin_matched_wh;
    const pr = row.arrays[arr]?.performance_ratio;
    table.append(h("tr", {},
      h("td", {}, h("span", { class: "dot", style: `background:${colorOf(arr)}` }), arr),
      h("td", {}, energy(m)), h("td", { title: twinNote(row) }, energy(t)), h("td", {}, energy(tm ?? null)),
      h("td", {}, typeof pr === "number" ? `${num(100 * pr, 0)} %` : "—")));
  }
  box.append(table);
  if (twinNote(row)) box.append(h("div", { class: "muted", "data-testid": "twin-note" }, `Twin “—”: ${twinNote(row)}.`));
  if (partial) {
    // the array covering least names the day: one without a reading covers nothing (it
    // had counted as 100 %: "the readings cover 100 %" on a day the tracker never reported)
    const covers = ARRAYS.map((a) => [a, row.arrays[a]?.readings ? row.arrays[a]?.coverage_pct ?? 100 : 0]);
    const [arr, cov] = covers.reduce((least, c) => (c[1] < least[1] ? c : least));
    const what = cov === 0 ? `the ${arr} has no readings` :
      `the ${arr}'s readings cover ${num(cov, 0)} % of the twin's expected energy`;
    box.append(h("div", { class: "banner partial", "data-testid": "partial-day" },
      `Partial day: ${what}, so the readings are compared with the twin over the same minutes.`));
  }
  const expect = partial ? row.twin_matched_gain_pct : gainOf(row, "twin");
  if (row.gain_note) { // why there is no measured gain, in the service's words
    box.append(h("div", { class: "muted", "data-testid": "gain-unalike" }, `No measured gain: ${row.gain_note}.`));
  }
  const gain = gainOf(row, "measured");
  box.append(
    // no measured gain: the note above says why (a large red "—" under it read as a fault)
    ...(gain === null ? [] : [h("div", { class: "gain-big", "data-testid": "gain-day" }, pct(gain))]),
    h("div", { class: "muted", "data-testid": "gain-day-twin" },
      `${gain === null ? "" : "tracking gain measured (tracker over fixed); "}the twin expects ${pct(expect)}${partial ? " over the same minutes" : ""}`));
}

/** A date axis with one tick per day (per week past ten days) at local midnight, labelled
 * "18 Nov": never hourly ticks that repeat a day's label. */
function dayAxis(tz, dates) {
  const day = 86400000;
  return { type: "date", title: { text: `Day (${tz})` }, tickformat: "%d %b", gridcolor: "#e9edf1",
    tick0: dates[0] || "2000-01-03", dtick: dates.length > 10 ? 7 * day : day, ticklabelmode: "instant" };
}

/** The whole window, always (days without readings show the twin alone, never a shorter axis). */
async function drawHistory(rows) {
  const tz = st.tz;
  const dates = rows.map((r) => localDate(tz, Date.parse(r.period_start)));
  if (!rows.length) {
    showEmpty("chart-daily", "No daily energy in the last 4 weeks.");
    showEmpty("chart-cumulative", "No daily energy in the last 4 weeks.");
    return;
  }
  const kwh = (v) => (v === null ? null : v / 1000);
  const traces = [];
  for (const arr of ARRAYS) {
    traces.push({ x: dates, y: rows.map((r) => kwh(energyOf(r, arr, "measured"))), name: `${arr} measured`, type: "bar",
      marker: { color: colorOf(arr), opacity: rows.map((r) => (r.partial ? 0.45 : 1)), pattern: { shape: rows.map((r) => (r.partial ? "/" : "")) } },
      customdata: rows.map((r) => (r.partial ? " (partial day)" : "")), hovertemplate: "%{y:.2f} kWh%{customdata}" });
  }
  for (const arr of ARRAYS) {
    traces.push({ x: dates, y: rows.map((r) => kwh(energyOf(r, arr, "twin"))), name: `${arr} twin`, type: "scatter",
      mode: "markers", marker: { color: colorOf(arr), symbol: "line-ew-open", size: 14, line: { width: 2, color: colorOf(arr) } },
      hovertemplate: "%{y:.2f} kWh" });
  }
  // The gain axis is set by whole days only and starts at zero with round ticks: a partial
  // day's gain (+220 % over an hour of morning) is drawn apart, faint, clamped to the axis.
  const gains = rows.map((r) => gainOf(r, "measured"));
  const partial = rows.map((r) => r.partial === true);
  const wholeGains = gains.filter((g, i) => !partial[i] && g !== null);
  const gainAxis = zeroBasedAxis(wholeGains.length ? wholeGains : gains);
  const { whole, part } = splitPartial(dates, gains, partial, gainAxis.range);
  // four weeks without a measured gain (no readings): no gain axis (it was drawn 0–1 %,
  // empty), a word instead
  const noGain = gains.every((g) => g === null);
  if (!noGain) traces.push({ x: whole.x, y: whole.y, name: "gain", yaxis: "y2", type: "scatter", connectgaps: false,
    mode: "lines+markers", line: { color: COLORS.gain, width: 1.5 }, marker: { size: 5 }, hovertemplate: "%{y:.1f} %" });
  if (part.x.length) {
    traces.push({ x: part.x, y: part.y, name: "gain, partial day", yaxis: "y2", type: "scatter", mode: "markers",
      opacity: 0.5, marker: { color: COLORS.gain, size: 8, symbol: part.clipped.map((c) => (c ? "triangle-up-open" : "circle-open")) },
      customdata: part.value.map((v, i) => [v, part.clipped[i] ? "partial day, off the axis" : "partial day"]),
      hovertemplate: "%{customdata[0]:.1f} % (%{customdata[1]})" });
  }
  const layout = baseLayout({
    barmode: "group", bargap: 0.25,
    xaxis: dayAxis(tz, dates),
    yaxis: { title: { text: "Energy [kWh]" }, rangemode: "tozero", gridcolor: "#e9edf1" },
    ...(noGain ? {
      annotations: [{ text: "no measured gain in these four weeks: no day with readings of both arrays",
        xref: "paper", yref: "paper", x: 1, y: 1, xanchor: "right", yanchor: "bottom", showarrow: false,
        font: { size: 11, color: "#6c757d" } }],
    } : {
      yaxis2: { title: { text: "Tracking gain [%] (whole days)" }, overlaying: "y", side: "right", showgrid: false, zeroline: true,
        zerolinecolor: "#c3e6cb", ticksuffix: " %", ...gainAxis },
    }),
  });
  const energyCols = ARRAYS.flatMap((a) => SOURCES.map((src) => [a, src]));
  const table = {
    columns: ["date", ...energyCols.map(([a, src]) => `${a}_${src}_wh`), "gain_pct", "twin_gain_pct",
      "twin_matched_gain_pct", "partial", "twin_note"],
    rows: rows.map((r, i) => [dates[i], ...energyCols.map(([a, src]) => energyOf(r, a, src)),
      gainOf(r, "measured"), gainOf(r, "twin"), r.twin_matched_gain_pct ?? null, r.partial ?? null, r.twin_note ?? ""]),
    filename: `daily_energy_${st.site.site_id}_${dates[0]}_${dates[dates.length - 1]}.csv`,
  };
  await draw("chart-daily", traces, layout, table);

  // Cumulative over complete logger days only (every array ≥ 90 % of its usual readings per
  // day), so measured and twin add up the same hours and compare like for like.
  const usual = Object.fromEntries(ARRAYS.map((a) => [a, Math.max(0, ...rows.map((r) => r.arrays[a]?.readings ?? 0))]));
  const complete = rows.map((r) => ARRAYS.every((a) => (r.arrays[a]?.readings ?? 0) >= 0.9 * usual[a] && usual[a] > 0));
  const cumRows = rows.filter((_, i) => complete[i]);
  const cumDates = dates.filter((_, i) => complete[i]);
  if (!cumRows.length) {
    showEmpty("chart-cumulative", "No complete logger day in the last 4 weeks yet.");
    return;
  }
  const cum = [];
  const cumTable = cumDates.map((d) => [d]);
  for (const arr of ARRAYS) {
    for (const source of SOURCES) {
      let acc = 0;
      const y = cumRows.map((r, i) => {
        acc += energyOf(r, arr, source) || 0;
        cumTable[i].push(acc);
        return acc / 1000;
      });
      cum.push({ x: cumDates, y, name: `${arr} ${source}`, type: "scatter", mode: "lines+markers", marker: { size: 4 },
        line: { color: colorOf(arr), width: source === "measured" ? 2.5 : 1.5, dash: source === "measured" ? "solid" : "dash" },
        hovertemplate: "%{y:.2f} kWh" });
    }
  }
  await draw("chart-cumulative", cum, baseLayout({
    xaxis: dayAxis(tz, cumDates),
    yaxis: { title: { text: "Cumulative energy [kWh]" }, rangemode: "tozero", gridcolor: "#e9edf1" },
  }), {
    columns: ["date", ...ARRAYS.flatMap((a) => SOURCES.map((src) => `${a}_${src}_cumulative_wh`))],
    rows: cumTable, filename: `cumulative_energy_${st.site.site_id}_${cumDates[0]}_${cumDates[cumDates.length - 1]}.csv`,
  });
}

/** ok / warn / bad from the service's logger state ("reporting", "stale", "never") or the age;
 * a stale logger by its silence (SiteStatusRead silent_s: the daylight seconds the alerts
 * count, so a logger asleep since sunset is not red "4.0 h ago" while Alerts say nothing). */
function freshness(entry, ageS) {
  if (entry?.logger === "reporting") return "ok";
  if (entry?.logger === "never") return "bad";
  const silent = entry?.silent_s ?? ageS;
  if (silent === null || silent === undefined) return "bad";
  const fresh = entry?.fresh_s || lastDay.status?.fresh_s || 300;
  if (silent <= fresh) return "ok";
  return silent <= 12 * fresh ? "warn" : "bad";
}

/** One array's tile of the status (SiteStatusRead); {} while no status is loaded. */
function arrayStatus(status, arr) {
  return status ? status.arrays[arr] ?? {} : {};
}

function ageOf(entry) {
  return entry.age_s ?? null;
}

function drawTiles(status) {
  const box = $("tiles");
  box.innerHTML = "";
  if (!status) return;
  const tz = st.tz;
  const tr = arrayStatus(status, "tracker");
  const fx = arrayStatus(status, "fixed");
  const powerTile = (label, e) => tile(label, `${num(e.power_w, 0)} W`,
    `twin ${num(e.twin_power_w, 0)} W · ${e.last_ts ? fmtAge(e.last_ts) : "no reading yet"}`, freshness(e, ageOf(e)));
  if (ARRAYS.length) {
    box.append(
      powerTile("Tracker power now", tr),
      powerTile("Fixed power now", fx),
      tile("Tracker energy today", energy(tr.energy_today_wh), `twin so far ${energy(tr.twin_energy_today_wh)}`),
      tile("Fixed energy today", energy(fx.energy_today_wh), `twin so far ${energy(fx.twin_energy_today_wh)}`),
      tile("Gain today", pct(status.gain_today_pct), status.partial_today
        // so far today, said in both: at sunrise a tracker facing the sun makes several times
        // a fixed plane's little (an operator read "twin +913.9 %" at 05:59 as the day's gain;
        // a partial morning's "twin over the same minutes +272.3 %" reads the same)
        ? `tracker over fixed, so far · partial day: twin over the same minutes ${pct(status.twin_matched_gain_today_pct)}`
        : `tracker over fixed, so far · twin so far ${pct(status.twin_gain_today_pct)}`),
    );
  }
  box.append(
    tile("Sun now", `${num(status.sun.elevation_deg, 1)}°`,
      `elevation · azimuth ${num(status.sun.azimuth_deg, 1)}° from N`),
    tile("Tracker angles now", `${num(status.tracker.elevation_joint_deg, 1)}°`,
      `elevation · azimuth ${num(status.tracker.azimuth_joint_deg, 1)}° (twin)`),
    tile("Site time", fmtTime(tz, status.time_utc), tz),
  );
}

function drawLoggers(status, series) {
  const box = $("loggers");
  box.innerHTML = "";
  if (!ARRAYS.length) {
    box.append(h("p", { class: "muted" }, "No loggers: this site has no PV arrays."));
    return;
  }
  const table = h("table", {}, h("tr", {}, h("th", {}, "Array"), h("th", {}, "Last reading"), h("th", {}, "Readings"), h("th", {}, "Gaps")));
  for (const arr of ARRAYS) {
    const s = arrayStatus(status, arr);
    const m = series[`${arr}-measured`];
    const last = s.last_ts || (m && m.rows.length ? m.rows[m.rows.length - 1][0] : null);
    const age = s.last_ts ? ageOf(s) : last ? (Date.now() - Date.parse(last)) / 1000 : null;
    const gaps = m ? m.gaps : [];
    const longest = gaps.reduce((a, g) => Math.max(a, g[2]), 0);
    const gapText = !m ? "—" : !m.count ? "no readings" : gaps.length ? `${gaps.length} (longest ${num(longest, 0)} min)` : "none";
    const unknown = !status && !last; // neither answer came: not "never" (a stopped service)
    table.append(h("tr", {},
      h("td", { title: s.logger || "" }, h("span", { class: `dot ${unknown ? "" : freshness(s, age)}` }), arr),
      h("td", { title: last ? fmtDateTime(st.tz, last) : "" }, last ? fmtAge(last) : unknown ? "unknown" : "never"),
      h("td", { "data-testid": `readings-${arr}` }, m ? num(m.count) : "—"),
      h("td", { "data-testid": `gaps-${arr}`, title: gaps.map((g) => `${fmtTime(st.tz, g[0])}–${fmtTime(st.tz, g[1])}`).join(", ") },
        gapText)));
  }
  box.append(table, h("div", { class: "muted" }, "Readings and gaps (> 5 min) of the selected day; hover for times."));
}

async function refreshStatus(signal) {
  try {
    lastDay.status = await getStatus(st.site.site_id, signal);
  } catch (err) {
    if (err.name === "AbortError") return;
    lastDay.status = null;
    banner(`Status unavailable: ${err.message}`);
  }
  drawTiles(lastDay.status);
  drawLoggers(lastDay.status, lastDay.measured);
}

/** Load everything for the selected day; `quiet` keeps the charts while refreshing. */
async function load(quiet = false) {
  if (!st.site) return;
  controller?.abort();
  controller = new AbortController();
  const { signal } = controller;
  const site = st.site.site_id;
  const day = st.day;
  const today = localDate(st.tz);
  $("day-input").value = day;
  $("day-input").max = today;
  $("day-next").disabled = day >= today;
  lastDay.followToday = day === today; // then the page moves on to the next day at midnight
  if (st.page === "overview") remember(st, "overview");
  if (!quiet) {
    for (const id of ["chart-power", "chart-daily", "chart-cumulative"]) {
      const el = $(id);
      if (!el.classList.contains("js-plotly-plot")) showEmpty(id, "Loading…");
    }
  }
  ARRAYS = siteArrays(st.site);
  if (!ARRAYS.length) {
    lastDay.measured = {};
    await drawPower({});
    drawDayEnergy(null);
    showEmpty("chart-daily", "This site has no PV arrays.");
    showEmpty("chart-cumulative", "This site has no PV arrays.");
    await refreshStatus(signal);
    banner("");
    document.body.dataset.overviewLoaded = `${site}/${day}`;
    return;
  }
  const end = addDays(day, 1);
  const series = {};
  const measurementJobs = [];
  for (const arr of ARRAYS) {
    for (const source of SOURCES) {
      measurementJobs.push(getMeasurements(site, { array: arr, source, start: day, end, maxPoints: MAX_POINTS }, signal)
        .then((body) => { series[`${arr}-${source}`] = toSeries(body, st.tz); })
        // a failed request leaves no series: an empty one read as "No readings" and "never"
        // with the service stopped (a tester's finding); lastDay.failed says why instead
        .catch((err) => { if (err.name !== "AbortError") delete series[`${arr}-${source}`]; throw err; }));
    }
  }
  const energyJob = getEnergy(site, { start: addDays(day, 1 - HISTORY_DAYS), end, interval: "day" }, signal);
  energyJob.catch(() => {}); // awaited below unless a newer load aborts this one first
  const statusJob = refreshStatus(signal);
  const errors = [];
  const measured = await Promise.allSettled(measurementJobs);
  if (signal.aborted) return;
  for (const r of measured) if (r.status === "rejected") errors.push(r.reason.message);
  lastDay.failed = errors[0] || "";
  lastDay.measured = series;
  await drawPower(series);
  drawLoggers(lastDay.status, series);
  try {
    const body = await energyJob;
    if (signal.aborted) return;
    const rows = (body && body.rows) || [];
    drawDayEnergy(rows.find((r) => localDate(st.tz, Date.parse(r.period_start)) === day));
    await drawHistory(rows);
  } catch (err) {
    if (err.name === "AbortError") return;
    errors.push(err.message);
    drawDayEnergy(null, err.message);
    showEmpty("chart-daily", "Energy unavailable.");
    showEmpty("chart-cumulative", "Energy unavailable.");
  }
  await statusJob;
  if (signal.aborted) return;
  weatherTwin(site, day, end, series, signal); // redraws when it arrives; never blocks the page
  banner(errors.length ? `Some data could not be loaded: ${errors[0]}` : "");
  // "updated" only when it was: a load that failed said "updated 01:20" with nothing loaded
  $("live-stamp").textContent = `${errors.length ? "update failed" : "updated"} ${fmtTime(st.tz, new Date().toISOString())}`;
  document.body.dataset.overviewLoaded = `${site}/${day}`;
  if (!performance.getEntriesByName("heliotwin:overview-loaded").length) performance.mark("heliotwin:overview-loaded");
}

/** The twin under the measured sky (source=twin_weather: an irradiance sensor's or the fixed
 * array's), when the fixed array reported that day; the chart then shows it as the expectation. */
async function weatherTwin(site, day, end, series, signal) {
  const fixed = series[`${ARRAYS.find((a) => st.site.arrays?.[a]?.mount === "fixed")}-measured`];
  const done = () => { document.body.dataset.overviewWeather = `${site}/${day}`; };
  if (!fixed || !fixed.count) { done(); return; }
  try {
    const bodies = await Promise.all(ARRAYS.map((arr) =>
      getMeasurements(site, { array: arr, source: "twin_weather", start: day, end, maxPoints: MAX_POINTS }, signal)));
    if (signal.aborted) return;
    bodies.forEach((body, k) => {
      if (body.sky && body.sky.source !== "clear_sky") series[`${ARRAYS[k]}-twin_weather`] = toSeries(body, st.tz);
    });
    await drawPower(series);
  } catch (err) {
    if (err.name === "AbortError") return;
    banner(`The twin under the measured sky could not be computed: ${err.message}`);
  }
  done();
}

function tick() {
  if (!st.site || document.hidden) return;
  const today = localDate(st.tz);
  if (lastDay.followToday && st.day !== today) {
    st.day = today; // left open overnight on "today": follow the new day
    load();
  } else if (st.day === today) {
    load(true); // only the current day changes
  } else {
    refreshStatus(); // an older day needs only the tiles
  }
}

function startLive() {
  stopLive();
  if ($("live-toggle").checked) timer = setInterval(tick, LIVE_MS);
}

function stopLive() {
  if (timer) clearInterval(timer);
  timer = null;
}

function setDay(day) {
  const today = localDate(st.tz);
  st.day = day > today ? today : day;
  load();
}

/** The day of the address (#overview?site=…&day=YYYY-MM-DD), when it is a valid one. */
function hashDay() {
  const day = new URLSearchParams(location.hash.split("?")[1] || "").get("day");
  return day && /^\d{4}-\d{2}-\d{2}$/.test(day) && !Number.isNaN(Date.parse(day)) ? day : null;
}

/** An edited address is followed, never overwritten by the day shown before. */
function followHash() {
  if (!location.hash.startsWith("#overview")) return false;
  const day = hashDay();
  if (!day || day === st.day) return false;
  const today = localDate(st.tz);
  st.day = day > today ? today : day;
  return true;
}

export function init(state) {
  st = state;
  $("day-prev").addEventListener("click", () => setDay(addDays(st.day, -1)));
  $("day-next").addEventListener("click", () => setDay(addDays(st.day, 1)));
  $("day-today").addEventListener("click", () => setDay(localDate(st.tz)));
  $("day-input").addEventListener("change", (ev) => { if (ev.target.value) setDay(ev.target.value); });
  $("live-toggle").addEventListener("change", startLive);
  document.addEventListener("visibilitychange", () => { if (!document.hidden && timer) tick(); });
  document.addEventListener("keydown", (ev) => {
    // ← → step through the days when the overview is shown and no field has the focus
    if (st.page !== "overview" || ev.altKey || ev.ctrlKey || ev.metaKey) return;
    if (ev.target.closest?.("input, select, textarea")) return;
    if (ev.key === "ArrowLeft") setDay(addDays(st.day, -1));
    else if (ev.key === "ArrowRight" && st.day < localDate(st.tz)) setDay(addDays(st.day, 1));
  });
  report.init(st);
  load();
  startLive();
}

export function show() {
  startLive();
  load(!followHash());
}

export function hide() {
  stopLive();
}

export function siteChanged(state, visible) {
  st = state;
  followHash();
  report.siteChanged(st);
  for (const id of ["chart-power", "chart-daily", "chart-cumulative"]) showEmpty(id, "Loading…");
  if (visible) load();
}
