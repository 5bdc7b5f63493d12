// Overview: the diagnosis panel — per day the tracker against the weather-aware twin
// (GET /api/v1/sites/{id}/diagnosis), faults in plain words, a daily PR / gain chart.
import { api } from "./api.js";
import { COLORS, baseLayout, draw, showEmpty } from "./charts.js";
import { h, num } from "./ui.js";

const KIND_WORDS = {
  stuck: "tracker stuck",
  azimuth_offset: "azimuth offset",
  elevation_offset: "elevation offset",
  clock_offset: "clock offset",
  module_loss: "module or string lost",
  soiling: "soiling",
  dropout: "logger dropout",
};

function addDays(iso, n) {
  const d = new Date(`${iso}T12:00:00Z`);
  d.setUTCDate(d.getUTCDate() + n);
  return d.toISOString().slice(0, 10);
}

function shortDate(iso) {
  return new Date(`${iso}T12:00:00Z`).toLocaleDateString(undefined, { day: "numeric", month: "short", timeZone: "UTC" });
}

/** One line per fault (the latest day it was seen), e.g. "tracker stuck since 12 Mar …". */
export function faultLines(days) {
  const last = new Map();
  for (const d of days) for (const f of d.faults) last.set(`${f.kind}|${f.since}`, f);
  return [...last.values()].map((f) =>
    `${KIND_WORDS[f.kind] || f.kind} since ${shortDate(f.since)}: ${f.detail}; confidence ${num(f.confidence, 2)}`);
}

async function load(state) {
  const start = document.getElementById("diag-start").value;
  const end = document.getElementById("diag-end").value;
  const list = document.getElementById("diag-faults");
  list.replaceChildren(h("li", { class: "muted" }, "Computing…"));
  let body;
  try {
    body = await api(`/api/v1/sites/${encodeURIComponent(state.site.site_id)}/diagnosis`, { params: { start, end } });
  } catch (err) {
    list.replaceChildren(h("li", { class: "error" }, `Diagnosis failed: ${err.message}`));
    showEmpty("chart-diagnosis", "No diagnosis");
    return;
  }
  const lines = faultLines(body.days);
  list.replaceChildren(...(lines.length ? lines.map((t) => h("li", { "data-testid": "diag-fault" }, t))
    : [h("li", { class: "muted", "data-testid": "diag-none" }, "No fault found in this range.")]));
  const x = body.days.map((d) => d.date);
  const pr = body.days.map((d) => d.tracker.performance_ratio);
  await draw("chart-diagnosis", [
    { x, y: body.days.map((d) => d.gain_measured_pct), name: "gain measured %", type: "bar", marker: { color: COLORS.gain } },
    { x, y: body.days.map((d) => d.gain_expected_pct), name: "gain expected for that sky %", type: "bar", marker: { color: COLORS.grey } },
    { x, y: pr, name: "tracker PR", yaxis: "y2", mode: "lines+markers", line: { color: COLORS.tracker } },
  ], baseLayout({ barmode: "group", yaxis: { title: "gain %", gridcolor: "#e9edf1" },
    yaxis2: { title: "PR", overlaying: "y", side: "right", range: [0, 1.2] } }),
  { columns: ["date", "clearness_index", "tracker_measured_wh", "tracker_expected_wh", "tracker_expected_wh_low",
    "tracker_expected_wh_high", "performance_ratio", "gain_measured_pct", "gain_expected_pct"],
  rows: body.days.map((d) => [d.date, d.sky.clearness_index, d.tracker.measured_wh, d.tracker.expected_wh,
    d.tracker.expected_wh_low, d.tracker.expected_wh_high, d.tracker.performance_ratio, d.gain_measured_pct,
    d.gain_expected_pct]),
  filename: `${state.site.site_id}_diagnosis_${start}_${end}.csv` });
}

/** Wire the panel once; the range defaults to the 7 days up to the selected day. */
export function init(state) {
  const form = document.getElementById("diag-form");
  if (!form || !state.site) return;
  document.getElementById("diag-end").value = addDays(state.day, 1);
  document.getElementById("diag-start").value = addDays(state.day, -6);
  form.addEventListener("submit", (ev) => { ev.preventDefault(); load(state); });
}
