// Overview: report of a date range (day, week, month, year, custom) — totals, monthly and
// annual tables, CSV and a one-page PNG (GET /api/v1/sites/{id}/report, .csv, .png).
import { api } from "./api.js";
import { addDays } from "./time.js";
import { banner, energy, h, num, pct } from "./ui.js";

let st = null;
let controller = null;
const $ = (id) => document.getElementById(id);

/** [start, end) of the period of `kind` that holds `day` (weeks start on Monday). */
export function rangeOf(kind, day) {
  const [y, m] = day.split("-").map(Number);
  const pad = (n) => String(n).padStart(2, "0");
  if (kind === "day") return [day, addDays(day, 1)];
  if (kind === "week") {
    const dow = (new Date(`${day}T12:00:00Z`).getUTCDay() + 6) % 7;
    const monday = addDays(day, -dow);
    return [monday, addDays(monday, 7)];
  }
  if (kind === "month") return [`${y}-${pad(m)}-01`, m === 12 ? `${y + 1}-01-01` : `${y}-${pad(m + 1)}-01`];
  if (kind === "year") return [`${y}-01-01`, `${y + 1}-01-01`];
  return null;
}

function url(kind) {
  const q = new URLSearchParams({ start: $("report-start").value, end: $("report-end").value });
  return `/api/v1/sites/${encodeURIComponent(st.site.site_id)}/report${kind}?${q}`;
}

function ratio(v) {
  return typeof v === "number" ? num(v, 2) : "—";
}

function periodTable(rows, label, arrays, fmt) {
  if (!rows.length) return h("p", { class: "muted" }, "No period in the range.");
  const head = h("tr", {}, h("th", {}, label), ...arrays.flatMap((a) => [h("th", {}, `${a} measured`),
    h("th", {}, `${a} twin`), h("th", { title: "measured over the twin of the same minutes" }, `${a} PR`)]),
  h("th", {}, "gain measured"), h("th", { title: "the twin over the same minutes as the readings" }, "gain twin, same minutes"));
  const table = h("table", { class: "report" }, head);
  for (const r of rows) {
    table.append(h("tr", { class: r.partial ? "partial" : "", title: r.partial ? "partial: readings miss part of the twin's energy" : (r.twin_note || "") },
      h("td", {}, fmt(r.period_start), r.partial ? " (partial)" : ""),
      ...arrays.flatMap((a) => [h("td", {}, energy(r.arrays[a].measured_wh)), h("td", {}, energy(r.arrays[a].twin_wh)),
        h("td", {}, ratio(r.arrays[a].performance_ratio))]),
      h("td", {}, pct(r.gain_pct)), h("td", {}, pct(r.twin_matched_gain_pct))));
  }
  return table;
}

function drawTotals(rep) {
  const box = $("report-totals");
  box.innerHTML = "";
  const t = rep.totals;
  if (!rep.arrays.length) {
    box.append(h("p", { class: "muted" }, "This site has no PV arrays (a camera site): no energy to report."));
    return;
  }
  const table = h("table", { class: "report" }, h("tr", {}, h("th", {}, ""), h("th", {}, "Measured"), h("th", {}, "Twin"),
    h("th", {}, "Twin, same minutes"), h("th", {}, "Coverage"), h("th", { title: "measured / twin over the same minutes" }, "Performance ratio")));
  for (const a of rep.arrays) {
    const x = t.arrays[a];
    table.append(h("tr", {}, h("td", {}, a), h("td", {}, energy(x.measured_wh)), h("td", {}, energy(x.twin_wh)),
      h("td", {}, energy(x.twin_matched_wh)), h("td", {}, typeof x.coverage_pct === "number" ? `${num(x.coverage_pct, 1)} %` : "—"),
      h("td", { "data-testid": `report-pr-${a}` }, ratio(x.performance_ratio))));
  }
  box.append(table, h("p", { "data-testid": "report-gain" },
    `Tracking gain ${pct(t.gain_pct)} measured; the twin expects ${pct(t.twin_matched_gain_pct)} over the same minutes `
    + `(${pct(t.twin_gain_pct)} over the whole range).${t.partial ? " Partial: the readings do not cover the whole range." : ""}`));
}

/** Nothing of the previous range stays: its tables, its gain, its downloads. A range the
 * service refused left the previous range's months and years under its error, read as the
 * answer to the new one (a tester's finding). */
const REPORT_BANNER = "Report unavailable: ";

function clearReport(...message) {
  $("report-totals").replaceChildren(...message);
  $("report-months").replaceChildren();
  $("report-years").replaceChildren();
  $("report-csv").hidden = true;
  $("report-png").hidden = true;
  delete document.body.dataset.reportLoaded;
}

export async function load() {
  if (!st?.site) return;
  const start = $("report-start").value;
  const end = $("report-end").value;
  if (!start || !end) return;
  controller?.abort();
  controller = new AbortController();
  clearReport("Loading…");
  // the downloads of the range asked for now: the inputs may change while it loads
  const csv = url(".csv"), png = url(".png");
  try {
    const rep = await api(`/api/v1/sites/${encodeURIComponent(st.site.site_id)}/report`,
      { params: { start, end }, signal: controller.signal });
    drawTotals(rep);
    // ReportRead.readings_note: the service's words for a range no array has a reading in
    if (rep.readings_note) $("report-totals").prepend(h("div", { class: "banner", "data-testid": "report-no-readings" }, `${rep.readings_note}.`));
    $("report-months").replaceChildren(periodTable(rep.months, "Month", rep.arrays, (s) => s.slice(0, 7)));
    $("report-years").replaceChildren(periodTable(rep.years, "Year", rep.arrays, (s) => s.slice(0, 4)));
    $("report-csv").href = csv;
    $("report-png").href = png;
    $("report-csv").hidden = false;
    $("report-png").hidden = false;
    document.body.dataset.reportLoaded = `${st.site.site_id}/${start}/${end}`;
    // a refused range's banner goes with the answer that replaces it (another card's stays)
    if ($("banner").textContent.startsWith(REPORT_BANNER)) banner("");
  } catch (err) {
    if (err.name === "AbortError") return;
    clearReport(h("p", { class: "error", "data-testid": "report-error" }, err.message));
    banner(`${REPORT_BANNER}${err.message}`);
  }
}

function setKind() {
  const kind = $("report-kind").value;
  const range = rangeOf(kind, $("report-start").value || st.day);
  $("report-end").readOnly = kind !== "custom";
  if (range) [$("report-start").value, $("report-end").value] = range;
}

export function init(state) {
  st = state;
  setKind();
  $("report-kind").addEventListener("change", () => { setKind(); load(); });
  $("report-start").addEventListener("change", () => { setKind(); });
  $("report-form").addEventListener("submit", (ev) => { ev.preventDefault(); setKind(); load(); });
  load();
}

export function siteChanged(state) {
  st = state;
  load();
}
